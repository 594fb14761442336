"""The gate-rule experiment's bookkeeping (studies.gate_rule) on synthetic runs: its ratios are those
of the records, and its pre-registered decision follows the data."""

from __future__ import annotations

import numpy as np
import pytest

from studies import gate_rule as gr

TASKS = ["front", "left"]


def _fake(floor_lag: float, first_vs_rbd: float = 0.5, seeds=range(8)) -> dict:
    """Per seed: RBD at 0.4 rad; UL at ``base``; GLw at 1.3 x UL on "left" (J4 gate effect 2 at the first attempt);
    GLf at ``floor_lag`` x UL there; every learner's first "left" attempt at ``first_vs_rbd`` x RBD."""
    rng = np.random.default_rng(0)
    runs = {}
    for s in seeds:
        run: dict[str, list] = {k: [] for k in gr.LEARNERS}
        for t in TASKS:
            for k in range(4):
                base = float(rng.uniform(0.05, 0.2))
                rec = {"task": t, "task_attempt": k, "phase": "train"}
                first_left = t == "left" and k == 0
                lag = {"GLw": 1.3 if t == "left" else 1.0, "GLf": floor_lag if t == "left" else 1.0}
                for label in gr.LEARNERS:
                    if label == "rbd":
                        rmse = 0.4
                    elif first_left:
                        rmse = 0.4 * first_vs_rbd
                    else:
                        rmse = base * lag.get(label, 1.0)
                    r = {**rec, "tracking_rmse": rmse, "joint_rmse": [rmse] * 6}
                    if label.startswith("GL"):
                        g = 2.0 if (first_left and label == "GLw") else 1.0
                        r["joint_rmse"] = [rmse] * 3 + [rmse * g] + [rmse] * 2
                        r["paired"] = {gr.UNGATED: {"tracking_rmse": rmse, "joint_rmse": [rmse] * 6}}
                    run[label].append(r)
        runs[str(s)] = run
    return {"config": {"tasks": TASKS, "attempts": 4, "seeds": list(seeds), "payload_mass": 1.2}, "runs": runs}


def _decide(res: dict) -> dict:
    rows = gr.ratios(res)
    return gr.decide(rows, gr.wrist(res), tuple(TASKS), "GLf", "GLw")


def test_ratios_are_those_of_the_records() -> None:
    res = _fake(1.0)
    rows = gr.ratios(res)
    run = res["runs"]["3"]

    def pick(q):
        return next(r for r in rows if r["seed"] == 3 and r["quantity"] == q)

    def last(label, task):
        return next(a for a in run[label] if a["task"] == task and a["task_attempt"] == 3)["tracking_rmse"]

    assert pick("last_left_GLw")["ratio"] == pytest.approx(last("GLw", "left") / last("UL", "left")) == \
        pytest.approx(1.3)
    assert pick("last_front_null")["ratio"] == last("UL'", "front") / last("UL", "front")
    assert pick("rules_last_left")["ratio"] == pytest.approx(1.0 / 1.3)
    assert pick("first_left_vs_rbd_GLf")["ratio"] == pytest.approx(0.5)
    assert {r["quantity"] for r in rows} >= {"first_left_vs_rbd_UL", "last_front_GLf", "last_left_null"}
    w = gr.wrist(res)
    assert w["GLw"]["3"]["g0"] == pytest.approx(2.0) and w["GLf"]["3"]["g0"] == pytest.approx(1.0)


def test_the_decision_adopts_the_floor_rule_only_when_every_rule_holds() -> None:
    yes = _decide(_fake(1.0))
    assert yes["A"] and yes["B"] and yes["C"] and yes["D"] and yes["adopt"]
    assert yes["E_n_candidate_better"] == yes["E_n"] == 8 and yes["E_wilcoxon_p_less"] < 0.01
    assert yes["mechanism"]["GLw"]["g0"] == pytest.approx(2.0)
    # Still lagging on "left" (A fails, D holds): not adopted.
    lag = _decide(_fake(1.2))
    assert not lag["A"] and lag["D"] and not lag["adopt"]
    # Worse than RBD on a first attempt (C fails): not adopted, however well it ends.
    unsafe = _decide(_fake(1.0, first_vs_rbd=1.05))
    assert not unsafe["C"] and not unsafe["adopt"]
    # No better than the Wiener rule on these seeds (D fails): not adopted.
    same = _decide(_fake(1.3))
    assert not same["D"] and not same["adopt"]


def test_the_summary_page_renders_from_the_json_alone(tmp_path) -> None:
    res = _fake(1.0)
    res["ratios"] = gr.ratios(res)
    res["wrist"] = gr.wrist(res)
    res["summary"] = {q: gr.ratio_stats([r["ratio"] for r in res["ratios"] if r["quantity"] == q], None)
                      for q in dict.fromkeys(r["quantity"] for r in res["ratios"])}
    res["decision"] = gr.decide(res["ratios"], res["wrist"], tuple(TASKS))
    res["wall_seconds"], res["jobs"] = 1.0, {"n_cached": 0, "n_jobs": 40, "job_seconds_sum": 2.0}
    text = gr.summary_markdown(res)
    assert "**GLf's rule adopted as the default gate: True**" in text
    assert "| 3 | 2.00, 1.00, 1.30 | 1.00, 1.00, 1.00 |" in text  # GLw: gate 2 at J4, model 1.3 later
    gr.plot(res, tmp_path / "g.png")
    assert (tmp_path / "g.png").stat().st_size > 0


def test_jobs_are_one_per_seed_and_learner_with_the_null_offset() -> None:
    jobs = gr.gate_rule_jobs(gr.GATE_RULE_CONFIG, (12, 13))
    assert [(j["config"]["seed"], j["_label"]) for j in jobs[:5]] == [(12, k) for k in gr.LEARNERS]
    by = {j["_label"]: j for j in jobs if j["config"]["seed"] == 13}
    assert by["UL'"]["config"]["fit_seed_offset"] == gr.NULL_FIT_SEED_OFFSET
    assert by["UL"]["config"]["fit_seed_offset"] == 0
    assert by["GLf"]["name"] == "sp-inward-fgated" and by["GLf"]["paired"] == [gr.UNGATED]
    assert by["rbd"]["paired"] is None and tuple(by["rbd"]["config"]["tasks"]) == ("front", "left")


def test_the_innovation_protocol_decides_by_a_b_c_alone() -> None:
    """Without a control learner on its seeds, D and E are left out and A, B and C decide."""
    res = _fake(1.0)
    for run in res["runs"].values():
        run["GLi"] = run.pop("GLf")
        del run["GLw"]
    res["protocol"] = {"name": "innovation", "candidate": "GLi", "control": None}
    rows = gr.ratios(res)
    assert not any(r["quantity"].startswith("rules_") for r in rows)
    assert {r["quantity"] for r in rows} >= {"last_left_GLi", "first_left_vs_rbd_GLi"}
    dec = gr.decide(rows, gr.wrist(res), tuple(TASKS), "GLi", None)
    assert dec["A"] and dec["B"] and dec["C"] and "D" not in dec and dec["adopt"]
    assert set(gr.wrist(res)) == {"GLi"}
    jobs = gr.gate_rule_jobs(gr.GATE_RULE_CONFIG, gr.INNOVATION_SEEDS[:1], gr.INNOVATION_LEARNERS)
    assert [j["name"] for j in jobs] == ["rbd", "sp-inward", "sp-inward", "sp-inward-igated"]
    assert set(gr.INNOVATION_SEEDS).isdisjoint(range(20))  # seeds no earlier learner experiment used

