r"""Optional compiled form of an online sample (:meth:`cascgp.models.online.OnlineWindow.add`).

Why compiled, and why by hand: a sample's arithmetic for a 6-joint cascade at n = 500 with a window of 150 is six
pairs of triangular solves with the fitted factors and two products with each window's :math:`B` (about 19 MB of
memory read: those BLAS calls alone take 0.4-0.6 ms on a 2-core machine, ``scripts.bench_online``), but the NumPy
form issues some forty array calls per joint (the proposal, the rank-one updates, the fast path's rows), each a
microsecond or more of dispatch, which more than doubled the cost. One compiled call proposes the sample to every
joint and a second commits it. The memory-heavy steps are the same BLAS routines the NumPy path calls (SciPy's
``dtrsv``, ``dgemv``, ``dsymv`` and ``dsyr``, through its Cython API, passed to the loops as arguments so that Numba
caches them); what is written here is the glue between them (kernel values, dot products, copies), in the NumPy
path's order of operations. The two paths agree to round-off (NumPy's ``exp`` and dot products may differ in the
last bit). The compiler is Numba, as for the control tick (:mod:`cascgp.models.fastkernel`); without it, or with
``CASCGP_JIT=0``, the NumPy path runs.
"""

from __future__ import annotations

import functools
import importlib
import math
from typing import Any

import numpy as np

from cascgp.models.fastkernel import BLAS_ARGS, blas_routine

__all__ = ["CONSTS", "blas", "propose", "commit"]

#: ImportError without Numba (the ``fast`` extra): :mod:`cascgp.models.online` then runs the NumPy path.
numba: Any = importlib.import_module("numba")
_jit = numba.njit(cache=True, nogil=True, error_model="numpy")  # x / 0 is inf or NaN, as in NumPy
_SQRT5 = math.sqrt(5.0)
_SQRT3 = math.sqrt(3.0)
#: Columns of the per-joint constants :func:`propose` and :func:`commit` take: signal variance, noise (plus
#: jitter), target mean, target scale, the fast path's weight scale (target scale times signal variance).
CONSTS = ("signal_var", "noise", "y_mean", "y_std", "scale")


@_jit
def _kval(kid: int, r2: float) -> float:  # pragma: no cover - runs compiled
    """:meth:`cascgp.gp.kernels.Kernel.value` of one squared distance (0: Matern 5/2, 1: RBF, 2: Matern 3/2)."""
    r2 = max(r2, 0.0)
    if kid == 0:
        sr = _SQRT5 * math.sqrt(r2)
        return (1.0 + sr + (5.0 / 3.0) * r2) * math.exp(-sr)
    if kid == 2:
        sr = _SQRT3 * math.sqrt(r2)
        return (1.0 + sr) * math.exp(-sr)
    return math.exp(-0.5 * r2)


@_jit
def _trsv(fn: Any, trans: int, L: np.ndarray, x: np.ndarray, fi: np.ndarray,
          ch: np.ndarray) -> None:  # pragma: no cover
    r"""``x <- L^-1 x`` (``trans`` "T", 84) or ``L^-T x`` ("N", 78): BLAS ``dtrsv`` on the Fortran-ordered
    :math:`L^\top` whose memory is the C-ordered lower factor ``L`` (what ``dtrsv(U00, x, lower=0, trans=...)``
    calls)."""
    n = L.shape[0]
    ch[0], ch[1], ch[2] = 85, trans, 78  # "U", trans, "N" (not unit)
    fi[0], fi[1], fi[2] = n, n, 1
    fn(ch[0:].ctypes, ch[1:].ctypes, ch[2:].ctypes, fi[0:].ctypes, L.ctypes, fi[1:].ctypes, x.ctypes, fi[2:].ctypes)


@_jit
def _gemv(fn: Any, trans: int, m: int, n: int, A: np.ndarray, x: np.ndarray, y: np.ndarray, fi: np.ndarray,
          fd: np.ndarray, ch: np.ndarray) -> None:  # pragma: no cover
    """``y <- op(A) x`` by BLAS ``dgemv`` for the Fortran-ordered ``(m, .)`` matrix whose memory is the C-ordered
    ``A`` (leading dimension ``A.shape[1]``): ``trans`` "T" (84) gives ``A[:n] @ x``, "N" (78) ``x @ A[:n]``."""
    ch[0] = trans
    fi[0], fi[1], fi[2], fi[3] = m, n, A.shape[1], 1
    fd[0], fd[1] = 1.0, 0.0
    fn(ch[0:].ctypes, fi[0:].ctypes, fi[1:].ctypes, fd[0:].ctypes, A.ctypes, fi[2:].ctypes, x.ctypes,
       fi[3:].ctypes, fd[1:].ctypes, y.ctypes, fi[3:].ctypes)


