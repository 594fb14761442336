"""A GP taken from another fitted bank instead of being fitted again (``GPBank.fit(shared=...)``), and a cascade
that takes the standard model's GP of its chain's first joint (``CascadedGPModel.fit(share=...)``): the fits are
the ones made without sharing, bit for bit, and every mismatch is refused before any work."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from cascgp import DynamicsData, GPFitConfig, make_model
from cascgp.gp import GPBank

CFG = GPFitConfig(n_restarts=4, seed=3)


def _bank_data(seed: int = 0, n: int = 40) -> tuple[list[np.ndarray], list[np.ndarray]]:
    rng = np.random.default_rng(seed)
    X = [rng.uniform(-1, 1, (n, d)) for d in (4, 2, 4)]
    y = [np.sin(x.sum(1)) + 0.05 * rng.standard_normal(n) for x in X]
    return X, y


def _same_fit(a: GPBank, b: GPBank, gps: range | list[int]) -> None:
    for g in gps:
        np.testing.assert_array_equal(a.theta[g], b.theta[g])
        np.testing.assert_array_equal(a.posterior(g).alpha, b.posterior(g).alpha)
        np.testing.assert_array_equal(a.posterior(g).L, b.posterior(g).L)


def test_shared_gp_gives_the_unshared_fit_bit_for_bit() -> None:
    X, y = _bank_data()
    ref = GPBank(CFG).fit(X, y)
    # another bank with GP 0 on the same data but other GPs beside it
    X2, y2 = _bank_data(seed=1)
    src = GPBank(CFG).fit([X[0], X2[1], X2[2]], [y[0], y2[1], y2[2]])
    _same_fit(src, ref, [0])
    got = GPBank(CFG).fit(X, y, shared={0: (src, 0)})
    _same_fit(got, ref, range(3))
    assert [fi["shared"] for fi in got.fit_info] == [True, False, False]
    assert [fi["shared"] for fi in ref.fit_info] == [False] * 3
    assert {k: v for k, v in got.fit_info[0].items() if k != "shared"} == \
        {k: v for k, v in src.fit_info[0].items() if k != "shared"}
    assert got.fit_summary["n_eval"] < ref.fit_summary["n_eval"]  # GP 0 was not optimised again
    # warm-started fits share too
    ref_w = GPBank(CFG).fit(X, y, init=ref)
    src_w = GPBank(CFG).fit([X[0], X2[1], X2[2]], [y[0], y2[1], y2[2]], init=src)
    _same_fit(GPBank(CFG).fit(X, y, init=got, shared={0: (src_w, 0)}), ref_w, range(3))


@pytest.mark.parametrize("case, match", [
    ("not a dict", "shared: expected a dict"),
    ("key out of range", r"shared: key 3 is not a GP"),
    ("other index", r"shared\[2\]: expected GP 2 of a bank of width 4"),
    ("other width", r"shared\[0\]: expected GP 0 of a bank of width 4"),
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
    elif case == "other width":
        shared = {0: (GPBank(CFG).fit([X[0][:, :3], X[1]], [y[0], y[1]]), 0)}
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
    with pytest.raises((ValueError, TypeError), match=match):
        bank.fit(X, y, init=init, shared=shared)  # type: ignore[arg-type]
    np.testing.assert_array_equal(bank.theta, before)


def _arm_data(seed: int, n: int = 60, dof: int = 3) -> DynamicsData:
    rng = np.random.default_rng(seed)
    q, qd, qdd = (rng.uniform(-1, 1, (n, dof)) for _ in range(3))
    tau = np.sin(q) * 2 + 0.3 * qd + 0.1 * qdd[:, ::-1] + 0.01 * rng.standard_normal((n, dof))
    return DynamicsData(q=q, qd=qd, qdd=qdd, tau=tau, t=np.arange(n) * 0.01, segment=np.zeros(n, dtype=np.int64))


@pytest.mark.parametrize("name", ["np-inward", "np-outward", "np-inward-df", "np-outward-df"])
def test_cascade_sharing_the_standard_models_gp_is_its_own_fit(name: str) -> None:
    data = [_arm_data(0, 40), _arm_data(0, 70)]  # a growing prefix: the second fit is warm-started
    std_name = name.replace("inward", "standard").replace("outward", "standard")
    prev_std = prev_own = prev_sh = None
    for d in data:
        std = make_model(std_name, 3, gp_config=CFG).fit(d, init=prev_std)
        own = make_model(name, 3, gp_config=CFG).fit(d, init=prev_own)
        sh = make_model(name, 3, gp_config=CFG).fit(d, init=prev_sh, share=std)
        _same_fit(sh.banks[0], own.banks[0], range(3))
        j0 = sh.order[0]
        assert [fi["shared"] for fi in sh.fit_info] == [j == j0 for j in range(3)]
        np.testing.assert_array_equal(sh.predict_data(d)[0], own.predict_data(d)[0])
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
