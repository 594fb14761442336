r"""The cascaded GP model: one GP per joint, chained in cascade order (:class:`CascadedGPModel`).

Owns training (one batched :class:`~cascgp.gp.GPBank` fit, or N fits in cascade order with ``train_on_predicted``)
and batched prediction; the single-query path is :mod:`cascgp.models.fastpath`, the checks of queries
:mod:`cascgp.models.queries`, the derivatives of the mean (input noise) :mod:`cascgp.models.jacobian`, learning
inside an episode :mod:`cascgp.models.online`, files :mod:`cascgp.models.io`; the variants in :mod:`cascgp.models`.
"""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path
from typing import Any, Literal, Sequence, overload

import numpy as np

from cascgp.checks import check_positive
from cascgp.data import DynamicsData, all_finite
from cascgp.features import build_inputs, history_from_data, input_spec, states_from_arrays
from cascgp.gp import GPBank, GPFitConfig
from cascgp.gp.bank import SharedGPError
from cascgp.gp.config import check_target_floor
from cascgp.models.fastpath import FastPath, FastVariance
from cascgp.models.fit_start import shared_chain_first, warm_start_banks
from cascgp.models.jacobian import check_input_var, mean_jacobian_arrays
from cascgp.models.queries import check_queries, clipped, load_query, state_cols
from cascgp.models.training_rows import training_arrays
# defined in a module without torch (command lines check names before importing the library); exported here too
from cascgp.settings import MODEL_NAMES, parse_name

__all__ = ["MODEL_NAMES", "CascadedGPModel", "make_model", "parse_name"]

