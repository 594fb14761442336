r"""Optional compiled form of the single-query cascade mean (:meth:`cascgp.models.fastpath.FastPath.mean`).

Why compiled, and why by hand: one query of the 6-joint cascade at n = 500 is about 55,000 multiply-adds and
3,000 kernel evaluations, a few microseconds of arithmetic, but the NumPy form needs about ten array calls per
joint (the cascade chains the joints, so the kernel rows cannot be batched across them) and each costs a
microsecond of dispatch. One compiled loop over the joints and training points does the same arithmetic in a
single call, with no temporaries. Its exponential is evaluated in the loop itself (range reduction to
:math:`2^k e^r` and a polynomial, the constants below) rather than by the math library's ``exp``, which is a
call per element that the compiler cannot vectorise: the library call was a third of the query's time. Floating
multiply-adds may be fused (``fastmath={"contract"}``: one rounding instead of two).

The propagated variance (:meth:`cascgp.models.fastpath.FastVariance.mean_var`) has a compiled loop too
(:func:`jit_var`): its six triangular solves read 6 MB of factors at n = 500, the query's floor, and calling BLAS
``dtrsv`` joint by joint from Python added about a fifth on top (argument conversion, a scaled copy of the kernel
row, the dot product, the chaining). The loop calls the same BLAS ``dtrsv`` (SciPy's, through its Cython API), so
the solves are the same to the bit; only the sum of squares runs in another order than NumPy's dot.
The compiler is Numba, the standard just-in-time compiler for numerical Python
loops over NumPy arrays (no C toolchain at install time, the same source as the reference, cached on disk).

It is an optional fast path: used when ``numba`` can be imported and ``CASCGP_JIT`` is not ``0`` (or ``false``,
``no``, ``off``); otherwise (and as
the reference the tests compare with) :meth:`~cascgp.models.fastpath.FastPath.mean_numpy` runs. The two agree to
round-off (the sums run in another order; the kernel's ``exp``/``sqrt`` may differ in the last bit).
"""

from __future__ import annotations

import ctypes
import importlib
import math
import os
import warnings
from typing import Any, Callable

import numpy as np

from cascgp.data import F64 as _F64

__all__ = ["jit_mean", "jit_enabled", "jit_var", "jit_var_factors", "warn_dropped"]

_KERNEL_IDS = {"matern52": 0, "rbf": 1, "matern32": 2}
# exp(x), x = -s <= 0, as 2^k e^r: k = round(x / ln 2), r = x - k ln 2 (Cody-Waite: ln 2 in two parts, the first
# with trailing zero bits so that k ln2_hi is exact), |r| <= ln(2) / 2, e^r by its Taylor polynomial of degree 13
# (remainder below 1e-17 relative), 2^k from its exponent bits. Below e^-708 (k near the smallest normal
# exponent) the result is 0: the kernel values there are below 1e-300.
_EXP_MAX = 708.0
_LOG2E = 1.4426950408889634
_LN2_HI = 6.93147180369123816490e-01
_LN2_LO = 1.90821492927058770002e-10
_THIRD = 1.0 / 3.0
_SIXTH = 1.0 / 6.0
_C3, _C4, _C5, _C6, _C7, _C8, _C9, _C10, _C11, _C12, _C13 = (1.0 / math.factorial(i) for i in range(3, 14))
_compiled: dict[str, Callable[..., Any] | None] = {}


def jit_enabled() -> bool:
    """Whether the compiled path may be used: ``CASCGP_JIT`` unset or not one of ``0``, ``false``, ``no``, ``off``
    (any case), and ``numba`` importable."""
    if os.environ.get("CASCGP_JIT", "1").strip().lower() in ("0", "false", "no", "off"):
        return False
    return _kernel() is not None


def kernel_id(name: str) -> int:
    """The compiled kernel's code of a kernel name (-1: not compiled)."""
    return _KERNEL_IDS.get(name, -1)


