"""GP fit defaults: early-stopping rule, memory guard (chunking), conditioning bound, audit API."""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest
import torch

from cascgp.fit_audit import audit_bank, audit_model, cold_config, summarise_gaps
from cascgp.gp import GPBank, GPFitConfig, estimate_fit_bytes, nll_and_grad, plan_chunk
from cascgp.gp.kernels import kernel_of_r2
from cascgp.gp.lbfgs import MemberState
from cascgp.gp.restarts import prune_rule


def _data(rng: np.random.Generator, n: int, d: int, B: int, noise: float = 0.05):
    X = rng.normal(size=(n, d))
    Y = np.stack([np.sin(1.3 * X[:, 0] + b) + 0.3 * X[:, -1] * X[:, 0] + noise * rng.normal(size=n)
                  for b in range(B)], 1)
    return X, Y


# ------------------------------------------------------------------------------------------------ chunking
@pytest.mark.parametrize("kernel", ["matern52", "matern32", "rbf"])
def test_nll_and_grad_independent_of_chunk(kernel):
    rng = np.random.default_rng(3)
    k, n, D = 7, 35, 4
    X = torch.tensor(rng.normal(size=(k, n, D)))
    y = torch.tensor(rng.normal(size=(k, n)))
    theta = torch.tensor(np.concatenate([rng.uniform(-0.5, 1.0, (k, D)), rng.uniform(-1, 1, (k, 1)),
                                         rng.uniform(-5, -1, (k, 1))], 1))
    f1, g1, _ = nll_and_grad(theta, X, y, kernel=kernel, chunk=1)
    for ch in (2, 3, 7, 100):
        f, g, _ = nll_and_grad(theta, X, y, kernel=kernel, chunk=ch)
        np.testing.assert_allclose(f.numpy(), f1.numpy(), rtol=1e-13, atol=1e-12)
        np.testing.assert_allclose(g.numpy(), g1.numpy(), rtol=1e-11, atol=1e-11 * float(g1.abs().max()))


def test_nll_and_grad_block_with_failed_members_equals_members_alone():
    """The gradient is computed for a whole block at once: members that fail (a non-finite value, a trial point
    far out) or need jitter must not change their neighbours' results, and get NLL inf and a zero gradient."""
    rng = np.random.default_rng(5)
    k, n, D = 5, 12, 3
    X, y = rng.normal(size=(k, n, D)), rng.normal(size=(k, n))
    theta = np.concatenate([rng.uniform(-0.5, 1.0, (k, D)), rng.uniform(-1, 1, (k, 1)), rng.uniform(-5, -1, (k, 1))],
                           1)
    y[1, 3] = np.nan  # a non-finite NLL
    theta[2, 0] = -1e6  # a lengthscale of exp(-1e6): skipped before the factor
    theta[3, :D], theta[3, D + 1] = 6.0, -60.0  # K numerically singular: the factor needs jitter
    kw = {"kernel": "rbf", "noise_floor": 0.0}
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the failed members' junk must not raise NumPy warnings either
        f, g, jit = nll_and_grad(torch.tensor(theta), torch.tensor(X), torch.tensor(y), **kw)
    assert math.isinf(float(f[1])) and math.isinf(float(f[2])) and np.all(g[1:3].numpy() == 0)
    assert float(jit[3]) > 0 and math.isfinite(float(f[3]))
    for m in (0, 3, 4):
        f1, g1, j1 = nll_and_grad(torch.tensor(theta[m:m + 1]), torch.tensor(X[m:m + 1]), torch.tensor(y[m:m + 1]),
                                  **kw)
        assert float(f1[0]) == pytest.approx(float(f[m]), rel=1e-13) and float(j1[0]) == float(jit[m])
        np.testing.assert_allclose(g[m].numpy(), g1[0].numpy(), rtol=1e-11, atol=1e-11 * float(g1.abs().max()))


