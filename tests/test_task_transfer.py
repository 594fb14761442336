"""Policy evaluation of the task-transfer loop (cascgp.learning) on JacoPour-v0 (seeded; one shared run).

The shared run takes about 4 minutes on a 2-core machine, so the tests that use it are marked ``slow``
(``make test-slow``); ``tests/test_task_transfer_quick.py`` is their fast sibling in the default suite.

Two tasks in different parts of the workspace, payload unknown to every controller, under the env's default sensing
(``sensor_pipeline="jaco2"``: the real Jaco 2's signal, what users run):
- PD only and the nominal RBD feedforward attempt each task once;
- the SP inward cascade (the paper's), the gated one (the default gate, the innovation rule) and the gated one
  learning online each attempt task A four times (retrained after each attempt on all data so far), then task
  B four times, then revisit A once. All learners see the same seeds. After each attempt of the ungated
  cascade, the gated controller also runs on its model (paired: the gate's own effect, everything else equal).
"""

from __future__ import annotations

import numpy as np
import pytest

from cascgp.learning import make_controller, run_controller
from cascgp_experiments.run_hooks import PairedEpisodes
from cascgp_experiments.transfer import TransferConfig, jaco_feedback

TASK_A, TASK_B = "front", "left"
#: Revisit tolerance: the first attempt back on task A may be at most this much worse (relative)
#: than the last attempt there before, although the buffer now also holds task B and is thinned to the cap.
REVISIT_TOLERANCE = 0.15
#: The gate is the default rule, the innovation gate (docs/studies/gate_rule.md).
GATED = "sp-inward-igated"
LEARNERS = ("sp-inward", GATED, GATED + "-online")


@pytest.fixture(scope="module")
def runs():
    from jaco_env import nominal_urdf

    from cascgp.rbd import load_nominal

    cfg = TransferConfig(controllers=("pd", "rbd", "sp-inward"), tasks=(TASK_A, TASK_B), attempts=4,
                         payload_mass=1.2, seed=0, restarts=2, cap=400, sensor_pipeline="jaco2")
    env = cfg.make_env()
    rbd = load_nominal(nominal_urdf(env.unwrapped.link_inertials))
    once = [(TASK_A, 0, "eval"), (TASK_B, 0, "eval")]
    learn = ([(TASK_A, k, "train") for k in range(4)] + [(TASK_B, k, "train") for k in range(4)]
             + [(TASK_A, 4, "revisit")])
    args = (rbd, jaco_feedback(), cfg.retrain())
    opts = cfg.reset_options()
    out = {name: run_controller(name, env, once, *args, reset_options=opts) for name in ("pd", "rbd")}
    for name in LEARNERS:  # the ungated learner also runs the gated controller on its own model (paired)
        hooks = [PairedEpisodes(name, (GATED,), env, rbd, jaco_feedback())] if name == "sp-inward" else []
        out[name] = run_controller(name, env, learn, *args, reset_options=opts, hooks=hooks)
    env.close()
    return {name: run.attempts for name, run in out.items()}


_slow = pytest.mark.slow


def _rmse(attempts, task, k=None, phase=None):
    sel = [a for a in attempts if a["task"] == task and (k is None or a["task_attempt"] == k)
           and (phase is None or a["phase"] == phase)]
    assert len(sel) == 1
    return sel[0]["tracking_rmse"]


@_slow
@pytest.mark.parametrize("task", [TASK_A, TASK_B])
def test_rbd_feedforward_tracks_better_than_pd(runs, task):
    # Measured under the default sensing (seed 0, 1.2 kg): RBD's RMSE is 0.73 of PD's on both tasks (the
    # unmodelled payload torque on the softly held wrist dominates both); a margin of 10 % keeps the test meaningful.
    assert _rmse(runs["rbd"], task) < 0.9 * _rmse(runs["pd"], task)


@_slow
@pytest.mark.parametrize("task", [TASK_A, TASK_B])
def test_sp_inward_after_three_retrainings_beats_rbd(runs, task):
    # Attempt index 3 on a task runs the model retrained after that task's three earlier attempts.
    assert _rmse(runs["sp-inward"], task, k=3, phase="train") < _rmse(runs["rbd"], task)


@_slow
def test_learning_improves_over_the_first_attempt(runs):
    first = _rmse(runs["sp-inward"], TASK_A, k=0)
    assert _rmse(runs["sp-inward"], TASK_A, k=3) < 0.8 * first


@_slow
def test_revisit_is_as_good_as_the_last_attempt_before(runs):
    last = _rmse(runs["sp-inward"], TASK_A, k=3, phase="train")
    revisit = _rmse(runs["sp-inward"], TASK_A, phase="revisit")
    assert revisit <= (1.0 + REVISIT_TOLERANCE) * last


