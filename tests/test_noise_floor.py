"""Physical noise floor (``GPFitConfig.noise_floor_target``, ``make_model(..., noise_var_floor=...)``): a lower bound
of each GP's noise variance in target units, converted per GP with its ``y_std``; off by default."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import torch

from cascgp.gp import GPBank, GPFitConfig, nll_and_grad
from cascgp.models import load_model, make_model


def _smooth(rng: np.random.Generator, n: int = 80, noise: float = 1e-3, scale: float = 3.0):
    """A smooth 2-D function with tiny noise (std ``noise``), amplitude ``scale``: the free fit's noise variance
    ends far below 0.01."""
    X = rng.uniform(-2, 2, size=(n, 2))
    y = scale * (np.sin(1.5 * X[:, 0]) + 0.3 * X[:, 1] ** 2) + noise * rng.normal(size=n)
    return X, y


def test_floor_bounds_the_fitted_noise_variance_where_the_free_fit_goes_below():
    rng = np.random.default_rng(0)
    X, y = _smooth(rng)
    cfg = GPFitConfig(n_restarts=3, max_iter=200)
    free = GPBank(cfg).fit([X], [y])
    floor = 0.01  # e.g. a 0.1 N m torque sensor, in target units squared
    assert free.hyperparameters(0)["noise_var"] < 0.1 * floor  # the unconstrained fit collapses below the floor
    bank = GPBank(dataclasses.replace(cfg, noise_floor_target=floor)).fit([X], [y])
    hp = bank.hyperparameters(0)
    assert hp["noise_var"] >= floor * (1 - 1e-12)
    P = bank.posterior(0)
    assert P.noise_var * P.y_std**2 >= floor * (1 - 1e-12)  # the factors use the same floor
    # the normalised floor is floor / y_std^2 (combined with noise_floor by max)
    np.testing.assert_allclose(bank.config.floors(np.array([P.y_std])), [max(cfg.noise_floor, floor / P.y_std**2)])
    # the bound binds: the fitted noise sits at (or just above) the floor
    assert hp["noise_var"] < 1.5 * floor
    # a saved and reloaded bank keeps the floor (recomputed from the config and y_std)
    again = GPBank.from_state_dict(bank.state_dict())
    assert again.hyperparameters(0)["noise_var"] == hp["noise_var"]
    mu0, v0 = bank.predict([X[:7]])
    mu1, v1 = again.predict([X[:7]])
    np.testing.assert_array_equal(mu0, mu1)
    np.testing.assert_array_equal(v0, v1)


def test_floor_per_gp_and_scalar_floor_below_noise_floor_changes_nothing():
    rng = np.random.default_rng(1)
    X, y0 = _smooth(rng, scale=1.0)
    y1 = 10.0 * y0 + 0.002 * rng.normal(size=y0.size)
    cfg = GPFitConfig(n_restarts=2, max_iter=100)
    bank = GPBank(dataclasses.replace(cfg, noise_floor_target=[0.0, 0.04])).fit([X, X], [y0, y1])
    free = GPBank(cfg).fit([X, X], [y0, y1])
    # GP 0: floor 0 -> max(noise_floor, 0) = noise_floor, the default fit bit for bit (array path = scalar path)
    np.testing.assert_array_equal(bank.theta[0], free.theta[0])
    assert bank.hyperparameters(0)["noise_var"] == free.hyperparameters(0)["noise_var"]
    assert bank.hyperparameters(1)["noise_var"] >= 0.04 * (1 - 1e-12)
    assert free.hyperparameters(1)["noise_var"] < 0.04


def test_no_floor_is_the_default_fit_bit_for_bit():
    rng = np.random.default_rng(2)
    X, y = _smooth(rng, n=50)
    cfg = GPFitConfig(n_restarts=2, max_iter=60)
    assert cfg.noise_floor_target is None and cfg.floors(np.ones(1)) is None
    a = GPBank(cfg).fit([X], [y])
    # a floor of 0 goes through the floor's code path (max(noise_floor, 0 / y_std^2)) and must change nothing
    b = GPBank(dataclasses.replace(cfg, noise_floor_target=0.0)).fit([X], [y])
    np.testing.assert_array_equal(a.theta, b.theta)
    assert a.fit_info == b.fit_info
    # a config saved before the field existed loads with no floor
    d = dataclasses.asdict(cfg)
    d.pop("noise_floor_target")
    assert GPFitConfig.from_dict(d).noise_floor_target is None


def test_nll_and_grad_per_member_floor_equals_scalar():
    rng = np.random.default_rng(3)
    k, n, D = 3, 20, 2
    X = torch.tensor(rng.normal(size=(k, n, D)))
    y = torch.tensor(rng.normal(size=(k, n)))
    th = torch.tensor(rng.normal(scale=0.3, size=(k, D + 2)))
    f0, g0, _ = nll_and_grad(th, X, y, noise_floor=0.02)
    f1, g1, _ = nll_and_grad(th, X, y, noise_floor=np.full(k, 0.02))
    np.testing.assert_array_equal(f0.numpy(), f1.numpy())
    np.testing.assert_array_equal(g0.numpy(), g1.numpy())
    with pytest.raises(ValueError, match="noise_floor"):
        nll_and_grad(th, X, y, noise_floor=np.full(k + 1, 0.02))


@pytest.mark.parametrize("train_on_predicted", [False, True])
def test_cascade_floor_per_joint(arm3, arm3_train, arm3_test, tmp_path, train_on_predicted):
    cfg = GPFitConfig(n_restarts=2, max_iter=60)
    floor = (0.01, 0.02, 0.0)
    m = make_model("np-inward", 3, gp_config=cfg, train_on_predicted=train_on_predicted,
                   noise_var_floor=floor).fit(arm3_train)
    assert m.gp_config.noise_floor_target == floor
    nv = m.noise_var
    assert np.all(nv >= np.array(floor) * (1 - 1e-12))
    free = make_model("np-inward", 3, gp_config=cfg, train_on_predicted=train_on_predicted).fit(arm3_train)
    assert free.gp_config.noise_floor_target is None
    if train_on_predicted:  # joint 2 is fitted first (inward) and has no floor: its GP is the free one's
        k, b = m.where[2]
        np.testing.assert_array_equal(m.banks[k].theta, free.banks[free.where[2][0]].theta)
    path = m.save(tmp_path / "floor.npz")
    again = load_model(path)
    np.testing.assert_array_equal(again.noise_var, nv)
    mu0, v0 = m.predict_data(arm3_test)
    mu1, v1 = again.predict_data(arm3_test)
    np.testing.assert_array_equal(mu0, mu1)
    np.testing.assert_array_equal(v0, v1)


@pytest.mark.parametrize("bad", [-0.01, math.nan, math.inf, [0.01, 0.01], [[0.01, 0.01, 0.01]], [0.01, -1, 0.01],
                                 "0.01", True])
def test_bad_floor_values_name_the_field(bad):
    with pytest.raises(ValueError, match="noise_var_floor"):
        make_model("np-inward", 3, noise_var_floor=bad)
    if not (isinstance(bad, list) and len(bad) == 2):  # a 2-vector is a valid config value (2 GPs)
        with pytest.raises(ValueError, match="noise_floor_target"):
            GPFitConfig(noise_floor_target=bad)


def test_floor_shape_errors_name_the_field():
    with pytest.raises(ValueError, match="gp_config.noise_floor_target"):
        make_model("np-inward", 3, gp_config=GPFitConfig(noise_floor_target=(0.01, 0.01)))
    with pytest.raises(ValueError, match="noise_var_floor"):
        make_model("np-inward", 3, gp_config=GPFitConfig(noise_floor_target=0.01), noise_var_floor=0.01)
    rng = np.random.default_rng(4)
    X, y = _smooth(rng, n=20)
    with pytest.raises(ValueError, match="noise_floor_target"):
        GPBank(GPFitConfig(n_restarts=1, noise_floor_target=(0.01, 0.01, 0.01))).fit([X, X], [y, y])