def test_jitter_retry_does_not_repeat_the_failed_factor(monkeypatch):
    """A member whose factor fails is factorised again with growing jitter, starting at the first non-zero one:
    the failed zero-jitter factor is not computed twice. Counted on a member that needs jitter, with the LAPACK
    call wrapped; the jitter each call saw is read from the matrix's diagonal."""
    import cascgp.gp.likelihood as lik

    rng = np.random.default_rng(5)
    n, D = 12, 3
    X, y = rng.normal(size=(1, n, D)), rng.normal(size=(1, n))
    theta = np.concatenate([np.full(D, 6.0), [0.0], [-60.0]])[None]  # K numerically singular (as above)
    diagonals = []
    real = lik._dpotrf

    def counting(a, **kw):
        diagonals.append(float(np.diagonal(a).mean()))
        return real(a, **kw)

    monkeypatch.setattr(lik, "_dpotrf", counting)
    f, _, jit = nll_and_grad(torch.tensor(theta), torch.tensor(X), torch.tensor(y), kernel="rbf", noise_floor=0.0)
    assert float(jit[0]) > 0 and math.isfinite(float(f[0]))
    assert len(diagonals) >= 2 and len(set(diagonals)) == len(diagonals)  # every call a new jitter
    assert diagonals[-1] == pytest.approx(diagonals[0] + float(jit[0]), rel=1e-12)
    diagonals.clear()  # jitter_max below the first jitter step: no jitter at all, one factorisation
    f, _, jit = nll_and_grad(torch.tensor(theta), torch.tensor(X), torch.tensor(y), kernel="rbf", noise_floor=0.0,
                             jitter_max=0.0)
    assert math.isinf(float(f[0])) and float(jit[0]) == 0.0 and len(diagonals) == 1


def test_snr_bound_gradient_matches_finite_differences():
    rng = np.random.default_rng(4)
    n, D = 30, 2
    X = torch.tensor(rng.normal(size=(1, n, D)))
    y = torch.tensor(rng.normal(size=(1, n)))
    theta = np.array([0.2, -0.3, 1.5, -6.0])
    _, g, _ = nll_and_grad(torch.tensor(theta[None]), X, y, snr_max=1e3)
    for j in range(theta.size):
        e = np.zeros_like(theta)
        e[j] = 1e-6
        fp, _, _ = nll_and_grad(torch.tensor((theta + e)[None]), X, y, need_grad=False, snr_max=1e3)
        fm, _, _ = nll_and_grad(torch.tensor((theta - e)[None]), X, y, need_grad=False, snr_max=1e3)
        assert float(g[0, j]) == pytest.approx(float(fp[0] - fm[0]) / 2e-6, rel=1e-5, abs=1e-6)


# ------------------------------------------------------------------------------------------------ memory guard
def test_memory_estimate_and_n2000_target_within_2GB():
    # n = 2000, 7 GPs x 10 starts, d = 21: one member per block keeps the estimate under the 2 GiB default
    need = estimate_fit_bytes(2000, 21, 7, 10, chunk=1)
    assert need < 2 * 1024**3
    assert plan_chunk(GPFitConfig(), 2000, 21, 7) == 1
    # the estimate grows as n^2 (work matrices and the stored factors)
    assert 3.7 < estimate_fit_bytes(8000, 21, 7, 10) / estimate_fit_bytes(4000, 21, 7, 10) <= 4.0


def test_memory_guard_refuses_over_limit_with_clear_message():
    rng = np.random.default_rng(0)
    X, Y = _data(rng, 400, 3, 2)
    limit = estimate_fit_bytes(400, 3, 2, 2, chunk=1) - 1  # one byte short of one start at a time
    cfg = GPFitConfig(n_restarts=2, max_batch_bytes=limit)
    with pytest.raises(ValueError, match=r"max_batch_bytes.*GPFitConfig\.max_batch_bytes"):
        GPBank(cfg).fit([X, X], [Y[:, 0], Y[:, 1]])
    with pytest.raises(ValueError, match=r"n=400"):
        plan_chunk(cfg, 400, 3, 2)
    assert plan_chunk(dataclasses.replace(cfg, max_batch_bytes=limit + 1), 400, 3, 2) == 1
    with pytest.raises(ValueError, match="max_batch_bytes"):
        GPFitConfig(max_batch_bytes=0)