@_jit
def _without(symv: Any, o: int, ST: np.ndarray, x: np.ndarray, t: np.ndarray, has_t: bool, y: np.ndarray,
             fi: np.ndarray, fd: np.ndarray, ch: np.ndarray) -> None:  # pragma: no cover
    """:meth:`cascgp.models.online._JointWindow._without` into ``y``: ``S^-1 x`` (BLAS ``dsymv``, lower
    triangle of the Fortran-ordered :math:`S^{-1}` whose memory is ``ST``) with slot ``o`` left out."""
    W = ST.shape[0]
    ch[0] = 76  # "L"
    fi[0], fi[1] = W, 1
    fd[0], fd[1] = 1.0, 0.0
    symv(ch[0:].ctypes, fi[0:].ctypes, fd[0:].ctypes, ST.ctypes, fi[0:].ctypes, x.ctypes, fi[1:].ctypes,
         fd[1:].ctypes, y.ctypes, fi[1:].ctypes)
    if has_t:
        f = np.dot(t, x) / t[o]
        for i in range(W):
            y[i] -= t[i] * f
    y[o] = 0.0


@_jit
def _syr(fn: Any, alpha: float, x: np.ndarray, ST: np.ndarray, fi: np.ndarray, fd: np.ndarray,
         ch: np.ndarray) -> None:  # pragma: no cover
    """Lower triangle of :math:`S^{-1}` (memory ``ST``) ``+= alpha x x^T``: BLAS ``dsyr``."""
    ch[0] = 76
    fi[0], fi[1] = ST.shape[0], 1
    fd[0] = alpha
    fn(ch[0:].ctypes, fi[0:].ctypes, fd[0:].ctypes, x.ctypes, fi[1:].ctypes, ST.ctypes, fi[0:].ctypes)


@_jit
def propose(trsv: Any, gemv: Any, symv: Any, kid: int, zlim: float, m: int, n_in: int, xs: tuple,
            y: np.ndarray, consts: np.ndarray, xm: tuple, xsc: tuple, Lf: tuple, Z: tuple, Z2: tuple,
            u0: tuple, alpha_fit: tuple, Zw: tuple, B: tuple, ST: tuple, r: tuple, Pz: np.ndarray,
            Prow: np.ndarray, Pb: np.ndarray, Pa0: np.ndarray, Pk: np.ndarray, Ps: np.ndarray,
            Pt: np.ndarray, Phv: np.ndarray, Pr: np.ndarray, Paw: np.ndarray, Pw: np.ndarray,
            Psc: np.ndarray, fi: np.ndarray, fd: np.ndarray, ch: np.ndarray) -> int:  # pragma: no cover
    """Every joint's :meth:`~cascgp.models.online._JointWindow.propose` (same steps, same names) into the
    ``P*`` rows, changing nothing of the windows: ``-1``, or the first joint whose enlarged matrix would not be
    positive definite (its Schur complement in ``Psc[j, 1]``). ``Lf[j]``: the C-ordered lower factor (the memory
    of ``U00``); ``ST[j]``: the memory of the Fortran-ordered :math:`S^{-1}` (its transpose, C-ordered)."""
    N = len(Z)
    W = Zw[0].shape[0]
    o = n_in % W  # the slot of the new sample: that of the oldest when the window is full
    drop = m == W
    h = W if drop else m  # slots held
    for j in range(N):
        if not (Lf[j].flags.c_contiguous and B[j].flags.c_contiguous and ST[j].flags.c_contiguous):
            raise ValueError("online sample: BLAS reads the factor, B and the inverse as contiguous blocks")
        n0, d = Z[j].shape
        sv, noise = consts[j, 0], consts[j, 1]
        x, mu, sc, z = xs[j], xm[j], xsc[j], Pz[j]
        zz = 0.0
        for i in range(d):  # the normalised, clipped input (OnlineWindow._add)
            v = (x[i] - mu[i]) / sc[i] if math.isfinite(sc[i]) else 0.0
            v = min(max(v, -zlim), zlim)
            z[i] = v
            zz += v * v
        k0, row, b = Pk[j], Prow[j], Pb[j]
        Zj, Z2j = Z[j], Z2[j]
        for k in range(n0):  # |z - Z_k|^2 expanded
            dz = 0.0
            for i in range(d):
                dz += Zj[k, i] * z[i]
            k0[k] = sv * _kval(kid, Z2j[k] - 2.0 * dz + zz)
            row[k] = k0[k]
        _trsv(trsv, 84, Lf[j], row, fi, ch)  # L00^-1 k0
        for k in range(n0):
            b[k] = row[k]
        _trsv(trsv, 78, Lf[j], b, fi, ch)  # L00^-T L00^-1 k0
        s, w = Ps[j], Pw[j]
        s[:] = 0.0
        if h:
            _gemv(gemv, 84, n0, h, B[j], k0, w, fi, fd, ch)  # B[:h] @ k0
            Zwj = Zw[j]
            for i in range(h):
                dd = 0.0
                for q in range(d):
                    e = z[q] - Zwj[i, q]
                    dd += e * e
                s[i] = sv * _kval(kid, dd) - w[i]
            s[o] = 0.0
        c = sv + noise - np.dot(row, row)
        t, STj = Pt[j], ST[j]
        if drop:  # column o of S^-1 from its lower triangle: STj[a, b] is S^-1[b, a]
            for i in range(W):
                t[i] = STj[o, i] if i >= o else STj[i, o]
        g = Phv[j]
        _without(symv, o, STj, s, t, drop, g, fi, fd, ch)
        delta = c - np.dot(s, g)
        Psc[j, 0], Psc[j, 1] = c, delta
        ok = delta > 0.0 and math.isfinite(delta)
        for i in range(W):
            ok = ok and math.isfinite(g[i])
        for k in range(n0):
            ok = ok and math.isfinite(b[k])
        if not ok:
            return j
        rn = Pr[j]
        rn[:] = r[j]
        rn[o] = (y[j] - consts[j, 2]) / consts[j, 3] - np.dot(row, u0[j])  # the normalised target's residual
        hv = g  # g is not needed after this: hv = g with hv[o] = -1
        hv[o] = -1.0  # S_new^-1 = (S^-1 without o) + hv hv^T / delta
        aw = Paw[j]
        _without(symv, o, STj, rn, t, drop, aw, fi, fd, ch)
        f = np.dot(hv, rn) / delta
        for i in range(W):
            aw[i] += hv[i] * f
        a0 = Pa0[j]
        _gemv(gemv, 78, n0, W, B[j], aw, a0, fi, fd, ch)  # aw @ B
        af, Bj = alpha_fit[j], B[j]
        for k in range(n0):
            a0[k] = af[k] - a0[k]
        f = aw[o]
        for k in range(n0):  # B's row o: the new sample's
            a0[k] += f * (Bj[o, k] - b[k])
    return -1


