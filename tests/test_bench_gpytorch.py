"""The fit benchmark's GPyTorch runner and its common NLL: behaviour on tiny problems (no timing)."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("gpytorch")

from cascgp.gp import GPBank, GPFitConfig
from scripts import gpytorch_fit as gf


def _data_1d(n: int = 25, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    x = np.sort(rng.uniform(0.0, 5.0, n))
    return x[:, None], np.sin(x) + 0.1 * rng.standard_normal(n)


def _standardised() -> tuple[np.ndarray, np.ndarray]:
    X, y = _data_1d()
    return (X - X.mean(0)) / X.std(0), (y - y.mean()) / y.std()


def test_hyper_nll_is_the_closed_form_gaussian_density() -> None:
    """Two points: K is 2 x 2, so the NLL can be written out by hand."""
    X = np.array([[0.0], [0.7]])
    y = np.array([0.3, -0.5])
    ls, sf2, sn2, c = np.array([0.9]), 1.3, 0.2, 0.1
    r = 0.7 / 0.9
    k12 = sf2 * (1 + math.sqrt(5) * r + 5 * r * r / 3) * math.exp(-math.sqrt(5) * r)
    a, b = sf2 + sn2, k12
    det = a * a - b * b
    u = y - c
    quad = (a * u[0] ** 2 - 2 * b * u[0] * u[1] + a * u[1] ** 2) / det
    expected = 0.5 * quad + 0.5 * math.log(det) + math.log(2 * math.pi)
    assert gf.hyper_nll(X, y, ls, sf2, sn2, mean=c) == pytest.approx(expected, abs=1e-12)


def test_common_nll_equals_cascgps_own_nll_of_its_fit() -> None:
    """On raw (not standardised) data: cascgp centres on the sample mean and reports the NLL in normalised units,
    so its value plus ``n log y_std`` is the NLL with mean ``y.mean()`` in data units."""
    X, y = _data_1d()
    X, y = 2.0 * X + 1.0, 3.0 * y + 2.0
    bank = GPBank(GPFitConfig(n_restarts=3)).fit([X], [y])
    h = bank.hyperparameters(0)
    got = gf.hyper_nll(X, y, h["lengthscale"], h["signal_var"], h["noise_var"], mean=float(y.mean()))
    assert got == pytest.approx(bank.fit_info[0]["best_nll"] + y.size * math.log(y.std()), abs=1e-8)


def test_gpytorch_lbfgs_reaches_cascgps_optimum_on_the_same_objective() -> None:
    X, y = _standardised()
    bank = GPBank(GPFitConfig(n_restarts=3)).fit([X], [y])
    fit = gf.fit_one(X, y, optimizer="lbfgs", restarts=3, mean="zero", noise_lb=1e-6)
    h = fit["hyper"]
    assert fit["nll"] == pytest.approx(gf.hyper_nll(X, y, h["lengthscale"], h["signal_var"], h["noise_var"]),
                                       abs=1e-8)
    assert abs(fit["nll"] - bank.fit_info[0]["best_nll"]) < 0.02
    # its own predictor is the closed-form posterior mean
    Xq = np.linspace(-2.0, 2.0, 7)[:, None]
    ref = gf.predict_mean(X, y, Xq, h["lengthscale"], h["signal_var"], h["noise_var"])
    assert np.allclose(gf.predict(fit, Xq), ref, atol=1e-7)


def test_gpytorch_default_recipe_is_no_worse_than_cascgp_on_its_own_objective() -> None:
    """The recipe (constant mean, Adam 150 x 10 starts) optimises the constant-mean objective: its loss is within a
    small tolerance of (or below) cascgp's optimum with the constant profiled out."""
    X, y = _standardised()
    bank = GPBank(GPFitConfig()).fit([X], [y])
    hc = bank.hyperparameters(0)
    ref = gf.hyper_nll(X, y, hc["lengthscale"], hc["signal_var"], hc["noise_var"], mean=None)
    fit = gf.fit_one(X, y, optimizer="adam")
    assert fit["nll"] < ref + 0.1


def test_batched_adam_follows_the_separate_runs() -> None:
    X, y = _standardised()
    Y = np.stack([y, np.cos(X[:, 0])], 1)
    sep = [gf.fit_one(X, Y[:, j], optimizer="adam", restarts=2, iters=15, output=j) for j in range(2)]
    bat = gf.fit_adam_batched(X, Y, restarts=2, iters=15)
    for s, b in zip(sep, bat):
        assert np.allclose(s["nll_per_restart"], b["nll_per_restart"], atol=1e-8)


def test_cascgp_predictor_with_given_hyperparameters() -> None:
    """bench_cascgp.bank_with: cascgp's predictor with another library's hyperparameters and constant mean is the
    closed-form posterior mean."""
    from scripts.fit_accuracy import bank_with

    X, y = _standardised()
    bank = GPBank(GPFitConfig(n_restarts=2)).fit([X], [y])
    h = {"lengthscale": np.array([0.8]), "signal_var": 0.9, "noise_var": 0.05}
    Xq = np.linspace(-2.5, 2.5, 9)[:, None]
    got = bank_with(bank, [h], [0.3]).predict([Xq], return_var=False)[0][:, 0]
    assert np.allclose(got, gf.predict_mean(X, y, Xq, h["lengthscale"], 0.9, 0.05, mean=0.3), atol=1e-9)