def test_memory_guard_says_what_fits_and_knows_the_machine(monkeypatch):
    """The refusal says how many points fit within the limit (the largest n whose estimate is within it), and a
    limit raised beyond the machine's memory does not let a fit start that the machine cannot hold (a 75 GiB
    estimate on a 23 GiB machine ran until the kernel killed it)."""
    import pickle

    import cascgp.gp.memory as memory

    monkeypatch.setattr(memory, "physical_memory_bytes", lambda: None)  # the limit alone, whatever this machine
    cfg = GPFitConfig(n_restarts=3, max_batch_bytes=2 * 1024**3)
    with pytest.raises(memory.FitMemoryError) as exc:
        plan_chunk(cfg, 4000, 9, 3)
    e = exc.value
    assert isinstance(e, ValueError) and not e.machine and e.n == 4000 and e.limit == cfg.max_batch_bytes
    assert estimate_fit_bytes(e.max_n, 9, 3, 3) <= e.limit < estimate_fit_bytes(e.max_n + 1, 9, 3, 3)
    assert f"at most n={e.max_n} points fit within it" in str(e) and "raise GPFitConfig.max_batch_bytes" in str(e)
    # a limit below the fixed overhead: fewer points cannot help, and the advice says to raise the limit alone
    with pytest.raises(memory.FitMemoryError, match=r"; not even 2 points fit within it: raise GPFitConfig\."
                                                    r"max_batch_bytes$") as low:
        plan_chunk(GPFitConfig(n_restarts=3, max_batch_bytes=100 * 2**20), 80, 9, 3)
    assert low.value.max_n == 0 and "use fewer points" not in str(low.value)
    copy = pickle.loads(pickle.dumps(e))  # crosses processes whole
    assert (str(copy), copy.need, copy.limit, copy.n, copy.max_n, copy.machine) == (
        str(e), e.need, e.limit, e.n, e.max_n, e.machine)
    # a 1 GiB machine: a fit within max_batch_bytes by the high estimate runs if it can (its least need fits) ...
    monkeypatch.setattr(memory, "physical_memory_bytes", lambda: 1024**3)
    assert memory.minimum_fit_bytes(3000, 9, 3, 3) < 1024**3 < estimate_fit_bytes(3000, 9, 3, 3)
    assert plan_chunk(cfg, 3000, 9, 3) >= 1
    # ... and one that cannot is refused, also with the limit raised beyond the machine
    big = dataclasses.replace(cfg, max_batch_bytes=64 * 1024**3)
    with pytest.raises(memory.FitMemoryError, match=r"at least \d+ MiB, more than this machine's 1024 MiB of memory "
                                                    r"\(GPFitConfig\.max_batch_bytes allows 65536 MiB\)") as exc:
        plan_chunk(big, 6000, 9, 3)
    assert exc.value.machine and exc.value.limit == 1024**3
    assert memory.minimum_fit_bytes(exc.value.max_n, 9, 3, 3) <= 1024**3 < memory.minimum_fit_bytes(
        exc.value.max_n + 1, 9, 3, 3)
    with pytest.raises(ValueError, match="limit: expected a finite number of bytes"):
        memory.largest_fit_n(float("inf"), 9, 3, 3)


def test_chunked_fit_equals_unchunked_to_roundoff():
    rng = np.random.default_rng(1)
    n, d, B, R = 60, 3, 3, 4
    X, Y = _data(rng, n, d, B)
    big = GPFitConfig(n_restarts=R, max_iter=80)
    assert plan_chunk(big, n, d, B) > 1
    tight = dataclasses.replace(big, max_batch_bytes=estimate_fit_bytes(n, d, B, R, chunk=1))
    assert plan_chunk(tight, n, d, B) == 1
    a = GPBank(big).fit([X] * B, [Y[:, b] for b in range(B)])
    c = GPBank(tight).fit([X] * B, [Y[:, b] for b in range(B)])
    np.testing.assert_allclose(c.theta, a.theta, rtol=0, atol=1e-8)
    np.testing.assert_allclose([f["best_nll"] for f in c.fit_info], [f["best_nll"] for f in a.fit_info],
                               rtol=0, atol=1e-9)


# ------------------------------------------------------------------------------------------------ early stopping
def _states(traces: list[list[float]]) -> list[MemberState]:
    out = []
    for t in traces:
        st = MemberState(x=np.zeros(3), f=t[-1], n_iter=len(t) - 1)
        st.trace = list(t)
        out.append(st)
    return out


def test_prune_rule_never_stops_the_leader_and_stops_stalled_followers():
    cfg = GPFitConfig(stall_window=2, stall_tol=0.01, catch_up_windows=10.0)
    gp_of = np.array([0, 0, 0, 1])
    traces = [
        [10.0, 5.0, 4.999, 4.998],  # GP 0 leader, stalled: kept (the leader always converges)
        [12.0, 9.0, 8.995, 8.994],  # stalled follower: stopped
        [30.0, 20.0, 12.0, 7.0],  # follower still improving fast: kept
        [3.0, 2.9995, 2.999, 2.9989],  # GP 1's only start (leader): kept
    ]
    st = _states(traces)
    out = prune_rule(cfg, st, gp_of, 2, np.zeros(2, dtype=bool))
    assert out.tolist() == [False, True, False, False]
    assert st[1].reason == "stalled"
    # catch-up: a follower 50 nats behind that gained 1 nat over the window (< 50 / 10) is stopped as well
    st = _states([[10.0, 5.0, 4.9, 4.8], [60.0, 56.0, 55.3, 55.0]])
    out = prune_rule(cfg, st, np.array([0, 0]), 1, np.zeros(1, dtype=bool))
    assert out.tolist() == [False, True]


