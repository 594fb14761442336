"""A GP taken from another fitted bank instead of being fitted again (``GPBank.fit(shared=...)``), and a cascade
that takes the standard model's GP of its chain's first joint (``CascadedGPModel.fit(share=...)``): the shared GP
is copied exactly, the other GPs start where they would without sharing (compared after one optimiser iteration)
and end at the same optimum, and every mismatch is refused before any work.

The optimum is compared to 1e-6, not bit for bit: torch's batched kernels may round the last bit differently for a
block of another size on some CPU, which the optimiser can carry forward."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from cascgp import DynamicsData, GPFitConfig, make_model
from cascgp.gp import GPBank
from cascgp.gp.bank import SharedGPError

CFG = GPFitConfig(n_restarts=4, seed=3)


def _bank_data(seed: int = 0, n: int = 40) -> tuple[list[np.ndarray], list[np.ndarray]]:
    rng = np.random.default_rng(seed)
    X = [rng.uniform(-1, 1, (n, d)) for d in (4, 2, 4)]
    y = [np.sin(x.sum(1)) + 0.05 * rng.standard_normal(n) for x in X]
    return X, y


def _same_fit(a: GPBank, b: GPBank, gps: range | list[int], rtol: float = 1e-6) -> None:
    for g in gps:
        np.testing.assert_allclose(a.theta[g], b.theta[g], rtol=rtol, atol=rtol)
        np.testing.assert_allclose(a.posterior(g).alpha, b.posterior(g).alpha, rtol=rtol, atol=rtol)


def _same_starts(a: GPBank, b: GPBank, gps: range | list[int]) -> None:
    """After one optimiser iteration (max_iter=1) every start is still next to where it began: starts drawn
    otherwise would differ at O(1)."""
    for g in gps:
        np.testing.assert_allclose(np.array(a.fit_info[g]["nll"], float), np.array(b.fit_info[g]["nll"], float),
                                   rtol=1e-10)
        np.testing.assert_allclose(a.theta[g], b.theta[g], rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("shared_gp", [0, 1])  # the first GP draws its starts first, the middle one between others
@pytest.mark.parametrize("cfg", [CFG, replace(CFG, screen_n=20, max_iter=1), replace(CFG, max_iter=1)],
                         ids=["optimum", "screened, starts", "starts"])
def test_shared_gp_gives_the_unshared_fit(shared_gp: int, cfg: GPFitConfig) -> None:
    X, y = _bank_data()
    ref = GPBank(cfg).fit(X, y)
    # another bank with the shared GP on the same data but other GPs beside it
    X2, y2 = _bank_data(seed=1)
    Xs = [X[b] if b == shared_gp else X2[b] for b in range(3)]
    ys = [y[b] if b == shared_gp else y2[b] for b in range(3)]
    src = GPBank(cfg).fit(Xs, ys)
    got = GPBank(cfg).fit(X, y, shared={shared_gp: (src, shared_gp)})
    np.testing.assert_array_equal(got.theta[shared_gp], src.theta[shared_gp])  # copied
    np.testing.assert_array_equal(got.posterior(shared_gp).alpha, src.posterior(shared_gp).alpha)
    check = _same_starts if cfg.max_iter == 1 else _same_fit
    check(got, ref, range(3))
    assert [fi["shared"] for fi in got.fit_info] == [b == shared_gp for b in range(3)]
    assert [fi["shared"] for fi in ref.fit_info] == [False] * 3
    assert {k: v for k, v in got.fit_info[shared_gp].items() if k not in ("shared", "best_nll")} == \
        {k: v for k, v in src.fit_info[shared_gp].items() if k not in ("shared", "best_nll")}
    assert got.fit_info[shared_gp]["best_nll"] == pytest.approx(src.fit_info[shared_gp]["best_nll"], rel=1e-12)
    assert got.fit_summary["n_eval"] < ref.fit_summary["n_eval"]  # the shared GP was not optimised again
    # warm-started fits share too
    ref_w = GPBank(cfg).fit(X, y, init=ref)
    src_w = GPBank(cfg).fit(Xs, ys, init=src)
    check(GPBank(cfg).fit(X, y, init=got, shared={shared_gp: (src_w, shared_gp)}), ref_w, range(3))


def test_shared_gp_with_a_noise_floor_per_gp() -> None:
    """Per-GP noise floors: the shared GP's must match; the other GPs' may differ."""
    X, y = _bank_data()
    cfg = replace(CFG, noise_floor_target=(1e-4, 2e-4, 3e-4))
    src = GPBank(replace(cfg, noise_floor_target=(1e-4, 5e-4, 5e-4))).fit(X, y)
    got = GPBank(cfg).fit(X, y, shared={0: (src, 0)})
    np.testing.assert_array_equal(got.theta[0], src.theta[0])
    _same_fit(got, GPBank(cfg).fit(X, y), range(3))
    with pytest.raises(ValueError, match=r"shared\[1\]: GP 1 was fitted with other settings"):
        GPBank(cfg).fit(X, y, shared={1: (src, 1)})


@pytest.mark.parametrize("case, match", [
    ("not a dict", "shared: expected a dict"),
    ("key out of range", r"shared: key 3 is not a GP"),
    ("other index", r"shared\[2\]: expected GP 2 of a bank of 3 GPs and width 4"),
    ("boolean index", r"shared\[1\]: expected GP 1 of a bank of 3 GPs and width 4"),
    ("other width", r"shared\[0\]: expected GP 0 of a bank of 3 GPs and width 4"),
    ("other number of GPs", r"shared\[0\]: expected GP 0 of a bank of 3 GPs and width 4 .*, got GP 0 of a bank of 2"),
    ("unfitted", r"shared\[0\]: expected \(a fitted GPBank"),
    ("other seed", r"shared\[0\]: GP 0 was fitted with other settings"),
    ("other targets", r"shared\[0\]: GP 0 was fitted on other inputs or targets"),
    ("other inputs", r"shared\[0\]: GP 0 was fitted on other inputs or targets"),
    ("warm start", r"shared\[0\]: GP 0 was fitted without a warm start"),
])
def test_shared_gp_mismatch_is_refused_and_changes_nothing(case: str, match: str) -> None:
    X, y = _bank_data()
    src = GPBank(CFG).fit(X, y)
    shared: object = {0: (src, 0)}
    init = None
    if case == "not a dict":
        shared = [(src, 0)]
    elif case == "key out of range":
        shared = {3: (src, 3)}
    elif case == "other index":
        shared = {2: (src, 0)}
    elif case == "boolean index":
        shared = {1: (src, True)}
    elif case == "other width":
        shared = {0: (GPBank(CFG).fit([X[0], X[1], np.hstack([X[2], X[2][:, :2]])], y), 0)}
    elif case == "other number of GPs":
        shared = {0: (GPBank(CFG).fit([X[0], X[1]], [y[0], y[1]]), 0)}
    elif case == "unfitted":
        shared = {0: (GPBank(CFG), 0)}
    elif case == "other seed":
        shared = {0: (GPBank(replace(CFG, seed=4)).fit(X, y), 0)}
    elif case == "other targets":
        shared = {0: (GPBank(CFG).fit(X, [y[0] + 1e-9, y[1], y[2]]), 0)}
    elif case == "other inputs":
        shared = {0: (GPBank(CFG).fit([X[0] * 1.001, X[1], X[2]], y), 0)}
    elif case == "warm start":
        init = src
    bank = GPBank(CFG).fit(X, y)
    before = bank.theta
    with pytest.raises((ValueError, TypeError), match=match) as err:
        bank.fit(X, y, init=init, shared=shared)  # type: ignore[arg-type]
    # an entry's mismatch is a SharedGPError (a ValueError), which a cascade rewraps as its ``share`` error
    assert isinstance(err.value, SharedGPError) == match.startswith(r"shared\[")
    np.testing.assert_array_equal(bank.theta, before)


def _arm_data(seed: int, n: int = 60, dof: int = 3) -> DynamicsData:
    rng = np.random.default_rng(seed)
    q, qd, qdd = (rng.uniform(-1, 1, (n, dof)) for _ in range(3))
    tau = np.sin(q) * 2 + 0.3 * qd + 0.1 * qdd[:, ::-1] + 0.01 * rng.standard_normal((n, dof))
    return DynamicsData(q=q, qd=qd, qdd=qdd, tau=tau, t=np.arange(n) * 0.01, segment=np.zeros(n, dtype=np.int64))


class _LinearRBD:
    """A rigid-body stand-in for the SP models: tau = 1.5 qdd + 0.2 qd."""

    dof = 3

    def inverse_dynamics(self, q, qd, qdd):
        return 1.5 * np.asarray(qdd) + 0.2 * np.asarray(qd)


@pytest.mark.parametrize("name", ["np-inward", "np-outward", "np-inward-df", "sp-outward", "sp-inward-df"])
def test_cascade_sharing_the_standard_models_gp_is_its_own_fit(name: str) -> None:
    data = [_arm_data(0, 40), _arm_data(0, 70)]  # a growing prefix: the second fit is warm-started
    std_name = name.replace("inward", "standard").replace("outward", "standard")
    rbd = _LinearRBD() if name.startswith("sp") else None
    for cfg, check in ((CFG, _same_fit), (replace(CFG, max_iter=1), _same_starts)):
        prev_std = prev_own = prev_sh = None
        for d in data:
            std = make_model(std_name, 3, rbd, gp_config=cfg).fit(d, init=prev_std)
            own = make_model(name, 3, rbd, gp_config=cfg).fit(d, init=prev_own)
            sh = make_model(name, 3, rbd, gp_config=cfg).fit(d, init=prev_sh, share=std)
            j0 = sh.order[0]
            np.testing.assert_array_equal(sh.banks[0].theta[j0], std.banks[0].theta[j0])
            check(sh.banks[0], own.banks[0], range(3))
            assert [fi["shared"] for fi in sh.fit_info] == [j == j0 for j in range(3)]
            np.testing.assert_allclose(sh.predict_data(d)[0], own.predict_data(d)[0], rtol=1e-6, atol=1e-6)
            prev_std, prev_own, prev_sh = std, own, sh


def test_cascade_share_errors_name_share_and_change_nothing() -> None:
    d = _arm_data(0)
    std = make_model("np-standard", 3, gp_config=CFG).fit(d)
    inward = make_model("np-inward", 3, gp_config=CFG).fit(d)
    before = inward.banks[0].theta
    with pytest.raises(ValueError, match="share: only a cascade"):
        make_model("np-standard", 3, gp_config=CFG).fit(d, share=std)
    with pytest.raises(ValueError, match="share: expected a fitted 'np-standard-df' model"):
        make_model("np-inward-df", 3, gp_config=CFG).fit(d, share=std)
    with pytest.raises(ValueError, match="share: expected a fitted 'np-standard' model"):
        inward.fit(d, share=make_model("np-standard", 3, gp_config=CFG))
    with pytest.raises(ValueError, match="share: a train_on_predicted cascade"):
        make_model("np-inward", 3, gp_config=CFG, train_on_predicted=True).fit(d, share=std)
    with pytest.raises(ValueError, match=r"share: .* cannot stand in for this fit of joint 3: shared\[2\]: GP 2 "
                                         "was fitted on other inputs"):
        inward.fit(_arm_data(1), share=std)
    with pytest.raises(ValueError, match="share: .*other settings"):
        inward.fit(d, share=make_model("np-standard", 3, gp_config=replace(CFG, seed=9)).fit(d))
    np.testing.assert_array_equal(inward.banks[0].theta, before)
