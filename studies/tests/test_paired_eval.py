"""Paired evaluation on the Jaco env (:class:`cascgp_experiments.run_hooks.PairedEpisodes` through
``controller_job(paired=...)``) and the gate evaluation's bookkeeping (studies.gate_eval): the paired episodes change
nothing in the learner's own run, a paired controller that is the same controller gives the same episode, and the
ratios are those of the records."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from studies import gate_eval
from studies.gate_eval import GATED, UNGATED, ratios, run_gate_eval, summarise
from cascgp_experiments.transfer import TransferConfig, controller_job

TINY = TransferConfig(controllers=(UNGATED,), tasks=("front", "left"), attempts=1, revisit=False, restarts=1, cap=100)


@pytest.fixture(scope="module")
def tiny_runs() -> dict[str, list[dict]]:
    cfg = TINY.to_dict()
    return {"paired": controller_job(cfg, UNGATED, None, paired=[GATED]),
            "alone": controller_job(cfg, UNGATED, None),
            "gated": controller_job(cfg, GATED, None)}


@pytest.mark.slow  # three tiny transfer runs (about 30 s)
def test_paired_episodes_change_nothing_in_the_learners_run(tiny_runs) -> None:
    paired, alone = tiny_runs["paired"], tiny_runs["alone"]
    assert [{k: v for k, v in a.items() if k not in ("paired", "fit_seconds")} for a in paired] == \
           [{k: v for k, v in a.items() if k != "fit_seconds"} for a in alone]
    assert all(set(a["paired"]) == {GATED} for a in paired)


@pytest.mark.slow  # three tiny transfer runs (about 30 s)
def test_a_paired_controller_equal_to_the_learner_gives_the_same_episode(tiny_runs) -> None:
    paired, gated = tiny_runs["paired"], tiny_runs["gated"]
    # Before any data both are the RBD feedforward: the same episode.
    assert paired[0]["paired"][GATED]["tracking_rmse"] == paired[0]["tracking_rmse"]
    # On task B the gated learner's model was fitted on the same data (task A's one attempt, run with RBD
    # feedforward) with the same seed as the ungated learner's: the gated episode on the ungated learner's
    # model is the gated learner's own episode.
    assert gated[1]["n_train"] == paired[1]["n_train"] > 0
    assert paired[1]["paired"][GATED]["tracking_rmse"] == gated[1]["tracking_rmse"]
    assert paired[1]["paired"][GATED]["tracking_rmse"] != paired[1]["tracking_rmse"]  # the gate does act


def _fake_results() -> dict:
    rng = np.random.default_rng(0)
    tasks = ["front", "left", "right"]

    def attempts(with_paired: bool) -> list[dict]:
        out = [{"task": t, "task_attempt": k, "phase": "train", "tracking_rmse": float(rng.uniform(0.05, 0.5))}
               for t in tasks for k in range(2)]
        out.append({"task": "front", "task_attempt": 2, "phase": "revisit", "tracking_rmse": 0.1})
        if with_paired:
            for a in out:
                a["paired"] = {p: {"tracking_rmse": float(rng.uniform(0.05, 0.5))} for p in gate_eval.PAIRED}
        return out

    runs = {str(s): {UNGATED: attempts(True), GATED: attempts(False), "rbd": attempts(False)} for s in (0, 1, 2)}
    return {"config": {"tasks": tasks, "attempts": 2, "seeds": [0, 1, 2], "payload_mass": 1.2}, "runs": runs}


def test_ratios_are_those_of_the_records_and_the_summary_their_quartiles() -> None:
    res = _fake_results()
    rows = ratios(res)
    run = res["runs"]["1"]
    last_left = next(a for a in run[UNGATED] if a["task"] == "left" and a["task_attempt"] == 1)
    row = next(r for r in rows if r["seed"] == 1 and r["task"] == "left" and r["quantity"] == "gate_same_model_last")
    assert row["ratio"] == last_left["paired"][GATED]["tracking_rmse"] / last_left["tracking_rmse"]
    first_right = next(a for a in run[GATED] if a["task"] == "right" and a["task_attempt"] == 0)
    rbd_right = next(a for a in run["rbd"] if a["task"] == "right" and a["task_attempt"] == 0)
    row = next(r for r in rows if r["seed"] == 1 and r["task"] == "right" and r["quantity"] == "gated_first_vs_rbd")
    assert row["ratio"] == first_right["tracking_rmse"] / rbd_right["tracking_rmse"]
    # No first-attempt-vs-RBD row for the first task (the model has seen nothing there).
    assert not any(r["task"] == "front" and r["quantity"].endswith("first_vs_rbd") for r in rows)
    summary = summarise(rows)
    vals = [r["ratio"] for r in rows if r["quantity"] == "gate_learners_last"]
    st = summary["gate_learners_last"]["all"]
    assert st["n"] == 9 and st["median"] == pytest.approx(np.median(vals))
    assert (st["q1"], st["q3"]) == pytest.approx(tuple(np.percentile(vals, [25, 75])))
    assert st["n_meeting"] == sum(v <= 1.10 for v in vals)
    assert summary["gate_learners_last"]["seen"]["n"] == 3 and summary["gate_learners_last"]["new"]["n"] == 6


def test_a_non_finite_rmse_gives_a_nan_ratio_that_the_summary_counts_apart() -> None:
    res = _fake_results()
    last_left = next(a for a in res["runs"]["2"][GATED] if a["task"] == "left" and a["task_attempt"] == 1)
    last_left["tracking_rmse"] = None  # what JSON makes of a NaN
    rows = ratios(res)
    bad = [r for r in rows if r["seed"] == 2 and r["task"] == "left" and r["quantity"] == "gate_learners_last"]
    assert len(bad) == 1 and np.isnan(bad[0]["ratio"])
    st = summarise(rows)["gate_learners_last"]["all"]
    assert st["n"] == 8 and st["n_nonfinite"] == 1 and np.isfinite(st["median"])
    text = gate_eval.summary_markdown({"config": res["config"], "summary": summarise(rows), "ratios": rows})
    assert "1 not finite" in text and "| nan |" in text


@pytest.mark.slow
def test_gate_eval_end_to_end_writes_its_outputs(tmp_path) -> None:
    cfg = replace(TINY, controllers=gate_eval.GATE_EVAL_CONFIG.controllers, revisit=True)
    res = run_gate_eval(tmp_path, cfg, (0,), workers=1, show_progress=False)
    for f in ("gate_eval.json", "gate_eval.md", "gate_eval.png"):
        assert (tmp_path / f).stat().st_size > 0
    assert {r["quantity"] for r in res["ratios"]} >= {"gate_learners_last", "gated_first_vs_rbd",
                                                      "online_first_same_model"}
    # Resumed from the cache: the same numbers.
    again = run_gate_eval(tmp_path, cfg, (0,), workers=1, show_progress=False)
    assert again["ratios"] == res["ratios"] and again["jobs"]["n_cached"] == 3
