r"""Prediction of a fitted model with the *measured* neighbour torque as each cascade joint's torque input.

:meth:`~cascgp.models.CascadedGPModel.predict` chains the model's own predictions: joint :math:`j`'s GP input is
:math:`x_j = (s_{\mathcal S_j}, \hat\tau_{t(j)})` with :math:`\hat\tau_{t(j)}` the torque the model predicted for its
neighbour :math:`t(j)` (inward :math:`t(j) = j + 1`, outward :math:`t(j) = j - 1`). Here the neighbour's
measured torque :math:`\tau_{t(j)}` of the data takes its place,

.. math:: \mu_j^{\mathrm{meas}} = \tau_{\mathrm{RBD},j} + \mu_j(s_{\mathcal S_j}, \tau_{t(j)}),

the inputs the GPs were trained on (:func:`cascgp.features.build_inputs`). It is a scoring protocol (a sensor
reading of the neighbour's torque is at hand), not what a controller computing a torque command has. The chain's
first joint (inward: joint :math:`N`; outward: joint 1) and a standard model have no torque input: their
predictions equal :meth:`~cascgp.models.CascadedGPModel.predict_data`'s.
"""

from __future__ import annotations

import numpy as np

from cascgp.data import DynamicsData
from cascgp.features import build_inputs, history_from_data, states_from_arrays
from cascgp.models.queries import clipped

__all__ = ["predict_measured_neighbour"]


def predict_measured_neighbour(model, data: DynamicsData) -> np.ndarray:
    """Mean torques ``(T, N)`` of the fitted ``model`` on the rows of ``data``, every torque input taken from
    ``data.tau`` (``-df`` models: history from ``data`` as in ``predict_data``)."""
    posts = model.posteriors()  # raises if not fitted
    if not isinstance(data, DynamicsData):
        raise TypeError(f"data: expected DynamicsData, got {type(data).__name__}")
    if data.dof != model.dof:
        raise ValueError(f"data: DOF mismatch: the model has dof={model.dof}, data.dof={data.dof}")
    q_hist = history_from_data(data, model.df_delta)[0] if model.feature_kind == "df" else None
    S = states_from_arrays(model.feature_kind, data.q, data.qd, data.qdd, q_hist)
    X = build_inputs(S, data.tau, model.structure)
    mean = np.stack([P.predict(clipped(P, x), return_var=False)[0] for P, x in zip(posts, X)], axis=1)
    if model.parametric == "sp":
        tau_rbd = np.asarray(model.rbd.inverse_dynamics(data.q, data.qd, data.qdd), dtype=np.float64)
        mean = mean + tau_rbd.reshape(mean.shape)
    return mean
