"""The learner-divergence experiment's pieces: the uncertainty along a reference, and the ratios and decision rules
of studies.learner_divergence (on synthetic records)."""

from __future__ import annotations

import numpy as np
import pytest

from cascgp.gp import GPFitConfig
from cascgp.learning import Feedback, RetrainConfig
from cascgp.models import make_model
from studies import learner_divergence as ld

PLAN = [("sine", 0, "train"), ("sine", 1, "train"), ("sine", 2, "train")]
FEEDBACK = Feedback(np.full(2, 20.0), np.full(2, 5.0), np.full(2, 10.0))
SMALL = RetrainConfig(seed=3, restarts=2, cap=60)


def test_reference_uncertainty_is_the_models_propagated_variance_along_the_points(arm3_train, arm3_rbd) -> None:
    data = arm3_train.take(np.arange(60))
    model = make_model("sp-inward", data.dof, rbd=arm3_rbd, gp_config=GPFitConfig(n_restarts=2, max_iter=100)).fit(data)
    q, qd, qdd = arm3_train.q[100:140], arm3_train.qd[100:140], arm3_train.qdd[100:140]
    out = ld.reference_uncertainty(model, arm3_rbd, q, qd, qdd)
    mean, var = model.predict(q, qd, qdd, propagate=True)
    d = mean - arm3_rbd.inverse_dynamics(q, qd, qdd)
    np.testing.assert_allclose(out["rel_var"], np.median(var / model.signal_var, axis=0))
    np.testing.assert_allclose(out["weight"], (d**2 / (d**2 + var)).mean(axis=0))
    np.testing.assert_allclose(out["sd_rms"], np.sqrt(var.mean(axis=0)))
    assert all(0.0 <= w <= 1.0 for w in out["weight"])


def _fake(gl_factor: float, relvar_factor: float, seeds=range(6)) -> dict:
    """Synthetic runs: GL tracks ``gl_factor`` x UL's early attempts and has ``relvar_factor`` x UL's relative
    variance; its lag at the last attempt grows with that factor (plus noise); UL' differs from UL by noise."""
    rng = np.random.default_rng(1)
    tasks = ["front", "left", "right"]
    cfg = {"tasks": tasks, "attempts": 4, "seeds": list(seeds), "payload_mass": 1.2}
    runs = {}
    for s in seeds:
        ul, gl, null = [], [], []
        for t in tasks:
            for k in range(4):
                base = float(rng.uniform(0.05, 0.2))
                f = float(relvar_factor * rng.uniform(0.8, 1.25))
                lag = f ** 0.5 if k == 3 else gl_factor
                rec = {"task": t, "task_attempt": k, "phase": "train"}
                ul.append({**rec, "tracking_rmse": base, "before": {"rel_var": [0.1, 0.2]}})
                gl.append({**rec, "tracking_rmse": base * lag, "before": {"rel_var": [0.1 * f, 0.2 * f]},
                           "paired": {ld.UNGATED: {"tracking_rmse": base * lag / 1.02}}})
                null.append({**rec, "tracking_rmse": base * float(rng.uniform(0.97, 1.03))})
        runs[str(s)] = {"GL": gl, "UL": ul, "UL'": null}
    return {"config": cfg, "runs": runs}


def test_divergence_ratios_are_those_of_the_records_and_multiply_out() -> None:
    res = _fake(1.5, 2.0)
    rows = ld.ratios(res)
    run = res["runs"]["2"]
    pick = {q: next(r for r in rows if r["seed"] == 2 and r["task"] == "left" and r["quantity"] == q)
            for q in ("null_last", "gate_learners_last", "gate_on_gl_model", "gl_model_vs_ul", "rel_var_gl_vs_ul",
                      "early_tracking_gl_vs_ul")}
    g, u, n = (next(a for a in run[k] if a["task"] == "left" and a["task_attempt"] == 3) for k in ("GL", "UL", "UL'"))
    assert pick["null_last"]["ratio"] == n["tracking_rmse"] / u["tracking_rmse"]
    assert pick["gate_learners_last"]["ratio"] == g["tracking_rmse"] / u["tracking_rmse"]
    assert pick["gate_on_gl_model"]["ratio"] * pick["gl_model_vs_ul"]["ratio"] == \
        pytest.approx(pick["gate_learners_last"]["ratio"])
    assert pick["rel_var_gl_vs_ul"]["ratio"] == pytest.approx(np.mean(g["before"]["rel_var"]) / 0.15)
    early = [a["tracking_rmse"] for a in run["GL"] if a["task"] == "left" and a["task_attempt"] < 3]
    early_u = [a["tracking_rmse"] for a in run["UL"] if a["task"] == "left" and a["task_attempt"] < 3]
    assert pick["early_tracking_gl_vs_ul"]["ratio"] == pytest.approx(np.mean(early) / np.mean(early_u))
    # No early-tracking row on the first task (every learner starts there from the same RBD attempt).
    assert not any(r["task"] == "front" and r["quantity"] == "early_tracking_gl_vs_ul" for r in rows)


