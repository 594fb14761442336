r"""The batched negative log marginal likelihood of exact GPs and its analytic gradient (the cost of a fit).

Negative log marginal likelihood and its gradient
-------------------------------------------------
With :math:`K = s_f^2 k(R^2) + s_n^2 I = L L^\top` and :math:`\alpha = K^{-1} \tilde y`,

.. math::

    \mathcal L(\theta) = \tfrac12 \tilde y^\top \alpha + \sum_i \log L_{ii} + \tfrac n2 \log 2\pi,
    \qquad
    \frac{\partial \mathcal L}{\partial \theta_j}
    = \tfrac12 \operatorname{tr}\!\Big(M \frac{\partial K}{\partial \theta_j}\Big),
    \quad M = K^{-1} - \alpha\alpha^\top.

For the lengthscales, with scaled inputs :math:`Z = \tilde X \operatorname{diag}(1/\ell)`,
:math:`\partial K_{ij} / \partial \log \ell_k = -2 s_f^2 k'(r^2_{ij}) (z_{ik} - z_{jk})^2`. Writing
:math:`P = M \circ s_f^2 k'(R^2)` (symmetric),

.. math::

    \frac{\partial \mathcal L}{\partial \log \ell_k}
      = -\sum_{ij} P_{ij} (z_{ik} - z_{jk})^2
      = -2 \Big( \sum_i z_{ik}^2 (P\mathbf 1)_i - \sum_i z_{ik} (P Z)_{ik} \Big),

which costs one ``(n, n) @ (n, d)`` product: :math:`O(n^2 d)` without an ``(n, n, d)`` tensor. Further
:math:`\partial \mathcal L / \partial \log s_f^2 = \tfrac12 s_f^2 \sum_{ij} M_{ij} k_{ij}` and
:math:`\partial \mathcal L / \partial \theta_{d+2} = \tfrac12 e^{\theta_{d+2}} \operatorname{tr} M` (with the
``snr_max`` floor, :math:`\partial \mathcal L / \partial \log s_f^2` gains :math:`\tfrac12 (s_f^2/\rho_{\max})
\operatorname{tr} M`).

Cost of one evaluation (:func:`nll_and_grad`): per start, one Cholesky (LAPACK ``dpotrf``, :math:`n^3/3` flops),
two triangular solves for :math:`\alpha`, :math:`K^{-1}` from the factor (``dpotri``, :math:`2n^3/3`), and
:math:`O(n^2 d)` for the kernel and the gradient (one ``(n, n) @ (n, d)`` product on the upper triangle of
:math:`P`). The element-wise work runs on cache-sized blocks with reused buffers (no ``(n, n)`` temporaries), and
OpenBLAS runs on one thread during a fit (:func:`blas_threads`). Only the three LAPACK calls and the NLL run member
by member; the kernel and the gradient are batched over the block, which matters at small n where a block holds
many members (a fit at n = 8 and 28 costs about half as much per evaluation as with the gradient's tensor
operations issued member by member: ``docs/bench/bench_scaling_block_gradient.json``). Measured at n = 500,
d = 18, one thread (SARCOS bench, ``docs/bench``): 7.2 ms per start and evaluation (kernel 1.6, Cholesky 1.5,
inverse 2.8, gradient 1.2, optimiser 0.1), against 22.8 ms for the earlier all-batch torch version
(``torch.cholesky_inverse`` on a ``(60, 500, 500)`` batch, memory-bound).

Memory
------
:func:`cascgp.gp.memory.estimate_fit_bytes` bounds the memory of a fit from ``(starts, outputs, n, d)`` before
anything large is allocated: three ``(chunk, n, n)`` work matrices, the ``(B, n, n)`` factors kept for prediction and
the data. :func:`cascgp.gp.memory.plan_chunk` picks the block size within ``GPFitConfig.max_batch_bytes`` (default
2 GiB) and raises :class:`cascgp.gp.memory.FitMemoryError` (a ``ValueError`` naming ``max_batch_bytes``) when even
one start at a time does not fit. The batch of starts never
needs ``(starts, n, n)`` at once, so memory grows as :math:`n^2 (B + 3)` and not with the number of starts; results
do not depend on the block size (tested to round-off).

Conditioning
------------
Noise-free or nearly noise-free targets drive the noise to its floor while :math:`s_f^2` grows; before the bound,
a fit with :math:`s_f^2 / s_n^2 \approx 5 \cdot 10^{14}` had :math:`\operatorname{cond}(K) \approx 10^{17}` and
predictions off by ~1e-4 from an exact solve. With :math:`s_n^2 \ge s_f^2 / \rho_{\max}` and :math:`k \le 1`,
:math:`\lambda_{\max}(K) \le n s_f^2 + s_n^2` and :math:`\lambda_{\min}(K) \ge s_n^2`, so
:math:`\operatorname{cond}(K) \le 1 + n \rho_{\max}`; predictions then match a float64 reference solve to 1e-8
(``tests/test_gp_fit_rules.py``). On SARCOS the fitted ratios are <= 1.3e5, so the default bound 1e6 is inactive
there (``snr_max=None`` removes it).

Jitter is added only when a Cholesky fails (``dpotrf`` in the fit, ``torch.linalg.cholesky_ex`` for the final
factors), for just the failing members, starting at ``1e-8`` times the mean diagonal and growing 10x up to
``jitter_max``; the amount is recorded in ``fit_info``.
A point where even that fails has NLL ``inf`` (the line search backs off).

"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import torch
from scipy.linalg.lapack import dpotrf as _dpotrf, dpotri as _dpotri, dpotrs as _dpotrs

from cascgp.gp.kernels import get_kernel
from cascgp.gp.memory import CACHE_CHUNK_BYTES

__all__ = ["nll_and_grad", "blas_threads", "fit_threads", "PROFILE", "DTYPE",
           "LOG2PI"]

#: Every GP computation is float64.
DTYPE = torch.float64
LOG2PI = math.log(2.0 * math.pi)


_BLAS_LIBS: list | None = None  # the BLAS libraries threadpoolctl finds in this process, looked up on first use
_OWNERSHIP: Any = None  # threadpoolctl's per-thread count of limits that hold OpenBLAS's controlling thread


@contextlib.contextmanager
def blas_threads(k: int) -> Iterator[None]:
    """Limit the BLAS/LAPACK threads of NumPy/SciPy (OpenBLAS) to ``k`` while fitting.

    The per-member LAPACK calls are small (n x n); OpenBLAS's own threads gained nothing there and, on a shared
    2-core machine, spun against the other process (measured: 25 ms instead of 8 ms per evaluation at n = 500).
    The libraries are found once per process by a ``threadpoolctl.ThreadpoolController`` (building one inspects
    the loaded libraries: 1.9 ms per ``threadpool_limits`` call); each call then reads and sets their thread
    counts through its library controllers, setting only those that differ from ``k`` and restoring them after,
    instead of ``controller.limit``, which also builds the report of every library (``info()``) at each call: this
    runs around every online sample between control ticks (:mod:`cascgp.models.online`). As ``limit`` does, the
    block holds threadpoolctl's ownership of OpenBLAS's controlling thread (a pthreads OpenBLAS obeys one Python
    thread at a time), released when the thread's last limit ends.
    """
    global _BLAS_LIBS, _OWNERSHIP
    if _BLAS_LIBS is None:
        import threadpoolctl

        _BLAS_LIBS = [lib for lib in threadpoolctl.ThreadpoolController().lib_controllers if lib.user_api == "blas"]
        _OWNERSHIP = getattr(threadpoolctl, "CONTROLLING_THREAD_OWNERSHIP", None)  # threadpoolctl >= 3.7
    changed = []
    if _OWNERSHIP is not None:
        _OWNERSHIP.increment()
    try:
        for lib in _BLAS_LIBS:
            prev = lib.get_num_threads()
            if prev is not None and prev != k:
                lib.set_num_threads(k)
                changed.append((lib, prev))
        yield
    finally:
        for lib, prev in changed:
            lib.set_num_threads(prev)
        if _OWNERSHIP is not None:
            _OWNERSHIP.decrement()


@contextlib.contextmanager
def fit_threads(k: int | None) -> Iterator[None]:
    """Run a fit with ``k`` threads in torch's intra-op pool and in BLAS/LAPACK, restoring both afterwards.

    ``k = None`` changes nothing. The rule for the default (``GPFitConfig.threads = 1``) and its measurement are in
    :class:`cascgp.gp.GPFitConfig`: torch's OpenMP workers spin-wait for cores that another process holds, which
    made a plain script 2.7x (one busy neighbour) to 16x (a busy machine) slower than one thread. torch's setting
    is process-wide: other Python threads of the process see it while the fit runs.
    """
    if k is None:
        yield
        return
    prev = torch.get_num_threads()
    torch.set_num_threads(int(k))
    try:
        with blas_threads(int(k)):
            yield
    finally:
        torch.set_num_threads(prev)



def _potrf_jitter(kk: torch.Tensor, K: torch.Tensor, sf2: float, sn2: float,
                  jitter_max: float) -> tuple[np.ndarray | None, float]:
    """Cholesky (LAPACK ``dpotrf``) of ``sf2 * kk + (sn2 + jitter) I`` written into the buffer ``K``, after the
    factor without jitter has failed: the jitter grows tenfold from ``1e-8`` of the mean diagonal until the factor
    succeeds.

    ``kk`` and ``K`` are C-contiguous ``(n, n)``; ``K``'s memory read as an F-ordered array is the same symmetric
    matrix, so LAPACK works in place. Returns the F-ordered factor (lower triangle = L, strict upper = junk) and
    the jitter, or ``(None, jitter)`` when even ``jitter_max`` (relative to the mean diagonal) fails.
    """
    scale = sf2 + sn2  # mean diagonal of K (unit kernel diagonal)
    j = 1e-8
    if j > jitter_max * (1 + 1e-12):  # no jitter allowed (jitter_max below the first step): the factor has failed
        return None, 0.0
    Kf = K.numpy().T
    while True:
        jit = j * scale
        torch.mul(kk, sf2, out=K)
        K.diagonal().add_(sn2 + jit)
        c, info = _dpotrf(Kf, lower=1, overwrite_a=1, clean=0)
        if info == 0:
            return c, jit
        j *= 10.0
        if j > jitter_max * (1 + 1e-12):
            return None, jit


#: When a dict, :func:`nll_and_grad` adds the seconds spent per phase (``kernel``: distances and kernel values,
#: ``cholesky``: factor, solve and log-determinant, ``inverse``: :math:`K^{-1}` from the factor, ``gradient``:
#: the rest of the gradient) and counts ``members`` (for the time breakdown of ``scripts.bench_cascgp``).
PROFILE: dict[str, float] | None = None


def nll_and_grad(
    theta: torch.Tensor,
    X: torch.Tensor,
    y: torch.Tensor,
    mask: torch.Tensor | None = None,
    kernel: str = "matern52",
    noise_floor: float | np.ndarray = 1e-6,
    jitter_max: float = 1e-2,
    need_grad: bool = True,
    chunk: int | None = None,
    snr_max: float | None = None,
) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor]:
    r"""Negative log marginal likelihood and its analytic gradient for a batch of GPs.

    The batch is processed in chunks of ``chunk`` members (default: as many as keep one ``(chunk, n, n)`` block
    near 1 MB, i.e. in cache); three ``(chunk, n, n)`` work buffers are reused for every chunk. Per member: one
    Cholesky :math:`K = L L^\top` (LAPACK ``dpotrf``), :math:`\alpha` by two triangular solves (``dpotrs``),
    :math:`K^{-1}` from the factor (``dpotri``); then, for the whole block, the ARD gradient from the upper
    triangle :math:`U` of the symmetric :math:`P` (diagonal included; its terms vanish):

    .. math::

        \sum_{ij} P_{ij} (z_{ik} - z_{jk})^2 = 2 \Big( \sum_i z_{ik}^2 \big[(U\mathbf 1)_i + (U^\top\mathbf 1)_i\big]
        - 2 \sum_i z_{ik} (U Z)_{ik} \Big),

    one ``(n, n) @ (n, D)`` product and no symmetrisation pass. Peak extra memory: ``3 * chunk * n^2 * 8`` bytes,
    independent of the batch size.

    Args:
        theta: ``(k, D + 2)`` log hyperparameters ``(log l_1..l_D, log s_f^2, log(s_n^2 - floor))``.
        X: ``(k, n, D)`` normalised inputs (padded columns must be zero).
        y: ``(k, n)`` normalised targets.
        mask: ``(k, D)`` 1 for active input columns, 0 for padding/ignored columns (default: all active).
        kernel: kernel name.
        noise_floor: :math:`s_{n,\min}^2`: a number for every member, or an array ``(k,)`` with one per member
            (the per-GP floors of :meth:`~cascgp.gp.config.GPFitConfig.floors`).
        jitter_max: largest jitter (relative to the mean diagonal of K) tried when a Cholesky fails.
        need_grad: compute the gradient.
        chunk: members per block (``None``: cache-sized).
        snr_max: if set, the noise floor grows with the signal: ``floor = noise_floor + s_f^2 / snr_max``
            (see :class:`~cascgp.gp.config.GPFitConfig`), which bounds
            :math:`\operatorname{cond}(K) \le 1 + n\,\mathrm{snr\_max}`.

    Returns:
        ``(nll (k,), grad (k, D+2) or None, jitter (k,))``; ``nll`` is ``inf`` where the Cholesky failed even with
        jitter or the value is not finite (the gradient there is 0).
    """
    k_, n, D = X.shape
    theta = theta.to(DTYPE)
    if mask is None:
        mask = torch.ones(k_, D, dtype=DTYPE, device=X.device)
    if chunk is None:
        chunk = max(1, CACHE_CHUNK_BYTES // (8 * n * n))
    chunk = min(chunk, max(k_, 1))
    prof = PROFILE
    clock = time.perf_counter
    th_np = theta.detach().cpu().numpy()
    mask_np = mask.numpy()
    nll = np.full(k_, math.inf)
    jitter = np.zeros(k_)
    grad = np.zeros((k_, D + 2)) if need_grad else None
    half_n_log2pi = 0.5 * n * LOG2PI
    bufA = torch.empty(chunk, n, n, dtype=DTYPE)
    bufB = torch.empty(chunk, n, n, dtype=DTYPE)
    bufC = torch.empty(chunk, n, n, dtype=DTYPE)
    inv_snr = 0.0 if snr_max is None else 1.0 / snr_max
    floor_k = None if isinstance(noise_floor, (int, float)) else np.asarray(noise_floor, dtype=np.float64)
    floor_1 = noise_floor if isinstance(noise_floor, (int, float)) else math.nan  # used when floor_k is None
    if floor_k is not None and floor_k.shape != (k_,):
        raise ValueError(f"noise_floor: expected a number or shape ({k_},), got shape {floor_k.shape}")
    kern = get_kernel(kernel)
    r2s = kern.r2_scale
    with np.errstate(over="ignore", invalid="ignore"):
        sf2_all = np.exp(th_np[:, D])
        en_all = np.exp(th_np[:, D + 1])
        row_ok = np.all(np.isfinite(np.exp(-th_np[:, :D])), axis=1) & np.all(np.isfinite(th_np), axis=1)
    for s0 in range(0, k_, chunk):
        if prof is not None:
            t0 = clock()
        c_ = min(chunk, k_ - s0)
        sl = slice(s0, s0 + c_)
        A, Bu, C = bufA[:c_], bufB[:c_], bufC[:c_]
        inv_l = torch.exp(-theta[sl, :D]) * mask[sl]
        Z = X[sl] * inv_l[:, None, :]
        sq = (Z * Z).sum(-1).mul_(r2s)
        torch.baddbmm(sq.unsqueeze(-1), Z, Z.transpose(-1, -2), alpha=-2.0 * r2s, out=A)
        A.add_(sq.unsqueeze(-2)).clamp_min_(0.0)
        A.diagonal(dim1=-2, dim2=-1).zero_()
        c_u = kern.value_and_grad_(A, Bu, C)
        y_np = y[sl].numpy()
        if prof is not None:
            t1 = clock()
            prof["kernel"] = prof.get("kernel", 0.0) + t1 - t0
            prof["members"] = prof.get("members", 0) + c_
        # K = sf2 k + sn2 I for the whole block (element-wise, so each member's K is what it alone would get)
        sf2_c = sf2_all[sl]
        with np.errstate(over="ignore", invalid="ignore"):  # a far-out trial point: inf/nan, skipped below
            sn2_c = (floor_1 if floor_k is None else floor_k[sl]) + sf2_c * inv_snr + en_all[sl]
        torch.mul(A, torch.from_numpy(sf2_c)[:, None, None], out=C)
        C.diagonal(dim1=-2, dim2=-1).add_(torch.from_numpy(sn2_c)[:, None])
        alphas = np.zeros((c_, n))
        done = np.zeros(c_, dtype=bool)  # members whose gradient the block computes below
        # Per member only the LAPACK calls and the NLL (n x n factorisations, one call each); everything else is
        # batched over the block, so a small n pays a few calls per member rather than ~20 (at n = 8 those cost
        # ~0.2 ms per member and evaluation, against a few us of LAPACK).
        for i in range(c_):
            if prof is not None:
                t1 = clock()
            m = s0 + i
            sf2 = float(sf2_c[i])
            sn2 = float(sn2_c[i])
            if not (row_ok[m] and math.isfinite(sn2) and math.isfinite(sf2)):
                continue  # a trial point far out (huge step): NLL inf, the line search backs off
            cf, info = _dpotrf(C[i].numpy().T, lower=1, overwrite_a=1, clean=0)
            if info != 0:  # the factor failed: again from the kernel, with jitter (only this member)
                cf, jit = _potrf_jitter(A[i], C[i], sf2, sn2, jitter_max)
                jitter[m] = jit
                if cf is None:
                    continue
            yi = y_np[i]
            alpha, _ = _dpotrs(cf, yi, lower=1)
            f = 0.5 * float(yi @ alpha) + float(np.log(np.diagonal(cf)).sum()) + half_n_log2pi
            if prof is not None:
                t2 = clock()
                prof["cholesky"] = prof.get("cholesky", 0.0) + t2 - t1
            if not math.isfinite(f):
                continue
            nll[m] = f
            if grad is None:  # not need_grad
                continue
            ci, info = _dpotri(cf, lower=1, overwrite_c=1)
            if prof is not None:
                prof["inverse"] = prof.get("inverse", 0.0) + clock() - t2
            if info != 0:
                nll[m] = math.inf
                continue
            alphas[i] = alpha
            done[i] = True
        if grad is not None and done.any():
            if prof is not None:
                t3 = clock()
            _block_gradient(grad, sl, done, A, Bu, C, Z, alphas, sf2_c, en_all[sl], c_u, inv_snr, mask_np)
            if prof is not None:
                prof["gradient"] = prof.get("gradient", 0.0) + clock() - t3
    return torch.from_numpy(nll), (torch.from_numpy(grad) if need_grad else None), torch.from_numpy(jitter)


def _block_gradient(grad: np.ndarray, sl: slice, done: np.ndarray, A: torch.Tensor, Bu: torch.Tensor,
                    C: torch.Tensor, Z: torch.Tensor, alphas: np.ndarray, sf2: np.ndarray, en: np.ndarray,
                    c_u: float, inv_snr: float, mask_np: np.ndarray) -> None:
    r"""The gradient of a block's members (rows ``sl`` of ``grad``) where ``done``; the others keep 0.

    On entry ``C[i]`` holds :math:`K^{-1}` in its upper triangle (``dpotri``'s lower triangle in F order),
    ``A[i]`` the kernel :math:`k`, ``Bu[i]`` the :math:`u` of :math:`\partial k / \partial r^2 = c_u u`, ``Z`` the
    scaled inputs; ``A`` and ``C`` are overwritten. Members not ``done`` may hold anything (non-finite values
    included): they are left out, and their rows of ``grad`` are not written.
    """
    rows = np.arange(sl.start, sl.stop)
    mask_rows = mask_np[sl]
    if not done.all():  # rare (a failed factor or a far-out trial point): gather the members that are done
        ix = torch.from_numpy(np.flatnonzero(done))
        A, Bu, C, Z = A[ix], Bu[ix], C[ix], Z[ix]
        alphas, sf2, en, rows, mask_rows = alphas[done], sf2[done], en[done], rows[done], mask_rows[done]
    with np.errstate(over="ignore", invalid="ignore"):  # an overflowing gradient is set to 0 below, not warned
        _block_gradient_rows(grad, rows, A, Bu, C, Z, alphas, sf2, en, c_u, inv_snr, mask_rows)


def _block_gradient_rows(grad: np.ndarray, rows: np.ndarray, A: torch.Tensor, Bu: torch.Tensor, C: torch.Tensor,
                         Z: torch.Tensor, alphas: np.ndarray, sf2: np.ndarray, en: np.ndarray, c_u: float,
                         inv_snr: float, mask_rows: np.ndarray) -> None:
    """:func:`_block_gradient` on members that are all done, written to ``grad[rows]``."""
    at = torch.from_numpy(alphas)
    U = C.baddbmm_(at.unsqueeze(-1), at.unsqueeze(-2), alpha=-1.0).triu_()  # upper triangle of M = K^-1 - a a^T
    trM = U.diagonal(dim1=-2, dim2=-1).sum(-1).numpy()
    # sum_ij U_ij k_ij member by member (A is not needed after this); a batched matrix product here would round
    # differently with the block size, and a fit's result must not depend on it
    UA = A.mul_(U).view(A.shape[0], -1).sum(-1).numpy()
    g_sf = 0.5 * sf2 * (2.0 * UA - trM)  # diag(k) = 1
    U.mul_(Bu)  # upper triangle of P / (c_u sf2)
    # NumPy's matmul: one BLAS gemm per member, the same whatever the block size (torch.bmm rounds differently
    # for a batch of one and a larger batch at some n)
    UZ = torch.from_numpy(np.matmul(U.numpy(), Z.numpy()))
    rc = U.sum(-1).add_(U.sum(-2))
    g_l = ((Z * Z * rc.unsqueeze(-1)).sum(-2) - 2.0 * (Z * UZ).sum(-2)).numpy() * (-2.0 * c_u * sf2)[:, None]
    g = np.concatenate([g_l * mask_rows, (g_sf + 0.5 * sf2 * inv_snr * trM)[:, None], (0.5 * en * trM)[:, None]],
                       axis=1)
    g[~np.all(np.isfinite(g), axis=1)] = 0.0
    grad[rows] = g