def _source(ints: np.ndarray, flts: np.ndarray, WT: np.ndarray, W2: np.ndarray, Zt: np.ndarray, alpha: np.ndarray,
            zc: float, kid: int, buf: np.ndarray, tau: np.ndarray, has_tau: bool, out: np.ndarray, want_var: bool,
            K: np.ndarray, G: np.ndarray) -> None:  # pragma: no cover - runs compiled (tests compare it)
    """The loop Numba compiles: :meth:`FastPath.mean_numpy` fused over the joints, with the training inputs
    transposed (``WT``: ``(N, D, n)``) so that the distance loops run along the training points (SIMD). With
    ``want_var`` also each joint's kernel row ``K[j]`` and the derivative of its mean in the torque input
    ``G[j]`` (0 without one), what :meth:`FastVariance.mean_var` needs besides the solves. The fast path's small
    fixed arrays come packed in two (:func:`pack_fixed`): fewer arguments to convert per call."""
    N = ints.shape[0]
    D = ints.shape[1] - 3
    n = WT.shape[2]
    z = np.empty(D)
    dot = np.empty(n)
    a = np.empty(n)
    s = np.empty(n)
    e = np.empty(n)
    kv = np.empty(n)
    ib = np.empty(n, dtype=np.int64)
    eb = ib.view(np.float64)
    for jj in range(N):
        j = ints[jj, D + 2]  # the cascade's order
        nc = ints[j, D]  # state columns of joint j
        zz = 0.0
        for d in range(nc):
            v = (buf[ints[j, d]] - flts[j, d]) * flts[j, D + d]
            v = min(max(v, -zc), zc)
            z[d] = v
            zz += v * v
        dot[:] = 0.0
        for d in range(0, nc, 3):  # a joint's state columns come in threes (q, s', s'')
            z0, z1, z2 = z[d], z[d + 1], z[d + 2]
            for k in range(n):
                dot[k] += WT[j, d, k] * z0 + WT[j, d + 1, k] * z1 + WT[j, d + 2, k] * z2
        tj = ints[j, D + 1]
        tq = 0.0
        if tj >= 0:  # chain: the neighbour's PREDICTED torque
            tq = (out[tj] - flts[j, 2 * D]) * flts[j, 2 * D + 1]
            tq = min(max(tq, -zc), zc)
            for k in range(n):
                dt = Zt[j, k] - tq
                a[k] = dt * dt + max(W2[j, k] - 2.0 * dot[k] + zz, 0.0)
        else:
            for k in range(n):
                a[k] = max(W2[j, k] - 2.0 * dot[k] + zz, 0.0)
        # Matern 5/2 in a = 5 r^2: kappa = (1 + rho + a / 3) e^{-rho}, rho = sqrt(a); Matern 3/2 in a = 3 r^2:
        # kappa = (1 + rho) e^{-rho}
        if kid != 1:
            for k in range(n):
                s[k] = np.sqrt(a[k])
        else:  # RBF in a = r^2 / 2: kappa = e^{-a}
            for k in range(n):
                s[k] = a[k]
        for k in range(n):  # e[k] = exp(-s[k]), in SIMD lanes (module docstring)
            x = -min(s[k], _EXP_MAX)
            kf = np.floor(x * _LOG2E + 0.5)
            r = (x - kf * _LN2_HI) - kf * _LN2_LO
            p = ((((_C13 * r + _C12) * r + _C11) * r + _C10) * r + _C9) * r + _C8
            p = ((((((p * r + _C7) * r + _C6) * r + _C5) * r + _C4) * r + _C3) * r + 0.5) * r + 1.0
            e[k] = p * r + 1.0
            ib[k] = (np.int64(kf) + 1023) << 52
        for k in range(n):
            e[k] = e[k] * eb[k] if s[k] <= _EXP_MAX else 0.0
        if kid == 0:
            for k in range(n):
                kv[k] = (1.0 + s[k] + a[k] * _THIRD) * e[k]
        elif kid == 2:
            for k in range(n):
                kv[k] = (1.0 + s[k]) * e[k]
        else:
            for k in range(n):
                kv[k] = e[k]
        a0 = a1 = a2 = a3 = 0.0  # four interleaved partial sums: independent adds
        n4 = n - n % 4
        for k in range(0, n4, 4):
            a0 += kv[k] * alpha[j, k]
            a1 += kv[k + 1] * alpha[j, k + 1]
            a2 += kv[k + 2] * alpha[j, k + 2]
            a3 += kv[k + 3] * alpha[j, k + 3]
        for k in range(n4, n):
            a0 += kv[k] * alpha[j, k]
        acc = (a0 + a1) + (a2 + a3)
        gacc = 0.0
        if want_var:
            for k in range(n):
                K[j, k] = kv[k]
            if tj >= 0:  # d kappa / d a: -(1 + rho) e^{-rho} / 6 (Matern 5/2), -e^{-rho} / 2 (3/2), -e^{-a} (RBF)
                if kid == 0:
                    for k in range(n):
                        gacc -= ((1.0 + s[k]) * e[k] * _SIXTH) * (tq - Zt[j, k]) * alpha[j, k]
                elif kid == 2:
                    for k in range(n):
                        gacc -= (0.5 * e[k]) * (tq - Zt[j, k]) * alpha[j, k]
                else:
                    for k in range(n):
                        gacc -= e[k] * (tq - Zt[j, k]) * alpha[j, k]
        if want_var:
            G[j] = 2.0 * flts[j, 2 * D + 1] * gacc
        m = flts[j, 2 * D + 2] + acc
        if has_tau:
            m += tau[j]
        out[j] = m