def test_default_fit_reaches_the_cold_start_optimum_on_small_data():
    rng = np.random.default_rng(5)
    X, Y = _data(rng, 50, 3, 3)
    r = audit_bank(X, Y, n_cold=4)
    assert r["gaps"].shape == (3,)
    np.testing.assert_allclose(r["gaps"], r["default_nll"] - r["cold_nll"])
    assert np.all(r["gaps"] <= 0.1)
    assert r["summary"]["frac_within"] == 1.0
    assert r["cold_config"]["stall_window"] is None and r["cold_config"]["n_restarts"] == 4


# ------------------------------------------------------------------------------------------------ audit API
def test_audit_api_on_a_model_and_errors(arm3_train):
    from cascgp.models import make_model

    m = make_model("np-standard", 3, gp_config=GPFitConfig(n_restarts=2, max_iter=60)).fit(arm3_train)
    r = audit_model(m, n_cold=2)
    assert r["gaps"].shape == (3,)
    np.testing.assert_allclose(r["model_nll"], [fi["best_nll"] for fi in m.fit_info])
    np.testing.assert_allclose(r["gaps"], r["model_nll"] - r["cold_nll"])
    with pytest.raises(TypeError, match="model"):
        audit_model(object())
    with pytest.raises(ValueError, match="n_cold"):
        cold_config(n_cold=0)
    s = summarise_gaps(np.array([0.0, 0.05, 0.2, -1.0]))
    assert s["frac_within"] == 0.75 and s["n_better"] == 1 and s["max_gap"] == 0.2


# ------------------------------------------------------------------------------------------------ conditioning
def _reference_mean(bank: GPBank, Xq: np.ndarray) -> np.ndarray:
    """Float64 reference: LU solve of K alpha = y plus iterative refinement with long-double residuals."""
    P = bank.posterior(0)
    Z = P.Z
    K = P.signal_var * kernel_of_r2(P.kernel, ((Z[:, None, :] - Z[None, :, :]) ** 2).sum(-1))
    K += (P.noise_var + P.jitter) * np.eye(Z.shape[0])
    yn = (bank.training_data()[1][0] - P.y_mean) / P.y_std
    a = np.linalg.solve(K, yn)
    for _ in range(3):
        r = (yn.astype(np.longdouble) - K.astype(np.longdouble) @ a.astype(np.longdouble)).astype(np.float64)
        a = a + np.linalg.solve(K, r)
    zq = (Xq - P.x_mean) / P.x_scale
    ks = P.signal_var * kernel_of_r2(P.kernel, ((zq[:, None, :] - Z[None, :, :]) ** 2).sum(-1))
    return P.y_mean + P.y_std * (ks @ a)


def test_snr_bound_keeps_noise_free_fits_well_conditioned():
    """Noise-free smooth data: without the bound the noise goes to its floor and K is near singular (the issue's
    ~1e-4 prediction error); with the default ``snr_max`` predictions match a float64 reference solve to 1e-8."""
    rng = np.random.default_rng(0)
    X = rng.uniform(-2, 2, size=(60, 1))  # draws kept in this order: the 1-D set, then the 3-D set
    X = rng.uniform(-2, 2, size=(150, 3))
    y = np.sin(2 * X[:, 0]) + (0.5 * X[:, 1:] ** 2).sum(1)
    Xq = rng.uniform(-2, 2, size=(200, 3))
    free = GPBank(GPFitConfig(n_restarts=3, snr_max=None)).fit([X], [y])
    assert free.posterior(0).noise_var < 1.01 * free.config.noise_floor  # noise at its floor
    assert free.posterior(0).signal_var / free.posterior(0).noise_var > 1e10

    bank = GPBank(GPFitConfig(n_restarts=3)).fit([X], [y])
    hp = bank.hyperparameters(0)
    assert hp["signal_var"] / hp["noise_var"] <= bank.config.snr_max * (1 + 1e-12)
    L = bank.posterior(0).L
    assert float(np.linalg.cond(L @ L.T)) <= 1 + X.shape[0] * bank.config.snr_max
    ref = _reference_mean(bank, Xq)
    mean, _ = bank.predict([Xq], return_var=False)
    one, _ = bank.posterior(0).predict(Xq, return_var=False)
    scale = 1 + np.abs(ref).max()
    assert np.abs(mean[:, 0] - ref).max() <= 1e-8 * scale
    assert np.abs(one - ref).max() <= 1e-8 * scale