def test_decision_rules_support_the_hypothesis_only_when_the_data_do() -> None:
    yes = ld.tests_of_hypotheses(ld.ratios(_fake(1.5, 2.0)))
    assert yes["divergence_hypothesis_supported"]
    assert yes["null_within_10pct"] == yes["null_n"] == 18
    assert yes["spread_gate_vs_null"]["p_mannwhitney_gate_greater"] < 0.05
    # GL tracks as UL early on and is no less certain: not supported, whatever else holds.
    no = ld.tests_of_hypotheses(ld.ratios(_fake(1.0, 1.0)))
    assert not no["divergence_hypothesis_supported"]


def test_reproduction_counts_identical_attempts() -> None:
    res = _fake(1.5, 2.0, seeds=range(2))
    ref = {"runs": {s: {ld.GATED: [dict(a) for a in r["GL"]], ld.UNGATED: [dict(a) for a in r["UL"]]}
                    for s, r in res["runs"].items()}}
    ref["runs"]["1"][ld.GATED][5]["tracking_rmse"] += 1e-3
    rep = ld.reproduction(res, ref)
    assert rep["attempts_compared"] == 2 * 2 * 12 and rep["identical"] == rep["attempts_compared"] - 1
    assert rep["max_abs_difference"] == pytest.approx(1e-3)


def test_the_summary_page_renders_from_the_json_alone() -> None:
    res = _fake(1.5, 2.0)
    res["ratios"] = ld.ratios(res)
    res["summary"] = ld.summarise(res["ratios"])
    res["tests"] = ld.tests_of_hypotheses(res["ratios"])
    res["wall_seconds"], res["jobs"] = 0.5, {"n_cached": 3, "n_jobs": 18, "job_seconds_sum": 40.0}
    text = ld.summary_markdown(res)
    assert "3 of 18 jobs from the cache" in text and "took 40 s" in text
    assert "divergence hypothesis supported (rule 2): True" in text
    n_null = res["summary"]["null_last"]
    assert f"| null_last | 18 | {n_null['median']:.3f} |" in text and f"{n_null['n_meeting']} of 18 |" in text


def test_per_task_medians_are_those_of_the_seeds() -> None:
    rows = ld.ratios(_fake(1.5, 2.0))
    pt = ld.per_task(rows)
    v = [r["ratio"] for r in rows if r["task"] == "left" and r["quantity"] == "gate_learners_last"]
    assert pt["left"]["gate_learners_last"]["n"] == 6
    assert pt["left"]["gate_learners_last"]["median"] == pytest.approx(np.median(v))
    assert pt["left"]["gate_learners_last"]["median_abs_log"] == pytest.approx(np.median(np.abs(np.log(v))))
    assert "early_tracking_gl_vs_ul" not in pt["front"]


def test_reproduction_refuses_a_reference_of_other_settings() -> None:
    res = _fake(1.5, 2.0, seeds=range(1))
    ref = {"runs": {"0": {ld.GATED: res["runs"]["0"]["GL"][:-1], ld.UNGATED: res["runs"]["0"]["UL"]}}}
    with pytest.raises(ValueError, match="reference: seed 0 sp-inward-gated has 11 attempts"):
        ld.reproduction(res, ref)


def test_joint_split_is_the_per_joint_decomposition() -> None:
    def rec(task, k, gl, paired=None):
        r = {"task": task, "task_attempt": k, "joint_rmse": [gl, 2 * gl]}
        if paired is not None:
            r["paired"] = {ld.UNGATED: {"joint_rmse": [paired, 2 * paired]}}
        return r

    results = {"runs": {"0": {"GL": [rec("front", 0, 1.0, 1.0), rec("left", 0, 0.3, 0.1), rec("left", 1, 0.2, 0.2)],
                              "UL": [rec("front", 0, 1.0), rec("left", 0, 0.1), rec("left", 1, 0.1)]}}}
    split = ld.joint_split(results, "left", 1)
    assert [r["attempt"] for r in split["0"]] == [0, 1]
    np.testing.assert_allclose([(r["gate"], r["model"]) for r in split["0"]], [(3.0, 1.0), (1.0, 2.0)])
    assert "3.00, 1.00" in ld.joint_split_markdown(split)
    with pytest.raises(ValueError, match="right"):
        ld.joint_split(results, "right", 0)


def test_wrist_reading_classifies_seeds_and_applies_p1_p2() -> None:
    def rows(g0, m0, later):
        return [{"attempt": 0, "gate": g0, "model": m0}] + [{"attempt": k + 1, "gate": 1.0, "model": m}
                                                            for k, m in enumerate(later)]

    split = {"8": rows(2.0, 1.0, [2.0, 1.8, 1.5]), "9": rows(1.8, 0.9, [1.6, 1.4, 1.2]),
             "10": rows(1.05, 0.9, [1.0, 1.1, 0.9]), "11": rows(1.0, 2.0, [2.0, 2.0, 2.0])}
    r = ld.wrist_reading(split)
    assert [r["seeds"][s]["kind"] for s in split] == ["gate-triggered", "gate-triggered", "calm", "front-triggered"]
    assert r["seeds"]["9"]["m13"] == 1.4 and r["replicated"] is True
    split["10"] = rows(1.05, 0.9, [1.5, 1.5, 1.5])  # a calm seed that lags anyway: P2 fails
    assert ld.wrist_reading(split)["replicated"] is False
    split["9"] = rows(1.3, 0.9, [1.0, 1.0, 1.0])  # only one gate-triggered seed: inconclusive
    assert ld.wrist_reading(split)["replicated"] is None
