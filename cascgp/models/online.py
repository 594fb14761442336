r"""Learning inside an episode: new measured samples enter a fitted cascade at a bounded cost.

Between retrainings the hyperparameters are held; each joint's GP keeps its fitted training set (``n0`` points,
factor :math:`L_{00}`) and gains a window of at most ``window`` recent samples (the oldest is dropped when it is
full). The factor of the enlarged kernel matrix is kept in block form,

.. math::

    K = \begin{pmatrix} K_{00} & K_{0w} \\ K_{w0} & K_{ww} \end{pmatrix}
      = \begin{pmatrix} L_{00} & 0 \\ L_{w0} & L_{ww} \end{pmatrix}
        \begin{pmatrix} L_{00}^\top & L_{w0}^\top \\ 0 & L_{ww}^\top \end{pmatrix},
    \quad L_{w0} = K_{w0} L_{00}^{-\top}, \quad L_{ww} L_{ww}^\top = K_{ww} - L_{w0} L_{w0}^\top,

so a new sample costs one triangular solve with :math:`L_{00}` for its row of :math:`L_{w0}` (:math:`O(n_0^2)`),
the Cholesky factor of the small window block (:math:`O(w^3)`, recomputed, which also makes dropping the oldest
sample exact), and the weights :math:`\alpha = K^{-1}\tilde y` by block substitution (:math:`O(n_0^2 + n_0 w)`),
with :math:`L_{00}^{-1}\tilde y_0` computed once. Why by hand: a rank-1 *extension* of a fixed factor is not a
library routine in NumPy/SciPy/torch, and refitting or refactorising the whole :math:`(n_0 + w)` matrix per sample
(:math:`O(n^3)`) would not fit between control ticks.

The single-query paths (:meth:`~cascgp.models.CascadedGPModel.predict_one`, ``predict_one_var``) read the
enlarged sets: the fast path is rebuilt with room for the window (padded rows carry zero weight), and the
variance adds :math:`\|L_{ww}^{-1}(k_w - L_{w0} L_{00}^{-1} k_0)\|^2` to the fitted set's term. Each joint's
input uses the *measured* neighbour torque and its target is the measured torque (minus the RBD torque for SP
models), exactly as in training. Derivative-based (``db``) models only.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.linalg import solve_triangular
from scipy.linalg.blas import dtrsv
from scipy.linalg.lapack import dpotrf

from cascgp.gp.checks import check_scale
from cascgp.gp.kernels import get_kernel
from cascgp.gp.likelihood import blas_threads
from cascgp.models.fastpath import FastPath, FastVariance
from cascgp.models.queries import one_real, state_cols

__all__ = ["OnlineWindow", "check_supported"]


class _JointWindow:
    """Block factor and window of one joint's GP (normalised units)."""

    def __init__(self, P: Any, window: int) -> None:
        self.P = P
        n0, d = P.Z.shape
        self.kernel = get_kernel(P.kernel)
        self.noise = P.noise_var + P.jitter
        self.L00 = P.L
        self.U00 = np.ascontiguousarray(P.L).T  # L00^T, Fortran-ordered: what BLAS reads without a copy
        # u0 = L00^-1 y0 with y0 = K alpha the normalised targets; algebraically L00^T alpha, but kept as the
        # solve it always was: the documented online runs (README, docs/) reproduce bit for bit with it.
        y0 = P.L @ (P.L.T @ P.alpha)
        self.u0 = solve_triangular(P.L, y0, lower=True)
        # The window's rows live in buffers of twice its length: dropping the oldest sample moves the window one
        # row on, and only once every `window` samples are its rows copied back to the front (shifting every row
        # per sample was a fifth of the sample's time). Same rows, same order: same arithmetic.
        self.window = window
        self._Zw = np.zeros((2 * window, d))
        self._Lw0 = np.zeros((2 * window, n0))
        self._yw = np.zeros(2 * window)
        self.start = 0
        self.S = np.zeros((0, 0))  # S = K_ww + noise I - L_w0 L_w0^T of the m samples held
        self.m = 0
        self.alpha0 = P.alpha.copy()
        self.alphaw = np.zeros(0)
        self.Lww = np.zeros((0, 0))

    @property
    def Zw(self) -> np.ndarray:
        """``(window, d)``: the normalised inputs of the window (rows ``:m`` held, oldest first)."""
        return self._Zw[self.start:self.start + self.window]

    @property
    def Lw0(self) -> np.ndarray:
        """``(window, n0)``: the window's rows of :math:`L_{w0}` (rows ``:m`` held)."""
        return self._Lw0[self.start:self.start + self.window]

    @property
    def yw(self) -> np.ndarray:
        """``(window,)``: the window's normalised targets (``:m`` held)."""
        return self._yw[self.start:self.start + self.window]

    def _drop_oldest(self) -> None:
        """The window without its oldest sample (one row on in the buffers, or its rows moved to the front)."""
        W = self.window
        if self.start + W < self._yw.size:
            self.start += 1
        else:
            k = self.start + 1  # = W + 1: rows k .. 2W - 1 move to 0 .. W - 2 (no overlap)
            self._Zw[:W - 1], self._Lw0[:W - 1], self._yw[:W - 1] = self._Zw[k:], self._Lw0[k:], self._yw[k:]
            self.start = 0
        self.m -= 1

    def propose(self, z: np.ndarray, y: float) -> tuple:
        """Everything that adding the normalised input ``z`` and target ``y`` would change, computed without
        changing anything: the new row of :math:`L_{w0}`, the window block ``S`` and its factor. Raises (e.g.
        ``LinAlgError`` for a block that is not positive definite) with the window as it was; :meth:`commit`
        applies it and cannot fail."""
        P, W = self.P, self.window
        drop = self.m == W  # the oldest (row 0) leaves
        keep = slice(1, self.m) if drop else slice(0, self.m)
        k0 = P.signal_var * self.kernel.value(((z - P.Z) ** 2).sum(1))
        row = dtrsv(self.U00, k0, lower=0, trans=1)  # L00^-1 k0 (BLAS directly: the wrapper cost more)
        kw = P.signal_var * self.kernel.value(((z - self.Zw[keep]) ** 2).sum(1))
        s_new = kw - self.Lw0[keep] @ row  # S = K_ww + noise I - L_w0 L_w0^T, one new row and column
        i = s_new.size
        S = np.empty((i + 1, i + 1))
        S[:i, :i] = self.S[keep, keep]
        S[i, :i] = S[:i, i] = s_new
        S[i, i] = P.signal_var + self.noise - float(row @ row)
        Lww, info = dpotrf(S, lower=1, clean=1)  # scipy.linalg.cholesky's routine, without its wrapper
        if info != 0:
            raise np.linalg.LinAlgError(f"the window block is not positive definite (dpotrf info {info})")
        if not (np.isfinite(Lww.sum()) and np.isfinite(row.sum())):  # |entries| <= sqrt(S_ii): no overflow
            raise np.linalg.LinAlgError("the window block's factor is not finite")
        return drop, z, float(y), row, S, Lww

    def commit(self, proposal: tuple) -> None:
        """Apply a :meth:`propose` result: shift out the oldest sample if full, add the new one, new weights."""
        drop, z, y, row, S, Lww = proposal
        if drop:
            self._drop_oldest()
        i = self.m
        self.Zw[i], self.Lw0[i], self.yw[i] = z, row, y
        self.m = m = i + 1
        self.S = S
        self.Lww = Lww
        Lw0 = self.Lw0[:m]
        uw = dtrsv(self.Lww, self.yw[:m] - Lw0 @ self.u0, lower=1)  # Lww: Fortran-ordered (dpotrf)
        self.alphaw = dtrsv(self.Lww, uw, lower=1, trans=1)
        self.alpha0 = dtrsv(self.U00, self.u0 - Lw0.T @ self.alphaw, lower=0)  # L00^-T (...)

    def extra_var(self, kap_w: np.ndarray, u: np.ndarray) -> float:
        """Window term of the latent variance (torque units) given the fitted set's ``u = c L_00^{-1} kappa_0``."""
        if self.m == 0:
            return 0.0
        P = self.P
        r = self.Lww.shape[0]
        a = dtrsv(self.Lww, P.y_std * P.signal_var * kap_w[:r] - self.Lw0[:r] @ u, lower=1)
        return float(a @ a)