def _var_source(trsv: Any, Lc: tuple, scale: np.ndarray, prior: np.ndarray, ints: np.ndarray, K: np.ndarray,
                G: np.ndarray, var: np.ndarray, u: np.ndarray, fi: np.ndarray, ch: np.ndarray,
                window: tuple | None) -> None:  # pragma: no cover - runs compiled (tests compare it)
    r"""The loop Numba compiles: :meth:`FastVariance.mean_var`'s per-joint part after the kernel rows, in the
    cascade's order (``ints`` as in :func:`pack_fixed`). ``trsv``: BLAS ``dtrsv`` (:func:`blas_routine`), called
    as :meth:`FastVariance.solve` calls it (``Lc[j]``, joint j's C-ordered lower factor, is the Fortran-ordered
    :math:`L_j^\top` that BLAS reads; ``fi``, ``ch``: work arrays for its integer and character arguments), so
    :math:`u = L_j^{-1} c_j \kappa_j` is the same to the bit; ``var[j]`` is :math:`\max(p_j - \|u\|^2 - e_j, 0)`
    plus :math:`G_j^2` times the neighbour's variance.

    ``window``: None (:math:`e_j = 0`; Numba compiles this case without the window's code), or an online window
    (:meth:`cascgp.models.online._JointWindow.extra_var`) as ``(gemv, symv, held, Lw, ST, v, y, fd)``: BLAS
    ``dgemv`` and ``dsymv``, the samples held, per joint :math:`L_{w0}` (C-ordered) and the memory of the
    Fortran-ordered :math:`S^{-1}` (lower triangle), and work arrays; with samples held,
    :math:`e_j = v^\top S^{-1} v`, :math:`v = c_j \kappa_{jw} - L_{w0} u`, by SciPy's BLAS ``dgemv`` and ``dsymv``
    (the per-joint path calls the same ``dsymv``; its product :math:`L_{w0} u` runs in NumPy's BLAS)."""
    N = ints.shape[0]
    D = ints.shape[1] - 3
    ch[0], ch[1], ch[2], ch[3] = 85, 84, 78, 76  # "U", "T", "N": L^T upper, transposed, not unit; "L": lower
    for jj in range(N):
        j = ints[jj, D + 2]
        L = Lc[j]
        n0 = L.shape[0]
        c = scale[j]
        for i in range(n0):
            u[i] = c * K[j, i]
        fi[0], fi[1], fi[2] = n0, n0, 1  # n, lda, incx
        trsv(ch[0:].ctypes, ch[1:].ctypes, ch[2:].ctypes, fi[0:].ctypes, L.ctypes, fi[1:].ctypes, u.ctypes,
             fi[2:].ctypes)
        q = 0.0
        for i in range(n0):
            q += u[i] * u[i]
        if window is not None:
            gemv, symv, held, Lw, ST, v, y, fd = window
            if held:
                Wn = ST[j].shape[0]
                if not (Lw[j].flags.c_contiguous and ST[j].flags.c_contiguous and Lw[j].shape == (Wn, n0)
                        and ST[j].shape[1] == Wn and K.shape[1] >= n0 + Wn and v.shape[0] >= Wn
                        and y.shape[0] >= Wn):
                    raise ValueError("online variance: BLAS reads L_w0 (W, n0) and the inverse (W, W) as contiguous "
                                     "blocks, with W kernel values per joint after the fitted set's")
                fi[3] = Wn
                fd[0], fd[1] = 1.0, 0.0  # BLAS's alpha and beta
                gemv(ch[1:].ctypes, fi[0:].ctypes, fi[3:].ctypes, fd[0:].ctypes, Lw[j].ctypes, fi[1:].ctypes,
                     u.ctypes, fi[2:].ctypes, fd[1:].ctypes, y.ctypes, fi[2:].ctypes)  # y = L_w0 u
                for i in range(Wn):
                    v[i] = c * K[j, n0 + i] - y[i]
                symv(ch[3:].ctypes, fi[3:].ctypes, fd[0:].ctypes, ST[j].ctypes, fi[3:].ctypes, v.ctypes,
                     fi[2:].ctypes, fd[1:].ctypes, y.ctypes, fi[2:].ctypes)  # y = S^-1 v
                e = 0.0
                for i in range(Wn):
                    e += v[i] * y[i]
                q += e
        w = max(prior[j] - q, 0.0)
        tj = ints[j, D + 1]
        if tj >= 0:
            w += G[j] * G[j] * var[tj]
        var[j] = w