@_slow
def test_no_fallbacks_or_instability(runs):
    for attempts in runs.values():
        for a in attempts:
            assert a["n_fallbacks"] == 0 and not a["unstable"]
            assert np.isfinite(a["tracking_rmse"])


def test_unknown_controller_name_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown controller 'sp-sideways'"):
        make_controller("sp-sideways", rbd=None, model=None, feedback=jaco_feedback())


# ------------------------------------------------------------------ issue 10: gated and online feedforward
@_slow
@pytest.mark.parametrize("task", [TASK_A, TASK_B])
def test_gated_first_attempt_is_never_worse_than_rbd(runs, task):
    """On the first attempt of a task (task B: the model has seen only task A) the gated controller tracks
    at most 2 % worse than the nominal RBD feedforward."""
    assert _rmse(runs[GATED], task, k=0) <= 1.02 * _rmse(runs["rbd"], task)


@_slow
@pytest.mark.parametrize("task", [TASK_A, TASK_B])
def test_gated_still_learns(runs, task):
    """After three retrainings on a task the gated controller tracks far better than RBD (it learns)."""
    assert _rmse(runs[GATED], task, k=3) < 0.5 * _rmse(runs["rbd"], task)


@_slow
def test_gated_learner_tracks_about_as_well_as_the_ungated_after_three_attempts_on_the_first_task(runs):
    """The gated learner after three retrainings on task A at most 1.4x the ungated learner (a gate that fell back
    to RBD would be about 3x).

    Issue 10's criterion is 10 %, but one seed cannot decide a 10 % band between two learners that collect their
    own data: on "front", over seeds 20-27 under the idealised sensing, the innovation learner / ungated learner ratio
    was 1.069 in the median and 1.269 at worst, and two *ungated* learners that differ only in their fits' random
    starts (the null) 1.357 at worst (docs/studies/gate_rule.md). This seed gave 0.98 (0.140 vs 0.143 rad) under the
    default sensing. The paired test below checks the gate's own effect on one model, on both tasks."""
    assert _rmse(runs[GATED], TASK_A, k=3) <= 1.40 * _rmse(runs["sp-inward"], TASK_A, k=3)


@_slow
@pytest.mark.parametrize("task", [TASK_A, TASK_B])
def test_the_gate_on_the_same_model_costs_little_after_three_attempts(runs, task):
    """The gate's own effect: after three retrainings on a task, the gated controller on the ungated learner's
    model tracks at most 25 % worse than that learner (a gate that fell back to RBD would cost about 3x).

    Issue 10's criterion is 10 %, but one seed cannot decide a 10 % band: over seeds 20-27 under the idealised
    sensing the innovation gate on its learner's own model after three attempts gave 0.88-1.13 on "front" and "left",
    2 of 16 above 1.10 (docs/studies/gate_rule_innovation.json); the 10 % held in the median (1.02). This seed gives
    0.91 on task A and 0.86 on task B under the default sensing."""
    ungated = [a for a in runs["sp-inward"] if a["task"] == task and a["task_attempt"] == 3][0]
    assert ungated["paired"][GATED]["tracking_rmse"] <= 1.25 * ungated["tracking_rmse"]


@_slow
def test_online_learning_lowers_the_first_attempt_on_a_new_task(runs):
    """Task B's first attempt: learning inside the episode beats offline-only (same gate, same seeds)."""
    online = [a for a in runs[GATED + "-online"] if a["task"] == TASK_B and a["task_attempt"] == 0][0]
    assert online["online_samples"] > 100
    assert _rmse(runs[GATED + "-online"], TASK_B, k=0) < _rmse(runs[GATED], TASK_B, k=0)


def test_controller_variants_parse_and_refuse_nonsense():
    from cascgp.learning import parse_controller

    assert parse_controller("sp-inward-gated-online") == ("sp-inward", "wiener", True)
    assert parse_controller("np-outward-df-vgated") == ("np-outward-df", "variance", False)
    assert parse_controller("sp-inward-fgated-online") == ("sp-inward", "floor", True)
    assert parse_controller("np-inward-igated") == ("np-inward", "innovation", False)
    assert parse_controller("sp-standard") == ("sp-standard", None, False)
    for bad in ("rbd-gated", "pd-online", "sp-inward-online-gated", "np-inward-df-online", "np-inward-fgated",
                "rbd-fgated", "np-inward-df-igated"):
        with pytest.raises(ValueError, match="unknown controller"):
            parse_controller(bad)

