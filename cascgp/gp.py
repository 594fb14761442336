r"""Batched exact Gaussian-process regression (float64, torch) with hand-written analytic gradients.

Model (one GP per output ``b``, all independent)
------------------------------------------------
Inputs and targets are normalised per GP: :math:`\tilde x = (x - \mu_x) / \sigma_x` per column,
:math:`\tilde y = (y - \mu_y) / \sigma_y`. On the normalised data

.. math::

    \tilde y = f(\tilde x) + \varepsilon, \quad f \sim \mathcal{GP}(0, s_f^2\, k(r^2)), \quad
    \varepsilon \sim \mathcal N(0, s_n^2), \quad
    r^2 = \sum_k (\tilde x_k - \tilde x'_k)^2 / \ell_k^2

with a Matern 5/2 (default) or squared-exponential kernel :math:`k` (:mod:`cascgp.kernels`). The
hyperparameters are optimised in log space,

.. math::

    \theta = (\log \ell_1, \dots, \log \ell_d, \log s_f^2, \log(s_n^2 - s_{n,\min}^2 - s_f^2 / \rho_{\max})),

so that :math:`s_f^2 = e^{\theta_{d+1}} > 0` and :math:`s_n^2 = s_{n,\min}^2 + s_f^2/\rho_{\max} + e^{\theta_{d+2}}`
(``noise_floor`` :math:`s_{n,\min}^2`, default 1e-6 in normalised units, keeps the noise away from exactly zero;
``snr_max`` :math:`\rho_{\max}`, default 1e6, bounds the signal-to-noise variance ratio, see "Conditioning").

Negative log marginal likelihood and its gradient
-------------------------------------------------
With :math:`K = s_f^2 k(R^2) + s_n^2 I = L L^\top` and :math:`\alpha = K^{-1} \tilde y`,

.. math::

    \mathcal L(\theta) = \tfrac12 \tilde y^\top \alpha + \sum_i \log L_{ii} + \tfrac n2 \log 2\pi,
    \qquad
    \frac{\partial \mathcal L}{\partial \theta_j} = \tfrac12 \operatorname{tr}\!\Big(M \frac{\partial K}{\partial \theta_j}\Big),
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
OpenBLAS runs on one thread during a fit (:func:`_blas_threads`). Measured at n = 500, d = 18, one thread (SARCOS
bench, ``docs/bench``): 7.2 ms per start and evaluation (kernel 1.6, Cholesky 1.5, inverse 2.8, gradient 1.2,
optimiser 0.1), against 22.8 ms for the earlier all-batch torch version (``torch.cholesky_inverse`` on a
``(60, 500, 500)`` batch, memory-bound).

Batching
--------
All GPs x all restarts form one batch ``(B, n, n)``. GPs with fewer inputs than the widest are padded with zero
columns; their lengthscales are masked (gradient zero, never moved, reported as ``inf`` scale). Input columns that
are constant in the training data are treated the same way (they carry no information; at prediction time their
value is ignored). Each batch member runs its own L-BFGS (:mod:`cascgp.lbfgs`) and leaves the batch when it stops.

Restarts and early stopping
---------------------------
``n_restarts`` starts per GP: start 0 is a data-driven default (lengthscales :math:`\sqrt{d}` on standardised
inputs, :math:`s_f^2 = 1`, noise from the residual of a linear least-squares fit), the others are random
perturbations of it (seeded by ``seed``); with ``init=`` a previous bank's hyperparameters (converted to the new
normalisation) replace start 0. The best start per GP is kept.

Default rule (``stall_window``, ``stall_tol``, ``catch_up_windows``): after every batched round, the *leader* of
each GP (the start with the lowest current NLL) always continues to L-BFGS convergence (``rel_tol``, the same test
as GPy's L-BFGS-B). Any other start stops (``reason="stalled"``) once its NLL decreased by at most
``max(stall_tol, gap / catch_up_windows)`` over its last ``stall_window`` iterations, ``gap`` being its distance
to the leader (default: 0.01 nat over 5 iterations, or a tenth of the gap). Why this is safe: a stopped start
could only matter if it would later drop below the leader's final NLL; a start that has plateaued, or that at its
current pace needs more than 10 windows to reach the leader's *current* value, almost never does. Evidence (rerun
with ``python -m scripts.fit_audit``; report in ``docs/bench/fit_audit.md``): on 78 GPs (SARCOS subsets
n = 100-300, synthetic n = 50-200) the default's best NLL was within 0.03 nat of 10 starts run to convergence on
all of them. Rules measured and rejected on that audit: keeping the 5 best starts after 10 iterations ("racing",
option ``race_at``/``race_keep``, off by default: lost up to 1.2 nats on 2 of 36 synthetic GPs) and a shorter
catch-up horizon (``catch_up_windows=2``: lost up to 1.6 nats). On SARCOS (n = 500, 6 GPs x 10 starts) the rule
cuts the evaluations from 6,156 to 3,098 (each start: 103 -> 52; ``docs/bench``).

Other options (off by default): ``screen_n`` optimises all starts on a random subset of ``screen_n`` points first
and continues the ``screen_keep`` best on the full data (all of them if ``screen_keep >= n_restarts``); measured
on SARCOS, the subset's ranking did not predict the full data's (up to 7.8 nats lost), hence off. ``drop_after``
stops a start that is more than ``drop_margin`` nats behind its GP's best after ``drop_after`` iterations.

Memory
------
:func:`estimate_fit_bytes` bounds the memory of a fit from ``(starts, outputs, n, d)`` before anything large is
allocated: three ``(chunk, n, n)`` work matrices, the ``(B, n, n)`` factors kept for prediction and the data.
:func:`plan_chunk` picks the block size within ``GPFitConfig.max_batch_bytes`` (default 2 GiB) and raises a
``ValueError`` naming ``max_batch_bytes`` when even one start at a time does not fit. The batch of starts never
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
factors), for just the failing members, starting at ``1e-8`` times the mean diagonal and growing 10x up to ``jitter_max``; the amount is recorded in ``fit_info``.
A point where even that fails has NLL ``inf`` (the line search backs off).

Edge cases (documented behaviour)
---------------------------------
* Constant target ``y[b]`` (standard deviation <= 1e-12 x max(1, |mean|)): the GP is not optimised,
  ``y_std = 1``, hyperparameters stay at the default start, the posterior mean is exactly the constant and
  ``fit_info[b]["constant_target"]`` is True.
* Constant input column: ignored (see above).
* NaN/inf or wrong shapes, ``n < 2``, different ``n`` across GPs, unknown kernel: ``ValueError`` naming the field.
"""

from __future__ import annotations

import contextlib
import json
import math
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np
import torch
from scipy.linalg.lapack import dpotrf as _dpotrf, dpotri as _dpotri, dpotrs as _dpotrs

from cascgp.kernels import check_kernel, kernel_of_r2, kernel_of_r2_torch, scaled_sqdist
from cascgp.lbfgs import LBFGSOptions, MemberState, minimize_batched

__all__ = ["GPFitConfig", "GPBank", "GPPosterior", "nll_and_grad", "estimate_fit_bytes", "plan_chunk", "STATE_VERSION"]

STATE_VERSION = 1
_DT = torch.float64
_LOG2PI = math.log(2.0 * math.pi)


