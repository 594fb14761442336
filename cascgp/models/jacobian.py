r"""Derivatives of a :class:`~cascgp.models.CascadedGPModel`'s mean in the measured states, for the test-time
input-noise term of :meth:`~cascgp.models.CascadedGPModel.predict` (``input_var``).

The total derivative :math:`J_{j,s} = d\mu_j / ds` of joint :math:`j`'s predicted torque in the state entry
:math:`s = (q_k, \dot q_k, \ddot q_k)_k` runs in cascade order (:func:`mean_jacobian_arrays`):

.. math::

    J_{j,s} = \frac{\partial \mu_j}{\partial s} + \frac{\partial \mu_j}{\partial \tau}\, J_{t,s}
    \;\big(+\ \frac{\partial \tau_{RBD,j}}{\partial s}\ \text{for SP models}\big),

with :math:`t` the neighbour whose predicted torque joint :math:`j` is fed. The GP parts are in closed form
(:meth:`cascgp.gp.posterior.GPPosterior.mean_grad_all`; 0 where an input is clipped), the rigid-body part analytic
where the nominal model gives it and by central differences otherwise (:func:`rbd_jacobian`). A measurement noise
of variance :math:`\sigma^2_s` on each state entry then adds :math:`\sum_s J_{j,s}^2 \sigma^2_s` to joint
:math:`j`'s variance.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from cascgp.data import as_real_array
from cascgp.models.fastpath import ZCLIP
from cascgp.models.queries import clipped

if TYPE_CHECKING:
    from cascgp.models.cascade import CascadedGPModel

__all__ = ["check_input_var", "mean_jacobian_arrays", "rbd_jacobian"]


def check_input_var(model: "CascadedGPModel", input_var: Any) -> np.ndarray:
    """``input_var`` (see :meth:`~cascgp.models.CascadedGPModel.predict`) as an (N, 3) array of finite
    variances >= 0; ``ValueError`` naming it otherwise, or for a derivative-free model."""
    if model.feature_kind != "db":
        raise ValueError(f"input_var: the input-noise term needs a derivative-based model (states q, qd, qdd), "
                         f"got {model.name!r}")
    v = as_real_array("input_var", input_var, "(N, 3)")
    try:
        v = np.broadcast_to(v, (model.dof, 3)).astype(np.float64)
    except ValueError:
        raise ValueError(f"input_var: expected a shape that broadcasts to ({model.dof}, 3) (q, qd, qdd "
                         f"variances per joint), got {v.shape}") from None
    if not (np.isfinite(v).all() and (v >= 0).all()):
        raise ValueError("input_var: expected finite variances >= 0")
    return v


def mean_jacobian_arrays(model: "CascadedGPModel", q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                         mean: np.ndarray | None = None) -> np.ndarray:
    """(T, N, 3N) total Jacobian of the mean (state columns ``3 k + c`` as in the flattened states);
    ``mean``: the predicted torques at these states (the chained inputs) when the caller has them."""
    T, N = q.shape
    sflat = model._states(q, qd, qdd, None).reshape(T, -1)
    if mean is None:
        mean, _ = model._predict_arrays(q, qd, qdd, None, return_var=False)
    J = rbd_jacobian(model, q, qd, qdd) if model.parametric == "sp" else np.zeros((T, N, 3 * N))
    for j in model.order:  # cascade order: J[:, tj] is complete before joint j uses it
        sj, tj = model.specs[j]
        cols = np.concatenate([[3 * s, 3 * s + 1, 3 * s + 2] for s in sj])
        x = sflat[:, cols]
        if tj is not None:
            x = np.concatenate([x, mean[:, tj:tj + 1]], axis=1)
        P = model._post[j]
        g = P.mean_grad_all(clipped(P, x)) * (np.abs((x - P.x_mean) / P.x_scale) <= ZCLIP)
        J[:, j, cols] += g[:, :len(cols)]
        if tj is not None:
            J[:, j] += g[:, -1:] * J[:, tj]
    return J


def rbd_jacobian(model: "CascadedGPModel", q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                 h: float = 1e-6) -> np.ndarray:
    """(T, N, 3N) derivative of the rigid-body torque, column ``3 k + c`` by state ``c`` (q, qd, qdd) of
    joint ``k``: analytic where the nominal model gives it (``inverse_dynamics_derivatives``, e.g.
    :class:`cascgp.rbd.RigidBodyModel`'s from Pinocchio), else by central differences (step ``h``), which is
    all a user's ``inverse_dynamics``-only model offers."""
    T, N = q.shape
    derivatives = getattr(model.rbd, "inverse_dynamics_derivatives", None)
    if derivatives is not None:
        D = np.stack([np.asarray(d, dtype=np.float64).reshape(T, N, N) for d in derivatives(q, qd, qdd)], axis=-1)
        if not np.isfinite(D).all():
            raise ValueError("rbd: the rigid-body model returned non-finite torque derivatives")
        return D.reshape(T, N, 3 * N)
    J = np.empty((T, N, 3 * N))
    states = (q, qd, qdd)
    for c in range(3):
        for k in range(N):
            step = np.zeros_like(states[c])
            step[:, k] = h
            hi = [s + step if i == c else s for i, s in enumerate(states)]
            lo = [s - step if i == c else s for i, s in enumerate(states)]
            J[:, :, 3 * k + c] = (model._rbd_torque(*hi) - model._rbd_torque(*lo)) / (2.0 * h)
    return J