@_jit
def commit(syr: Any, m: int, n_in: int, consts: np.ndarray, tfrom: np.ndarray, c: float, Zw: tuple,
           B: tuple, Lw0: tuple, S: tuple, ST: tuple, r: tuple, alphaw: tuple, alpha0: tuple,
           fW: np.ndarray, fW2: np.ndarray, fWT: np.ndarray, has_WT: bool, fZt: np.ndarray,
           falpha: np.ndarray, Pz: np.ndarray, Prow: np.ndarray, Pb: np.ndarray, Pa0: np.ndarray,
           Ps: np.ndarray, Pt: np.ndarray, Phv: np.ndarray, Pr: np.ndarray, Paw: np.ndarray,
           Psc: np.ndarray, fi: np.ndarray, fd: np.ndarray, ch: np.ndarray) -> None:  # pragma: no cover
    """Every joint's :meth:`~cascgp.models.online._JointWindow.commit` of :func:`propose`'s rows, and the
    fast path's rows and weights (``OnlineWindow._add``); the counts and the periodic recomputation stay with
    the caller."""
    N = len(B)
    W = Zw[0].shape[0]
    o = n_in % W
    drop = m == W
    for j in range(N):
        n0 = B[j].shape[1]
        d = Zw[j].shape[1]
        STj, t = ST[j], Pt[j]
        if not STj.flags.c_contiguous:
            raise ValueError("online sample: BLAS writes the inverse as a contiguous block")
        if drop:
            _syr(syr, -1.0 / t[o], t, STj, fi, fd, ch)
            for i in range(W):
                STj[o, i] = 0.0
                STj[i, o] = 0.0
        _syr(syr, 1.0 / Psc[j, 1], Phv[j], STj, fi, fd, ch)
        Sj, s = S[j], Ps[j]
        for i in range(W):
            Sj[o, i] = s[i]
            Sj[i, o] = s[i]
        Sj[o, o] = Psc[j, 0]
        z = Pz[j]
        for i in range(d):
            Zw[j][o, i] = z[i]
        for k in range(n0):
            B[j][o, k] = Pb[j, k]
            Lw0[j][o, k] = Prow[j, k]
            alpha0[j][k] = Pa0[j, k]
        for i in range(W):
            r[j][i] = Pr[j, i]
            alphaw[j][i] = Paw[j, i]
        ds = d - (tfrom[j] >= 0)
        row_ = n0 + o
        nn = 0.0
        for i in range(fW.shape[2]):
            v = c * z[i] if i < ds else 0.0
            fW[j, row_, i] = v
            if has_WT:
                fWT[j, i, row_] = v
            nn += v * v
        fW2[j, row_] = nn
        if tfrom[j] >= 0:
            fZt[j, row_] = c * z[ds]
        scale = consts[j, 4]
        for k in range(n0):
            falpha[j, k] = Pa0[j, k] * scale
        for i in range(W):
            falpha[j, n0 + i] = Paw[j, i] * scale


@functools.cache
def blas() -> dict[str, Any]:
    """SciPy's BLAS ``dtrsv``, ``dgemv``, ``dsymv`` and ``dsyr`` as ctypes functions that compiled code calls
    (:func:`cascgp.models.fastkernel.blas_routine`), gathered once per process (two lookups per sample)."""
    return {name: blas_routine(name) for name in BLAS_ARGS}