#: Values of fields added after the first saved format, for configs saved without them (old behaviour).
_LEGACY_DEFAULTS: dict[str, Any] = {"snr_max": None, "stall_window": None}


@dataclass
class GPFitConfig:
    r"""Hyperparameter optimisation settings.

    Attributes:
        kernel: ``"matern52"`` (paper) or ``"rbf"``.
        n_restarts: starts per GP (>= 1); the best is kept.
        max_iter: L-BFGS iterations per start.
        grad_tol: stop when max |dNLL/dtheta| <= grad_tol.
        rel_tol: stop when the relative NLL decrease of one iteration <= rel_tol (SciPy's ``factr`` test).
        seed: seed of the random starts and of the screening subset.
        history: L-BFGS memory.
        noise_floor: lower bound of the noise variance in normalised units.
        jitter_max: largest jitter (relative to the mean diagonal of K) tried when a Cholesky fails.
        init_spread: half-width (in log units) of the random perturbation of the log lengthscales.
        drop_after: drop hopeless starts after this many iterations (``None``: never drop).
        drop_margin: a start is hopeless when its NLL exceeds the best of its GP by more than this (nats).
        screen_n: if set and ``n > screen_n``, first optimise all starts on ``screen_n`` random training points.
        screen_keep: starts per GP that continue on the full data after screening.
        screen_max_iter: iteration cap of the screening stage.
        screen_rel_tol: relative-change tolerance of the screening stage.
        stall_window: iterations over which a non-leading start's progress is measured (``None``: every start runs
            to convergence, the behaviour before the early-stopping rule).
        stall_tol: a non-leading start that gained at most this (nats) over ``stall_window`` iterations stops.
        catch_up_windows: ... or that gained less than ``gap / catch_up_windows`` (``gap``: its NLL minus the
            leader's), i.e. would need more than this many windows to reach the leader at its current pace.
        race_at: if set, after every start of a GP has done ``race_at`` iterations only the ``race_keep`` best
            continue (off by default: the audit showed lost optima).
        race_keep: starts kept by ``race_at``.
        snr_max: bound of the signal-to-noise variance ratio, :math:`s_n^2 \ge s_f^2 / \mathrm{snr\_max}`
            (``None``: no bound); keeps :math:`\operatorname{cond}(K) \le 1 + n\,\mathrm{snr\_max}`.
        max_batch_bytes: memory limit of a fit (bytes); the evaluation is chunked to stay within it, and a fit that
            cannot (:func:`estimate_fit_bytes` with one start at a time) is refused with a ``ValueError``.
    """

    kernel: str = "matern52"
    n_restarts: int = 10
    max_iter: int = 1000
    grad_tol: float = 1e-5
    rel_tol: float = 2e-9
    seed: int = 0
    history: int = 10
    noise_floor: float = 1e-6
    jitter_max: float = 1e-2
    init_spread: float = 1.0
    drop_after: int | None = None
    drop_margin: float = 20.0
    stall_window: int | None = 5
    stall_tol: float = 0.01
    catch_up_windows: float = 10.0
    race_at: int | None = None
    race_keep: int = 5
    snr_max: float | None = 1e6
    max_batch_bytes: int = 2 * 1024**3
    screen_n: int | None = None
    screen_keep: int = 2
    screen_max_iter: int = 200
    screen_rel_tol: float = 1e-6

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> GPFitConfig:
        """Config from a saved ``asdict`` (unknown keys ignored). Fields missing from a save that predates them take
        the value that reproduces the old behaviour (``snr_max=None``, ``stall_window=None``), so that a loaded
        model predicts exactly as when it was saved."""
        if not isinstance(d, dict):
            raise TypeError(f"config: expected a dict, got {type(d).__name__}")
        names = {f.name for f in fields(cls)}
        kw = {k: v for k, v in d.items() if k in names}
        for k, v in _LEGACY_DEFAULTS.items():
            kw.setdefault(k, v)
        return cls(**kw)

    def __post_init__(self) -> None:
        check_kernel(self.kernel)
        for name in ("n_restarts", "max_iter", "history", "screen_keep", "screen_max_iter", "race_keep"):
            v = getattr(self, name)
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < 1:
                raise ValueError(f"{name}: expected an integer >= 1, got {v!r}")
        for name in ("grad_tol", "rel_tol", "noise_floor", "jitter_max", "init_spread", "drop_margin", "stall_tol",
                     "screen_rel_tol"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                raise ValueError(f"{name}: expected a finite number >= 0, got {v!r}")
        if self.drop_after is not None and (not isinstance(self.drop_after, int) or self.drop_after < 1):
            raise ValueError(f"drop_after: expected None or an integer >= 1, got {self.drop_after!r}")
        for name in ("stall_window", "race_at"):
            v = getattr(self, name)
            if v is not None and (not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < 1):
                raise ValueError(f"{name}: expected None or an integer >= 1, got {v!r}")
        if self.snr_max is not None and (not isinstance(self.snr_max, (int, float)) or not math.isfinite(self.snr_max)
                                         or self.snr_max <= 0):
            raise ValueError(f"snr_max: expected None or a finite number > 0, got {self.snr_max!r}")
        if not isinstance(self.max_batch_bytes, (int, np.integer)) or isinstance(self.max_batch_bytes, bool) or \
                self.max_batch_bytes < 1:
            raise ValueError(f"max_batch_bytes: expected an integer >= 1, got {self.max_batch_bytes!r}")
        if not isinstance(self.catch_up_windows, (int, float)) or not self.catch_up_windows > 0:
            raise ValueError(f"catch_up_windows: expected a number > 0, got {self.catch_up_windows!r}")
        if self.screen_n is not None and (not isinstance(self.screen_n, int) or self.screen_n < 2):
            raise ValueError(f"screen_n: expected None or an integer >= 2, got {self.screen_n!r}")


@dataclass(frozen=True)
class GPPosterior:
    r"""Cached posterior of one fitted GP as plain NumPy float64 arrays (for hand-written fast paths).

    .. math::

        z = (x - x_{mean}) / x_{scale}, \quad
        \mu(x) = y_{mean} + y_{std}\, s_f^2\, k(r^2(z, Z))^\top \alpha, \quad
        \sigma^2(x) = y_{std}^2\, \big(s_f^2 - \|L^{-1} s_f^2 k(r^2(z, Z))\|^2\big)

    ``x_scale`` is ``inf`` for ignored (constant) input columns, so their ``z`` is 0.
    ``noise_var`` and ``signal_var`` are in normalised units (multiply by ``y_std**2`` for target units).
    """

    kernel: str
    x_mean: np.ndarray
    x_scale: np.ndarray
    Z: np.ndarray
    alpha: np.ndarray
    L: np.ndarray
    signal_var: float
    noise_var: float
    y_mean: float
    y_std: float
    jitter: float = 0.0

    def predict(self, x: np.ndarray, return_var: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """Reference NumPy prediction: ``x`` ``(m, d)`` or ``(d,)`` -> mean ``(m,)``, latent variance ``(m,)``."""
        x = np.atleast_2d(np.asarray(x, dtype=np.float64))
        z = (x - self.x_mean) / self.x_scale
        r2 = (z * z).sum(1)[:, None] + (self.Z * self.Z).sum(1)[None, :] - 2.0 * z @ self.Z.T
        ks = self.signal_var * kernel_of_r2(self.kernel, r2)
        mean = self.y_mean + self.y_std * (ks @ self.alpha)
        if not return_var:
            return mean, None
        from scipy.linalg import solve_triangular

        v = solve_triangular(self.L, ks.T, lower=True)
        var = np.maximum(self.signal_var - (v * v).sum(0), 0.0) * self.y_std**2
        return mean, var


# ----------------------------------------------------------------------------------------------------------------
# core evaluation


def _robust_cholesky(K: torch.Tensor, jitter_max: float) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Batched Cholesky; jitter only for the members whose factorisation fails.

    Returns ``(L, jitter (k,), failed (k,) bool)``; failed members get an identity factor (caller marks them).
    """
    L, info = torch.linalg.cholesky_ex(K)
    jitter = torch.zeros(K.shape[0], dtype=K.dtype, device=K.device)
    bad = info != 0
    failed = torch.zeros_like(bad)
    if bool(bad.any()):
        idx = bad.nonzero().squeeze(1)
        scale = K[idx].diagonal(dim1=-2, dim2=-1).mean(-1).abs().clamp_min(1e-300)
        j = 1e-8
        while idx.numel() > 0 and j <= jitter_max * (1 + 1e-12):
            Kj = K[idx].clone()
            Kj.diagonal(dim1=-2, dim2=-1).add_((j * scale)[:, None])
            Lj, infoj = torch.linalg.cholesky_ex(Kj)
            ok = infoj == 0
            if bool(ok.any()):
                L[idx[ok]] = Lj[ok]
                jitter[idx[ok]] = j * scale[ok]
            idx, scale = idx[~ok], scale[~ok]
            j *= 10.0
        if idx.numel() > 0:
            failed[idx] = True
            L[idx] = torch.eye(K.shape[-1], dtype=K.dtype, device=K.device)
    return L, jitter, failed


@contextlib.contextmanager
def _blas_threads(k: int) -> Iterator[None]:
    """Limit the BLAS/LAPACK threads of NumPy/SciPy (OpenBLAS) to ``k`` while fitting.

    The per-member LAPACK calls are small (n x n); OpenBLAS's own threads gained nothing there and, on a shared
    2-core machine, spun against the other process (measured: 25 ms instead of 8 ms per evaluation at n = 500).
    Uses ``threadpoolctl`` when installed; otherwise set ``OPENBLAS_NUM_THREADS=1`` yourself.
    """
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - optional
        yield
        return
    with threadpool_limits(limits=k, user_api="blas"):
        yield


# Cache-sized chunks: the element-wise kernel work runs on (c, n, n) blocks of about this many bytes per tensor
# (measured, 1 thread: one (60, 500, 500) batch per op was 2.2x slower per evaluation than member-sized blocks, the
# whole batch being memory-bandwidth bound; at n = 300 and 500 one member per block was 6 % faster than 5).
_CACHE_CHUNK_BYTES = 1 << 20


def _kernel_parts(kernel: str, A: torch.Tensor, B: torch.Tensor, C: torch.Tensor) -> float:
    r"""In place: ``A`` holds :math:`s\,r^2` on entry (``s`` from :func:`_r2_scale`) and the unit kernel :math:`k` on
    exit; ``B`` receives ``u`` with :math:`\partial k / \partial (r^2) = c\, u`; ``C`` is scratch. Returns ``c``.

    Matern 5/2 (:math:`s = 5`, :math:`\rho = \sqrt{5 r^2}`): :math:`u = (1 + \rho) e^{-\rho}`,
    :math:`k = u + \tfrac13 \rho^2 e^{-\rho}`, :math:`c = -5/6`; RBF (:math:`s = 1`): :math:`u = k = e^{-r^2/2}`,
    :math:`c = -1/2`. No temporaries: fresh large tensors cost page faults that were measured to take longer than
    the element-wise arithmetic itself.
    """
    if kernel == "rbf":
        A.mul_(-0.5).exp_()
        B.copy_(A)
        return -0.5
    torch.sqrt(A, out=B)  # rho
    torch.neg(B, out=C).exp_()  # e^{-rho}
    B.add_(1.0).mul_(C)  # u
    torch.addcmul(B, A, C, value=1.0 / 3.0, out=A)  # k = u + rho^2 e^{-rho} / 3
    return -5.0 / 6.0


def _r2_scale(kernel: str) -> float:
    """Factor folded into the squared distances before :func:`_kernel_parts` (saves one pass)."""
    return 1.0 if kernel == "rbf" else 5.0


def _potrf_jitter(kk: torch.Tensor, K: torch.Tensor, sf2: float, sn2: float,
                  jitter_max: float) -> tuple[np.ndarray | None, float]:
    """Cholesky (LAPACK ``dpotrf``) of ``sf2 * kk + sn2 I`` written into the buffer ``K``; jitter only if it fails.

    ``kk`` and ``K`` are C-contiguous ``(n, n)``; ``K``'s memory read as an F-ordered array is the same symmetric
    matrix, so LAPACK works in place. Returns the F-ordered factor (lower triangle = L, strict upper = junk) and
    the jitter, or ``(None, jitter)`` when even ``jitter_max`` (relative to the mean diagonal) fails.
    """
    jit = 0.0
    scale = sf2 + sn2  # mean diagonal of K (unit kernel diagonal)
    j = 1e-8
    Kf = K.numpy().T
    while True:
        torch.mul(kk, sf2, out=K)
        K.diagonal().add_(sn2 + jit)
        c, info = _dpotrf(Kf, lower=1, overwrite_a=1, clean=0)
        if info == 0:
            return c, jit
        if j > jitter_max * (1 + 1e-12):
            return None, jit
        jit = j * scale
        j *= 10.0


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
    noise_floor: float = 1e-6,
    jitter_max: float = 1e-2,
    need_grad: bool = True,
    chunk: int | None = None,
    snr_max: float | None = None,
) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor]:
    r"""Negative log marginal likelihood and its analytic gradient for a batch of GPs.

    The batch is processed in chunks of ``chunk`` members (default: as many as keep one ``(chunk, n, n)`` block
    near 1 MB, i.e. in cache); three ``(chunk, n, n)`` work buffers are reused for every chunk. Per member: one
    Cholesky :math:`K = L L^\top` (LAPACK ``dpotrf``), :math:`\alpha` by two triangular solves (``dpotrs``),
    :math:`K^{-1}` from the factor (``dpotri``), and the ARD gradient from the upper triangle :math:`U` of the
    symmetric :math:`P` (diagonal included; its terms vanish):

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
        noise_floor: :math:`s_{n,\min}^2`.
        jitter_max: largest jitter (relative to the mean diagonal of K) tried when a Cholesky fails.
        need_grad: compute the gradient.
        chunk: members per block (``None``: cache-sized).
        snr_max: if set, the noise floor grows with the signal: ``floor = noise_floor + s_f^2 / snr_max``
            (see :class:`GPFitConfig`), which bounds :math:`\operatorname{cond}(K) \le 1 + n\,\mathrm{snr\_max}`.

    Returns:
        ``(nll (k,), grad (k, D+2) or None, jitter (k,))``; ``nll`` is ``inf`` where the Cholesky failed even with
        jitter or the value is not finite (the gradient there is 0).
    """
    k_, n, D = X.shape
    theta = theta.to(_DT)
    if mask is None:
        mask = torch.ones(k_, D, dtype=_DT, device=X.device)
    if chunk is None:
        chunk = max(1, _CACHE_CHUNK_BYTES // (8 * n * n))
    chunk = min(chunk, max(k_, 1))
    prof = PROFILE
    clock = time.perf_counter
    th_np = theta.detach().cpu().numpy()
    mask_np = mask.numpy()
    nll = np.full(k_, math.inf)
    jitter = np.zeros(k_)
    grad = np.zeros((k_, D + 2)) if need_grad else None
    half_n_log2pi = 0.5 * n * _LOG2PI
    bufA = torch.empty(chunk, n, n, dtype=_DT)
    bufB = torch.empty(chunk, n, n, dtype=_DT)
    bufC = torch.empty(chunk, n, n, dtype=_DT)
    inv_snr = 0.0 if snr_max is None else 1.0 / snr_max
    r2s = _r2_scale(kernel)
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
        c_u = _kernel_parts(kernel, A, Bu, C)
        y_np = y[sl].numpy()
        if prof is not None:
            t1 = clock()
            prof["kernel"] = prof.get("kernel", 0.0) + t1 - t0
            prof["members"] = prof.get("members", 0) + c_
        for i in range(c_):
            if prof is not None:
                t1 = clock()
            m = s0 + i
            sf2 = float(sf2_all[m])
            en = float(en_all[m])
            sn2 = noise_floor + sf2 * inv_snr + en
            if not (row_ok[m] and math.isfinite(sn2) and math.isfinite(sf2)):
                continue  # a trial point far out (huge step): NLL inf, the line search backs off
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
            if not need_grad:
                continue
            ci, info = _dpotri(cf, lower=1, overwrite_c=1)
            if prof is not None:
                t3 = clock()
                prof["inverse"] = prof.get("inverse", 0.0) + t3 - t2
            if info != 0:
                nll[m] = math.inf
                continue
            # ci (F order, the memory of C[i]) holds K^-1 in its lower triangle = the upper triangle of C[i].
            U = C[i]
            at = torch.from_numpy(alpha)
            U.addr_(at, at, alpha=-1.0).triu_()  # upper triangle of M = K^-1 - alpha alpha^T
            trM = float(U.diagonal().sum())
            Ai = A[i]
            g_sf = 0.5 * sf2 * (2.0 * float(torch.dot(U.view(-1), Ai.view(-1))) - trM)  # diag(k) = 1
            U.mul_(Bu[i])  # upper triangle of P / (c_u sf2)
            Zi = Z[i]
            UZ = U @ Zi
            rc = U.sum(1).add_(U.sum(0))
            g_l = (-2.0 * c_u * sf2) * ((Zi * Zi * rc.unsqueeze(-1)).sum(0) - 2.0 * (Zi * UZ).sum(0))
            g = grad[m]
            g[:D] = g_l.numpy() * mask_np[m]
            g[D] = g_sf + 0.5 * sf2 * inv_snr * trM
            g[D + 1] = 0.5 * en * trM
            if not np.all(np.isfinite(g)):
                g[:] = 0.0
            if prof is not None:
                prof["gradient"] = prof.get("gradient", 0.0) + clock() - t3
    return torch.from_numpy(nll), (torch.from_numpy(grad) if need_grad else None), torch.from_numpy(jitter)


# ----------------------------------------------------------------------------------------------------------------
# validation helpers


def _num(v: float) -> float | None:
    """JSON-friendly float: ``None`` for NaN (a start that was not run or not screened)."""
    return None if not np.isfinite(v) and np.isnan(v) else float(v)


def _as_list(v: Any, field_name: str) -> list[np.ndarray]:
    if isinstance(v, np.ndarray):
        raise TypeError(f"{field_name}: expected a list of arrays (one per GP), got a single ndarray")
    if not isinstance(v, (list, tuple)) or len(v) == 0:
        raise ValueError(f"{field_name}: expected a non-empty list of arrays (one per GP), got {type(v).__name__}")
    return list(v)


def _check_matrix(a: Any, field_name: str, d: int | None = None, n: int | None = None) -> np.ndarray:
    try:
        a = np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{field_name}: expected a numeric array ({e})") from None
    if a.ndim != 2:
        raise ValueError(f"{field_name}: expected a 2-D array (n, d), got shape {a.shape}")
    if a.shape[1] < 1:
        raise ValueError(f"{field_name}: expected at least one input column, got shape {a.shape}")
    if d is not None and a.shape[1] != d:
        raise ValueError(f"{field_name}: expected {d} columns, got shape {a.shape}")
    if n is not None and a.shape[0] != n:
        raise ValueError(f"{field_name}: expected {n} rows (the same n for every GP), got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        row = int(np.argwhere(~np.isfinite(a))[0, 0])
        raise ValueError(f"{field_name}: contains NaN or inf (first at row {row})")
    return a


def _check_vector(a: Any, field_name: str, n: int) -> np.ndarray:
    try:
        a = np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{field_name}: expected a numeric array ({e})") from None
    if a.ndim != 1 or a.shape[0] != n:
        raise ValueError(f"{field_name}: expected shape ({n},), got {a.shape}")
    if not np.all(np.isfinite(a)):
        row = int(np.argwhere(~np.isfinite(a))[0, 0])
        raise ValueError(f"{field_name}: contains NaN or inf (first at row {row})")
    return a


def _noise_var(cfg: GPFitConfig, sf2: float, e: float) -> float:
    r"""Noise variance (normalised units) from :math:`s_f^2` and :math:`e^{\theta_{d+2}}`:
    :math:`s_n^2 = s_{n,\min}^2 + s_f^2 / \mathrm{snr\_max} + e^{\theta_{d+2}}`."""
    return cfg.noise_floor + (sf2 / cfg.snr_max if cfg.snr_max is not None else 0.0) + e


def estimate_fit_bytes(n: int, d: int, n_gps: int, n_starts: int, chunk: int = 1) -> int:
    """Bytes :meth:`GPBank.fit` needs beyond the interpreter, before fitting (a deliberately high estimate).

    ``3 * chunk`` work matrices ``(n, n)`` of the batched evaluation (:func:`nll_and_grad`), the stored factor of
    every GP ``(n_gps, n, n)`` plus twelve ``(n, n)`` for the temporaries of the final factors and for allocator
    fragmentation (freed ``(n, n)`` blocks are not always returned to the system), the data copies (normalised
    inputs of every start, ``(n_gps * n_starts, n, d)``, twice), all float64, and 128 MiB of fixed overhead.
    Measured (``bench_cascgp --scaling``, 6 GPs x 10 starts, d = 18, two runs): peak RSS growth 40 / 68 /
    161-187 / 565-703 MiB at n = 250 / 500 / 1000 / 2000.
    """
    return 8 * (3 * chunk * n * n + (n_gps + 12) * n * n + 2 * n_gps * n_starts * n * d + 6 * n_gps * n * d) \
        + (128 << 20)


def plan_chunk(cfg: GPFitConfig, n: int, d: int, n_gps: int) -> int:
    """Members per evaluation block: cache-sized, shrunk to keep :func:`estimate_fit_bytes` within
    ``cfg.max_batch_bytes``; ``ValueError`` naming ``max_batch_bytes`` when even one member does not fit."""
    chunk = max(1, _CACHE_CHUNK_BYTES // (8 * n * n))
    need1 = estimate_fit_bytes(n, d, n_gps, cfg.n_restarts, 1)
    if need1 > cfg.max_batch_bytes:
        raise ValueError(
            f"max_batch_bytes: fitting {n_gps} GPs x {cfg.n_restarts} starts on n={n} points (d={d}) needs about "
            f"{need1 / 2**20:.0f} MiB even one start at a time (3 + {n_gps + 12} matrices of {n}x{n} float64 plus "
            f"the data), over GPFitConfig.max_batch_bytes = {cfg.max_batch_bytes / 2**20:.0f} MiB; raise "
            "GPFitConfig.max_batch_bytes, or use fewer training points (memory grows as n^2)")
    while chunk > 1 and estimate_fit_bytes(n, d, n_gps, cfg.n_restarts, chunk) > cfg.max_batch_bytes:
        chunk -= 1
    return chunk


def _prune_rule(cfg: GPFitConfig, states: list[MemberState], gp_of: np.ndarray, B: int,
                raced: np.ndarray) -> np.ndarray:
    """Which live starts to stop now (see "Restarts and early stopping" in the module docstring).

    The leader of a GP (lowest current NLL; ties: lowest member index; finished starts included) is never stopped
    here. ``raced`` (B,) marks GPs whose race has been held (updated in place). Sets ``reason`` of stopped starts.
    """
    f = np.array([s.f if math.isfinite(s.f) else math.inf for s in states])
    live = np.array([not s.done for s in states])
    it = np.array([s.n_iter for s in states])
    best = np.full(B, np.inf)
    np.minimum.at(best, gp_of, f)
    lead = np.full(B, -1)
    for m in np.argsort(f, kind="stable")[::-1]:
        lead[gp_of[m]] = m
    out = np.zeros(len(states), dtype=bool)
    reason = [""] * len(states)
    if cfg.drop_after is not None:
        hope = live & (it >= cfg.drop_after) & (f > best[gp_of] + cfg.drop_margin)
        for m in np.flatnonzero(hope):
            out[m], reason[m] = True, "dropped"
    if cfg.race_at is not None:
        for b in np.unique(gp_of):
            if raced[b]:
                continue
            mem = np.flatnonzero(gp_of == b)
            if np.all((it[mem] >= cfg.race_at) | ~live[mem]):
                raced[b] = True
                order = mem[np.argsort(f[mem], kind="stable")]
                for m in order[cfg.race_keep:]:
                    if live[m] and not out[m]:
                        out[m], reason[m] = True, "raced_out"
    if cfg.stall_window is not None:
        w = cfg.stall_window
        for m, s in enumerate(states):
            if live[m] and not out[m] and lead[gp_of[m]] != m and len(s.trace) > w:
                gain = s.trace[-1 - w] - s.trace[-1]
                gap = f[m] - best[gp_of[m]]
                if gain <= max(cfg.stall_tol, gap / cfg.catch_up_windows):
                    out[m], reason[m] = True, "stalled"
    for m in np.flatnonzero(out):
        states[m].reason = reason[m]
    return out


# ----------------------------------------------------------------------------------------------------------------


class GPBank:
    """``B`` independent exact GPs (one per output), fitted together in one batch.

    Example::

        bank = GPBank(GPFitConfig(n_restarts=10)).fit([X0, X1], [y0, y1])
        mean, var = bank.predict([Xq0, Xq1])        # (m, 2), (m, 2) in target units
        post = bank.posterior(0)                     # NumPy factors for a single-query fast path

    Attributes:
        config: the :class:`GPFitConfig`.
        fit_info: per GP a dict (JSON-serialisable): ``nll`` (final NLL per start in normalised units; for a
            dropped start its last NLL, for a start screened out or not run ``None``), ``n_iter``, ``n_eval``,
            ``reason`` (per start: ``grad_tol``, ``rel_tol``, ``stalled``, ``dropped``, ``screened_out``, ...),
            ``best`` (index of the kept start), ``best_nll``, ``converged`` (reason of the kept start), ``jitter``
            (jitter in the final factor, normalised units), ``max_jitter_fit`` (largest jitter met during the
            fit), ``constant_target``, ``warm_start`` (start 0 came from ``init``), ``screen_nll`` (subset NLL
            per start when screening was used).
        fit_summary: totals of the last fit (``time_s``, ``n_eval``, ``batch_rounds``).
    """

    def __init__(self, config: GPFitConfig | None = None) -> None:
        if config is not None and not isinstance(config, GPFitConfig):
            raise TypeError(f"config: expected GPFitConfig or None, got {type(config).__name__}")
        self.config = config or GPFitConfig()
        self.fit_info: list[dict[str, Any]] = []
        self.fit_summary: dict[str, Any] = {}
        self._fitted = False

    # ------------------------------------------------------------------ properties
    @property
    def fitted(self) -> bool:
        return self._fitted

    @property
    def n_gps(self) -> int:
        self._require_fitted()
        return int(self._dims.shape[0])

    @property
    def dims(self) -> tuple[int, ...]:
        """Input dimension of each GP."""
        self._require_fitted()
        return tuple(int(d) for d in self._dims)

    @property
    def n_train(self) -> int:
        self._require_fitted()
        return int(self._X.shape[1])

    def hyperparameters(self, b: int) -> dict[str, np.ndarray | float]:
        """Hyperparameters of GP ``b`` in *original* units: ``lengthscale`` (d,) (``inf`` for ignored columns),
        ``signal_var``, ``noise_var`` (target units squared)."""
        self._require_fitted()
        b = self._check_b(b)
        d = int(self._dims[b])
        th = self._theta[b]
        ls = np.where(self._mask[b, :d] > 0, np.exp(th[:d]) * self._x_std[b, :d], np.inf)
        ys2 = self._y_std[b] ** 2
        return {
            "lengthscale": ls,
            "signal_var": float(np.exp(th[-2]) * ys2),
            "noise_var": float(_noise_var(self.config, math.exp(th[-2]), math.exp(th[-1])) * ys2),
        }

    def _require_fitted(self) -> None:
        if not self._fitted:
            raise RuntimeError("GPBank: not fitted; call fit() or from_state_dict() first")

    def _check_b(self, b: int) -> int:
        if not isinstance(b, (int, np.integer)) or not 0 <= int(b) < self._dims.shape[0]:
            raise ValueError(f"b: expected an integer in [0, {self._dims.shape[0]}), got {b!r}")
        return int(b)

    # ------------------------------------------------------------------ fit
    def fit(self, X: list[np.ndarray], y: list[np.ndarray], init: GPBank | None = None) -> GPBank:
        """Normalise, optimise all GPs x all starts in one batch, keep the best start, cache the factors.

        Args:
            X: per GP ``(n, d_b)`` inputs (the same ``n`` for all GPs, ``d_b`` may differ).
            y: per GP ``(n,)`` targets.
            init: a fitted bank with the same number of GPs and input dimensions; its hyperparameters (converted
                to this data's normalisation) are used as start 0 of every GP.

        Returns:
            ``self``.
        """
        with _blas_threads(1):
            return self._fit(X, y, init)

    def _fit(self, X: list[np.ndarray], y: list[np.ndarray], init: GPBank | None) -> GPBank:
        t0 = time.perf_counter()
        cfg = self.config
        X = _as_list(X, "X")
        y = _as_list(y, "y")
        if len(X) != len(y):
            raise ValueError(f"y: expected {len(X)} target vectors (one per GP in X), got {len(y)}")
        X0 = _check_matrix(X[0], "X[0]")
        n = X0.shape[0]
        if n < 2:
            raise ValueError(f"X[0]: a GP needs at least 2 training samples, got n={n}")
        Xs = [X0] + [_check_matrix(X[b], f"X[{b}]", n=n) for b in range(1, len(X))]
        ys = [_check_vector(y[b], f"y[{b}]", n) for b in range(len(y))]
        B = len(Xs)
        dims = np.array([a.shape[1] for a in Xs], dtype=np.int64)
        D = int(dims.max())
        p = D + 2
        if init is not None:
            if not isinstance(init, GPBank) or not init.fitted:
                raise ValueError("init: expected a fitted GPBank or None")
            if init.dims != tuple(int(d) for d in dims):
                raise ValueError(f"init: input dimensions {init.dims} do not match X's {tuple(int(d) for d in dims)}")

        chunk = plan_chunk(cfg, n, D, B)  # memory guard: before any large allocation

        # --- normalisation (constant columns masked, constant targets flagged)
        Xp = np.zeros((B, n, D))
        x_mean = np.zeros((B, D))
        x_std = np.ones((B, D))
        mask = np.zeros((B, D))
        y_arr = np.zeros((B, n))
        y_mean = np.zeros(B)
        y_std = np.ones(B)
        const_y = np.zeros(B, dtype=bool)
        for b in range(B):
            d = dims[b]
            Xp[b, :, :d] = Xs[b]
            mu = Xs[b].mean(0)
            sd = Xs[b].std(0)
            active = sd > 1e-12 * np.maximum(1.0, np.abs(mu))
            x_mean[b, :d] = mu
            x_std[b, :d] = np.where(active, sd, 1.0)
            mask[b, :d] = active
            y_arr[b] = ys[b]
            y_mean[b] = ys[b].mean()
            s = ys[b].std()
            if s <= 1e-12 * max(1.0, abs(y_mean[b])):
                const_y[b] = True
            else:
                y_std[b] = s
        Xn = (Xp - x_mean[:, None, :]) / x_std[:, None, :] * mask[:, None, :]
        yn = (y_arr - y_mean[:, None]) / y_std[:, None]

        # --- starts
        rng = np.random.default_rng(cfg.seed)
        R = cfg.n_restarts
        theta0 = np.zeros((B, R, p))
        d_eff = np.maximum(mask.sum(1), 1.0)
        for b in range(B):
            noise0 = self._linear_noise(Xn[b][:, mask[b] > 0], yn[b]) if not const_y[b] else 0.1
            base = np.concatenate([np.full(D, 0.5 * math.log(d_eff[b])), [0.0, math.log(max(noise0, 1e-6))]])
            theta0[b, :, :] = base
            if R > 1:
                theta0[b, 1:, :D] += rng.uniform(-cfg.init_spread, cfg.init_spread, size=(R - 1, D))
                theta0[b, 1:, D] += rng.uniform(-1.0, 0.5, size=R - 1)
                theta0[b, 1:, D + 1] = np.log(np.clip(noise0 * np.exp(rng.uniform(-2.5, 1.5, size=R - 1)), 1e-6, 1.0))
        warm = False
        if init is not None:
            theta0[:, 0, :] = init._converted_theta(x_std, y_std, mask, D)
            warm = True
        theta0[:, :, :D] *= mask[:, None, :]  # inactive lengthscales fixed at 0 (unused)

        torch_X = torch.as_tensor(Xn, dtype=_DT)
        torch_y = torch.as_tensor(yn, dtype=_DT)
        torch_mask = torch.as_tensor(mask, dtype=_DT)
        opt_gps = np.flatnonzero(~const_y)
        member_gp = np.repeat(opt_gps, R)
        member_start = np.tile(np.arange(R), opt_gps.size)
        x0 = theta0[member_gp, member_start] if opt_gps.size else np.zeros((0, p))

        max_jit = np.zeros(B)
        n_eval_total = 0
        rounds = 0
        stage_evals = {"screen": 0, "full": 0}
        screen_nll = np.full((B, R), np.nan)
        final_theta = theta0[:, 0, :].copy()
        nll_r = np.full((B, R), np.nan)
        iter_r = np.zeros((B, R), dtype=np.int64)
        eval_r = np.zeros((B, R), dtype=np.int64)
        reason_r = [["not_run"] * R for _ in range(B)]

        def make_fun(tX: torch.Tensor, ty: torch.Tensor, gp_of: np.ndarray, stage: str):
            def fun(Th: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
                nonlocal n_eval_total, rounds
                gsel = torch.as_tensor(gp_of[idx])
                f, g, jit = nll_and_grad(torch.as_tensor(Th, dtype=_DT), tX[gsel], ty[gsel], torch_mask[gsel],
                                         cfg.kernel, cfg.noise_floor, cfg.jitter_max, chunk=chunk,
                                         snr_max=cfg.snr_max)
                jn = jit.numpy()
                np.maximum.at(max_jit, gp_of[idx], jn)
                n_eval_total += len(idx)
                stage_evals[stage] += len(idx)
                rounds += 1
                return f.numpy(), g.numpy()
            return fun

        def make_prune(gp_of: np.ndarray):
            if cfg.drop_after is None and cfg.stall_window is None and cfg.race_at is None:
                return None
            raced = np.zeros(B, dtype=bool)

            def prune(states: list[MemberState], rnd: int) -> np.ndarray | None:
                return _prune_rule(cfg, states, gp_of, B, raced)
            return prune

        if opt_gps.size:
            opts = LBFGSOptions(history=cfg.history, max_iter=cfg.max_iter, grad_tol=cfg.grad_tol, rel_tol=cfg.rel_tol)
            gp_of = member_gp
            starts = x0
            start_idx = member_start
            if cfg.screen_n is not None and n > cfg.screen_n:
                sub = np.sort(rng.choice(n, size=cfg.screen_n, replace=False))
                Xs_t = torch_X[:, sub].clone()
                ys_t = torch_y[:, sub].clone()
                sopts = LBFGSOptions(history=cfg.history, max_iter=cfg.screen_max_iter, grad_tol=cfg.grad_tol,
                                     rel_tol=cfg.screen_rel_tol)
                sst = minimize_batched(make_fun(Xs_t, ys_t, gp_of, "screen"), starts, sopts, make_prune(gp_of))
                sf = np.array([s.f for s in sst])
                keep = []
                for b in opt_gps:
                    mem = np.flatnonzero(gp_of == b)
                    screen_nll[b, member_start[mem]] = sf[mem]
                    order = mem[np.argsort(sf[mem], kind="stable")]
                    chosen = list(order[: cfg.screen_keep])
                    if warm:  # the warm start always continues
                        w = mem[member_start[mem] == 0]
                        if w.size and w[0] not in chosen:
                            chosen.append(int(w[0]))
                    for m in mem:
                        if m not in chosen:
                            reason_r[b][member_start[m]] = "screened_out"
                            iter_r[b, member_start[m]] = sst[m].n_iter
                            eval_r[b, member_start[m]] = sst[m].n_eval
                    keep.extend(sorted(int(c) for c in chosen))
                keep = np.array(keep, dtype=np.int64)
                starts = np.stack([sst[m].x if np.isfinite(sst[m].f) else x0[m] for m in keep])
                pre_iter = np.array([sst[m].n_iter for m in keep])
                pre_eval = np.array([sst[m].n_eval for m in keep])
                gp_of = gp_of[keep]
                start_idx = member_start[keep]
            else:
                pre_iter = np.zeros(len(gp_of), dtype=np.int64)
                pre_eval = np.zeros(len(gp_of), dtype=np.int64)
            states = minimize_batched(make_fun(torch_X, torch_y, gp_of, "full"), starts, opts, make_prune(gp_of))
            for k, st in enumerate(states):
                b, r = int(gp_of[k]), int(start_idx[k])
                nll_r[b, r] = st.f
                iter_r[b, r] = st.n_iter + pre_iter[k]
                eval_r[b, r] = st.n_eval + pre_eval[k]
                reason_r[b][r] = st.reason
            for b in opt_gps:
                cand = np.where(np.isfinite(nll_r[b]), nll_r[b], np.inf)
                r = int(np.argmin(cand))
                k = int(np.flatnonzero((gp_of == b) & (start_idx == r))[0])
                final_theta[b] = states[k].x
        best_r = np.zeros(B, dtype=np.int64)
        for b in opt_gps:
            cand = np.where(np.isfinite(nll_r[b]), nll_r[b], np.inf)
            best_r[b] = int(np.argmin(cand))

        # --- state and cached factors
        self._dims = dims
        self._X = Xp
        self._y = y_arr
        self._x_mean, self._x_std, self._mask = x_mean, x_std, mask
        self._y_mean, self._y_std = y_mean, y_std
        self._theta = final_theta
        self._const_y = const_y
        self._compute_factors()
        self.fit_info = []
        for b in range(B):
            self.fit_info.append({
                "nll": [_num(v) for v in nll_r[b]],
                "n_iter": [int(v) for v in iter_r[b]],
                "n_eval": [int(v) for v in eval_r[b]],
                "reason": list(reason_r[b]),
                "best": int(best_r[b]),
                "best_nll": float(self._final_nll[b]),
                "converged": "constant_target" if const_y[b] else reason_r[b][int(best_r[b])],
                "jitter": float(self._jitter[b]),
                "max_jitter_fit": float(max_jit[b]),
                "constant_target": bool(const_y[b]),
                "warm_start": warm,
                "screen_nll": [_num(v) for v in screen_nll[b]],
            })
        self.fit_summary = {"time_s": time.perf_counter() - t0, "n_eval": int(n_eval_total), "batch_rounds": rounds,
                            "n_eval_screen": stage_evals["screen"], "n_eval_full": stage_evals["full"]}
        return self

    @staticmethod
    def _linear_noise(Xa: np.ndarray, yb: np.ndarray) -> float:
        """Data-driven initial noise: a tenth of the residual variance of a linear least-squares fit (clipped)."""
        n = yb.shape[0]
        A = np.hstack([Xa, np.ones((n, 1))])
        if A.shape[1] >= n:
            return 0.1
        coef, *_ = np.linalg.lstsq(A, yb, rcond=None)
        res = float(np.mean((yb - A @ coef) ** 2))
        return float(np.clip(0.1 * res, 1e-4, 0.5))

    def _converted_theta(self, x_std_new: np.ndarray, y_std_new: np.ndarray, mask_new: np.ndarray,
                         D: int) -> np.ndarray:
        """This bank's hyperparameters expressed in another normalisation (for warm starts)."""
        B = self._theta.shape[0]
        out = np.zeros((B, D + 2))
        Dold = self._theta.shape[1] - 2
        for b in range(B):
            d = int(self._dims[b])
            th = self._theta[b]
            ll = th[:d] + np.log(self._x_std[b, :d]) - np.log(x_std_new[b, :d])
            ll = np.where((self._mask[b, :d] > 0) & (mask_new[b, :d] > 0), ll, 0.5 * math.log(max(d, 1)))
            out[b, :d] = ll
            scale = math.log(self._y_std[b] ** 2) - math.log(y_std_new[b] ** 2)
            out[b, D] = th[Dold] + scale
            sn2 = _noise_var(self.config, math.exp(th[Dold]), math.exp(th[Dold + 1])) * math.exp(scale)
            floor = _noise_var(self.config, math.exp(out[b, D]), 0.0)
            out[b, D + 1] = math.log(max(sn2 - floor, 1e-8))
        return out

    def _compute_factors(self) -> None:
        """Cholesky factor, ``alpha`` and final NLL of every GP at ``self._theta`` (one GP at a time: the
        temporaries are a few ``(n, n)`` matrices; only the ``(B, n, n)`` factor is kept)."""
        cfg = self.config
        Xn = (self._X - self._x_mean[:, None, :]) / self._x_std[:, None, :] * self._mask[:, None, :]
        yn = (self._y - self._y_mean[:, None]) / self._y_std[:, None]
        B, n, D = self._X.shape
        th = torch.as_tensor(self._theta, dtype=_DT)
        tX = torch.as_tensor(Xn, dtype=_DT)
        ty = torch.as_tensor(yn, dtype=_DT)
        tm = torch.as_tensor(self._mask, dtype=_DT)
        inv_l = torch.exp(-th[:, :D]) * tm
        Z = tX * inv_l[:, None, :]
        sf2 = torch.exp(th[:, D])
        sn2 = torch.tensor([_noise_var(cfg, float(sf2[b]), math.exp(float(th[b, D + 1]))) for b in range(B)],
                           dtype=_DT)
        L = torch.empty(B, n, n, dtype=_DT)
        alpha = torch.empty(B, n, dtype=_DT)
        jitter = np.zeros(B)
        nll = np.zeros(B)
        for b in range(B):
            K = kernel_of_r2_torch(cfg.kernel, scaled_sqdist(Z[b : b + 1])).mul_(sf2[b])
            K.diagonal(dim1=-2, dim2=-1).add_(sn2[b])
            Lb, jit, failed = _robust_cholesky(K, max(cfg.jitter_max, 1.0))
            del K
            if bool(failed.any()):
                raise RuntimeError(f"GPBank: Cholesky failed for GP {b} even with jitter 1.0")
            L[b] = Lb[0]
            alpha[b] = torch.cholesky_solve(ty[b, :, None], Lb[0])[:, 0]
            jitter[b] = float(jit[0])
            nll[b] = float(0.5 * (ty[b] * alpha[b]).sum() + torch.log(Lb[0].diagonal()).sum() + 0.5 * n * _LOG2PI)
        self._Z = Z
        self._L = L
        self._alpha = alpha
        self._sf2 = sf2
        self._sn2 = sn2
        self._jitter = jitter
        self._final_nll = nll
        self._inv_l = inv_l
        self._fitted = True

    # ------------------------------------------------------------------ prediction
    def predict(self, X: list[np.ndarray], return_var: bool = True,
                chunk: int = 4096) -> tuple[np.ndarray, np.ndarray | None]:
        """Posterior mean and latent variance of every GP.

        Args:
            X: per GP ``(m, d_b)`` query inputs (the same ``m`` for every GP).
            return_var: also return the variance of the latent function (no noise).
            chunk: queries per batched block (memory bound: ``B * chunk * n`` floats).

        Returns:
            ``mean (m, B)`` and ``var (m, B)`` (or ``None``) in original target units.
        """
        self._require_fitted()
        X = _as_list(X, "X")
        B = self.n_gps
        if len(X) != B:
            raise ValueError(f"X: expected {B} query arrays (one per GP), got {len(X)}")
        Q0 = _check_matrix(X[0], "X[0]", d=int(self._dims[0]))
        m = Q0.shape[0]
        Qs = [Q0] + [_check_matrix(X[b], f"X[{b}]", d=int(self._dims[b]), n=m) for b in range(1, B)]
        D = self._X.shape[2]
        Q = np.zeros((B, m, D))
        for b in range(B):
            Q[b, :, : self._dims[b]] = Qs[b]
        Qn = torch.as_tensor((Q - self._x_mean[:, None, :]) / self._x_std[:, None, :], dtype=_DT)
        means, vars_ = [], []
        for s in range(0, max(m, 1), chunk):
            Zq = Qn[:, s : s + chunk] * self._inv_l[:, None, :]
            Ks = kernel_of_r2_torch(self.config.kernel, scaled_sqdist(Zq, self._Z)) * self._sf2[:, None, None]
            means.append(torch.matmul(Ks, self._alpha.unsqueeze(-1)).squeeze(-1))
            if return_var:
                V = torch.linalg.solve_triangular(self._L, Ks.transpose(-1, -2), upper=False)
                vars_.append((self._sf2[:, None] - (V * V).sum(-2)).clamp_min_(0.0))
        mean = torch.cat(means, 1).numpy().T * self._y_std[None, :] + self._y_mean[None, :]
        if not return_var:
            return np.ascontiguousarray(mean), None
        var = torch.cat(vars_, 1).numpy().T * (self._y_std[None, :] ** 2)
        return np.ascontiguousarray(mean), np.ascontiguousarray(var)

    def posterior(self, b: int) -> GPPosterior:
        """NumPy factors of GP ``b`` (see :class:`GPPosterior`)."""
        self._require_fitted()
        b = self._check_b(b)
        d = int(self._dims[b])
        act = self._mask[b, :d] > 0
        x_scale = np.where(act, self._x_std[b, :d] * np.exp(self._theta[b, :d]), np.inf)
        return GPPosterior(
            kernel=self.config.kernel,
            x_mean=self._x_mean[b, :d].copy(),
            x_scale=x_scale,
            Z=self._Z[b, :, :d].numpy().copy(),
            alpha=self._alpha[b].numpy().copy(),
            L=self._L[b].numpy().copy(),
            signal_var=float(self._sf2[b]),
            noise_var=float(self._sn2[b]),
            y_mean=float(self._y_mean[b]),
            y_std=float(self._y_std[b]),
            jitter=float(self._jitter[b]),
        )

    # ------------------------------------------------------------------ persistence
    def state_dict(self) -> dict[str, Any]:
        """Plain NumPy arrays and scalars that reproduce the fitted bank exactly (see :meth:`from_state_dict`)."""
        self._require_fitted()
        return {
            "format": "cascgp.GPBank",
            "version": STATE_VERSION,
            "config_json": json.dumps(asdict(self.config)),
            "dims": self._dims.copy(),
            "X": self._X.copy(),
            "y": self._y.copy(),
            "x_mean": self._x_mean.copy(),
            "x_std": self._x_std.copy(),
            "mask": self._mask.copy(),
            "y_mean": self._y_mean.copy(),
            "y_std": self._y_std.copy(),
            "theta": self._theta.copy(),
            "constant_target": self._const_y.copy(),
            "fit_info_json": json.dumps(self.fit_info),
        }

    @classmethod
    def from_state_dict(cls, d: dict[str, Any]) -> GPBank:
        """Rebuild a fitted bank from :meth:`state_dict` output (the Cholesky factors are recomputed)."""
        if not isinstance(d, dict):
            raise ValueError(f"state: expected a dict, got {type(d).__name__}")
        required = ("format", "version", "config_json", "dims", "X", "y", "x_mean", "x_std", "mask", "y_mean",
                    "y_std", "theta", "constant_target", "fit_info_json")
        for k in required:
            if k not in d:
                raise ValueError(f"state[{k!r}]: missing")
        if str(np.asarray(d["format"])) != "cascgp.GPBank":
            raise ValueError(f"state['format']: expected 'cascgp.GPBank', got {d['format']!r}")
        if int(np.asarray(d["version"])) != STATE_VERSION:
            raise ValueError(f"state['version']: expected {STATE_VERSION}, got {d['version']!r}")
        try:
            config = GPFitConfig.from_dict(json.loads(str(np.asarray(d["config_json"]))))
        except (json.JSONDecodeError, TypeError) as e:
            raise ValueError(f"state['config_json']: not a valid GPFitConfig ({e})") from None
        dims = np.asarray(d["dims"], dtype=np.int64)
        if dims.ndim != 1 or dims.size == 0 or np.any(dims < 1):
            raise ValueError(f"state['dims']: expected a non-empty 1-D array of positive ints, got {dims!r}")
        B, D = dims.size, int(dims.max())
        Xp = np.asarray(d["X"], dtype=np.float64)
        if Xp.ndim != 3 or Xp.shape[0] != B or Xp.shape[2] != D or Xp.shape[1] < 2:
            raise ValueError(f"state['X']: expected shape ({B}, n>=2, {D}), got {Xp.shape}")
        n = Xp.shape[1]
        shapes = {"y": (B, n), "x_mean": (B, D), "x_std": (B, D), "mask": (B, D), "y_mean": (B,), "y_std": (B,),
                  "theta": (B, D + 2), "constant_target": (B,)}
        arrs = {}
        for k, shp in shapes.items():
            a = np.asarray(d[k])
            if a.shape != shp:
                raise ValueError(f"state[{k!r}]: expected shape {shp}, got {a.shape}")
            if k != "constant_target":
                a = a.astype(np.float64)
                if not np.all(np.isfinite(a)):
                    raise ValueError(f"state[{k!r}]: contains NaN or inf")
            arrs[k] = a
        if not np.all(np.isfinite(Xp)):
            raise ValueError("state['X']: contains NaN or inf")
        bank = cls(config)
        bank._dims = dims
        bank._X = Xp.copy()
        bank._y = arrs["y"].copy()
        bank._x_mean, bank._x_std, bank._mask = arrs["x_mean"].copy(), arrs["x_std"].copy(), arrs["mask"].copy()
        bank._y_mean, bank._y_std = arrs["y_mean"].copy(), arrs["y_std"].copy()
        bank._theta = arrs["theta"].copy()
        bank._const_y = arrs["constant_target"].astype(bool)
        bank._compute_factors()
        try:
            bank.fit_info = json.loads(str(np.asarray(d["fit_info_json"])))
        except json.JSONDecodeError as e:
            raise ValueError(f"state['fit_info_json']: not valid JSON ({e})") from None
        return bank
