r"""Checking the queries of a :class:`~cascgp.models.CascadedGPModel` and building its GP inputs.

A batched query (:meth:`~cascgp.models.CascadedGPModel.predict`, :meth:`~cascgp.models.CascadedGPModel.mean_jacobian`)
is checked in full: real dtype, shapes ``(T, N)`` or ``(N,)``, equal row counts, finiteness, with errors naming the
field (:func:`check_queries`). A single query (``predict_one``/``predict_one_var``, every control tick) gets the
cheap checks and is written straight into the fast path's input buffer (:func:`load_query`).

Joint :math:`j`'s GP input is the states :math:`(q_k, \dot q_k, \ddot q_k)` of the joints it sees
(:func:`state_cols`) followed, in a cascade, by its neighbour's torque; before prediction its normalised values are
clipped to :math:`\pm` :data:`~cascgp.gp.posterior.ZCLIP` (:func:`clipped`), so that the output is finite for
finite input.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from cascgp.data import F64 as _F64
from cascgp.data import all_finite, as_real_array
from cascgp.models.fastpath import ZCLIP, FastPath

if TYPE_CHECKING:
    from cascgp.models.cascade import CascadedGPModel

__all__ = ["one_real", "as_query", "check_queries", "load_query", "state_cols", "clipped"]


def one_real(name: str, a: Any) -> np.ndarray:
    """Cheap check of one controller query (no warnings machinery: this runs every control tick)."""
    x = np.asarray(a)
    if x.dtype.kind not in "fiu":
        raise TypeError(f"{name}: expected a real numeric array, got dtype {x.dtype}")
    return x.astype(np.float64, copy=False)


def as_query(name: str, a: Any, N: int, extra: tuple[int, ...] = ()) -> np.ndarray:
    """``a`` as a finite real ``(T, *extra, N)`` array (a single row gets ``T = 1``); errors name ``name``."""
    x = as_real_array(name, a, "(T, N)")
    if x.ndim == 1 + len(extra):
        x = x[None]
    if x.ndim == 2 + len(extra) and x.shape[1:] == (*extra, N) and x.shape[0] == 0:
        raise ValueError(f"{name}: expected at least one row, got shape {x.shape}")
    if x.ndim != 2 + len(extra) or x.shape[1:] != (*extra, N):
        want = ", ".join(["T", *map(str, extra), str(N)])
        raise ValueError(f"{name}: expected shape ({want}) or ({', '.join([*map(str, extra), str(N)])}), got {x.shape}")
    if not np.isfinite(x).all():
        r = int(np.flatnonzero((~np.isfinite(x.reshape(x.shape[0], -1))).any(axis=1))[0])
        raise ValueError(f"{name}: non-finite value (NaN or inf) at row {r}")
    return x


def check_queries(model: "CascadedGPModel", q: Any, qd: Any, qdd: Any, q_hist: Any
                  ) -> tuple[bool, np.ndarray, np.ndarray | None, np.ndarray | None, np.ndarray | None]:
    """A batched query of ``model`` checked: ``(single, q, qd, qdd, q_hist)`` as ``(T, N)`` arrays (``q_hist``
    ``(T, 2, N)`` for ``-df`` models, else None), ``single`` when ``q`` was one ``(N,)`` row."""
    N = model.dof
    single = np.ndim(q) == 1
    q = as_query("q", q, N)
    T = q.shape[0]
    need_deriv = model.feature_kind == "db" or model.parametric == "sp"
    if need_deriv:
        if qd is None or qdd is None:
            raise ValueError(f"qd/qdd: model {model.name!r} needs velocities and accelerations, got None")
    qd = as_query("qd", qd, N) if qd is not None else None
    qdd = as_query("qdd", qdd, N) if qdd is not None else None
    for nm, x in (("qd", qd), ("qdd", qdd)):
        if x is not None and x.shape[0] != T:
            raise ValueError(f"{nm}: expected {T} rows (as q), got {x.shape[0]}")
    if model.feature_kind == "df":
        if q_hist is None:
            raise ValueError(f"q_hist: model {model.name!r} (derivative free) needs q_hist of shape "
                             f"(T, 2, {N}) = (q(t-delta), q(t-2 delta)), got None")
        q_hist = as_query("q_hist", q_hist, N, extra=(2,))
        if q_hist.shape[0] != T:
            raise ValueError(f"q_hist: expected {T} rows (as q), got {q_hist.shape[0]}")
    else:
        q_hist = None
    return single, q, qd, qdd, q_hist


def load_query(model: "CascadedGPModel", q: Any, qd: Any, qdd: Any, q_hist: Any, rbd_torque: Any = None
               ) -> tuple[FastPath, np.ndarray | None]:
    """Check one query and write its state into the fast path's buffer; returns it and the RBD torque (NP: None),
    ``rbd_torque`` when given (SP: ``model.rbd``'s torque at this state, computed by the caller; checked as the
    model checks its own)."""
    f = model._require_fitted()
    N = model.dof
    buf = f.buf
    if (type(q) is np.ndarray and type(qd) is np.ndarray and type(qdd) is np.ndarray and q.dtype == _F64
            and qd.dtype == _F64 and qdd.dtype == _F64 and q.shape == qd.shape == qdd.shape == (N,)
            and model.feature_kind == "db"):
        # three float64 (N,) arrays (what a controller passes every tick): what the general form below writes,
        # without its conversions and shape checks
        buf[0:3 * N:3] = q
        buf[1:3 * N:3] = qd
        buf[2:3 * N:3] = qdd
        if not all_finite(buf):
            raise ValueError("q/qd/qdd/q_hist: non-finite value (NaN or inf) in the query")
        return f, _rbd_part(model, q, qd, qdd, rbd_torque)
    q = one_real("q", q)
    if q.shape != (N,):
        raise ValueError(f"q: expected shape ({N},), got {q.shape}")
    buf[0:3 * N:3] = q
    if model.feature_kind == "db" or model.parametric == "sp":
        if qd is None or qdd is None:
            raise ValueError(f"qd/qdd: model {model.name!r} needs velocities and accelerations, got None")
        qd = one_real("qd", qd)
        qdd = one_real("qdd", qdd)
        if qd.shape != (N,) or qdd.shape != (N,):
            raise ValueError(f"qd/qdd: expected shape ({N},), got {qd.shape} and {qdd.shape}")
        if model.feature_kind == "df" and not (all_finite(qd) and all_finite(qdd)):
            raise ValueError("qd/qdd: non-finite value (NaN or inf) in the query")
    if model.feature_kind == "db":
        buf[1:3 * N:3] = qd
        buf[2:3 * N:3] = qdd
    else:
        if q_hist is None:
            raise ValueError(f"q_hist: model {model.name!r} needs q_hist of shape (2, {N}), got None")
        h = one_real("q_hist", q_hist)
        if h.shape != (2, N):
            raise ValueError(f"q_hist: expected shape (2, {N}), got {h.shape}")
        buf[1:3 * N:3] = h[0]
        buf[2:3 * N:3] = h[1]
    if not all_finite(buf):
        raise ValueError("q/qd/qdd/q_hist: non-finite value (NaN or inf) in the query")
    return f, _rbd_part(model, q, qd, qdd, rbd_torque)


def _rbd_part(model: "CascadedGPModel", q: np.ndarray, qd: Any, qdd: Any, rbd_torque: Any) -> np.ndarray | None:
    """The RBD torque of a checked query (:func:`load_query`): None for NP models, ``rbd_torque`` checked when
    given, else the model's own."""
    if model.parametric != "sp":
        return None
    if rbd_torque is None:
        return model._rbd_torque(q, qd, qdd)
    N = model.dof
    if type(rbd_torque) is np.ndarray and rbd_torque.dtype == _F64 and rbd_torque.shape == (N,):
        tau = rbd_torque  # what one_real returns for it
    else:
        tau = one_real("rbd_torque", rbd_torque)
        if tau.shape != (N,):
            raise ValueError(f"rbd_torque: expected shape ({N},), got {tau.shape}")
    if not all_finite(tau):
        raise ValueError("rbd: the rigid-body model returned non-finite torques")
    return tau


def state_cols(sflat: np.ndarray, state_joints: tuple[int, ...]) -> np.ndarray:
    """The columns of the flattened states ``sflat`` (T, 3N) that hold the states of ``state_joints``."""
    cols = np.concatenate([[3 * s, 3 * s + 1, 3 * s + 2] for s in state_joints])
    return sflat[:, cols]


def clipped(P: Any, x: np.ndarray) -> np.ndarray:
    """``x`` with its normalised values clipped to +-ZCLIP (finite output for finite input)."""
    z = (x - P.x_mean) / P.x_scale
    if not (np.abs(z) <= ZCLIP).all():
        zc = np.clip(z, -ZCLIP, ZCLIP)
        x = np.where(np.isfinite(P.x_scale), P.x_mean + zc * P.x_scale, x)
    return x
