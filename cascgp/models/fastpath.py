r"""The single-query prediction path of a fitted cascade: what a controller calls every control tick.

Why hand-written: one query through torch costs tens of microseconds of dispatch per joint; the paper's
controller queries the model at the control rate. :class:`FastPath` holds every joint's posterior padded to a
common width so that the state part of all N kernel inputs is computed in one batched NumPy product; only the
scalar torque input is chained joint by joint (the cascade). For joint :math:`j` with state columns :math:`x_j`
and (cascades) the neighbour's predicted torque :math:`\hat\tau_{t(j)}`:

.. math::

    a_j = s\,\big(\|w_{jk}\|^2 + \|z_j\|^2 - 2 w_{jk}^\top z_j\big) + s\,(z^\tau_{jk} - z^\tau_j)^2,
    \qquad \mu_j = \bar y_j + \sum_k \kappa(a_{jk})\, \tilde\alpha_{jk}

with :math:`z = (x - \bar x) / \ell`, the kernel's ``r2_scale`` :math:`s` folded into the inputs
(:meth:`~cascgp.gp.kernels.Kernel.value_scaled_np_` evaluates :math:`\kappa`), and
:math:`\tilde\alpha = y_{std}\, s_f^2\, \alpha`. Normalised inputs are clipped to :math:`\pm 10^6` so no distance
overflows. Equals :meth:`CascadedGPModel.predict` to round-off (~1e-12).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
from scipy.linalg.blas import dtrsv

from cascgp.gp.kernels import Kernel, get_kernel
from cascgp.gp.posterior import ZCLIP, GPPosterior
from cascgp.models.fastkernel import JIT_WT, jit_args, jit_mean, jit_var, jit_var_factors

__all__ = ["FastPath", "FastVariance", "ZCLIP"]


@dataclass(frozen=True)
class FastPath:
    r"""Padded posterior arrays of an N-joint cascade (build with :meth:`build`).

    Attributes:
        kernel: the kernel object.
        order: joints in prediction order.
        idx: ``(N, D)`` state-vector index of each padded input column (``D = 3N``; index ``D`` reads a 0).
        x_mean, x_inv_scale: ``(N, D)`` state normalisation, pre-multiplied by :math:`\sqrt{s}` (0 for padding).
        W: ``(N, n, D)`` scaled training states; W2: ``(N, n)`` their squared norms.
        torque_from: per joint, the joint whose predicted torque it takes (``None``: none).
        t_mean, t_inv_scale: per joint, the torque input's normalisation (pre-scaled).
        Zt: ``(N, n)`` scaled training torque inputs.
        alpha: ``(N, n)`` :math:`y_{std}\, s_f^2\, \alpha`.
        y_mean: per joint target mean.
        zclip: clip bound of the scaled inputs.
        buf: ``(D + 1,)`` work buffer for the state vector (last entry stays 0).
        jit: the compiled mean's arguments (:mod:`cascgp.models.fastkernel`; its ``[JIT_WT]`` is ``W``
            transposed, ``(N, D, n)``, a copy that :meth:`set_rows` keeps equal), None when it is not used.
    """

    kernel: Kernel
    order: tuple[int, ...]
    idx: np.ndarray
    x_mean: np.ndarray
    x_inv_scale: np.ndarray
    W: np.ndarray
    W2: np.ndarray
    torque_from: tuple[int | None, ...]
    t_mean: tuple[float, ...]
    t_inv_scale: tuple[float, ...]
    Zt: np.ndarray
    alpha: np.ndarray
    y_mean: tuple[float, ...]
    zclip: float
    buf: np.ndarray
    jit: tuple | None = None

    @classmethod
    def build(cls, posts: Sequence[GPPosterior], specs: Sequence[tuple[tuple[int, ...], int | None]],
              order: tuple[int, ...], capacity: int = 0) -> FastPath:
        """From each joint's posterior and input spec ``(state joints, torque joint or None)``; ``capacity``
        extra zero-weight rows per joint leave room for online samples (:mod:`cascgp.models.online`)."""
        N = len(posts)
        kernel = get_kernel(posts[0].kernel)
        n0 = posts[0].Z.shape[0]
        n = n0 + capacity
        D = 3 * N
        c = math.sqrt(kernel.r2_scale)
        idx = np.full((N, D), D, dtype=np.intp)
        xm = np.zeros((N, D))
        xs_inv = np.zeros((N, D))
        W = np.zeros((N, n, D))
        tm = np.zeros(N)
        ts_inv = np.zeros(N)
        Zt = np.zeros((N, n))
        a = np.zeros((N, n))
        y_mean = np.zeros(N)
        for j, P in enumerate(posts):
            sj, tj = specs[j]
            cols = np.concatenate([[3 * s, 3 * s + 1, 3 * s + 2] for s in sj]).astype(np.intp)
            ds = cols.size
            idx[j, :ds] = cols
            xm[j, :ds] = P.x_mean[:ds]
            xs_inv[j, :ds] = c / P.x_scale[:ds]  # inf scale (ignored column) -> 0
            W[j, :n0, :ds] = c * P.Z[:, :ds]
            if tj is not None:
                tm[j] = P.x_mean[ds]
                ts_inv[j] = c / P.x_scale[ds]
                Zt[j, :n0] = c * P.Z[:, ds]
            a[j, :n0] = P.y_std * P.signal_var * P.alpha
            y_mean[j] = P.y_mean
        W2 = np.einsum("jnd,jnd->jn", W, W)
        tfrom = np.array([-1 if s[1] is None else s[1] for s in specs], dtype=np.intp)
        ncol = np.array([3 * len(s[0]) for s in specs], dtype=np.intp)
        WT = np.ascontiguousarray(W.transpose(0, 2, 1))
        jit = jit_args(kernel.name, (idx, ncol, xm, xs_inv, WT, W2, tfrom, np.asarray(order, dtype=np.intp), tm,
                                     ts_inv, Zt, a, y_mean, ZCLIP * c))
        return cls(kernel=kernel, order=tuple(order), idx=idx, x_mean=xm, x_inv_scale=xs_inv, W=W, W2=W2,
                   torque_from=tuple(s[1] for s in specs), t_mean=tuple(tm.tolist()),
                   t_inv_scale=tuple(ts_inv.tolist()), Zt=Zt, alpha=a, y_mean=tuple(y_mean.tolist()),
                   zclip=ZCLIP * c, buf=np.zeros(D + 1), jit=jit)

    def set_rows(self, j: int, lo: int, W: np.ndarray) -> None:
        """Write scaled training states ``W`` ``(m, D)`` into joint ``j``'s rows ``lo:lo + m`` (online samples),
        with their squared norms and the compiled path's transposed copy."""
        hi = lo + W.shape[0]
        self.W[j, lo:hi] = W
        self.W2[j, lo:hi] = np.einsum("nd,nd->n", W, W)
        if self.jit is not None:
            self.jit[JIT_WT][j, :, lo:hi] = W.T

    def state_r2(self) -> np.ndarray:
        """Scaled squared distances ``(N, n)`` of the state part of every joint's input (from ``buf``) to its
        training inputs, all joints at once: ``|W|^2 + |z|^2 - 2 W z``."""
        zc = self.zclip
        z = self.buf[self.idx]
        z -= self.x_mean
        z *= self.x_inv_scale
        np.clip(z, -zc, zc, out=z)
        r2s = np.matmul(self.W, z[:, :, None])[:, :, 0]
        r2s *= -2.0
        r2s += self.W2
        r2s += np.einsum("jd,jd->j", z, z)[:, None]
        np.maximum(r2s, 0.0, out=r2s)
        return r2s

    def mean(self, tau_mean: np.ndarray | None) -> np.ndarray:
        """Predicted torques ``(N,)`` for the state already written into ``buf[:3N]`` as
        ``(q_1, s_1', s_1'', q_2, ...)``; ``tau_mean`` (SP models) is added to each joint's GP mean before the
        torque is passed along the cascade. The compiled loop (:mod:`cascgp.models.fastkernel`) when it is
        available, else :meth:`mean_numpy` (equal to round-off)."""
        if self.jit is not None:
            out = np.empty(len(self.order))
            if jit_mean(self.jit, self.buf, tau_mean, out):
                return out
        return self.mean_numpy(tau_mean)

    def mean_numpy(self, tau_mean: np.ndarray | None) -> np.ndarray:
        """:meth:`mean` in NumPy: the reference of the compiled loop."""
        zc = self.zclip
        r2s = self.state_r2()
        out = np.empty(len(self.order))
        value_ = self.kernel.value_scaled_np_
        Zt, a, tjs, tm, tsi, ym = self.Zt, self.alpha, self.torque_from, self.t_mean, self.t_inv_scale, self.y_mean
        for j in self.order:
            r2 = r2s[j]
            tj = tjs[j]
            if tj is not None:  # chain: the neighbour's PREDICTED torque
                tq = (out[tj] - tm[j]) * tsi[j]
                tq = zc if tq > zc else (-zc if tq < -zc else tq)
                d = Zt[j] - tq
                d *= d
                r2 = d + r2
            m = ym[j] + float(value_(r2) @ a[j])
            if tau_mean is not None:
                m += float(tau_mean[j])
            out[j] = m
        return out


