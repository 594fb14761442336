"""Controller-level tests: the oracle pours, PD-only feedback at 40 Hz tracks clearly worse and spills.

The pour separation (payload 1.2 kg, seed 0) that ``scripts/pour_separation.py`` reports:
the oracle pours >= 90% on every default task, PD only < 30% on every task.
"""

from __future__ import annotations

import gymnasium as gym
import pytest

import jaco_env  # noqa: F401
from jaco_env import oracle, scene
from jaco_env.tasks import DEFAULT_TASKS

PAYLOAD = 1.2


def _run(task: str, factory, n_marbles: int = 30, payload: float = PAYLOAD):
    env = gym.make("JacoPour-v0", n_marbles=n_marbles)
    try:
        return oracle.run_episode(env, factory, task=task, payload_mass=payload, seed=0)
    finally:
        env.close()


def test_oracle_pours_and_pd_spills_one_task():
    """Fast sibling of the slow per-task tests (fewer marbles, one task)."""
    ora = _run("front", oracle.oracle_factory, n_marbles=12)
    pd = _run("front", oracle.pd_factory, n_marbles=12)
    assert not ora["unstable"] and not pd["unstable"]
    assert ora["in_jar"] >= 0.9
    assert pd["rmse"] > 3 * ora["rmse"]
    assert pd["in_jar"] < 0.3


def test_oracle_binds_to_marbles():
    """Bound to the env, the oracle lumps exactly the marbles in the bottle (all of them at reset)."""
    env = gym.make("JacoPour-v0", n_marbles=12)
    try:
        _, info = env.reset(seed=0, options={"task": "near", "payload_mass": PAYLOAD})
        u = env.unwrapped
        ctrl = oracle.OracleController(u.task, PAYLOAD, 12).bind(u)
        ctrl.feedforward(*u.task.reference(0.0))
        b = ctrl.model.body(oracle._PAYLOAD_BODY).id
        assert abs(ctrl.model.body_mass[b] - (PAYLOAD - scene.BOTTLE_MASS)) < 1e-9
        assert ctrl.model.body_ipos[b][2] > 0  # marbles above the payload body origin
    finally:
        env.close()


@pytest.mark.slow
@pytest.mark.parametrize("task", sorted(DEFAULT_TASKS))
def test_oracle_pours_and_pd_spills_every_default_task(task):
    ora = _run(task, oracle.oracle_factory)
    pd = _run(task, oracle.pd_factory)
    assert not ora["unstable"] and not pd["unstable"]
    assert ora["in_jar"] >= 0.9, ora
    assert pd["rmse"] > 3 * ora["rmse"]
    assert pd["in_jar"] < 0.3, pd
