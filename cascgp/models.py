r"""The paper's twelve inverse-dynamics models: ``{np,sp}-{standard,inward,outward}[-df]``.

================  =====================================================================
name part         meaning
================  =====================================================================
``np`` / ``sp``   non-parametric (the GP models :math:`\tau_i`) / semi-parametric (the GP
                  models :math:`\tau_i - \tau_{RBD,i}`, prediction adds :math:`\tau_{RBD,i}`
                  back: the rigid-body model is the GP's mean function, paper eq. 4)
``standard``      joint i's GP sees the states of all joints
``inward``        joint i's GP sees :math:`\tau_{i+1}, s_1..s_i` (joint N: all states);
                  prediction chains the predicted torques N -> 1
``outward``       joint i's GP sees :math:`\tau_{i-1}, s_i..s_N` (joint 1: all states);
                  prediction chains the predicted torques 1 -> N
``-df``           derivative-free states :math:`s_j = (q_j(t), q_j(t-\Delta), q_j(t-2\Delta))`
                  instead of :math:`(q_j, \dot q_j, \ddot q_j)` (see :mod:`cascgp.features`)
================  =====================================================================

Training and the cascade
------------------------
By default every joint's GP is trained on the *measured* torque of its neighbour (the
torque input), and all joints are trained in ONE :meth:`GPBank.fit` call (one batch).  In an
SP model the neighbour input is the full measured torque (not the residual).

At prediction the cascade always uses the model's own *predicted* torque: inward from joint
N down to 1, outward from 1 up to N; in an SP cascade the torque passed along is the full
predicted torque :math:`\tau_{RBD} + \text{GP mean}`.

``train_on_predicted=True`` (cascades only) trains each joint on the torque predicted for its
neighbour by the already-fitted neighbour model instead.  That needs the neighbour's model
before the joint's own, so the fit runs in cascade order as N single-GP fits (inward: joint N
first; outward: joint 1 first): after each fit, the model's in-sample chained prediction of
that joint on the training rows becomes the next joint's torque input.  (The model then holds
N one-GP banks instead of one N-GP bank; prediction is the same.)  The in-sample prediction is
close to the measured torque when the GP interpolates, so the two options differ most with
noisy torques and small n.

Prediction variance
-------------------
``var`` is the latent (noise-free) posterior variance of each joint's GP in torque units.  In
a cascade it is the variance of that joint's GP *given the chained mean input*: the
uncertainty of the neighbour's predicted torque is not propagated.

Bad input (documented behaviour)
--------------------------------
Unknown name, SP without ``rbd``, ``rbd.dof != dof``, data of another DOF, NaN/inf or wrong
shapes of queries: ``ValueError``/``TypeError`` naming the field.  Fewer than 2 usable rows
(``-df`` models lose the rows whose history reaches before their segment's start): ``ValueError``.
Duplicated samples are allowed (the noise variance absorbs them).  A joint with constant
targets gets the constant as its prediction (see :mod:`cascgp.gp`).  Predictions are finite
for finite inputs (normalised inputs are clipped to +-1e6 so no distance overflows).
"""

from __future__ import annotations

import json
import math
import os
import warnings
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from .data import DynamicsData
from .io import atomic_savez, check_format_header, read_npz
from .features import STRUCTURES, build_inputs, history_from_data, input_spec, states_from_arrays

__all__ = ["MODEL_NAMES", "FORMAT_VERSION", "CascadedGPModel", "make_model", "load_model", "parse_name"]

#: The twelve model names.
MODEL_NAMES: tuple[str, ...] = tuple(
    f"{p}-{s}{d}" for p in ("np", "sp") for s in STRUCTURES for d in ("", "-df"))
#: Version of the saved-model ``.npz`` layout.
FORMAT_VERSION = 1
_KIND = "cascgp.CascadedGPModel"
_ZCLIP = 1e6  # normalised inputs are clipped to +-_ZCLIP: no overflow of squared distances
_N_CHECK = 5  # stored check queries (save -> load verification)


