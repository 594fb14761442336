"""Fast sibling of ``tests/test_task_transfer.py``: the task-transfer loop on a short seeded run (default suite).

Under the default sensing (``"jaco2"``), PD and the nominal RBD feedforward attempt tasks A and B once. The default
learning controller of the demo (SP inward cascade, innovation gate, learning online) attempts task A twice,
retrained after each attempt, then task B once: its first attempt there uses a model that has seen task A only.
About 45 s on one core.
The full run, with more attempts, the revisit and the paired gate comparisons, is under ``-m slow``.
"""

from __future__ import annotations

import numpy as np
import pytest

from cascgp.learning import run_controller
from cascgp_experiments.transfer import TransferConfig, jaco_feedback

TASK_A, TASK_B = "front", "left"
LEARNER = "sp-inward-igated-online"


@pytest.fixture(scope="module")
def runs():
    from jaco_env import nominal_urdf

    from cascgp.rbd import load_nominal

    # Under the default sensing (jaco2), where the bounds below were set: over seeds 0-7 and seed 0 under another
    # CPU's kernels (.ci/other_kernels) RBD's ratio to PD was 0.72-0.74, the learner's second attempt on task A
    # 0.27-0.60 of RBD's error and its first attempt on task B 0.15-0.47 (docs/studies/quick_transfer_spread.md,
    # its addendum). The learner's attempts move with the CPU's kernels as with the seed.
    cfg = TransferConfig(controllers=("pd", "rbd", LEARNER), tasks=(TASK_A, TASK_B), attempts=2,
                         payload_mass=1.2, seed=0, restarts=2, cap=300)
    env = cfg.make_env()
    rbd = load_nominal(nominal_urdf(env.unwrapped.link_inertials))
    try:
        once = [(TASK_A, 0, "eval"), (TASK_B, 0, "eval")]
        learn = [(TASK_A, 0, "train"), (TASK_A, 1, "train"), (TASK_B, 0, "train")]
        args = (rbd, jaco_feedback(), cfg.retrain())
        opts = cfg.reset_options()
        out = {name: run_controller(name, env, once, *args, reset_options=opts) for name in ("pd", "rbd")}
        out[LEARNER] = run_controller(LEARNER, env, learn, *args, reset_options=opts)
    finally:
        env.close()
    return {name: run.attempts for name, run in out.items()}


def _rmse(attempts: list[dict], task: str, k: int = 0) -> float:
    sel = [a for a in attempts if a["task"] == task and a["task_attempt"] == k]
    assert len(sel) == 1
    return float(sel[0]["tracking_rmse"])


@pytest.mark.parametrize("task", [TASK_A, TASK_B])
def test_rbd_feedforward_tracks_better_than_pd(runs, task):
    # RBD's RMSE is 0.72-0.74 of PD's on both tasks over nine draws; the bound 0.9 keeps a margin.
    assert _rmse(runs["rbd"], task) < 0.9 * _rmse(runs["pd"], task)


def test_first_attempt_without_data_is_the_nominal_model(runs):
    """Before any data an SP learner is its RBD mean: same seed and task as RBD's attempt, so the same episode."""
    assert _rmse(runs[LEARNER], TASK_A, 0) == _rmse(runs["rbd"], TASK_A)
    assert "online_samples" not in runs[LEARNER][0]


def test_one_retraining_beats_rbd_on_the_task_it_has_seen(runs):
    # 0.27-0.60 over nine draws; the study's rule: 0.60 x 1.25 (a learner that did not learn gives about 1)
    assert _rmse(runs[LEARNER], TASK_A, 1) < 0.75 * _rmse(runs["rbd"], TASK_A)


def test_first_attempt_on_a_new_task_beats_rbd(runs):
    """Task B's first attempt uses a model trained on task A only: it still tracks far better than RBD."""
    assert _rmse(runs[LEARNER], TASK_B, 0) < 0.5 * _rmse(runs["rbd"], TASK_B)


def test_the_learner_retrains_after_every_attempt_and_learns_online(runs):
    attempts = runs[LEARNER]
    assert [a["n_train"] > 0 for a in attempts] == [False, True, True]
    assert all(a["online_samples"] > 100 for a in attempts[1:])


def test_no_fallbacks_or_instability(runs):
    for attempts in runs.values():
        for a in attempts:
            assert a["n_fallbacks"] == 0 and not a["unstable"]
            assert np.isfinite(a["tracking_rmse"])


def test_transfer_config_sensor_pipeline():
    """The default is the real arm's pipeline; a bad name is refused naming the field (also by the command);
    a record from before the option was run under "ideal"."""
    from cascgp_experiments.cli.transfer import parse_args

    cfg = TransferConfig()
    assert cfg.sensor_pipeline == "jaco2"
    assert TransferConfig.from_dict(cfg.to_dict()) == cfg
    old = {k: v for k, v in cfg.to_dict().items() if k != "sensor_pipeline"}
    assert TransferConfig.from_dict(old).sensor_pipeline == "ideal"
    with pytest.raises(ValueError, match="sensor_pipeline: expected"):
        TransferConfig(sensor_pipeline="real")
    with pytest.raises(SystemExit):
        parse_args(["--out", "unused", "--sensor-pipeline", "real"])
    assert parse_args(["--out", "unused", "--sensor-pipeline", "ideal+torque"])[0].sensor_pipeline == "ideal+torque"
