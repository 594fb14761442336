"""Batched exact GP (cascgp.gp): NLL/gradient against a plain NumPy/SciPy reference, optimum, prediction, errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg
import scipy.optimize
import torch

from cascgp.gp import GPBank, GPFitConfig, GPPosterior, nll_and_grad
from cascgp.gp.posterior import robust_cholesky
from cascgp.gp.kernels import kernel_of_r2

NOISE_FLOOR = 1e-6


# ------------------------------------------------------------------------------------------------ reference
def ref_kernel(kernel: str, X1: np.ndarray, X2: np.ndarray, ls: np.ndarray, sf2: float) -> np.ndarray:
    """Closed form, explicit differences (no distance tricks)."""
    diff = (X1[:, None, :] - X2[None, :, :]) / ls
    r2 = (diff**2).sum(-1)
    if kernel == "rbf":
        return sf2 * np.exp(-0.5 * r2)
    r = np.sqrt(r2)
    if kernel == "matern32":
        return sf2 * (1 + math.sqrt(3) * r) * np.exp(-math.sqrt(3) * r)
    return sf2 * (1 + math.sqrt(5) * r + 5.0 / 3.0 * r2) * np.exp(-math.sqrt(5) * r)


def ref_nll_grad(theta: np.ndarray, X: np.ndarray, y: np.ndarray, active: np.ndarray, kernel: str):
    """NumPy/SciPy reference: Cholesky NLL; gradient 1/2 tr((K^-1 - a a^T) dK/dtheta) with explicit dK."""
    n, D = X.shape
    ls = np.exp(theta[:D])
    Xa, la = X[:, active], ls[active]
    sf2, en = math.exp(theta[D]), math.exp(theta[D + 1])
    Kf = ref_kernel(kernel, Xa, Xa, la, sf2)
    K = Kf + (NOISE_FLOOR + en) * np.eye(n)
    c = scipy.linalg.cho_factor(K, lower=True)
    a = scipy.linalg.cho_solve(c, y)
    nll = 0.5 * y @ a + np.log(np.diag(c[0])).sum() + 0.5 * n * math.log(2 * math.pi)
    M = scipy.linalg.cho_solve(c, np.eye(n)) - np.outer(a, a)
    grad = np.zeros(D + 2)
    diff = (Xa[:, None, :] - Xa[None, :, :]) / la
    r2 = (diff**2).sum(-1)
    if kernel == "rbf":
        dk_dr2 = -0.5 * sf2 * np.exp(-0.5 * r2)
    elif kernel == "matern32":  # d/d(r^2) of (1 + sqrt(3) r) e^{-sqrt(3) r}, by hand: -3/2 e^{-sqrt(3) r}
        dk_dr2 = -1.5 * sf2 * np.exp(-math.sqrt(3) * np.sqrt(r2))
    else:
        r = np.sqrt(r2)
        dk_dr2 = -5.0 / 6.0 * sf2 * (1 + math.sqrt(5) * r) * np.exp(-math.sqrt(5) * r)
    for j, k in enumerate(np.flatnonzero(active)):
        dK = dk_dr2 * (-2.0) * diff[:, :, j] ** 2
        grad[k] = 0.5 * np.sum(M * dK)
    grad[D] = 0.5 * np.sum(M * Kf)
    grad[D + 1] = 0.5 * en * np.trace(M)
    return nll, grad


def make_data(rng, n, dims, noise=0.05):
    X = [rng.normal(size=(n, d)) for d in dims]
    y = [np.sin(1.3 * x[:, 0]) + 0.3 * x[:, -1] * x[:, 0] + 0.2 * np.cos(x).sum(1) + noise * rng.normal(size=n)
         for x in X]
    return X, y


# ------------------------------------------------------------------------------------------------ NLL and grad
@pytest.mark.parametrize("kernel", ["matern52", "matern32", "rbf"])
def test_nll_and_grad_equal_numpy_reference_padded_batch(kernel):
    rng = np.random.default_rng(1)
    n, dims = 40, [3, 5, 2, 5]
    D = max(dims)
    B = len(dims)
    X = np.zeros((B, n, D))
    mask = np.zeros((B, D))
    for b, d in enumerate(dims):
        X[b, :, :d] = rng.normal(size=(n, d))
        mask[b, :d] = 1
    y = rng.normal(size=(B, n))
    for _ in range(3):
        theta = np.concatenate([rng.uniform(-1.0, 1.5, size=(B, D)), rng.uniform(-1, 1, size=(B, 1)),
                                rng.uniform(-5, -1, size=(B, 1))], axis=1)
        theta[:, :D] *= mask
        f, g, jit = nll_and_grad(torch.tensor(theta), torch.tensor(X), torch.tensor(y), torch.tensor(mask),
                                 kernel, NOISE_FLOOR)
        assert torch.all(jit == 0)
        for b in range(B):
            fr, gr = ref_nll_grad(theta[b], X[b], y[b], mask[b] > 0, kernel)
            assert f[b].item() == pytest.approx(fr, rel=1e-8)
            np.testing.assert_allclose(g[b].numpy(), gr, rtol=1e-8, atol=1e-10 * np.abs(gr).max())
            # padded columns: zero gradient
            assert np.all(g[b].numpy()[dims[b]:D] == 0)


def test_grad_matches_finite_differences():
    rng = np.random.default_rng(2)
    n, d = 30, 4
    X = torch.tensor(rng.normal(size=(1, n, d)))
    y = torch.tensor(rng.normal(size=(1, n)))
    theta = np.concatenate([rng.uniform(-0.5, 1.0, size=d), [0.3, -2.0]])
    f0, g0, _ = nll_and_grad(torch.tensor(theta[None]), X, y)
    h = 1e-6
    fd = np.zeros_like(theta)
    for i in range(theta.size):
        tp, tm = theta.copy(), theta.copy()
        tp[i] += h
        tm[i] -= h
        fp, _, _ = nll_and_grad(torch.tensor(tp[None]), X, y, need_grad=False)
        fm, _, _ = nll_and_grad(torch.tensor(tm[None]), X, y, need_grad=False)
        fd[i] = (fp.item() - fm.item()) / (2 * h)
    np.testing.assert_allclose(g0[0].numpy(), fd, rtol=1e-5, atol=1e-6)


def test_kernel_of_r2_numpy_matches_closed_form():
    r2 = np.array([0.0, 1e-12, 0.3, 2.0, 50.0])
    r = np.sqrt(r2)
    np.testing.assert_allclose(kernel_of_r2("matern52", r2),
                               (1 + np.sqrt(5) * r + 5 / 3 * r2) * np.exp(-np.sqrt(5) * r), rtol=1e-14)
    np.testing.assert_allclose(kernel_of_r2("rbf", r2), np.exp(-r2 / 2), rtol=1e-14)
    np.testing.assert_allclose(kernel_of_r2("matern32", r2), (1 + np.sqrt(3) * r) * np.exp(-np.sqrt(3) * r),
                               rtol=1e-14)
    with pytest.raises(ValueError, match="kernel"):
        kernel_of_r2("periodic", r2)


@pytest.mark.parametrize("kernel", ["matern52", "matern32", "rbf"])
def test_every_form_of_a_kernel_equals_its_closed_form_and_derivative(kernel):
    """The NumPy, torch, in-place and scaled forms (:mod:`cascgp.gp.kernels`) give one function: the closed form
    of ``ref_kernel`` and, for the derivatives, central differences of it in r^2."""
    from cascgp.gp.kernels import get_kernel

    k = get_kernel(kernel)
    r2 = np.array([0.0, 1e-12, 0.01, 0.3, 2.0, 9.0, 50.0])
    ref = ref_kernel(kernel, np.sqrt(r2)[:, None], np.zeros((1, 1)), np.ones(1), 1.0)[:, 0]
    h = 1e-6
    ref_d = (ref_kernel(kernel, np.sqrt(r2 + h)[:, None], np.zeros((1, 1)), np.ones(1), 1.0)[:, 0]
             - ref_kernel(kernel, np.sqrt(np.maximum(r2 - h, 0.0))[:, None], np.zeros((1, 1)), np.ones(1), 1.0)[:, 0]
             ) / ((r2 + h) - np.maximum(r2 - h, 0.0))
    np.testing.assert_allclose(k.value(r2), ref, rtol=1e-13, atol=1e-300)
    np.testing.assert_allclose(k.value_torch(torch.tensor(r2)).numpy(), ref, rtol=1e-13)
    np.testing.assert_allclose(k.grad_r2(r2)[2:], ref_d[2:], rtol=1e-5)  # away from 0 (one-sided differences)
    a = k.r2_scale * r2
    np.testing.assert_allclose(k.value_scaled_np_(a.copy()), ref, rtol=1e-13)
    kappa, dkappa = k.value_and_grad_scaled_np(a)
    np.testing.assert_allclose(kappa, ref, rtol=1e-13)
    np.testing.assert_allclose(dkappa * k.r2_scale, k.grad_r2(r2), rtol=1e-13)  # d/d(r^2) = s d/da
    A, B, C = torch.tensor(a), torch.empty(len(a), dtype=torch.float64), torch.empty(len(a), dtype=torch.float64)
    c = k.value_and_grad_(A, B, C)
    np.testing.assert_allclose(A.numpy(), ref, rtol=1e-13)
    np.testing.assert_allclose(c * B.numpy(), k.grad_r2(r2), rtol=1e-13)


def test_cholesky_jitter_only_for_failing_members():
    n = 20
    good = torch.eye(n, dtype=torch.float64) * 2.0
    v = torch.arange(n, dtype=torch.float64)
    bad = torch.outer(v, v) / n + 0.0  # rank one: not positive definite
    L, jit, failed = robust_cholesky(torch.stack([good, bad]), jitter_max=1e-2)
    assert jit[0].item() == 0.0 and jit[1].item() > 0.0
    assert not failed.any()
    torch.testing.assert_close(L[0], torch.linalg.cholesky(good))


# ------------------------------------------------------------------------------------------------ fitting
def test_batched_fit_equals_fitting_each_alone_and_is_an_optimum():
    rng = np.random.default_rng(3)
    X, y = make_data(rng, 60, [2, 4, 3])
    cfg = GPFitConfig(n_restarts=3, seed=5)
    bank = GPBank(cfg).fit(X, y)
    for b in range(3):
        alone = GPBank(cfg).fit([X[b]], [y[b]])
        assert bank.fit_info[b]["best_nll"] == pytest.approx(alone.fit_info[0]["best_nll"], abs=1e-6)
        info = bank.fit_info[b]
        assert len(info["nll"]) == 3 and len(info["n_iter"]) == 3
        assert info["best_nll"] == pytest.approx(min(info["nll"]), abs=1e-9)
        assert all(it > 0 for it in info["n_iter"])
        # SciPy L-BFGS-B on the reference NLL, started at our optimum, finds nothing better
        Xn = (X[b] - X[b].mean(0)) / X[b].std(0)
        yn = (y[b] - y[b].mean()) / y[b].std()
        th = bank.theta[b]
        # (bounded to +-5 log units around it: an unbounded first step can overflow exp in the reference)
        res = scipy.optimize.minimize(ref_nll_grad, th, args=(Xn, yn, np.ones(Xn.shape[1], bool), "matern52"),
                                      jac=True, method="L-BFGS-B", bounds=[(t - 5.0, t + 5.0) for t in th])
        assert res.fun >= info["best_nll"] - 1e-4


def test_fit_with_screening_and_dropping_reaches_same_optimum():
    rng = np.random.default_rng(4)
    X, y = make_data(rng, 120, [3, 3])
    plain = GPBank(GPFitConfig(n_restarts=4, seed=1)).fit(X, y)
    fast = GPBank(GPFitConfig(n_restarts=4, seed=1, screen_n=60, screen_keep=2, drop_after=3,
                              drop_margin=5.0)).fit(X, y)
    for b in range(2):
        assert fast.fit_info[b]["best_nll"] <= plain.fit_info[b]["best_nll"] + 1e-3
        assert "screened_out" in fast.fit_info[b]["reason"]


def test_warm_start_is_used_and_converges_fast():
    rng = np.random.default_rng(5)
    X, y = make_data(rng, 80, [3, 2])
    first = GPBank(GPFitConfig(n_restarts=3)).fit(X, y)
    second = GPBank(GPFitConfig(n_restarts=2, seed=9)).fit(X, y, init=first)
    for b in range(2):
        assert second.fit_info[b]["warm_start"]
        assert second.fit_info[b]["nll"][0] == pytest.approx(first.fit_info[b]["best_nll"], abs=1e-5)
        assert second.fit_info[b]["n_iter"][0] <= 3
    with pytest.raises(ValueError, match="init"):
        GPBank().fit([X[0]], [y[0]], init=first)


# ------------------------------------------------------------------------------------------------ prediction
def closed_form(X, y, Xq, hp, kernel="matern52"):
    ls, sf2, sn2 = hp["lengthscale"], hp["signal_var"], hp["noise_var"]
    K = ref_kernel(kernel, X, X, ls, sf2) + sn2 * np.eye(len(y))
    Ks = ref_kernel(kernel, Xq, X, ls, sf2)
    mu = y.mean() + Ks @ np.linalg.solve(K, y - y.mean())
    var = sf2 - np.einsum("ij,ji->i", Ks, np.linalg.solve(K, Ks.T))
    return mu, var


@pytest.mark.parametrize("kernel", ["matern52", "matern32", "rbf"])
def test_predict_and_posterior_equal_closed_form(kernel):
    rng = np.random.default_rng(6)
    X, y = make_data(rng, 50, [3, 4])
    y[1] = 100.0 + 20.0 * y[1]  # different target scale
    bank = GPBank(GPFitConfig(kernel=kernel, n_restarts=2)).fit(X, y)
    Xq = [rng.normal(size=(7, 3)), rng.normal(size=(7, 4))]
    mean, var = bank.predict(Xq)
    assert mean.shape == (7, 2) and var.shape == (7, 2)
    for b in range(2):
        mu, v = closed_form(X[b], y[b], Xq[b], bank.hyperparameters(b), kernel)
        np.testing.assert_allclose(mean[:, b], mu, rtol=1e-8, atol=1e-8 * np.abs(y[b]).max())
        np.testing.assert_allclose(var[:, b], v, rtol=1e-6, atol=1e-9 * np.var(y[b]))
        post = bank.posterior(b)
        assert isinstance(post, GPPosterior) and post.kernel == kernel
        pm, pv = post.predict(Xq[b])
        np.testing.assert_allclose(pm, mean[:, b], rtol=1e-12, atol=1e-12 * np.abs(y[b]).max())
        np.testing.assert_allclose(pv, var[:, b], rtol=1e-9, atol=1e-12 * np.var(y[b]))
        # contract formula: mean = y_mean + y_std * k(r2(z, Z)) @ alpha
        z = (Xq[b] - post.x_mean) / post.x_scale
        r2 = ((z[:, None, :] - post.Z[None]) ** 2).sum(-1)
        m2 = post.y_mean + post.y_std * (post.signal_var * kernel_of_r2(kernel, r2)) @ post.alpha
        np.testing.assert_allclose(m2, mean[:, b], rtol=1e-10, atol=1e-10 * np.abs(y[b]).max())
    mean_only, none = bank.predict(Xq, return_var=False)
    assert none is None
    np.testing.assert_array_equal(mean_only, mean)


def test_posterior_predicts_many_rows_in_blocks_of_fixed_memory(monkeypatch):
    """GPPosterior.predict, mean_grad and mean_grad_all built (rows, n) matrices for all rows at once: a
    200,000-row log against n = 2000 took 13 GB (predict and evaluate of the command). They now run in blocks of
    rows, with the same results to round-off, and their memory does not grow with the rows."""
    import tracemalloc

    import cascgp.gp.posterior as posterior

    rng = np.random.default_rng(11)
    X, y = make_data(rng, 200, [3])
    P = GPBank(GPFitConfig(n_restarts=1)).fit(X, y).posterior(0)
    Xq = rng.normal(size=(20000, 3))
    whole = (*P.predict(Xq), P.mean_grad(Xq, 1), P.mean_grad_all(Xq))  # one block: 20000 x 200 fits 64 MiB
    monkeypatch.setattr(posterior, "BLOCK_BYTES", 2**20)  # 512 rows per block of at most 1 MiB
    assert len(posterior._row_blocks(20000, 200)) == 40
    tracemalloc.start()
    try:
        blocked = (*P.predict(Xq), P.mean_grad(Xq, 1), P.mean_grad_all(Xq))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    for a, b in zip(whole, blocked):
        np.testing.assert_allclose(b, a, rtol=1e-9, atol=1e-12 * np.abs(a).max())
    assert peak < 8 * 2**20  # all rows at once: 32 MB per (20000, 200) matrix
    mean, none = P.predict(Xq, return_var=False)
    assert none is None and mean.shape == (20000,)


def test_prediction_finite_far_away_and_constant_cases():
    rng = np.random.default_rng(7)
    n = 30
    Xa = rng.normal(size=(n, 3))
    Xa[:, 1] = 4.0  # constant column: ignored
    ya = np.sin(Xa[:, 0]) + 0.01 * rng.normal(size=n)
    Xb = rng.normal(size=(n, 2))
    yb = np.full(n, 3.5)  # constant target
    bank = GPBank(GPFitConfig(n_restarts=2)).fit([Xa, Xb], [ya, yb])
    assert bank.fit_info[1]["constant_target"] and not bank.fit_info[0]["constant_target"]
    assert math.isinf(bank.hyperparameters(0)["lengthscale"][1])
    Xq = [np.array([[1e6, -1e6, 1e6], [0.1, 100.0, 0.2]]), np.array([[1e8, 0.0], [0.0, 0.0]])]
    mean, var = bank.predict(Xq)
    assert np.all(np.isfinite(mean)) and np.all(np.isfinite(var)) and np.all(var >= 0)
    np.testing.assert_allclose(mean[:, 1], 3.5, rtol=0, atol=1e-12)
    # the constant column's query value is ignored
    m2, _ = bank.predict([np.array([[0.1, -7.0, 0.2]] * 2), Xq[1]])
    assert mean[1, 0] == pytest.approx(m2[1, 0], rel=1e-12)
    assert np.all(np.isfinite(bank.posterior(0).predict(Xq[0])[0]))
    # at any finite distance the prior (from 1e155 on the squared distance overflowed: NaN from the bank, SciPy's
    # error from the posterior)
    huge = np.array([[1e155, 0.0, 0.0], [-1e300, 1.0, 1e308]])
    hm, hv = bank.predict([huge, np.array([[1e200, 0.0], [0.0, -1e308]])])
    P = bank.posterior(0)
    np.testing.assert_allclose(hm[:, 0], P.y_mean, rtol=1e-12)
    np.testing.assert_allclose(hv[:, 0], P.signal_var * P.y_std**2, rtol=1e-12)
    np.testing.assert_allclose(np.stack(P.predict(huge)), np.stack([hm[:, 0], hv[:, 0]]), rtol=1e-12)
    assert np.all(np.isfinite(hm)) and np.all(np.isfinite(hv))


def test_a_round_off_column_around_zero_is_no_input():
    """q̈ differenced from a constant q̇ over accumulated sample times is round-off around 0 (sd ~1e-16): constant,
    ignored. (A rule relative to the mean made it an input with a lengthscale of ~1e-10, and the GP then predicted
    its prior wherever that q̈ was not 0 to ~1e-10.) Data in units below 1e-12 is constant by the same rule."""
    rng = np.random.default_rng(4)
    t = np.cumsum(np.full(60, 0.025))
    qdd = np.gradient(0.3 * t, t) - 0.3  # the differenced slope of q̇ = 0.3 t less 0.3: round-off around 0
    x1 = rng.uniform(-1, 1, 60)
    X = np.column_stack([x1, qdd])
    y = np.sin(2 * x1) + 0.01 * rng.normal(size=60)
    bank = GPBank(GPFitConfig(n_restarts=2)).fit([X], [y])
    assert math.isinf(bank.hyperparameters(0)["lengthscale"][1])
    far = bank.predict([np.column_stack([x1[:5], np.full(5, 0.05)])])[0][:, 0]
    np.testing.assert_array_equal(far, bank.predict([X[:5]])[0][:, 0])  # its value is ignored
    assert GPBank(GPFitConfig(n_restarts=2)).fit([X[:, :1]], [y * 1e-13]).fit_info[0]["constant_target"]


def test_state_dict_round_trip_identical_predictions():
    rng = np.random.default_rng(8)
    X, y = make_data(rng, 40, [3, 5])
    bank = GPBank(GPFitConfig(n_restarts=2)).fit(X, y)
    sd = bank.state_dict()
    for k, v in sd.items():
        assert isinstance(v, (np.ndarray, str, int, float)), k
    # survives a NumPy save/load cycle
    import io

    buf = io.BytesIO()
    np.savez(buf, **sd)
    buf.seek(0)
    loaded = dict(np.load(buf))
    bank2 = GPBank.from_state_dict(loaded)
    Xq = [rng.normal(size=(9, 3)), rng.normal(size=(9, 5))]
    m1, v1 = bank.predict(Xq)
    m2, v2 = bank2.predict(Xq)
    np.testing.assert_array_equal(m1, m2)
    np.testing.assert_array_equal(v1, v2)
    assert bank2.fit_info == bank.fit_info
    bad = dict(sd)
    bad["theta"] = bad["theta"][:, :-1]
    with pytest.raises(ValueError, match="theta"):
        GPBank.from_state_dict(bad)
    bad = dict(sd)
    del bad["X"]
    with pytest.raises(ValueError, match="X"):
        GPBank.from_state_dict(bad)
    for huge in (800.0, -800.0):  # finite, but exp() overflows or gives a zero lengthscale: named, not an OverflowError
        bad = dict(sd)
        bad["theta"] = sd["theta"] + huge
        with pytest.raises(ValueError, match=r"state\['theta'\]: expected log hyperparameters within"):
            GPBank.from_state_dict(bad)


# ------------------------------------------------------------------------------------------------ errors
def test_input_errors_name_the_field():
    rng = np.random.default_rng(9)
    X = rng.normal(size=(10, 2))
    y = rng.normal(size=10)
    bank = GPBank(GPFitConfig(n_restarts=1))
    Xn = X.copy()
    Xn[3, 1] = np.nan
    with pytest.raises(ValueError, match=r"X\[0\].*row 3"):
        bank.fit([Xn], [y])
    yi = y.copy()
    yi[4] = np.inf
    with pytest.raises(ValueError, match=r"y\[0\]"):
        bank.fit([X], [yi])
    with pytest.raises(ValueError, match=r"y\[0\]"):
        bank.fit([X], [y[:9]])
    with pytest.raises(ValueError, match=r"X\[0\]"):
        bank.fit([X[:, 0]], [y])
    with pytest.raises(ValueError, match=r"X\[1\]"):
        bank.fit([X, X[:9]], [y, y[:9]])
    with pytest.raises(ValueError, match="n=1"):
        bank.fit([X[:1]], [y[:1]])
    with pytest.raises(ValueError, match="y"):
        bank.fit([X, X], [y])
    with pytest.raises(TypeError, match="X"):
        bank.fit(X, [y])
    with pytest.raises(ValueError, match="kernel"):
        GPFitConfig(kernel="linear")
    with pytest.raises(ValueError, match="n_restarts"):
        GPFitConfig(n_restarts=0)
    for field, bad in (("snr_max", True), ("catch_up_windows", True)):
        with pytest.raises(ValueError, match=field):
            GPFitConfig(**{field: bad})
    assert GPFitConfig(threads=1024).for_fit().threads == 1024
    with pytest.raises(ValueError, match="threads: expected at most 1024, got 1025"):
        GPFitConfig(threads=1025).for_fit()
    with pytest.raises(ValueError, match=r"config\.threads: expected at most 1024, got 1025"):
        GPBank(GPFitConfig(threads=1025)).fit([X], [y])  # checked when a fit starts: a saved config still loads
    changed = GPFitConfig(n_restarts=1)
    changed.n_restarts = 0  # set after construction: the fit checks the settings again
    with pytest.raises(ValueError, match=r"config\.n_restarts: expected an integer >= 1, got 0"):
        GPBank(changed).fit([X], [y])
    with pytest.raises(RuntimeError, match="not fitted"):
        bank.predict([X])
    bank.fit([X], [y])
    with pytest.raises(ValueError, match=r"X\[0\]"):
        bank.predict([rng.normal(size=(3, 3))])
    Xq = rng.normal(size=(3, 2))
    Xq[0, 0] = np.nan
    with pytest.raises(ValueError, match=r"X\[0\]"):
        bank.predict([Xq])
    with pytest.raises(ValueError, match="X"):
        bank.predict([Xq, Xq])
    for bad in (0, 2.5, True):  # range() refused 0 and 2.5 without naming chunk; True was a chunk of 1
        with pytest.raises(ValueError, match="chunk: expected an integer >= 1"):
            bank.predict([X], chunk=bad)
    np.testing.assert_allclose(bank.predict([X], chunk=1)[0], bank.predict([X])[0], rtol=1e-12, atol=1e-12)
    with pytest.raises(ValueError, match="b"):
        bank.posterior(1)


def test_posterior_refuses_a_query_of_another_shape_and_keeps_a_row_vector():
    """``GPPosterior.predict`` broadcast a (m, 1) query against d columns and returned numbers; NaN and the wrong
    vector length raised NumPy's or SciPy's errors, naming nothing."""
    rng = np.random.default_rng(3)
    X = rng.normal(size=(30, 3))
    bank = GPBank(GPFitConfig(n_restarts=1)).fit([X], [X.sum(1)])
    post = bank.posterior(0)
    for bad in (np.zeros((4, 1)), np.zeros((4, 4)), np.zeros(2), np.zeros(4), np.zeros((2, 3, 1))):
        for call in (post.predict, post.mean_grad_all, lambda x: post.mean_grad(x, 0)):
            with pytest.raises(ValueError, match=r"^x: expected"):
                call(bad)
    nan = X[:2].copy()
    nan[1, 2] = np.nan
    with pytest.raises(ValueError, match=r"^x: contains NaN or inf \(first at row 1\)"):
        post.predict(nan)
    with pytest.raises(TypeError, match=r"^x: expected a real numeric"):
        post.predict(X[:2] + 1j)
    with pytest.raises(TypeError, match=r"^x: expected a numeric .*requires grad"):
        post.predict(torch.zeros(2, 3, requires_grad=True))
    with pytest.raises(TypeError, match=r"^X\[0\]: expected a numeric .*requires grad"):  # torch's RuntimeError
        GPBank(GPFitConfig(n_restarts=1)).fit([torch.tensor(X, requires_grad=True)], [X.sum(1)])
    for col in (3, -1):
        with pytest.raises(ValueError, match=r"^col: expected an input column in \[0, 3\)"):
            post.mean_grad(X[:2], col)
    for col in (1.0, True):
        with pytest.raises(TypeError, match=r"^col: expected an integer input column"):
            post.mean_grad(X[:2], col)
    # a (d,) vector is one row, a list is accepted, and every form predicts as the (m, d) array
    m, v = post.predict(X[:1])
    for q in (X[0], X[0].tolist(), [X[0].tolist()]):
        m2, v2 = post.predict(q)
        assert m2.shape == (1,) and v2.shape == (1,)
        np.testing.assert_array_equal(m2, m)
        np.testing.assert_array_equal(v2, v)
    assert post.predict(np.zeros((0, 3)))[0].shape == (0,)