def check_supported(model: Any) -> None:
    """``ValueError`` naming the model unless online samples can enter it: derivative-based features, and
    neighbour torques in training that were measured (online samples carry measured ones)."""
    if model.feature_kind != "db":
        raise ValueError(f"online: model {model.name!r}: online updates support derivative-based models only")
    if getattr(model, "train_on_predicted", False) and model.structure != "standard":
        raise ValueError(f"online: model {model.name!r} was trained on predicted neighbour torques; online "
                         "samples carry measured ones, so they would not match its training inputs")


class OnlineWindow:
    """Online samples of every joint of a fitted derivative-based cascade (see the module docstring).

    Args:
        model: a fitted :class:`~cascgp.models.CascadedGPModel` (``db`` features).
        window: samples kept per joint (the oldest is dropped beyond it).
    """

    def __init__(self, model: Any, window: int) -> None:
        check_supported(model)
        if isinstance(window, bool) or not isinstance(window, (int, np.integer)) or window < 1:
            raise ValueError(f"window: expected an integer >= 1, got {window!r}")
        self.model = model
        self.window = int(window)
        posts = model.posteriors()
        self.joints = [_JointWindow(P, self.window) for P in posts]
        self.fast = FastPath.build(posts, model.specs, model.order, capacity=self.window)
        self.n0 = posts[0].Z.shape[0]
        self.c = math.sqrt(self.fast.kernel.r2_scale)
        self.n_added = 0
        self._var: FastVariance | None = None

    def variance(self, base: FastVariance | None = None) -> FastVariance:
        """The variance path of the fitted sets plus this window (the window's term is read live at each
        query). ``base``: the fitted model's own (:meth:`~cascgp.models.CascadedGPModel.prepare_variance`),
        so that opening a window does not rebuild it."""
        if self._var is None:
            base = base if base is not None else FastVariance.build(self.model.posteriors())
            self._var = FastVariance(L=base.L, scale=base.scale, prior=base.prior, window=self)
        return self._var

    def extra_var(self, j: int, kap: np.ndarray, u: np.ndarray) -> float:
        """Hook of :meth:`FastVariance.mean_var`: the window term of joint ``j``."""
        return self.joints[j].extra_var(kap[self.n0:], u)

    def add_measured(self, q: Any, qd: Any, qdd: Any, tau: Any) -> None:
        """Add one measured sample ``(q, qd, qdd, tau)``, each (N,)
        (:meth:`~cascgp.models.CascadedGPModel.add_sample`): each joint's input holds its states and the
        *measured* neighbour torque, its target the measured torque (minus the RBD torque for SP models), as in
        training. ``ValueError`` for a non-finite value, changing nothing."""
        model = self.model
        N = model.dof
        arr = {}
        for nm, v in (("q", q), ("qd", qd), ("qdd", qdd), ("tau", tau)):
            a = one_real(nm, v)
            if a.shape != (N,) or not np.isfinite(a).all():
                raise ValueError(f"{nm}: expected a finite array of shape ({N},), got {a!r}")
            check_scale(np.stack([a, np.zeros(N)]), nm)
            arr[nm] = a
        S = model._states(arr["q"][None], arr["qd"][None], arr["qdd"][None], None).reshape(-1)
        target = arr["tau"] - (model._rbd_torque(arr["q"][None], arr["qd"][None], arr["qdd"][None])[0]
                               if model.parametric == "sp" else 0.0)
        xs = []
        for j in range(N):
            sj, tj = model.specs[j]
            x = state_cols(S[None], sj)[0]
            xs.append(np.append(x, arr["tau"][tj]) if tj is not None else x)
        self.add(xs, target)

    def add(self, x_per_joint: list[np.ndarray], y: np.ndarray) -> None:
        """Add one sample: each joint's raw GP input (states, measured neighbour torque) and target. BLAS runs
        on one thread (its threads spun against the simulation: 30 ms instead of 0.3 ms per window factor)."""
        with blas_threads(1):
            self._add(x_per_joint, y)

    def _add(self, x_per_joint: list[np.ndarray], y: np.ndarray) -> None:
        fast, n0, c = self.fast, self.n0, self.c
        proposals = []  # every joint first: a joint that refuses the sample leaves all of them unchanged
        for j, (J, x) in enumerate(zip(self.joints, x_per_joint)):
            P = J.P
            z = np.where(np.isfinite(P.x_scale), (x - P.x_mean) / P.x_scale, 0.0)
            z = np.clip(z, -fast.zclip / c, fast.zclip / c)
            proposals.append(J.propose(z, (float(y[j]) - P.y_mean) / P.y_std))
        for j, (J, proposal) in enumerate(zip(self.joints, proposals)):
            P = J.P
            J.commit(proposal)
            m = J.m
            ds = proposal[1].size - (fast.torque_from[j] is not None)
            Wj = np.zeros((m, fast.W.shape[2]))
            Wj[:, :ds] = c * J.Zw[:m, :ds]
            fast.set_rows(j, n0, Wj)
            if fast.torque_from[j] is not None:
                fast.Zt[j, n0:n0 + m] = c * J.Zw[:m, ds]
            scale = P.y_std * P.signal_var
            fast.alpha[j, :n0] = scale * J.alpha0
            fast.alpha[j, n0:n0 + m] = scale * J.alphaw
        self.n_added += 1