def warn_dropped(what: str, exc: Exception, instead: str = "the NumPy path", stacklevel: int = 4) -> None:
    """Warn that a compiled loop (``what``) is not used because of ``exc``, and that ``instead`` runs."""
    warnings.warn(f"cascgp: the compiled {what} is not used ({type(exc).__name__}: {exc}); {instead} runs",
                  RuntimeWarning, stacklevel=stacklevel)


def _kernel() -> Callable[..., Any] | None:
    """The compiled :func:`_source` (compiled once per process, cached on disk), or None without Numba."""
    if "mean" not in _compiled:
        try:
            numba: Any = importlib.import_module("numba")
            _compiled["mean"] = numba.njit(cache=True, nogil=True, fastmath={"contract"})(_source)
        except ImportError:
            _compiled["mean"] = None
        except Exception as exc:  # noqa: BLE001 - e.g. no writable cache location (Numba checks when it decorates)
            warn_dropped("single-query loop", exc)
            _compiled["mean"] = None
    return _compiled["mean"]


def _var_kernel() -> Callable[..., Any] | None:
    """The compiled :func:`_var_source` (as :func:`_kernel`), or None without Numba."""
    if "var" not in _compiled:
        try:
            numba: Any = importlib.import_module("numba")
            _compiled["var"] = numba.njit(cache=True, nogil=True)(_var_source)
        except ImportError:
            _compiled["var"] = None
        except Exception as exc:  # noqa: BLE001 - as in _kernel
            warn_dropped("variance loop", exc)
            _compiled["var"] = None
    return _compiled["var"]


#: BLAS routines the compiled loops call (here and in :mod:`cascgp.models.online_kernel`), by SciPy's Cython API
#: name, with their number of arguments (every one a pointer: Fortran).
BLAS_ARGS = {"dtrsv": 8, "dgemv": 11, "dsymv": 10, "dsyr": 7}


def blas_routine(name: str) -> Any:
    """SciPy's BLAS routine ``name`` (of :data:`BLAS_ARGS`; what ``scipy.linalg.blas`` wraps) as a ctypes function
    that compiled code calls, looked up once per process. Passed to the compiled loops as an argument, not read
    as a global, so that Numba can cache the loops on disk."""
    if name not in _compiled:
        extending: Any = importlib.import_module("numba.extending")
        vp = ctypes.c_void_p
        addr = extending.get_cython_function_address("scipy.linalg.cython_blas", name)
        _compiled[name] = ctypes.CFUNCTYPE(None, *([vp] * BLAS_ARGS[name]))(addr)
    return _compiled[name]


#: Position of the transposed training inputs ``WT`` in :func:`jit_args`' tuple (online samples write into it).
JIT_WT = 2


