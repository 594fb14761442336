r"""The rows a :class:`~cascgp.models.CascadedGPModel` fit trains on (:func:`training_arrays`).

A derivative-free (``-df``) model's inputs are each row's position and its positions :math:`\delta` and
:math:`2\delta` earlier (:math:`\delta` = ``df_delta``), :math:`q(t - \delta)` and :math:`q(t - 2\delta)`. By
default they are interpolated within the row's segment of the training data itself
(:func:`cascgp.features.history_from_data`). When those rows were taken from a longer record (thinned to a few
hundred rows, say), the history is better taken from the full record before the rows were chosen: the caller
passes it as ``q_hist`` (history from rows far apart is interpolated over gaps wider than :math:`\delta`, and
predictions, whose history comes from the full-rate log, would see other features than the fit did).
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING, Any

import numpy as np

from cascgp.data import DynamicsData, as_real_array
from cascgp.features import history_from_data
from cascgp.gp.checks import check_scale

if TYPE_CHECKING:
    from cascgp.models.cascade import CascadedGPModel

__all__ = ["training_arrays"]


def _given_history(q_hist: Any, data: DynamicsData) -> tuple[np.ndarray, np.ndarray]:
    """``q_hist`` checked against ``data`` (shape ``(T, 2, N)``, real numbers) and its rows that are all finite."""
    h = as_real_array("q_hist", q_hist, f"({data.n_samples}, 2, {data.dof})")  # TypeError: complex, bool, text
    if h.shape != (data.n_samples, 2, data.dof):
        raise ValueError(f"q_hist: expected shape ({data.n_samples}, 2, {data.dof}) (every row of data: q at "
                         f"t - df_delta and t - 2 df_delta), got {h.shape}")
    return h, np.asarray(np.isfinite(h).all(axis=(1, 2)))


def training_arrays(model: CascadedGPModel, data: DynamicsData, q_hist: Any = None) -> dict[str, np.ndarray]:
    """The training rows of ``data`` for ``model``: ``q, qd, qdd, tau`` and ``q_hist`` (``-df`` models; else
    ``None``) of the rows that have a history. ``q_hist`` (``-df`` models, optional): every row's history, shape
    ``(T, 2, N)``; rows with a non-finite entry (no history) are left out. ``TypeError`` / ``ValueError`` naming
    ``data`` or ``q_hist``."""
    if not isinstance(data, DynamicsData):
        raise TypeError(f"data: expected DynamicsData, got {type(data).__name__}")
    if data.dof != model.dof:
        raise ValueError(f"data: DOF mismatch: the model has dof={model.dof}, data.dof={data.dof}")
    if data.meta.get("has_tau") is False:
        raise ValueError("data: holds no measured torques (meta['has_tau'] is False: its tau is the zero placeholder "
                         "of a log read for prediction); a fit needs them")
    if model.feature_kind == "df" and q_hist is not None:
        q_hist, valid = _given_history(q_hist, data)
    elif model.feature_kind == "df":
        if np.isfinite(data.dt) and data.dt > model.df_delta * (1 + 1e-9):
            warnings.warn(f"data: sample period {data.dt:g} s exceeds df_delta={model.df_delta:g} s: the "
                          "derivative-free history q(t - df_delta) is interpolated between samples (pass q_hist= "
                          "from the full-rate record)", stacklevel=3)
        q_hist, valid = history_from_data(data, model.df_delta)
    elif q_hist is not None:
        raise ValueError(f"q_hist: model {model.name!r} is derivative-based (its inputs are q, qd, qdd); q_hist is "
                         "for -df models")
    else:
        valid = np.ones(data.n_samples, dtype=bool)
    n = int(valid.sum())
    if n < 2:
        raise ValueError(
            f"data: model {model.name!r} needs at least 2 usable training samples, got {n} "
            f"(of {data.n_samples} rows" + (f"; -df needs 2*df_delta={2 * model.df_delta:g} s of history "
                                             "within a segment)" if model.feature_kind == "df" else ")"))
    out = {"q": data.q[valid], "qd": data.qd[valid], "qdd": data.qdd[valid], "tau": data.tau[valid]}
    for key in ("q", "qd", "qdd", "tau"):
        check_scale(out[key], f"data.{key}")
    out["q_hist"] = q_hist[valid] if q_hist is not None else None
    return out