@dataclass(frozen=True)
class FastVariance:
    r"""What the single-query path needs for the *propagated* latent variance (build with :meth:`build`).

    With :math:`\kappa` the kernel row of the query (scaled as in :class:`FastPath`), :math:`L_j` joint j's
    Cholesky factor and :math:`c_j = y_{std}\, s_f^2`, joint j's latent variance given its inputs is
    :math:`p_j - \|u_j\|^2` with :math:`u_j = L_j^{-1} c_j \kappa` (one triangular solve, BLAS ``dtrsv``;
    :math:`p_j = y_{std}^2 s_f^2`, the prior variance), and the cascade adds
    :math:`(\partial\mu_j/\partial\tau)^2 v_{t(j)}` (see :meth:`cascgp.models.CascadedGPModel.predict`), with

    .. math::

        \frac{\partial\mu_j}{\partial\tau} = \sum_k \tilde\alpha_{jk}\, \kappa'(a_{jk})\,
            2\,(z^\tau_j - z^\tau_{jk})\, \frac{c}{\ell_\tau} \cdot \frac{1}{c^2} \cdot s
        = \sum_k \tilde\alpha_{jk}\, \kappa'(a_{jk})\, 2\,(z^\tau_j - z^\tau_{jk})\, t_j

    in the fast path's scaled coordinates (:math:`c = \sqrt s`, :math:`t_j` = ``t_inv_scale``). The solve reads
    half of an ``(n, n)`` matrix per joint (a product with the explicit inverse :math:`c_j L_j^{-1}` would read all
    of it); at n = 500 that memory traffic is most of the query's time.

    Attributes:
        L: per joint, :math:`L_j^\top` (a Fortran-ordered view of the factor, as BLAS reads it); scale: ``(N,)``
            :math:`c_j`; prior: ``(N,)`` prior variances (N² m²).
        window: online samples (:class:`cascgp.models.online.OnlineWindow`) whose variance term is added.
        Lc: the same factors for the compiled solves (:func:`~cascgp.models.fastkernel.jit_var`: ``L`` are their
            transposed views; with an online window, its term too), None when they are not used.
    """

    L: tuple[np.ndarray, ...]
    scale: np.ndarray
    prior: np.ndarray
    window: Any = None
    Lc: tuple[np.ndarray, ...] | None = None

    @classmethod
    def build(cls, posts: Sequence[GPPosterior]) -> FastVariance:
        Lc = jit_var_factors(tuple(P.L for P in posts))
        return cls(L=tuple(L.T for L in Lc) if Lc is not None else tuple(np.ascontiguousarray(P.L).T for P in posts),
                   scale=np.array([P.y_std * P.signal_var for P in posts]),
                   prior=np.array([P.y_std**2 * P.signal_var for P in posts]), Lc=Lc)

    def solve(self, j: int, b: np.ndarray) -> np.ndarray:
        """:math:`L_j^{-1} b` (a new array)."""
        return dtrsv(self.L[j], b, lower=0, trans=1)

    def mean_var(self, fast: FastPath, tau_mean: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """Predicted torques and their propagated latent variances ``(N,)``, ``(N,)`` for the state in
        ``fast.buf`` (as :meth:`FastPath.mean`). The kernel rows come from the compiled loop when the fast path
        has it (:mod:`cascgp.models.fastkernel`), and so do the solves and an online window's term; else they
        come from :meth:`mean_var_numpy` (equal to round-off)."""
        N = len(fast.order)
        mean, var = np.empty(N), np.empty(N)
        K, G = np.empty(fast.alpha.shape), np.zeros(N)
        if fast.jit is None or not jit_mean(fast.jit, fast.buf, tau_mean, mean, (K, G)):
            return self.mean_var_numpy(fast, tau_mean)
        window = self.window.compiled_var_terms() if self.window is not None else None
        if self.Lc is not None and jit_var(fast.jit, self.Lc, self.scale, self.prior, K, G, var, window):
            return mean, var
        for j in fast.order:
            tj = fast.torque_from[j]
            var[j] = self._var(j, K[j], G[j] * G[j] * var[tj] if tj is not None else None)
        return mean, var

    def _var(self, j: int, kap: np.ndarray, propagated: float | None) -> float:
        """Joint ``j``'s latent variance for its kernel row ``kap`` plus the neighbour's propagated term."""
        n0 = self.L[j].shape[0]
        u = self.solve(j, self.scale[j] * kap[:n0])
        q = float(u @ u) + (self.window.extra_var(j, kap, u) if self.window is not None else 0.0)
        v = max(self.prior[j] - q, 0.0)
        return v if propagated is None else v + propagated

    def mean_var_numpy(self, fast: FastPath, tau_mean: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`mean_var` in NumPy: the reference of the compiled kernel rows."""
        zc = fast.zclip
        r2s = fast.state_r2()
        N = len(fast.order)
        mean, var = np.empty(N), np.empty(N)
        for j in fast.order:
            r2 = r2s[j]
            tj = fast.torque_from[j]
            if tj is not None:
                tq = (mean[tj] - fast.t_mean[j]) * fast.t_inv_scale[j]
                tq = zc if tq > zc else (-zc if tq < -zc else tq)
                diff = tq - fast.Zt[j]
                r2 = diff * diff + r2
            kap, dkap = fast.kernel.value_and_grad_scaled_np(r2)
            a = fast.alpha[j]
            m = fast.y_mean[j] + float(kap @ a)
            if tau_mean is not None:
                m += float(tau_mean[j])
            mean[j] = m
            g = 2.0 * fast.t_inv_scale[j] * float((dkap * diff) @ a) if tj is not None else 0.0
            var[j] = self._var(j, kap, g * g * var[tj] if tj is not None else None)
        return mean, var
