r"""The fitted state of a GP bank: Cholesky factors, :math:`\alpha`, final NLL (:func:`compute_factors`), and the
per-GP NumPy posterior that hand-written prediction paths read (:class:`GPPosterior`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from cascgp.gp.checks import check_matrix, real_array
from cascgp.gp.config import GPFitConfig, noise_var
from cascgp.gp.kernels import get_kernel, scaled_sqdist
from cascgp.gp.likelihood import DTYPE, LOG2PI

__all__ = ["GPPosterior", "Factors", "compute_factors", "robust_cholesky", "ZCLIP"]

#: Scaled query inputs (lengthscales applied) are clipped to +-ZCLIP in prediction, so that no squared distance
#: overflows: the output is finite for any finite input (far beyond the data, where the kernel is 0 anyway).
ZCLIP = 1e6
#: Query rows per block are chosen so that each (rows, n) float64 matrix of a prediction holds at most this many
#: bytes: memory stays fixed however many rows are queried (a 200,000-row log against n = 2000 needed 13 GB).
BLOCK_BYTES = 64 * 2**20


def _row_blocks(m: int, n: int) -> list[slice]:
    """Slices of ``m`` query rows whose (rows, n) matrices each hold at most :data:`BLOCK_BYTES` (at least 256 rows,
    a multiple of 256); the results equal a computation of all rows at once to round-off."""
    rows = max(256, BLOCK_BYTES // (8 * max(n, 1)) // 256 * 256)
    return [slice(i, min(i + rows, m)) for i in range(0, m, rows)] or [slice(0, 0)]


@dataclass(frozen=True)
class GPPosterior:
    r"""Cached posterior of one fitted GP as plain NumPy float64 arrays (for hand-written fast paths).

    .. math::

        z = \operatorname{clip}((x - x_{mean}) / x_{scale}, \pm 10^6), \quad
        \mu(x) = y_{mean} + y_{std}\, s_f^2\, k(r^2(z, Z))^\top \alpha, \quad
        \sigma^2(x) = y_{std}^2\, \big(s_f^2 - \|L^{-1} s_f^2 k(r^2(z, Z))\|^2\big)

    ``x_scale`` is the input's standard deviation times its lengthscale, both in the input's units (so ``z`` is
    the scaled input and ``Z`` the scaled training inputs: apply no lengthscale again); ``inf`` for ignored
    (constant) input columns, so their ``z`` is 0. The clip (:data:`ZCLIP`) keeps the output finite for any
    finite input.
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

    def query(self, x: Any) -> np.ndarray:
        """``x`` as a float64 ``(m, d)`` array of finite numbers, a ``(d,)`` vector as one row; ``ValueError`` (shape,
        NaN or inf) or ``TypeError`` (not real numbers) naming ``x`` otherwise."""
        d = self.x_mean.shape[0]
        a = real_array(x, "x", f"(m, {d})")
        if a.ndim == 1:
            if a.shape[0] != d:
                raise ValueError(f"x: expected shape (m, {d}) or ({d},), got {a.shape}")
            a = a[None, :]
        return check_matrix(a, "x", d=d)

    def predict(self, x: np.ndarray, return_var: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """Reference NumPy prediction: ``x`` ``(m, d)`` or ``(d,)`` (:meth:`query`) -> mean ``(m,)``, latent
        variance ``(m,)`` (None when not ``return_var``), in blocks of rows (fixed memory for any ``m``:
        :data:`BLOCK_BYTES`)."""
        x = self.query(x)
        blocks = _row_blocks(x.shape[0], self.Z.shape[0])
        if len(blocks) > 1:
            parts = [self._predict_block(x[b], return_var) for b in blocks]
            return (np.concatenate([p[0] for p in parts]),
                    np.concatenate([p[1] for p in parts]) if return_var else None)
        return self._predict_block(x, return_var)

    def _predict_block(self, x: np.ndarray, return_var: bool) -> tuple[np.ndarray, np.ndarray | None]:
        z = np.clip((x - self.x_mean) / self.x_scale, -ZCLIP, ZCLIP)
        r2 = (z * z).sum(1)[:, None] + (self.Z * self.Z).sum(1)[None, :] - 2.0 * z @ self.Z.T
        ks = self.signal_var * get_kernel(self.kernel).value(r2)
        mean = self.y_mean + self.y_std * (ks @ self.alpha)
        if not return_var:
            return mean, None
        from scipy.linalg import solve_triangular

        v = solve_triangular(self.L, ks.T, lower=True)
        var = np.maximum(self.signal_var - (v * v).sum(0), 0.0) * self.y_std**2
        return mean, var

    def mean_grad(self, x: np.ndarray, col: int) -> np.ndarray:
        r"""Derivative of the posterior mean with respect to input column ``col`` at the rows of ``x``
        ``(m, d)``: :math:`\partial\mu/\partial x_c = \frac{y_{std} s_f^2}{x_{scale,c}} \sum_k
        2\,k'(r^2_k)\,(z_c - Z_{kc})\,\alpha_k` (0 for an ignored column)."""
        x = self.query(x)
        if isinstance(col, bool) or not isinstance(col, (int, np.integer)):
            raise TypeError(f"col: expected an integer input column, got {type(col).__name__} {col!r}")
        if not 0 <= col < x.shape[1]:
            raise ValueError(f"col: expected an input column in [0, {x.shape[1]}), got {col!r}")
        if not np.isfinite(self.x_scale[col]):
            return np.zeros(x.shape[0])
        out = np.empty(x.shape[0])
        for b in _row_blocks(x.shape[0], self.Z.shape[0]):  # fixed memory for any number of rows
            z, kprime = self._kernel_slope(x[b])
            dk = kprime * (2.0 * (z[:, col, None] - self.Z[None, :, col]))
            out[b] = self.y_std * self.signal_var * (dk @ self.alpha) / self.x_scale[col]
        return out

    def _kernel_slope(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Normalised queries ``z`` (m, d) and :math:`k'(r^2)` (m, n) against the training inputs."""
        z = (x - self.x_mean) / self.x_scale
        r2 = (z * z).sum(1)[:, None] + (self.Z * self.Z).sum(1)[None, :] - 2.0 * z @ self.Z.T
        return z, get_kernel(self.kernel).grad_r2(r2)

    def mean_grad_all(self, x: np.ndarray) -> np.ndarray:
        r"""Gradient of the posterior mean with respect to every input column at the rows of ``x`` ``(m, d)``,
        ``(m, d)``: the :meth:`mean_grad` of each column at once,

        .. math::

            \frac{\partial\mu}{\partial x_c} = \frac{2\, y_{std}\, s_f^2}{x_{scale,c}}
            \Big(z_c \sum_k k'(r^2_k)\,\alpha_k - \sum_k k'(r^2_k)\,\alpha_k Z_{kc}\Big)

        (two matrix products; 0 for ignored columns, whose ``x_scale`` is ``inf``)."""
        x = self.query(x)
        g = np.empty(x.shape)
        for b in _row_blocks(x.shape[0], self.Z.shape[0]):  # fixed memory for any number of rows
            z, kprime = self._kernel_slope(x[b])
            w = kprime * self.alpha[None, :]
            g[b] = z * w.sum(1)[:, None] - w @ self.Z
        return 2.0 * self.y_std * self.signal_var * g / self.x_scale


def robust_cholesky(K: torch.Tensor, jitter_max: float) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
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


@dataclass(frozen=True)
class Factors:
    r"""What prediction needs of every GP of a bank at its final hyperparameters (torch, float64).

    Attributes:
        Z: ``(B, n, D)`` training inputs, normalised and divided by the lengthscales.
        inv_l: ``(B, D)`` inverse lengthscales (0 for masked columns).
        L: ``(B, n, n)`` lower Cholesky factors of :math:`K`.
        alpha: ``(B, n)`` :math:`K^{-1} \tilde y`.
        sf2, sn2: ``(B,)`` signal and noise variances (normalised units).
        jitter: ``(B,)`` jitter added to the diagonal (normalised units).
        nll: ``(B,)`` final negative log marginal likelihood.
    """

    Z: torch.Tensor
    inv_l: torch.Tensor
    L: torch.Tensor
    alpha: torch.Tensor
    sf2: torch.Tensor
    sn2: torch.Tensor
    jitter: np.ndarray
    nll: np.ndarray


def compute_factors(cfg: GPFitConfig, Xn: np.ndarray, yn: np.ndarray, mask: np.ndarray,
                    theta: np.ndarray, floors: np.ndarray | None = None) -> Factors:
    """Cholesky factor, ``alpha`` and final NLL of every GP at ``theta`` on normalised data ``Xn (B, n, D)``,
    ``yn (B, n)`` (one GP at a time: the temporaries are a few ``(n, n)`` matrices; only the ``(B, n, n)``
    factor is kept). ``floors`` ``(B,)``: per-GP noise floors (:meth:`GPFitConfig.floors`; ``None``:
    ``cfg.noise_floor``). ``RuntimeError`` if a factorisation fails even with jitter 1.0."""
    B, n, D = Xn.shape
    kern = get_kernel(cfg.kernel)
    th = torch.as_tensor(theta, dtype=DTYPE)
    tX = torch.as_tensor(Xn, dtype=DTYPE)
    ty = torch.as_tensor(yn, dtype=DTYPE)
    tm = torch.as_tensor(mask, dtype=DTYPE)
    inv_l = torch.exp(-th[:, :D]) * tm
    Z = tX * inv_l[:, None, :]
    sf2 = torch.exp(th[:, D])
    sn2 = torch.tensor([noise_var(cfg, float(sf2[b]), math.exp(float(th[b, D + 1])),
                                  None if floors is None else float(floors[b])) for b in range(B)],
                       dtype=DTYPE)
    L = torch.empty(B, n, n, dtype=DTYPE)
    alpha = torch.empty(B, n, dtype=DTYPE)
    jitter = np.zeros(B)
    nll = np.zeros(B)
    for b in range(B):
        K = kern.value_torch(scaled_sqdist(Z[b : b + 1])).mul_(sf2[b])
        K.diagonal(dim1=-2, dim2=-1).add_(sn2[b])
        Lb, jit, failed = robust_cholesky(K, max(cfg.jitter_max, 1.0))
        del K
        if bool(failed.any()):
            raise RuntimeError(f"GPBank: Cholesky failed for GP {b} even with jitter 1.0")
        L[b] = Lb[0]
        alpha[b] = torch.cholesky_solve(ty[b, :, None], Lb[0])[:, 0]
        jitter[b] = float(jit[0])
        nll[b] = float(0.5 * (ty[b] * alpha[b]).sum() + torch.log(Lb[0].diagonal()).sum() + 0.5 * n * LOG2PI)
    return Factors(Z=Z, inv_l=inv_l, L=L, alpha=alpha, sf2=sf2, sn2=sn2, jitter=jitter, nll=nll)