def test_state_saved_before_new_fields_loads_with_old_behaviour():
    """A state whose config predates ``snr_max``/``stall_window`` loads with both off, and predicts as saved."""
    import json

    rng = np.random.default_rng(2)
    X, Y = _data(rng, 40, 2, 1, noise=0.0)
    bank = GPBank(GPFitConfig(n_restarts=2, snr_max=None, stall_window=None, max_iter=50)).fit([X], [Y[:, 0]])
    sd = bank.state_dict()
    cfg = json.loads(sd["config_json"])
    for k in ("snr_max", "stall_window", "catch_up_windows", "race_at", "race_keep", "max_batch_bytes"):
        del cfg[k]
    sd["config_json"] = json.dumps(cfg)
    old = GPBank.from_state_dict(sd)
    assert old.config.snr_max is None and old.config.stall_window is None
    np.testing.assert_array_equal(old.predict([X[:5]])[0], bank.predict([X[:5]])[0])
    assert old.hyperparameters(0)["noise_var"] == bank.hyperparameters(0)["noise_var"]


def test_far_out_trial_points_give_inf_not_an_error():
    """Line-search trial points with huge log hyperparameters (exp overflows) get NLL inf and gradient 0."""
    rng = np.random.default_rng(6)
    X = torch.tensor(rng.normal(size=(4, 20, 2)))
    y = torch.tensor(rng.normal(size=(4, 20)))
    theta = torch.tensor([[0.0, 0.0, 0.0, -3.0], [0.0, 0.0, 800.0, -3.0], [0.0, 0.0, 0.0, 900.0],
                          [-800.0, 0.0, 0.0, -3.0]])
    f, g, _ = nll_and_grad(theta, X, y, snr_max=1e6)
    assert math.isfinite(float(f[0])) and bool(torch.isinf(f[1:]).all())
    assert bool((g[1:] == 0).all()) and bool(torch.isfinite(g).all())


def test_log_hyperparameters_that_drift_far_are_clipped_to_what_a_saved_bank_holds(monkeypatch):
    """An unneeded input's log lengthscale (12,632) or a log noise far below its floor (-2,673) left the fit as they
    were, and the saved model was refused by its own loader (|log hyperparameter| <= 700). They are now clipped to
    +-700, where the input is ignored and the noise is the floor's to float64, as at the limit."""
    import cascgp.gp.bank as bank_module

    real = bank_module.minimize_batched

    def drifting(*args, **kwargs):
        states = real(*args, **kwargs)
        for st in states:  # input 2 unneeded, noise at its floor: the optimiser wandered off along flat directions
            st.x = st.x.copy()
            st.x[2], st.x[-1] = 12632.0, -2673.0
        return states

    monkeypatch.setattr(bank_module, "minimize_batched", drifting)
    rng = np.random.default_rng(4)
    X, Y = _data(rng, 30, 3, 2)
    bank = GPBank(GPFitConfig(n_restarts=2, max_iter=30)).fit([X, X], [Y[:, 0], Y[:, 1]])
    assert np.abs(bank.theta).max() == 700.0
    np.testing.assert_array_equal(bank.theta[:, [2, -1]], [[700.0, -700.0]] * 2)
    loaded = GPBank.from_state_dict(bank.state_dict())  # refused before
    Xs = rng.normal(size=(7, 3))
    other = Xs.copy()
    other[:, 2] = rng.normal(size=7) * 100.0
    for b in (bank, loaded):
        mean, var = b.predict([Xs, Xs])
        mean2, var2 = b.predict([other, other])
        assert all(np.isfinite(m).all() for m in mean + var)
        for m, m2 in zip(mean + var, mean2 + var2):  # the clipped lengthscale ignores its input, bit for bit
            np.testing.assert_array_equal(m, m2)
    assert bank.hyperparameters(0)["noise_var"] == loaded.hyperparameters(0)["noise_var"]


def test_a_warm_started_constant_target_keeps_its_log_hyperparameters_within_700():
    """A constant target is not optimised: it keeps the warm start, whose log lengthscales are shifted by the change
    of the inputs' spread, so a lengthscale at the bound (700) came back at 702.3 and the bank could not be loaded."""
    rng = np.random.default_rng(0)
    X = rng.normal(size=(40, 2))
    first = GPBank(GPFitConfig(n_restarts=1)).fit([X], [np.sin(X[:, 0])])
    first._data.theta[0, 1] = 700.0  # an unneeded input's lengthscale, clipped by its fit
    second = GPBank(GPFitConfig(n_restarts=1)).fit([X * 0.1], [np.full(40, 2.0)], init=first)
    assert second.fit_info[0]["constant_target"] and np.abs(second.theta).max() <= 700.0
    GPBank.from_state_dict(second.state_dict())  # refused before
