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
``var`` is the latent (noise-free) posterior variance of each joint's GP in torque units.  By
default, in a cascade it is the variance of that joint's GP *given the chained mean input*;
``predict(..., propagate=True)`` adds the neighbour's uncertainty to first order (see
:meth:`CascadedGPModel.predict`).

Bad input (documented behaviour)
--------------------------------
Unknown name, SP without ``rbd``, ``rbd.dof != dof``, data of another DOF, NaN/inf or wrong
shapes of queries: ``ValueError``/``TypeError`` naming the field.  Fewer than 2 usable rows
(``-df`` models lose the rows whose history reaches before their segment's start): ``ValueError``.
Repeated inputs with their own measured targets are allowed (the noise variance absorbs their spread); exact
duplicate rows (the same inputs *and* target) count as independent agreeing measurements and pull the fitted
noise toward its floor, so drop them first (``np.unique(..., axis=0)``).  A joint with constant
targets gets the constant as its prediction (see :mod:`cascgp.gp.bank`).  Predictions are finite
for finite inputs (normalised inputs are clipped to +-1e6 so no distance overflows).

Example
-------
A two-joint arm, an NP inward cascade fitted on 200 samples, then a batch and a single query::

    >>> import numpy as np
    >>> from cascgp import DynamicsData, GPFitConfig, make_model, nrmse
    >>> rng = np.random.default_rng(0)
    >>> q, qd, qdd = (rng.uniform(-1, 1, (200, 2)) for _ in range(3))
    >>> tau = np.stack([2 * qdd[:, 0] + np.sin(q[:, 0]), qdd[:, 1] + 0.5 * qd[:, 1]], axis=1)
    >>> data = DynamicsData(q=q, qd=qd, qdd=qdd, tau=tau, t=np.arange(200) * 0.1)
    >>> model = make_model("np-inward", 2, gp_config=GPFitConfig(n_restarts=1, max_iter=50)).fit(data)
    >>> mean, var = model.predict(q, qd, qdd)           # (T, 2) torques and latent variances
    >>> mean.shape, bool(np.all(var > 0)), bool(np.all(nrmse(tau, mean) < 0.01))
    ((200, 2), True, True)
    >>> tau_0 = model.predict_one(q[0], qd[0], qdd[0])  # one query: what a controller calls every tick
    >>> bool(np.allclose(tau_0, mean[0], rtol=1e-9, atol=1e-9))
    True

Modules
-------

=================================  ==========================================================
:mod:`cascgp.models.cascade`       :class:`CascadedGPModel`: training and batched prediction
:mod:`cascgp.models.fit_start`     what a fit starts from: a warm start, a GP shared with the standard model
:mod:`cascgp.models.fastpath`      the single-query path a controller calls every tick
:mod:`cascgp.models.queries`       checks of the queries; each joint's GP input
:mod:`cascgp.models.jacobian`      derivatives of the cascaded mean (the input-noise term)
:mod:`cascgp.models.online`        learning inside an episode (:meth:`CascadedGPModel.start_online`)
:mod:`cascgp.models.coverage`      each joint's range of training positions; queries far outside it
:mod:`cascgp.models.io`            model files (:func:`load_model`, ``model.save``)
=================================  ==========================================================
"""

from cascgp.models.cascade import MODEL_NAMES, CascadedGPModel, make_model, parse_name
from cascgp.models.io import FORMAT_VERSION, load_model, save_model

__all__ = ["MODEL_NAMES", "FORMAT_VERSION", "CascadedGPModel", "make_model", "load_model", "save_model", "parse_name"]