def pack_fixed(idx: np.ndarray, ncol: np.ndarray, xm: np.ndarray, xsi: np.ndarray, tfrom: np.ndarray,
               order: np.ndarray, tmean: np.ndarray, tsi: np.ndarray, ymean: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """The fast path's small arrays that never change after the build, packed for :func:`_source`: integers
    ``(N, D + 3)`` = ``[idx | ncol | tfrom | order]``, floats ``(N, 2 D + 3)`` = ``[xm | xsi | tmean | tsi |
    ymean]`` (the same values, copied)."""
    N, D = idx.shape
    ints = np.empty((N, D + 3), dtype=np.int64)
    ints[:, :D], ints[:, D], ints[:, D + 1], ints[:, D + 2] = idx, ncol, tfrom, order
    flts = np.empty((N, 2 * D + 3))
    flts[:, :D], flts[:, D:2 * D] = xm, xsi
    flts[:, 2 * D], flts[:, 2 * D + 1], flts[:, 2 * D + 2] = tmean, tsi, ymean
    return ints, flts


def jit_args(kernel: str, arrays: tuple) -> tuple | None:
    """The compiled mean's leading arguments, compiled and run once now so that the first control tick does not
    pay for it: from the fast path's ``(idx, ncol, xm, xsi, WT, W2, tfrom, order, tmean, tsi, Zt, alpha, ymean,
    zc)``, the packed fixed arrays (:func:`pack_fixed`), ``WT``, ``W2``, ``Zt``, ``alpha`` (the same objects:
    online samples write into them), ``zc`` and the kernel's code. None when the compiled path is not enabled
    (:func:`jit_enabled`) or the kernel has no compiled form."""
    kid = kernel_id(kernel)
    if kid < 0 or not jit_enabled():
        return None
    idx, ncol, xm, xsi, WT, W2, tfrom, order, tmean, tsi, Zt, alpha, ymean, zc = arrays
    args = (*pack_fixed(idx, ncol, xm, xsi, tfrom, order, tmean, tsi, ymean), WT, W2, Zt, alpha, zc, kid)
    N, D = idx.shape
    out = np.zeros(N)
    try:
        jit_mean(args, np.zeros(D + 1), None, out)
    except Exception as exc:  # noqa: BLE001 - e.g. no writable cache location: the NumPy path still works
        warn_dropped("single-query loop", exc)
        _compiled["mean"] = None
        return None
    return args


def jit_mean(args: tuple, buf: np.ndarray, tau: np.ndarray | None, out: np.ndarray,
             var_out: tuple[np.ndarray, np.ndarray] | None = None) -> bool:
    """Run the compiled mean with :func:`jit_args`' ``args`` for the state in ``buf`` into ``out`` (``tau``: the
    SP models' RBD torque added to each joint's GP mean); ``var_out``: ``(K, G)`` to fill as in :func:`_source`.
    False (nothing written) if the compiled loop has been dropped since (a later build failed)."""
    fn = _compiled.get("mean")
    if fn is None:
        return False
    if tau is None:
        t = out
    elif type(tau) is np.ndarray and tau.dtype == _F64 and tau.flags.c_contiguous:
        t = tau  # what np.ascontiguousarray returns for it
    else:
        t = np.ascontiguousarray(tau, dtype=np.float64)
    if var_out is None:
        fn(*args, buf, t, tau is not None, out, False, _NO_K, out)
    else:
        fn(*args, buf, t, tau is not None, out, True, var_out[0], var_out[1])
    return True


_NO_K = np.zeros((1, 1))


def jit_var_factors(factors: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...] | None:
    """The compiled variance's factors (each joint's lower Cholesky factor, C-ordered: the same arrays when they
    are), compiled and run once now (as :func:`jit_args`); None when the compiled path is not enabled."""
    fn = _var_kernel() if jit_enabled() else None
    if fn is None:
        return None
    Lc = tuple(np.ascontiguousarray(L, dtype=np.float64) for L in factors)
    N = len(Lc)
    ints = np.zeros((N, 3), dtype=np.int64)
    ints[:, 1], ints[:, 2] = -1, np.arange(N)
    n = max(L.shape[0] for L in Lc)
    try:
        fn(blas_routine("dtrsv"), Lc, np.ones(N), np.ones(N), ints, np.zeros((N, n)), np.zeros(N), np.zeros(N),
           np.zeros(n), np.zeros(4, dtype=np.int32), np.zeros(4, dtype=np.uint8), None)
    except Exception as exc:  # noqa: BLE001 - as in jit_args: the NumPy path still works
        warn_dropped("variance loop", exc)
        _compiled["var"] = None
        return None
    return Lc


def jit_var(args: tuple, Lc: tuple[np.ndarray, ...], scale: np.ndarray, prior: np.ndarray, K: np.ndarray,
            G: np.ndarray, var: np.ndarray, window: tuple | None = None) -> bool:
    """Each joint's propagated latent variance into ``var`` from the kernel rows ``K`` and mean derivatives ``G``
    that :func:`jit_mean` wrote (``args``: its :func:`jit_args`; ``Lc``: :func:`jit_var_factors`; ``window``: an
    online window's ``(held, Lw, ST)``, :meth:`cascgp.models.online.OnlineWindow.compiled_var_terms`). False
    (nothing written) if the compiled loop has been dropped since."""
    fn = _compiled.get("var")
    if fn is None:
        return False
    if window is not None:
        held, Lw, ST = window
        nw = ST[0].shape[0]
        window = (blas_routine("dgemv"), blas_routine("dsymv"), held, Lw, ST, np.zeros(nw), np.zeros(nw), np.empty(2))
    fn(blas_routine("dtrsv"), Lc, scale, prior, args[0], K, G, var, np.empty(K.shape[1]), np.empty(4, dtype=np.int32),
       np.empty(4, dtype=np.uint8), window)
    return True
