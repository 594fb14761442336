"""Cascade uncertainty (issue 10): the first-order propagated variance against Monte Carlo sampling of the cascade."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cascgp.data import DynamicsData
from cascgp.features import states_from_arrays
from cascgp.gp import GPFitConfig
from cascgp.models import make_model
from tests.conftest import make_arm, sinusoid_data


def _sample_cascade(model, q, qd, qdd, n: int, rng: np.random.Generator) -> np.ndarray:
    """Draw n joint-torque vectors at one query by sampling each joint's GP (latent, marginal) given a
    *sampled* neighbour torque, in cascade order: the distribution the propagation approximates."""
    S = states_from_arrays("db", q[None], qd[None], qdd[None], None).reshape(1, -1)
    tau_rbd = model.rbd.inverse_dynamics(q, qd, qdd) if model.parametric == "sp" else np.zeros(model.dof)
    out = np.empty((n, model.dof))
    for j in model.order:
        sj, tj = model.specs[j]
        cols = np.concatenate([[3 * s, 3 * s + 1, 3 * s + 2] for s in sj])
        x = np.repeat(S[:, cols], n, axis=0)
        if tj is not None:
            x = np.concatenate([x, out[:, tj:tj + 1]], axis=1)
        k, b = model.where[j]
        m, v = model.banks[k].posterior(b).predict(x)
        out[:, j] = tau_rbd[j] + m + np.sqrt(v) * rng.standard_normal(n)
    return out


@pytest.mark.parametrize("name", ["np-inward", "np-outward"])
def test_propagated_variance_matches_monte_carlo(name: str) -> None:
    arm = make_arm(3, friction=0.3)
    train = sinusoid_data(arm, 6.0, 10.0, seed=1, noise=0.05)
    model = make_model(name, 3, make_arm(3) if name.startswith("sp") else None,
                       gp_config=GPFitConfig(n_restarts=2, max_iter=100)).fit(train)
    test = sinusoid_data(arm, 20.0, 10.0, seed=5)
    rng = np.random.default_rng(0)
    mean0, var0 = model.predict(test.q, test.qd, test.qdd)
    mean1, var1 = model.predict(test.q, test.qd, test.qdd, propagate=True)
    np.testing.assert_array_equal(mean0, mean1)
    assert np.all(var1 >= var0)
    first = model.order[0]
    np.testing.assert_array_equal(var1[:, first], var0[:, first])  # the head of the chain has no input torque
    # queries where propagation matters (> 20 % more variance), up to 8 of them
    gain = (var1 / np.maximum(var0, 1e-300)).max(axis=1)
    rows = np.flatnonzero(gain > 1.2)[:8]
    assert rows.size >= 3, "the test data should exercise the propagation"
    mc = np.array([_sample_cascade(model, test.q[r], test.qd[r], test.qdd[r], 20000, rng).var(axis=0)
                   for r in rows])
    rel1 = np.abs(var1[rows] - mc) / mc
    rel0 = np.abs(var0[rows] - mc) / mc
    # first order: close to the sampled variance where the mean is near-linear over the input's spread
    # (median within 10 %, worst within 30 %), and much closer than the unpropagated variance
    assert np.median(rel1) < 0.10 and rel1.max() < 0.30, (rel1, rel0)
    assert rel1.sum() < 0.5 * rel0.sum(), (rel1, rel0)


@pytest.mark.parametrize("name", ["np-inward", "sp-outward", "np-standard", "np-outward-df"])
def test_single_query_mean_and_propagated_variance_equal_the_batched_path(name: str) -> None:
    arm = make_arm(3, friction=0.3)
    train = sinusoid_data(arm, 5.0, 10.0, seed=1, noise=0.05)
    model = make_model(name, 3, make_arm(3) if name.startswith("sp") else None,
                       gp_config=GPFitConfig(n_restarts=1, max_iter=40)).fit(train)
    test = sinusoid_data(arm, 2.0, 10.0, seed=4)
    hist = np.stack([test.q - 0.1 * test.qd, test.q - 0.2 * test.qd], axis=1)
    df = name.endswith("df")
    mean, var = model.predict(test.q, test.qd, test.qdd, hist if df else None, propagate=True)
    for r in range(0, test.n_samples, 3):
        m1, v1 = model.predict_one_var(test.q[r], test.qd[r], test.qdd[r], hist[r] if df else None)
        np.testing.assert_allclose(m1, mean[r], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(v1, var[r], rtol=1e-7, atol=1e-12)


# ----------------------------------------------------------------------------- input noise (NIGP test-time term)
@pytest.fixture(scope="module", params=["np-inward", "sp-outward"])
def fitted(request):
    arm = make_arm(3, friction=0.3)
    train = sinusoid_data(arm, 6.0, 10.0, seed=1, noise=0.05)
    name = request.param
    model = make_model(name, 3, make_arm(3) if name.startswith("sp") else None,
                       gp_config=GPFitConfig(n_restarts=2, max_iter=100)).fit(train)
    return model, sinusoid_data(arm, 20.0, 10.0, seed=5)


def test_mean_jacobian_matches_finite_differences(fitted) -> None:
    model, test = fitted
    rows = slice(0, 200, 25)
    q, qd, qdd = test.q[rows], test.qd[rows], test.qdd[rows]
    J = model.mean_jacobian(q, qd, qdd)
    assert J.shape == (q.shape[0], 3, 3, 3)
    h = 1e-5
    for c in range(3):
        for k in range(3):
            up, dn = [a.copy() for a in (q, qd, qdd)], [a.copy() for a in (q, qd, qdd)]
            up[c][:, k] += h
            dn[c][:, k] -= h
            fd = (model.predict(*up)[0] - model.predict(*dn)[0]) / (2 * h)
            np.testing.assert_allclose(J[:, :, k, c], fd, rtol=1e-4, atol=1e-5)  # FD round-off ~1e-6
    # The single query takes its own path (no batch matrix products): equal to round-off, not bit for bit
    np.testing.assert_allclose(model.mean_jacobian(q[0], qd[0], qdd[0]), J[0], rtol=1e-9, atol=1e-12)


def test_input_noise_variance_matches_monte_carlo(fitted) -> None:
    """The first-order term against the spread of the mean prediction over sampled noisy inputs."""
    model, test = fitted
    rng = np.random.default_rng(3)
    sd = np.array([0.02, 0.1, 0.3])  # q, qd, qdd noise std: small against the lengthscales, visible in the mean
    input_var = np.broadcast_to(sd**2, (3, 3))
    mean0, var0 = model.predict(test.q, test.qd, test.qdd, propagate=True)
    mean1, var1 = model.predict(test.q, test.qd, test.qdd, propagate=True, input_var=input_var)
    np.testing.assert_array_equal(mean0, mean1)
    extra = var1 - var0
    assert np.all(extra >= 0)
    np.testing.assert_array_equal(model.predict(test.q, test.qd, test.qdd, input_var=np.zeros(3))[1],
                                  model.predict(test.q, test.qd, test.qdd)[1])
    n = 4000
    rel = []
    for r in range(0, test.n_samples, 25):
        x = [np.repeat(a[r][None], n, 0) + s * rng.standard_normal((n, 3))
             for a, s in zip((test.q, test.qd, test.qdd), sd)]
        mc = model.predict(*x)[0].var(axis=0)
        rel.append(np.abs(extra[r] - mc) / mc)
    rel = np.array(rel)
    # first order, MC error about 2 % (4000 draws): median within 10 %, nearly all within 30 %
    assert np.median(rel) < 0.10 and np.quantile(rel, 0.9) < 0.30, rel


def test_input_var_errors() -> None:
    arm = make_arm(2)
    train = sinusoid_data(arm, 3.0, 10.0, seed=1, noise=0.05)
    cfg = GPFitConfig(n_restarts=1, max_iter=20)
    model = make_model("np-inward", 2, gp_config=cfg).fit(train)
    q, qd, qdd = train.q[:3], train.qd[:3], train.qdd[:3]
    with pytest.raises(ValueError, match="broadcasts"):
        model.predict(q, qd, qdd, input_var=np.ones(4))
    with pytest.raises(ValueError, match=">= 0"):
        model.predict(q, qd, qdd, input_var=-np.ones(3))
    with pytest.raises(ValueError, match="finite"):
        model.predict(q, qd, qdd, input_var=np.full(3, np.nan))
    with pytest.raises(ValueError, match=r"^input_var: the variance overflowed \(input_var up to 1e\+308, the mean"):
        model.predict(q, qd, qdd, input_var=np.full(3, 1e308))  # an infinite variance before
    df = make_model("np-inward-df", 2, gp_config=cfg).fit(train)
    hist = np.stack([q, q], axis=1)
    with pytest.raises(ValueError, match="derivative-based"):
        df.predict(q, qd, qdd, hist, input_var=np.ones(3))
    with pytest.raises(ValueError, match="derivative-based"):
        df.mean_jacobian(q, qd, qdd)


def test_savgol_noise_gain_is_the_variance_of_filtered_white_noise() -> None:
    from cascgp.data import DynamicsData, SavGol

    sg = SavGol(9, 2)
    assert sg.noise_gain(0.01) == pytest.approx(1.0 / (60 * 0.01**2))
    rng = np.random.default_rng(0)
    t = np.arange(20000) * 0.01
    qd = 0.005 * rng.standard_normal((t.size, 1))
    d = DynamicsData.from_measurements(t, np.zeros_like(qd), qd, np.zeros_like(qd), smoothing=sg)
    inner = d.qdd[4:-4, 0]
    assert inner.var() == pytest.approx(0.005**2 * sg.noise_gain(0.01), rel=0.05)
    assert abs(np.corrcoef(inner, qd[4:-4, 0])[0, 1]) < 0.03  # centre coefficient 0: uncorrelated
    with pytest.raises(ValueError, match="dt"):
        sg.noise_gain(0.0)


def test_an_sp_cascade_uses_the_nominal_models_analytic_derivatives() -> None:
    """With a Pinocchio nominal model the rigid-body part of the mean's Jacobian is analytic; it equals the central
    differences used for a nominal model that offers only inverse_dynamics."""
    from cascgp.rbd import load_nominal

    rbd = load_nominal(Path(__file__).resolve().parents[1] / "jaco_env" / "assets" / "jaco2_nominal.urdf")

    class TorqueOnly:  # the same dynamics, without inverse_dynamics_derivatives: the finite-difference path
        dof = rbd.dof

        def inverse_dynamics(self, q, qd, qdd):
            return rbd.inverse_dynamics(q, qd, qdd)

    rng = np.random.default_rng(3)
    q, qd, qdd = rng.uniform(-1, 1, (3, 40, 6)) * np.array([3.0, 1.0, 5.0])[:, None, None]
    tau = rbd.inverse_dynamics(q, qd, qdd) + 0.3 * np.sin(q) + 0.05 * rng.standard_normal((40, 6))
    data = DynamicsData(q=q, qd=qd, qdd=qdd, tau=tau, t=np.arange(40) * 0.1)
    cfg = GPFitConfig(n_restarts=1, max_iter=30)
    analytic = make_model("sp-inward", 6, rbd, gp_config=cfg).fit(data)
    numeric = make_model("sp-inward", 6, TorqueOnly(), gp_config=cfg).fit(data)
    np.testing.assert_allclose(analytic.predict(q[:5], qd[:5], qdd[:5])[0], numeric.predict(q[:5], qd[:5], qdd[:5])[0],
                               rtol=1e-12, atol=1e-10)  # the same fit
    np.testing.assert_allclose(analytic.mean_jacobian(q[:5], qd[:5], qdd[:5]),
                               numeric.mean_jacobian(q[:5], qd[:5], qdd[:5]), rtol=1e-6, atol=1e-5)