class CascadedGPModel:
    """One of the twelve variants (build with :func:`make_model`).

    Attributes:
        name: the variant's name, one of :data:`MODEL_NAMES` (``"sp-inward"``, ...).
        dof: number of joints N.
        parametric: ``"np"`` (the GPs model the torque) or ``"sp"`` (the residual to :attr:`rbd`).
        structure: ``"standard"``, ``"inward"`` or ``"outward"``.
        feature_kind: ``"db"`` (derivative-based inputs) or ``"df"`` (derivative-free: positions only).
        rbd: the rigid-body mean function of an SP model (:class:`cascgp.rbd.RigidBodyModel`); ``None`` for NP.
        gp_config: the :class:`cascgp.gp.GPFitConfig` of the fits.
        df_delta: the history step of ``-df`` features (s).
        train_on_predicted: cascades only (a standard model ignores it): each joint trained on its neighbour's
            predicted torque (not measured).
        order: joints (0-based) in prediction order (inward: N-1 .. 0, else 0 .. N-1).
        banks: the fitted :class:`cascgp.gp.GPBank` objects; ``where[j] = (k, b)``: joint j is GP ``b`` of ``banks[k]``.
    """

    def __init__(self, name: str, dof: int, rbd: Any = None, *, gp_config: Any = None,
                 df_delta: float = 0.1, train_on_predicted: bool = False) -> None:
        self.parametric, self.structure, self.feature_kind = parse_name(name)
        self.name = name
        if isinstance(dof, bool) or not isinstance(dof, (int, np.integer)) or dof < 1:
            raise ValueError(f"dof: expected a positive integer, got {dof!r}")
        self.dof = int(dof)
        if self.parametric == "sp":
            if rbd is None:
                raise ValueError(f"rbd: semi-parametric model {name!r} needs a rigid-body model "
                                 "(an object with .dof and .inverse_dynamics(q, qd, qdd)), got None")
            if not hasattr(rbd, "inverse_dynamics") or not hasattr(rbd, "dof"):
                raise TypeError(f"rbd: expected an object with .dof and .inverse_dynamics, got {type(rbd).__name__}")
            if int(rbd.dof) != self.dof:
                raise ValueError(f"rbd: DOF mismatch: the model has dof={self.dof}, the rigid-body model has "
                                 f"{rbd.dof} joints")
        self.rbd: Any = rbd if self.parametric == "sp" else None
        if gp_config is None:
            gp_config = GPFitConfig()
        if not isinstance(gp_config, GPFitConfig):
            raise TypeError(f"gp_config: expected GPFitConfig or None, got {type(gp_config).__name__}")
        t = gp_config.noise_floor_target
        if isinstance(t, tuple) and len(t) != self.dof:
            raise ValueError(f"gp_config.noise_floor_target: expected one noise-variance floor per joint "
                             f"({self.dof}, N² m²), got {len(t)}")
        self.gp_config = gp_config
        check_positive(df_delta, "df_delta", "s")
        self.df_delta = float(df_delta)
        if not isinstance(train_on_predicted, (bool, np.bool_)):  # bool("no") is True
            raise TypeError(f"train_on_predicted: expected True or False, got {train_on_predicted!r}")
        self.train_on_predicted = bool(train_on_predicted)
        N = self.dof
        self.order: tuple[int, ...] = tuple(range(N - 1, -1, -1)) if self.structure == "inward" else tuple(range(N))
        self.specs = [input_spec(self.structure, j, N) for j in range(N)]
        self.banks: list[Any] = []
        self.where: list[tuple[int, int]] = []
        self.n_train = 0
        self._post: list[Any] = []
        self._fast: FastPath | None = None
        self._fast_offline: FastPath | None = None
        self._fast_var: FastVariance | None = None
        self._fast_var_offline: FastVariance | None = None
        self._online: Any = None

    # ------------------------------------------------------------------ basics
    @property
    def fitted(self) -> bool:
        return bool(self.banks)

    def __repr__(self) -> str:
        return (f"CascadedGPModel(name={self.name!r}, dof={self.dof}, fitted={self.fitted}, "
                f"n_train={self.n_train})")

    def _require_fitted(self) -> FastPath:
        if not self.fitted or self._fast is None:  # fit() and adopt_banks() install both; returns the fast path
            raise RuntimeError(f"model {self.name!r}: not fitted; call fit() or load_model() first")
        return self._fast

    @property
    def fit_info(self) -> list[dict]:
        """``GPBank.fit_info`` entry of every joint, in joint order."""
        self._require_fitted()
        return [self.banks[k].fit_info[b] for k, b in self.where]

    def _rbd_torque(self, q: np.ndarray, qd: np.ndarray | None, qdd: np.ndarray | None) -> np.ndarray:
        if qd is None or qdd is None:
            raise ValueError(f"qd/qdd: the semi-parametric model {self.name!r} needs velocities and "
                             "accelerations for its rigid-body mean")
        tau = np.asarray(self.rbd.inverse_dynamics(q, qd, qdd), dtype=np.float64).reshape(q.shape)
        if not (all_finite(tau) if tau.ndim == 1 else np.isfinite(tau).all()):  # one query: every control tick
            raise ValueError("rbd: the rigid-body model returned non-finite torques")
        return tau

    # ------------------------------------------------------------------ training
    def _states(self, q: np.ndarray, qd: np.ndarray | None, qdd: np.ndarray | None,
                q_hist: np.ndarray | None) -> np.ndarray:
        return states_from_arrays(self.feature_kind, q, qd, qdd, q_hist)

    def fit(self, data: DynamicsData, init: "CascadedGPModel | Any | None" = None, *,
            share: "CascadedGPModel | None" = None, q_hist: Any = None) -> "CascadedGPModel":
        """Train every joint's GP on ``data`` (see the module docstring).

        ``init``: a fitted model of the same name and DOF (or, for the default one-bank layout,
        a fitted ``GPBank``) whose hyperparameters warm-start the fit (as one start).
        ``share`` (cascades, one-bank layout): the standard model of the same kind fitted with the same settings
        on the same ``data`` (warm-started from the standard twin of ``init``, if any); the cascade takes its GP of
        the chain's first joint, which has the same inputs, instead of fitting it again. The result is the fit
        without ``share`` (:mod:`cascgp.models.fit_start`).
        ``q_hist`` (``-df`` models, optional): each row's positions at ``t - df_delta`` and ``t - 2 df_delta``,
        ``(T, 2, N)``, taken from the full record when ``data`` are rows chosen from it (rows with a non-finite
        entry are left out: set those without history to NaN, which ``history_from_data`` clamps instead);
        default: interpolated within ``data`` (:mod:`cascgp.models.training_rows`).
        Returns ``self``.
        """
        arr = training_arrays(self, data, q_hist)
        S = self._states(arr["q"], arr["qd"], arr["qdd"], arr["q_hist"])
        tau = arr["tau"]
        tau_rbd = self._rbd_torque(arr["q"], arr["qd"], arr["qdd"]) if self.parametric == "sp" else None
        targets = tau - tau_rbd if tau_rbd is not None else tau
        N = self.dof
        sequential = self.train_on_predicted and self.structure != "standard"
        init_banks = warm_start_banks(self, init, sequential)
        shared = shared_chain_first(self, share, sequential)

        if not sequential:
            X = build_inputs(S, tau, self.structure)  # measured neighbour torques
            try:
                bank = GPBank(self.gp_config).fit(X, [targets[:, j] for j in range(N)],
                                                  init=init_banks[0] if init_banks else None, shared=shared)
            except SharedGPError as e:
                raise ValueError(f"share: {share!r} cannot stand in for this fit of joint "
                                 f"{self.order[0] + 1}: {e}") from None
            self.banks = [bank]
            self.where = [(0, j) for j in range(N)]
        else:
            banks: list[Any] = [None] * N
            where: list[tuple[int, int]] = [(0, 0)] * N
            tau_hat = np.zeros_like(tau)  # in-sample chained predicted torques
            sflat = S.reshape(S.shape[0], -1)
            for k, j in enumerate(self.order):
                sj, tj = self.specs[j]
                x = state_cols(sflat, sj)
                if tj is not None:
                    x = np.concatenate([x, tau_hat[:, tj:tj + 1]], axis=1)
                ib = init_banks[k] if init_banks else None
                bank = GPBank(self._joint_config(j)).fit([x], [targets[:, j]], init=ib)
                banks[k] = bank
                where[j] = (k, 0)
                m, _ = bank.posterior(0).predict(x, return_var=False)
                tau_hat[:, j] = m + (tau_rbd[:, j] if tau_rbd is not None else 0.0)
            self.banks = banks
            self.where = where
        self.n_train = int(S.shape[0])
        self._cache()
        return self

    def _joint_config(self, j: int) -> GPFitConfig:
        """The fit config of a one-GP bank holding joint ``j`` (a per-joint ``noise_floor_target`` reduced to
        joint ``j``'s value; otherwise ``gp_config`` itself)."""
        t = self.gp_config.noise_floor_target
        return replace(self.gp_config, noise_floor_target=(t[j],)) if isinstance(t, tuple) else self.gp_config

    def adopt_banks(self, banks: list[GPBank], where: Sequence[Sequence[int]], n_train: int) -> None:
        """Install fitted banks (``where[j] = (bank, GP)`` locates joint j's GP), e.g. read from a file;
        ``ValueError`` if they do not fit this model's joints and inputs. Changes nothing on error."""
        N = self.dof
        if len(where) != N or any(not (0 <= k < len(banks) and 0 <= b < banks[k].n_gps) for k, b in where):
            raise ValueError(f"config_json.where: {where} does not match {len(banks)} bank(s) and dof={N}")
        for j, (k, b) in enumerate(where):
            want = 3 * len(self.specs[j][0]) + (self.specs[j][1] is not None)
            if banks[k].dims[b] != want:
                raise ValueError(f"bank {k} GP {b}: input dimension {banks[k].dims[b]} does not match "
                                 f"{self.name!r} joint {j} ({want})")
        rows = {int(banks[k].n_train) for k, _ in where}
        if len(rows) != 1:
            raise ValueError(f"banks: the joints' GPs hold different numbers of training rows {sorted(rows)}")
        if isinstance(n_train, bool) or not isinstance(n_train, (int, np.integer)) or n_train not in rows:
            raise ValueError(f"n_train: expected the banks' number of training rows ({rows.pop()}), got {n_train!r}")
        post, fast = self._built(banks, where)  # may raise: nothing assigned yet
        self.banks, self.where, self.n_train = list(banks), [(k, b) for k, b in where], int(n_train)
        self._install(post, fast)

    # ------------------------------------------------------------------ caches
    def _built(self, banks: list[GPBank], where: Sequence[Sequence[int]]) -> tuple[list[Any], FastPath]:
        """Posterior factors per joint and the padded arrays of the single-query path (assigns nothing)."""
        post = [banks[k].posterior(b) for k, b in where]
        return post, FastPath.build(post, self.specs, self.order)

    def _cache(self) -> None:
        """Build and install the caches of the current banks."""
        self._install(*self._built(self.banks, self.where))

    def _install(self, post: list[Any], fast: FastPath) -> None:
        self._post = post
        self._fast = self._fast_offline = fast
        self._fast_var = self._fast_var_offline = None
        self._online = None

    # ------------------------------------------------------------------ prediction
    def predict(self, q: Any, qd: Any = None, qdd: Any = None, q_hist: Any = None, *,
                propagate: bool = False, input_var: Any = None) -> tuple[np.ndarray, np.ndarray]:
        r"""Predicted joint torques.

        Args:
            q, qd, qdd: (T, N) or (N,) (``qd``/``qdd`` may be None for NP ``-df`` models).
            q_hist: ``-df`` models only: (T, 2, N) or (2, N): ``q(t - df_delta)``, ``q(t - 2 df_delta)``.
                A derivative-based model ignores it, as an NP ``-df`` model ignores ``qd`` and ``qdd``, so that
                one call serves every variant.
            propagate: cascades only: add the uncertainty of the neighbour's predicted torque to each
                joint's variance (first-order propagation, below). ``False`` keeps the variance given the
                chained mean input.
            input_var: derivative-based models only: variances of the noise of the measured inputs, broadcast
                to (N, 3) = ``(q_j, qd_j, qdd_j)`` per joint (rad², (rad/s)², (rad/s²)²), independent; adds the
                test-time input-noise term below. ``None`` (default): inputs are taken as exact.

        Returns:
            ``mean``, ``var``: (T, N) (or (N,) for (N,) inputs).  ``mean`` is the full torque
            (RBD added back for SP).  ``var`` is the latent (noise-free) variance of each joint's
            torque in N² m²; add :attr:`noise_var` for the variance of a measurement.

        Propagation through the cascade (linearisation of the mean in the torque input, the
        "delta method"): joint :math:`j` is fed the predicted torque :math:`\hat\tau_t` of its
        neighbour, itself Gaussian with variance :math:`v_t`; to first order in :math:`\hat\tau_t`,

        .. math::

            v_j = \sigma^2_j(x_j) + \Big(\frac{\partial \mu_j}{\partial \tau}(x_j)\Big)^2 v_t,

        evaluated at the chained mean input :math:`x_j`, with :math:`\partial\mu_j/\partial\tau` in
        closed form (:meth:`cascgp.gp.posterior.GPPosterior.mean_grad`). The recursion runs in
        cascade order, so the first joint of the chain keeps its GP variance. The neglected terms are
        of second order in :math:`\sqrt{v_t}` over the GP's lengthscale in the torque input; a test
        compares it with Monte Carlo sampling of the cascade. In an SP model the rigid-body part is
        deterministic, so only the GP part carries variance.

        Input noise (``input_var``; NIGP's test-time term, McHutchon & Rasmussen 2011): the query is a noisy
        measurement :math:`\tilde s = s + \epsilon`, :math:`\epsilon \sim \mathcal N(0, \mathrm{diag}
        (\sigma^2_s))` over the 3N state entries :math:`s = (q_k, \dot q_k, \ddot q_k)_k`. To first order the
        predicted torque moves by :math:`J \epsilon`, with :math:`J_{j,s} = d\mu_j / ds` the *total*
        derivative of the cascaded mean (:meth:`mean_jacobian`: the GP's own state inputs, the chained
        neighbour torque :math:`d\mu_j/ds \mathrel{+}= \partial\mu_j/\partial\tau \; d\mu_t/ds`, and for SP
        models the rigid-body torque), so

        .. math::

            v_j \mathrel{+}= \sum_s J_{j,s}^2\, \sigma^2_s .

        It is added after the propagation, which carries only the GP (latent) variance of the neighbour, so
        the input noise, shared by the whole chain, is counted once. The term is not fitted: the caller passes
        the sensors' variances (e.g. from the sensor model and :meth:`cascgp.data.SavGol.noise_gain`). The
        training inputs were noisy too; their effect is in the fitted noise variance, as in an exact GP.
        """
        self._require_fitted()
        single, q, qd, qdd, q_hist = check_queries(self, q, qd, qdd, q_hist)
        input_var = check_input_var(self, input_var) if input_var is not None else None
        mean, var = self._predict_arrays(q, qd, qdd, q_hist, return_var=True, propagate=propagate)
        if input_var is not None:
            J = mean_jacobian_arrays(self, q, qd, qdd, mean)  # the chained inputs are this prediction's mean
            with np.errstate(over="ignore"):
                var = var + (J * J) @ input_var.reshape(-1)  # sum_s J_js^2 sigma_s^2 (see above)
            if not np.isfinite(var).all():
                raise ValueError(f"input_var: the variance overflowed (input_var up to {input_var.max():.3g}, the "
                                 f"mean's derivatives up to {np.abs(J).max():.3g})")
        return (mean[0], var[0]) if single else (mean, var)

    def mean_jacobian(self, q: Any, qd: Any, qdd: Any) -> np.ndarray:
        r"""Total derivative of the predicted (cascaded) mean torque with respect to the measured states.

        Args:
            q, qd, qdd: (T, N) or (N,) (derivative-based models only).

        Returns:
            ``J`` (T, N, N, 3) (or (N, N, 3)): ``J[t, j, k, c]`` = :math:`d\mu_j / d s_{k,c}` at row ``t`` with
            :math:`s_k = (q_k, \dot q_k, \ddot q_k)`, through the chained neighbour torques and (SP) the
            rigid-body torque (see :meth:`predict`). The GP parts are in closed form
            (:meth:`cascgp.gp.posterior.GPPosterior.mean_grad_all`; 0 where an input is clipped); the rigid-body
            part by central differences of ``rbd.inverse_dynamics``.
        """
        self._require_fitted()
        if self.feature_kind != "db":
            raise ValueError(f"mean_jacobian: needs a derivative-based model (states q, qd, qdd), got {self.name!r}")
        single, q, qd, qdd, _ = check_queries(self, q, qd, qdd, None)
        J = mean_jacobian_arrays(self, q, qd, qdd).reshape(q.shape[0], self.dof, self.dof, 3)
        return J[0] if single else J

    @property
    def noise_var(self) -> np.ndarray:
        """Fitted noise variance of each joint's GP in N² m², (N,): the measurement noise the model
        attributes to the torques (add it to ``var`` for a predictive interval of a measurement)."""
        self._require_fitted()
        return np.array([P.noise_var * P.y_std**2 for P in self._post])

    @property
    def signal_var(self) -> np.ndarray:
        """Prior (signal) variance of each joint's GP in N² m², (N,): the latent variance far from the
        training data."""
        self._require_fitted()
        return np.array([P.signal_var * P.y_std**2 for P in self._post])

    def _predict_arrays(self, q, qd, qdd, q_hist, return_var: bool,
                        propagate: bool = False) -> tuple[np.ndarray, np.ndarray]:
        S = self._states(q, qd, qdd, q_hist)
        T, N = q.shape
        sflat = S.reshape(T, -1)
        tau_rbd = self._rbd_torque(q, qd, qdd) if self.parametric == "sp" else None
        mean = np.empty((T, N))
        var = np.zeros((T, N))
        for j in self.order:  # cascade order: the torque input is the already PREDICTED torque
            sj, tj = self.specs[j]
            x = state_cols(sflat, sj)
            if tj is not None:
                x = np.concatenate([x, mean[:, tj:tj + 1]], axis=1)
            P = self._post[j]
            x = clipped(P, x)
            m, v = P.predict(x, return_var=return_var)
            mean[:, j] = m + (tau_rbd[:, j] if tau_rbd is not None else 0.0)
            if return_var:
                var[:, j] = v
                if propagate and tj is not None:
                    var[:, j] += P.mean_grad(x, x.shape[1] - 1) ** 2 * var[:, tj]
        return mean, var

    @overload
    def predict_data(self, data: DynamicsData, return_var: Literal[True] = ...) -> tuple[np.ndarray, np.ndarray]: ...

    @overload
    def predict_data(self, data: DynamicsData, return_var: Literal[False]) -> tuple[np.ndarray, None]: ...

    def predict_data(self, data: DynamicsData, return_var: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """:meth:`predict` on the rows of ``data`` (``-df``: history from ``data`` itself, see
        :func:`cascgp.features.history_from_data`; rows without full history use the clamped
        history: finite, but check ``state_features(data, "df")[1]`` before scoring them). ``return_var=False``:
        the mean alone, the same numbers, without the variance's triangular solves (``None`` in its place)."""
        self._require_fitted()
        if not isinstance(data, DynamicsData):
            raise TypeError(f"data: expected DynamicsData, got {type(data).__name__}")
        if data.dof != self.dof:
            raise ValueError(f"data: DOF mismatch: the model has dof={self.dof}, data.dof={data.dof}")
        q_hist = history_from_data(data, self.df_delta)[0] if self.feature_kind == "df" else None
        mean, var = self._predict_arrays(data.q, data.qd, data.qdd, q_hist, return_var=return_var)
        return mean, (var if return_var else None)

    def predict_one(self, q: Any, qd: Any = None, qdd: Any = None, q_hist: Any = None, *,
                    rbd_torque: Any = None) -> np.ndarray:
        """Mean torque (N,) for ONE query: ``q``, ``qd``, ``qdd`` (N,) (``qd``, ``qdd`` for ``-db`` and ``sp-*``
        models), ``q_hist`` (2, N) for ``-df`` models (``q`` at ``t - df_delta`` and ``t - 2 df_delta``). The lean
        path for a controller (no torch, no variance; :mod:`cascgp.models.fastpath`, compiled with Numba). Equals
        :meth:`predict` to round-off (~1e-12), except while an online window is open (:meth:`start_online`): then
        it includes the online samples, which :meth:`predict` does not. Inputs are checked for shape and finiteness
        (``ValueError``). ``rbd_torque`` (SP models, optional): ``self.rbd.inverse_dynamics(q, qd, qdd)`` when the
        caller has it already (a gated controller's nominal torque), so that it is not computed twice. Not
        thread-safe: the query is written into the model's own buffer, so threads need a model each."""
        f, tau_rbd = load_query(self, q, qd, qdd, q_hist, rbd_torque)
        return f.mean(tau_rbd)

    def predict_one_var(self, q: Any, qd: Any = None, qdd: Any = None, q_hist: Any = None, *,
                        rbd_torque: Any = None) -> tuple[np.ndarray, np.ndarray]:
        """Mean torque and *propagated* latent variance (N,), (N,) for ONE query (arguments as for
        :meth:`predict_one`): the single-query form of ``predict(..., propagate=True)`` (equal to round-off; with an
        online window open, of the enlarged sets). The first call gathers each joint's Cholesky factor
        (:meth:`prepare_variance`); a query then costs one ``(n, n)`` triangular solve per joint on top of
        :meth:`predict_one`."""
        f, tau_rbd = load_query(self, q, qd, qdd, q_hist, rbd_torque)
        return self.prepare_variance().mean_var(f, tau_rbd)

    def prepare_variance(self) -> FastVariance:
        """Build the single-query variance path now (each joint's Cholesky factor as BLAS reads it), e.g. before an
        episode, so that the first gated control tick does not pay for it. Built once
        per fit and shared by every online window opened on it; returns it."""
        self._require_fitted()
        if self._fast_var is None:
            if self._fast_var_offline is None:
                self._fast_var_offline = FastVariance.build(self._post)
            online = self._online
            self._fast_var = online.variance(self._fast_var_offline) if online is not None else self._fast_var_offline
        return self._fast_var

    def posteriors(self) -> list[Any]:
        """Each joint's fitted :class:`~cascgp.gp.posterior.GPPosterior`, in joint order."""
        self._require_fitted()
        return list(self._post)

    # ------------------------------------------------------------------ learning inside an episode
    def start_online(self, window: int = 150) -> None:
        """Let new samples enter the model (:meth:`add_sample`) until the next :meth:`fit`, with the
        hyperparameters held: each joint keeps its fitted set plus the ``window`` most recent samples
        (:mod:`cascgp.models.online`). Derivative-based models only."""
        from cascgp.models.online import OnlineWindow

        self._require_fitted()
        self._online = OnlineWindow(self, window)
        self._fast = self._online.fast
        self._fast_var = None

    def stop_online(self) -> None:
        """Drop the online window (:meth:`start_online`): predictions are again those of the fitted model.
        Does nothing when no window is open."""
        if self._online is not None:
            self._online = None
            self._fast = self._fast_offline
            self._fast_var = None

    def add_sample(self, q: Any, qd: Any, qdd: Any, tau: Any) -> None:
        """Add one measured sample ``(q, qd, qdd, tau)``, each (N,), to every joint (see :meth:`start_online`).
        Each joint's GP input uses the *measured* neighbour torque and its target is the measured torque (minus
        the RBD torque for SP), as in training. Rejects non-finite values and values too large to normalise (an SP
        target too: the measured torque minus the RBD torque), with ``ValueError``, changing nothing."""
        if getattr(self, "_online", None) is None:
            raise RuntimeError(f"model {self.name!r}: call start_online() before add_sample()")
        self._online.add_measured(q, qd, qdd, tau)

    @property
    def n_online(self) -> int:
        """Samples added since :meth:`start_online` (0 when not learning online)."""
        online = getattr(self, "_online", None)
        return 0 if online is None else online.n_added

    # ------------------------------------------------------------------ persistence
    def save(self, path: str | os.PathLike, provenance: Any = None) -> Path:
        """Write the fitted model (and ``provenance``) to ``path`` atomically: :func:`cascgp.models.io.save_model`."""
        from cascgp.models.io import save_model

        return save_model(self, path, provenance=provenance)


def make_model(name: str, dof: int, rbd: Any = None, *, gp_config: Any = None, df_delta: float = 0.1,
               train_on_predicted: bool = False, noise_var_floor: Any = None) -> CascadedGPModel:
    r"""Build an unfitted model.  ``name`` in :data:`MODEL_NAMES`; ``rbd`` (required for ``sp-*``): an object with
    ``dof`` and ``inverse_dynamics(q, qd, qdd)`` (e.g. :class:`cascgp.rbd.RigidBodyModel`) whose DOF equals ``dof``;
    ``np-*`` models ignore it, so that one call builds any of the twelve (``model.rbd`` is then ``None``).
    ``gp_config``, ``df_delta`` (s) and ``train_on_predicted``: as :class:`CascadedGPModel`'s attributes.

    ``noise_var_floor`` (opt-in, default ``None``: no floor, the fit is exactly the one without it): a lower bound
    of each joint's fitted noise variance in N² m² (torque units squared), one number for every joint or one per
    joint (shape ``(dof,)``), e.g. the torque sensor's noise variance :math:`\sigma_\tau^2` (a measured torque
    cannot be less noisy than its sensor). It sets ``gp_config.noise_floor_target``; each GP converts it with its
    target scale :math:`\sigma_y` (N m) to the normalised floor
    :math:`\max(\mathrm{noise\_floor}, \sigma_\tau^2 / \sigma_y^2)` (:meth:`cascgp.gp.GPFitConfig.floors`), so
    that its noise variance is :math:`\ge \sigma_\tau^2` in N² m². ``ValueError`` naming ``noise_var_floor`` for a
    negative or non-finite value, a wrong shape, or a ``gp_config`` that already sets ``noise_floor_target``."""
    if noise_var_floor is not None:
        cfg = GPFitConfig() if gp_config is None else gp_config
        if not isinstance(cfg, GPFitConfig):
            raise TypeError(f"gp_config: expected GPFitConfig or None, got {type(cfg).__name__}")
        if cfg.noise_floor_target is not None:
            raise ValueError("noise_var_floor: gp_config already sets noise_floor_target; give the floor once")
        floor = check_target_floor(noise_var_floor, "noise_var_floor")
        if isinstance(floor, tuple) and len(floor) != dof:
            raise ValueError(f"noise_var_floor: expected one number or shape ({dof},) (one per joint, N^2 m^2), got "
                             f"{len(floor)} values")
        gp_config = replace(cfg, noise_floor_target=floor)
    return CascadedGPModel(name, dof, rbd, gp_config=gp_config, df_delta=df_delta,
                           train_on_predicted=train_on_predicted)