def parse_name(name: str) -> tuple[str, str, str]:
    """``"sp-inward-df"`` -> ``("sp", "inward", "df")``; unknown names raise ``ValueError``."""
    if not isinstance(name, str) or name not in MODEL_NAMES:
        raise ValueError(f"name: expected one of {MODEL_NAMES}, got {name!r}")
    parts = name.split("-")
    return parts[0], parts[1], ("df" if len(parts) == 3 else "db")


def _as_query(name: str, a: Any, N: int, extra: tuple[int, ...] = ()) -> np.ndarray:
    try:
        x = np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name}: expected a numeric array ({exc})") from None
    if x.ndim == 1 + len(extra):
        x = x[None]
    if x.ndim != 2 + len(extra) or x.shape[1:] != (*extra, N) or x.shape[0] == 0:
        want = ", ".join(["T", *map(str, extra), str(N)])
        raise ValueError(f"{name}: expected shape ({want}) or ({', '.join([*map(str, extra), str(N)])}), got {x.shape}")
    if not np.isfinite(x).all():
        r = int(np.flatnonzero((~np.isfinite(x.reshape(x.shape[0], -1))).any(axis=1))[0])
        raise ValueError(f"{name}: non-finite value (NaN or inf) at row {r}")
    return x


class CascadedGPModel:
    """One of the twelve variants (build with :func:`make_model`).

    Attributes:
        name, dof, parametric (``"np"``/``"sp"``), structure, feature_kind (``"db"``/``"df"``),
        rbd (SP only), gp_config, df_delta (s), train_on_predicted,
        order: joints (0-based) in prediction order (inward: N-1 .. 0, else 0 .. N-1).
        banks: the fitted :class:`cascgp.gp.GPBank` objects; ``where[j] = (bank, b)`` locates
            joint j's GP.
    """

    def __init__(self, name: str, dof: int, rbd: Any = None, *, gp_config: Any = None,
                 df_delta: float = 0.1, train_on_predicted: bool = False) -> None:
        from .gp import GPFitConfig

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
        self.rbd = rbd if self.parametric == "sp" else None
        if gp_config is None:
            gp_config = GPFitConfig()
        if not isinstance(gp_config, GPFitConfig):
            raise TypeError(f"gp_config: expected GPFitConfig or None, got {type(gp_config).__name__}")
        self.gp_config = gp_config
        if not np.isfinite(df_delta) or df_delta <= 0:
            raise ValueError(f"df_delta: expected a positive time step (s), got {df_delta!r}")
        self.df_delta = float(df_delta)
        self.train_on_predicted = bool(train_on_predicted)
        N = self.dof
        self.order: tuple[int, ...] = tuple(range(N - 1, -1, -1)) if self.structure == "inward" else tuple(range(N))
        self.specs = [input_spec(self.structure, j, N) for j in range(N)]
        self.banks: list[Any] = []
        self.where: list[tuple[int, int]] = []
        self.n_train = 0
        self._post: list[Any] = []
        self._fast: dict[str, Any] = {}

    # ------------------------------------------------------------------ basics
    @property
    def fitted(self) -> bool:
        return bool(self.banks)

    def __repr__(self) -> str:
        return (f"CascadedGPModel(name={self.name!r}, dof={self.dof}, fitted={self.fitted}, "
                f"n_train={self.n_train})")

    def _require_fitted(self) -> None:
        if not self.fitted:
            raise RuntimeError(f"model {self.name!r}: not fitted; call fit() or load_model() first")

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
        if not np.isfinite(tau).all():
            raise ValueError("rbd: the rigid-body model returned non-finite torques")
        return tau

    # ------------------------------------------------------------------ training
    def _training_arrays(self, data: DynamicsData) -> dict[str, np.ndarray]:
        if not isinstance(data, DynamicsData):
            raise TypeError(f"data: expected DynamicsData, got {type(data).__name__}")
        if data.dof != self.dof:
            raise ValueError(f"data: DOF mismatch: the model has dof={self.dof}, data.dof={data.dof}")
        if self.feature_kind == "df":
            if np.isfinite(data.dt) and data.dt > self.df_delta * (1 + 1e-9):
                warnings.warn(f"data: sample period {data.dt:g} s exceeds df_delta={self.df_delta:g} s: the "
                              "derivative-free history q(t - df_delta) is interpolated between samples",
                              stacklevel=3)
            q_hist, valid = history_from_data(data, self.df_delta)
        else:
            q_hist, valid = None, np.ones(data.n_samples, dtype=bool)
        n = int(valid.sum())
        if n < 2:
            raise ValueError(
                f"data: model {self.name!r} needs at least 2 usable training samples, got {n} "
                f"(of {data.n_samples} rows" + (f"; -df needs 2*df_delta={2 * self.df_delta:g} s of history "
                                                 "within a segment)" if self.feature_kind == "df" else ")"))
        out = {"q": data.q[valid], "qd": data.qd[valid], "qdd": data.qdd[valid], "tau": data.tau[valid]}
        out["q_hist"] = q_hist[valid] if q_hist is not None else None
        return out

    def _states(self, q: np.ndarray, qd: np.ndarray | None, qdd: np.ndarray | None,
                q_hist: np.ndarray | None) -> np.ndarray:
        return states_from_arrays(self.feature_kind, q, qd, qdd, q_hist)

    def fit(self, data: DynamicsData, init: "CascadedGPModel | Any | None" = None) -> "CascadedGPModel":
        """Train every joint's GP on ``data`` (see the module docstring).

        ``init``: a fitted model of the same name and DOF (or, for the default one-bank layout,
        a fitted ``GPBank``) whose hyperparameters warm-start the fit (as one start).
        Returns ``self``.
        """
        from .gp import GPBank

        arr = self._training_arrays(data)
        S = self._states(arr["q"], arr["qd"], arr["qdd"], arr["q_hist"])
        tau = arr["tau"]
        tau_rbd = self._rbd_torque(arr["q"], arr["qd"], arr["qdd"]) if self.parametric == "sp" else None
        targets = tau - tau_rbd if tau_rbd is not None else tau
        N = self.dof
        sequential = self.train_on_predicted and self.structure != "standard"
        init_banks: list[Any] | None = None
        if init is not None:
            if isinstance(init, CascadedGPModel):
                if init.name != self.name or init.dof != self.dof or not init.fitted:
                    raise ValueError(f"init: expected a fitted {self.name!r} model with dof={self.dof}, got {init!r}")
                if len(init.banks) != (N if sequential else 1):
                    init_banks = None  # layouts differ (train_on_predicted changed): cold start
                else:
                    init_banks = list(init.banks)
            elif isinstance(init, GPBank):
                if sequential:
                    raise ValueError("init: a GPBank cannot warm-start a train_on_predicted cascade; pass a model")
                init_banks = [init]
            else:
                raise TypeError(f"init: expected a CascadedGPModel, a GPBank or None, got {type(init).__name__}")

        if not sequential:
            X = build_inputs(S, tau, self.structure)  # measured neighbour torques
            bank = GPBank(self.gp_config).fit(X, [targets[:, j] for j in range(N)],
                                              init=init_banks[0] if init_banks else None)
            self.banks = [bank]
            self.where = [(0, j) for j in range(N)]
        else:
            banks: list[Any] = [None] * N
            where: list[tuple[int, int]] = [(0, 0)] * N
            tau_hat = np.zeros_like(tau)  # in-sample chained predicted torques
            sflat = S.reshape(S.shape[0], -1)
            for k, j in enumerate(self.order):
                sj, tj = self.specs[j]
                x = _state_cols(sflat, sj)
                if tj is not None:
                    x = np.concatenate([x, tau_hat[:, tj:tj + 1]], axis=1)
                ib = init_banks[k] if init_banks else None
                bank = GPBank(self.gp_config).fit([x], [targets[:, j]], init=ib)
                banks[k] = bank
                where[j] = (k, 0)
                m, _ = bank.posterior(0).predict(x, return_var=False)
                tau_hat[:, j] = m + (tau_rbd[:, j] if tau_rbd is not None else 0.0)
            self.banks = banks
            self.where = where
        self.n_train = int(S.shape[0])
        self._cache()
        return self

    # ------------------------------------------------------------------ caches
    def _cache(self) -> None:
        """Posterior factors per joint and the padded arrays of the single-query path."""
        N = self.dof
        self._post = [self.banks[k].posterior(b) for k, b in self.where]
        kernel = self._post[0].kernel
        n = self._post[0].Z.shape[0]
        D = 3 * N
        # Matern 5/2: k = (1 + s + s^2/3) e^{-s} with s = sqrt(5 r2): pre-scale by sqrt(5).
        # RBF: k = exp(-r2/2): pre-scale by sqrt(1/2).  Then one sqrt / exp per joint.
        c = math.sqrt(5.0) if kernel == "matern52" else math.sqrt(0.5)
        idx = np.full((N, D), D, dtype=np.intp)   # index D -> the appended constant 0
        xm = np.zeros((N, D))
        xs_inv = np.zeros((N, D))
        W = np.zeros((N, n, D))
        tm = np.zeros(N)
        ts_inv = np.zeros(N)
        Zt = np.zeros((N, n))
        a = np.zeros((N, n))
        y_mean = np.zeros(N)
        for j, P in enumerate(self._post):
            sj, tj = self.specs[j]
            cols = np.concatenate([[3 * s, 3 * s + 1, 3 * s + 2] for s in sj]).astype(np.intp)
            ds = cols.size
            idx[j, :ds] = cols
            xm[j, :ds] = P.x_mean[:ds]
            xs_inv[j, :ds] = c / P.x_scale[:ds]  # inf scale (ignored column) -> 0
            W[j, :, :ds] = c * P.Z[:, :ds]
            if tj is not None:
                tm[j] = P.x_mean[ds]
                ts_inv[j] = c / P.x_scale[ds]
                Zt[j] = c * P.Z[:, ds]
            a[j] = P.y_std * P.signal_var * P.alpha
            y_mean[j] = P.y_mean
        self._fast = {
            "matern": kernel == "matern52", "idx": idx, "xm": xm, "xs_inv": xs_inv, "W": W,
            "W2": np.einsum("jnd,jnd->jn", W, W), "Wt": np.ascontiguousarray(W.transpose(0, 2, 1)),
            "tm": tm.tolist(), "ts_inv": ts_inv.tolist(), "Zt": Zt, "a": a, "y_mean": y_mean.tolist(),
            "tj": [self.specs[j][1] for j in range(N)], "buf": np.zeros(D + 1),
            "zclip": _ZCLIP * c,
        }

    # ------------------------------------------------------------------ prediction
    def _check_queries(self, q: Any, qd: Any, qdd: Any, q_hist: Any
                       ) -> tuple[bool, np.ndarray, np.ndarray | None, np.ndarray | None, np.ndarray | None]:
        N = self.dof
        single = np.ndim(q) == 1
        q = _as_query("q", q, N)
        T = q.shape[0]
        need_deriv = self.feature_kind == "db" or self.parametric == "sp"
        if need_deriv:
            if qd is None or qdd is None:
                raise ValueError(f"qd/qdd: model {self.name!r} needs velocities and accelerations, got None")
        qd = _as_query("qd", qd, N) if qd is not None else None
        qdd = _as_query("qdd", qdd, N) if qdd is not None else None
        for nm, x in (("qd", qd), ("qdd", qdd)):
            if x is not None and x.shape[0] != T:
                raise ValueError(f"{nm}: expected {T} rows (as q), got {x.shape[0]}")
        if self.feature_kind == "df":
            if q_hist is None:
                raise ValueError(f"q_hist: model {self.name!r} (derivative free) needs q_hist of shape "
                                 f"(T, 2, {N}) = (q(t-delta), q(t-2 delta)), got None")
            q_hist = _as_query("q_hist", q_hist, N, extra=(2,))
            if q_hist.shape[0] != T:
                raise ValueError(f"q_hist: expected {T} rows (as q), got {q_hist.shape[0]}")
        else:
            q_hist = None
        return single, q, qd, qdd, q_hist

    def predict(self, q: Any, qd: Any = None, qdd: Any = None, q_hist: Any = None
                ) -> tuple[np.ndarray, np.ndarray]:
        """Predicted joint torques.

        Args:
            q, qd, qdd: (T, N) or (N,) (``qd``/``qdd`` may be None for NP ``-df`` models).
            q_hist: ``-df`` models only: (T, 2, N) or (2, N): ``q(t - df_delta)``, ``q(t - 2 df_delta)``.

        Returns:
            ``mean``, ``var``: (T, N) (or (N,) for (N,) inputs).  ``mean`` is the full torque
            (RBD added back for SP).  ``var`` is the latent variance of each joint's GP; for a
            cascade it is the GP variance of that joint given the chained *mean* input (the
            neighbour's uncertainty is not propagated).
        """
        self._require_fitted()
        single, q, qd, qdd, q_hist = self._check_queries(q, qd, qdd, q_hist)
        mean, var = self._predict_arrays(q, qd, qdd, q_hist, return_var=True)
        return (mean[0], var[0]) if single else (mean, var)

    def _predict_arrays(self, q, qd, qdd, q_hist, return_var: bool) -> tuple[np.ndarray, np.ndarray]:
        S = self._states(q, qd, qdd, q_hist)
        T, N = q.shape
        sflat = S.reshape(T, -1)
        tau_rbd = self._rbd_torque(q, qd, qdd) if self.parametric == "sp" else None
        mean = np.empty((T, N))
        var = np.zeros((T, N))
        for j in self.order:  # cascade order: the torque input is the already PREDICTED torque
            sj, tj = self.specs[j]
            x = _state_cols(sflat, sj)
            if tj is not None:
                x = np.concatenate([x, mean[:, tj:tj + 1]], axis=1)
            P = self._post[j]
            m, v = _posterior_predict(P, x, return_var)
            mean[:, j] = m + (tau_rbd[:, j] if tau_rbd is not None else 0.0)
            if return_var:
                var[:, j] = v
        return mean, var

    def predict_data(self, data: DynamicsData) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`predict` on the rows of ``data`` (``-df``: history from ``data`` itself, see
        :func:`cascgp.features.history_from_data`; rows without full history use the clamped
        history: finite, but check ``state_features(data, "df")[1]`` before scoring them)."""
        self._require_fitted()
        if not isinstance(data, DynamicsData):
            raise TypeError(f"data: expected DynamicsData, got {type(data).__name__}")
        if data.dof != self.dof:
            raise ValueError(f"data: DOF mismatch: the model has dof={self.dof}, data.dof={data.dof}")
        q_hist = history_from_data(data, self.df_delta)[0] if self.feature_kind == "df" else None
        return self._predict_arrays(data.q, data.qd, data.qdd, q_hist, return_var=True)

    def predict_one(self, q: Any, qd: Any = None, qdd: Any = None, q_hist: Any = None) -> np.ndarray:
        """Mean torque (N,) for ONE query: the lean NumPy path for a controller (no torch, no variance).

        The state part of every joint's kernel input is computed in one batch (per-joint state
        inputs padded to the common width 3N); only the scalar torque input is chained joint by
        joint.  Equals :meth:`predict` to round-off (~1e-12).  Inputs are checked for shape and
        finiteness (``ValueError``).
        """
        f = self._fast
        if not f:
            self._require_fitted()
        N = self.dof
        q = np.asarray(q, dtype=np.float64)
        if q.shape != (N,):
            raise ValueError(f"q: expected shape ({N},), got {q.shape}")
        buf = f["buf"]
        buf[0:3 * N:3] = q
        if self.feature_kind == "db" or self.parametric == "sp":
            if qd is None or qdd is None:
                raise ValueError(f"qd/qdd: model {self.name!r} needs velocities and accelerations, got None")
            qd = np.asarray(qd, dtype=np.float64)
            qdd = np.asarray(qdd, dtype=np.float64)
            if qd.shape != (N,) or qdd.shape != (N,):
                raise ValueError(f"qd/qdd: expected shape ({N},), got {qd.shape} and {qdd.shape}")
            if self.feature_kind == "df" and not (np.isfinite(qd).all() and np.isfinite(qdd).all()):
                raise ValueError("qd/qdd: non-finite value (NaN or inf) in the query")
        if self.feature_kind == "db":
            buf[1:3 * N:3] = qd
            buf[2:3 * N:3] = qdd
        else:
            if q_hist is None:
                raise ValueError(f"q_hist: model {self.name!r} needs q_hist of shape (2, {N}), got None")
            h = np.asarray(q_hist, dtype=np.float64)
            if h.shape != (2, N):
                raise ValueError(f"q_hist: expected shape (2, {N}), got {h.shape}")
            buf[1:3 * N:3] = h[0]
            buf[2:3 * N:3] = h[1]
        if not np.isfinite(buf).all():
            raise ValueError("q/qd/qdd/q_hist: non-finite value (NaN or inf) in the query")
        # state part of every joint at once: z (N, D), r2s (N, n) = |W|^2 + |z|^2 - 2 W z
        z = buf[f["idx"]]
        z -= f["xm"]
        z *= f["xs_inv"]
        np.clip(z, -f["zclip"], f["zclip"], out=z)
        r2s = np.matmul(f["W"], z[:, :, None])[:, :, 0]
        r2s *= -2.0
        r2s += f["W2"]
        r2s += np.einsum("jd,jd->j", z, z)[:, None]
        np.maximum(r2s, 0.0, out=r2s)
        out = np.empty(N)
        if self.parametric == "sp":
            out_rbd = np.asarray(self.rbd.inverse_dynamics(q, qd, qdd), dtype=np.float64)
        matern = f["matern"]
        Zt, a, tjs, tm, tsi, ym = f["Zt"], f["a"], f["tj"], f["tm"], f["ts_inv"], f["y_mean"]
        zc = f["zclip"]
        for j in self.order:
            r2 = r2s[j]
            tj = tjs[j]
            if tj is not None:  # chain: the neighbour's PREDICTED torque
                tq = (out[tj] - tm[j]) * tsi[j]
                tq = zc if tq > zc else (-zc if tq < -zc else tq)
                d = Zt[j] - tq
                d *= d
                r2 = d + r2
            if matern:
                s = np.sqrt(r2)
                e = np.exp(-s)
                r2 *= 1.0 / 3.0
                r2 += s
                r2 += 1.0
                r2 *= e
                m = ym[j] + float(r2 @ a[j])
            else:
                m = ym[j] + float(np.exp(-r2) @ a[j])
            if self.parametric == "sp":
                m += float(out_rbd[j])
            out[j] = m
        return out

    # ------------------------------------------------------------------ persistence
    def _config(self) -> dict[str, Any]:
        rbd_ref = None
        if self.rbd is not None:
            src = getattr(self.rbd, "source", None)
            arm = getattr(self.rbd, "armature", None)
            rbd_ref = {"source": None if src is None else str(src),
                       "nominal": bool(getattr(self.rbd, "meta", None)),
                       "armature": None if arm is None else np.asarray(arm, float).tolist(),
                       "type": type(self.rbd).__name__}
        return {"name": self.name, "dof": self.dof, "df_delta": self.df_delta,
                "train_on_predicted": self.train_on_predicted, "gp_config": asdict(self.gp_config),
                "where": [list(w) for w in self.where], "n_banks": len(self.banks), "n_train": self.n_train,
                "rbd": rbd_ref}

    def save(self, path: str | os.PathLike) -> Path:
        """Write the fitted model to ``path`` (``.npz``, atomically).

        Contents: format kind/version, config JSON (name, dof, df_delta, train_on_predicted,
        GP config, RBD reference), every bank's ``state_dict`` (normalisation, hyperparameters,
        training inputs and targets), and check queries with their predictions (verified by
        :func:`load_model`).  The RBD itself is not stored: SP models record
        ``rbd.source`` (URDF path) for :func:`load_model`.
        """
        self._require_fitted()
        arrays: dict[str, np.ndarray] = {
            "format_kind": np.array(_KIND), "format_version": np.array(FORMAT_VERSION),
            "config_json": np.array(json.dumps(self._config())),
        }
        for k, bank in enumerate(self.banks):
            for key, val in bank.state_dict().items():
                arrays[f"bank{k}/{key}"] = np.asarray(val)
        # check queries: the first training rows (features rebuilt from the bank's inputs)
        chk = self._check_set()
        arrays.update({f"check/{k}": v for k, v in chk.items()})
        return atomic_savez(path, arrays)

    def _check_set(self) -> dict[str, np.ndarray]:
        """Deterministic check queries and their predictions (stored by save, verified by load)."""
        rng = np.random.default_rng(12345)
        N, m = self.dof, _N_CHECK
        q = rng.uniform(-1.0, 1.0, (m, N))
        qd = rng.uniform(-1.0, 1.0, (m, N))
        qdd = rng.uniform(-1.0, 1.0, (m, N))
        qh = np.stack([q - 0.1 * qd, q - 0.2 * qd], axis=1)
        mean, var = self._predict_arrays(q, qd, qdd, qh if self.feature_kind == "df" else None, True)
        return {"q": q, "qd": qd, "qdd": qdd, "q_hist": qh, "mean": mean, "var": var}


def _state_cols(sflat: np.ndarray, state_joints: tuple[int, ...]) -> np.ndarray:
    cols = np.concatenate([[3 * s, 3 * s + 1, 3 * s + 2] for s in state_joints])
    return sflat[:, cols]


def _posterior_predict(P: Any, x: np.ndarray, return_var: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """GPPosterior.predict with the normalised inputs clipped (finite output for finite input)."""
    z = (x - P.x_mean) / P.x_scale
    if not (np.abs(z) <= _ZCLIP).all():
        zc = np.clip(z, -_ZCLIP, _ZCLIP)
        x = np.where(np.isfinite(P.x_scale), P.x_mean + zc * P.x_scale, x)
    return P.predict(x, return_var=return_var)


def make_model(name: str, dof: int, rbd: Any = None, *, gp_config: Any = None, df_delta: float = 0.1,
               train_on_predicted: bool = False) -> CascadedGPModel:
    """Build an unfitted model.  ``name`` in :data:`MODEL_NAMES`; ``rbd`` (required for ``sp-*``):
    an object with ``dof`` and ``inverse_dynamics(q, qd, qdd)`` (e.g.
    :class:`cascgp.rbd.RigidBodyModel`) whose DOF equals ``dof``.  See :class:`CascadedGPModel`."""
    return CascadedGPModel(name, dof, rbd, gp_config=gp_config, df_delta=df_delta,
                           train_on_predicted=train_on_predicted)


def load_model(path: str | os.PathLike, rbd: Any = None) -> CascadedGPModel:
    """Read a model written by :meth:`CascadedGPModel.save`.

    SP models need their rigid-body model: pass ``rbd=``; without it the URDF recorded at
    save time (``rbd.source``) is loaded with :func:`cascgp.rbd.load_nominal` (when it had a
    sidecar) or :meth:`RigidBodyModel.from_urdf` with the recorded armature.  After loading, the
    stored check predictions are recomputed; any difference (corrupt file, another RBD) raises
    ``ValueError``.  Missing file: ``FileNotFoundError``; corrupt/truncated archive, missing
    fields or another format version: ``ValueError`` naming the file.
    """
    from .gp import GPBank, GPFitConfig

    z = read_npz(path, "cascgp model")
    check_format_header(z, path, _KIND, FORMAT_VERSION)
    try:
        cfg = json.loads(str(z["config_json"]))
        gp_config = GPFitConfig.from_dict(cfg["gp_config"])
        name, dof = cfg["name"], int(cfg["dof"])
        where = [tuple(int(v) for v in w) for w in cfg["where"]]
        n_banks = int(cfg["n_banks"])
    except (KeyError, ValueError, TypeError) as exc:
        raise ValueError(f"{path}: config_json: missing or invalid ({type(exc).__name__}: {exc})") from exc
    p, _, _ = parse_name(name)
    if p == "sp" and rbd is None:
        ref = cfg.get("rbd") or {}
        src = ref.get("source")
        if not src or not Path(src).is_file():
            raise ValueError(f"{path}: rbd: the semi-parametric model {name!r} needs its rigid-body model; pass "
                             f"load_model(path, rbd=...) (recorded URDF {src!r} not available)")
        from .rbd import RigidBodyModel, load_nominal, sidecar_path

        if ref.get("nominal") and sidecar_path(src).is_file():
            rbd = load_nominal(src, dof=dof)
        else:
            rbd = RigidBodyModel.from_urdf(src, armature=ref.get("armature"), dof=dof)
    model = CascadedGPModel(name, dof, rbd, gp_config=gp_config, df_delta=float(cfg["df_delta"]),
                            train_on_predicted=bool(cfg["train_on_predicted"]))
    banks = []
    for k in range(n_banks):
        pre = f"bank{k}/"
        sd = {key[len(pre):]: val for key, val in z.items() if key.startswith(pre)}
        if not sd:
            raise ValueError(f"{path}: {pre}*: missing GP bank {k}")
        try:
            banks.append(GPBank.from_state_dict(sd))
        except (ValueError, RuntimeError) as exc:
            raise ValueError(f"{path}: bank {k}: {exc}") from exc
    if len(where) != dof or any(not (0 <= k < n_banks and 0 <= b < banks[k].n_gps) for k, b in where):
        raise ValueError(f"{path}: config_json.where: {where} does not match {n_banks} bank(s) and dof={dof}")
    for j, (k, b) in enumerate(where):
        want = 3 * len(model.specs[j][0]) + (model.specs[j][1] is not None)
        if banks[k].dims[b] != want:
            raise ValueError(f"{path}: bank {k} GP {b}: input dimension {banks[k].dims[b]} does not match "
                             f"{name!r} joint {j} ({want})")
    model.banks = banks
    model.where = where
    model.n_train = int(cfg.get("n_train", banks[0].n_train))
    model._cache()
    need = [f"check/{k}" for k in ("q", "qd", "qdd", "q_hist", "mean", "var")]
    if any(k not in z for k in need):
        raise ValueError(f"{path}: missing check fields {[k for k in need if k not in z]}")
    mean, var = model._predict_arrays(z["check/q"], z["check/qd"], z["check/qdd"],
                                      z["check/q_hist"] if model.feature_kind == "df" else None, True)
    ref_m, ref_v = z["check/mean"], z["check/var"]
    tol_m = 1e-8 * (1.0 + np.abs(ref_m))
    if mean.shape != ref_m.shape or not (np.abs(mean - ref_m) <= tol_m).all() or \
            not np.allclose(var, ref_v, rtol=1e-6, atol=1e-10):
        raise ValueError(f"{path}: the loaded model does not reproduce its stored check predictions "
                         "(corrupt file, or a different rigid-body model than at save time)")
    return model
