"""Scoring a cascade with the measured neighbour torque (:mod:`cascgp.models.measured`)."""

from __future__ import annotations

import numpy as np
import pytest

from cascgp import DynamicsData, GPFitConfig, make_model
from cascgp.models.measured import predict_measured_neighbour


class _Rbd:
    dof = 3

    def inverse_dynamics(self, q, qd, qdd):
        return 1.5 * np.asarray(q)


def _data(seed: int, n: int = 80) -> DynamicsData:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.05
    q = np.sin(np.outer(t, rng.uniform(0.5, 2.0, 3)) + rng.uniform(0, 6, 3))
    qd, qdd = np.gradient(q, t, axis=0), np.gradient(np.gradient(q, t, axis=0), t, axis=0)
    tau = 2 * q + 0.3 * qdd + np.roll(q, 1, axis=1) + 0.01 * rng.standard_normal(q.shape)
    return DynamicsData(q=q, qd=qd, qdd=qdd, tau=tau, t=t)


@pytest.mark.parametrize("name", ["np-inward", "sp-outward", "np-outward-df", "np-standard"])
def test_measured_neighbour_inputs(name: str) -> None:
    train, test = _data(0), _data(1)
    m = make_model(name, 3, rbd=_Rbd() if name.startswith("sp") else None,
                   gp_config=GPFitConfig(n_restarts=1, max_iter=30)).fit(train)
    chained, _ = m.predict_data(test)
    meas = predict_measured_neighbour(m, test)
    assert meas.shape == (test.n_samples, 3) and np.isfinite(meas).all()
    first = [j for j in range(3) if m.specs[j][1] is None]  # joints without a torque input
    np.testing.assert_allclose(meas[:, first], chained[:, first], rtol=0, atol=1e-10)
    if name.endswith("standard"):
        return
    assert not np.allclose(meas, chained, atol=1e-6)  # the other joints see another torque
    # the measured torque replaced by the model's own chained prediction gives predict_data back
    same = DynamicsData(q=test.q, qd=test.qd, qdd=test.qdd, tau=chained, t=test.t)
    np.testing.assert_allclose(predict_measured_neighbour(m, same), chained, rtol=0, atol=1e-10)


def test_measured_neighbour_errors() -> None:
    with pytest.raises(RuntimeError, match="not fitted"):
        predict_measured_neighbour(make_model("np-inward", 3), _data(0))
    m = make_model("np-inward", 2, gp_config=GPFitConfig(n_restarts=1, max_iter=5))
    d = _data(0)
    m.fit(DynamicsData(q=d.q[:, :2], qd=d.qd[:, :2], qdd=d.qdd[:, :2], tau=d.tau[:, :2], t=d.t))
    with pytest.raises(ValueError, match="DOF mismatch"):
        predict_measured_neighbour(m, d)
    with pytest.raises(TypeError, match="DynamicsData"):
        predict_measured_neighbour(m, d.q)
