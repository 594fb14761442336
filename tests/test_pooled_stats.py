"""The study's primary statistics (:mod:`cascgp_experiments.pooled_stats`) against hand computations."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cascgp_experiments.pooled_stats import (JACO_FAMILIES, SARCOS_FAMILIES, chain_first, holm, pooled_log_ratio,
                                             pooled_test, run_family, sign_test_power, wilcoxon_p)


def test_pooled_statistic_by_hand() -> None:
    # 4 subsets x 3 joints, interval grid points 1 and 2 s (averaged), joint 3 the same model by construction
    A = np.array([[[0.2, 0.4, 0.5], [0.2, 0.4, 0.7]],   # subset 0: interval means 0.2, 0.4
                  [[0.3, 0.3, 0.5], [0.3, 0.3, 0.5]],
                  [[0.1, 0.8, 0.5], [0.3, 0.8, 0.5]],   # 0.2, 0.8
                  [[0.5, 0.5, 0.5], [0.5, 0.5, 0.5]]])
    B = np.full((4, 2, 3), 0.4)
    block = {"grid_s": [1.0, 2.0], "n_subsets": 4,
             "models": {"np-standard": {"nrmse_all": B}, "np-inward": {"nrmse_all": A}}}
    d_hand = [(math.log(0.5) + math.log(1.0)) / 2, (math.log(0.75) * 2) / 2,
              (math.log(0.5) + math.log(2.0)) / 2, math.log(1.25)]
    rows = run_family(block, JACO_FAMILIES["cascade vs standard (predicted neighbour torque)"],
                      intervals=((1.0, 2.0),))
    assert len(rows) == 1
    r = rows[0]
    assert r["excluded_joints"] == [2]
    np.testing.assert_allclose(r["d"], d_hand, rtol=1e-12)
    assert r["ratio"] == pytest.approx(math.exp(np.mean(d_hand)))
    assert (r["wins"], r["losses"], r["n"]) == (2, 1, 4)  # d = 0 in subset 2 (0.5 x 2.0): neither
    # Wilcoxon with the zero dropped: |d| = (.347, .288, .223) have ranks 3, 2, 1 and only the last is positive:
    # W+ = 1; the exact two-sided p of n = 3 is 2 * P(W+ <= 1) = 2 * 2 / 8 = 0.5
    assert r["p"] == pytest.approx(0.5)
    assert r["p_holm"] == r["p"]  # a family of one test
    np.testing.assert_allclose(pooled_log_ratio(A.mean(1), B.mean(1), (2,)), d_hand)


def test_wilcoxon_smallest_p_and_all_zero() -> None:
    assert wilcoxon_p(-np.arange(1.0, 11.0)) == pytest.approx(2 / 2**10)
    assert wilcoxon_p(np.zeros(5)) == 1.0
    d = np.log([0.9] * 9 + [1.01])
    t = pooled_test(d)
    assert (t["wins"], t["losses"]) == (9, 1) and t["ratio"] == pytest.approx(math.exp(d.mean()))
    assert t["p"] == pytest.approx(4 / 2**10)  # the single loss has the smallest |d|: W+ = 1


def test_holm_closed_form() -> None:
    p = np.array([0.01, 0.04, 0.03, 0.005])
    # sorted 0.005, 0.01, 0.03, 0.04 -> 4 * 0.005, max(3 * 0.01, .), max(2 * 0.03, .), max(1 * 0.04, .)
    want = {3: 0.02, 0: 0.03, 2: 0.06, 1: 0.06}
    np.testing.assert_allclose(holm(p), [want[i] for i in range(4)])
    np.testing.assert_allclose(holm([0.5, 0.9]), [1.0, 1.0])
    np.testing.assert_allclose(holm([0.2]), [0.2])
    # Holm rejects exactly the hypotheses of the step-down rule p_(k) < alpha / (m - k + 1) for all k <= i
    rng = np.random.default_rng(0)
    for _ in range(200):
        p = rng.uniform(0, 0.06, rng.integers(1, 12))
        m, order = p.size, np.argsort(p)
        reject = np.zeros(m, bool)
        for i, k in enumerate(order):
            if p[k] >= 0.05 / (m - i):
                break
            reject[k] = True
        np.testing.assert_array_equal(holm(p) < 0.05, reject)


def test_sign_test_power_closed_form() -> None:
    # n = 10: the two-sided exact sign test at 0.05 rejects for 0, 1, 9 or 10 wins
    r = 0.7
    want = r**10 + 10 * r**9 * (1 - r) + (1 - r)**10 + 10 * (1 - r)**9 * r
    assert sign_test_power(10, r) == pytest.approx(want)
    assert round(sign_test_power(10, 0.7), 2) == 0.15
    assert sign_test_power(10, 0.5) < 0.05  # its size


def test_families_fixed_and_small() -> None:
    """Each family can reject something with 10 (Jaco) and 9 (SARCOS) subsets: m * 2 / 2^S < 0.05."""
    for fams, S in ((JACO_FAMILIES, 10), (SARCOS_FAMILIES, 9)):
        for name, fam in fams.items():
            assert 3 * len(fam) * 2 / 2**S < 0.05, name
    assert len(JACO_FAMILIES["cascade vs standard (predicted neighbour torque)"]) == 4


def test_chain_first_matches_input_spec() -> None:
    from cascgp.features import input_spec

    for s in ("inward", "outward", "standard"):
        for n in (1, 2, 6, 7):
            none = [j for j in range(n) if input_spec(s, j, n)[1] is None]
            want = None if s == "standard" else none[0]
            assert chain_first(f"np-{s}", n) == want and (s == "standard" or none == [want])
