"""Controller-level tests: the oracle pours, PD-only feedback at 40 Hz tracks clearly worse and spills.

The pour separation (payload 1.2 kg, seed 0) that ``scripts/pour_separation.py`` reports, run
through the same episode runner (``cascgp.episodes.run_episode``): the oracle pours >= 90% on
every default task, PD only < 30% on every task.
"""

from __future__ import annotations

import gymnasium as gym
import pytest

import jaco_env  # noqa: F401
from cascgp.episodes import run_episode
from jaco_env import scene
from jaco_env.oracle import OracleController, PDController
from jaco_env.tasks import DEFAULT_TASKS

PAYLOAD = 1.2


def _run(task: str, controller, n_marbles: int = 30, payload: float = PAYLOAD):
    env = gym.make("JacoPour-v0", n_marbles=n_marbles)
    try:
        return run_episode(env, controller, seed=0, options={"task": task, "payload_mass": payload})
    finally:
        env.close()


def test_oracle_pours_and_pd_spills_one_task():
    """Fast sibling of the slow per-task tests (fewer marbles, one task)."""
    ora = _run("front", OracleController(), n_marbles=12)
    pd = _run("front", PDController(), n_marbles=12)
    assert not ora.unstable and not pd.unstable
    assert ora.in_jar >= 0.9
    assert pd.tracking_rmse > 3 * ora.tracking_rmse
    assert pd.in_jar < 0.3


def test_oracle_follows_the_marbles():
    """Started on the env, the oracle lumps exactly the marbles in the bottle (all of them at reset)."""
    env = gym.make("JacoPour-v0", n_marbles=12)
    try:
        _, info = env.reset(seed=0, options={"task": "near", "payload_mass": PAYLOAD})
        u = env.unwrapped
        ctrl = OracleController()
        ctrl.start(u, info)
        ctrl.feedforward(*u.task.reference(0.0))
        b = ctrl.model.body(scene.PAYLOAD_BODY).id
        assert abs(ctrl.model.body_mass[b] - (PAYLOAD - scene.BOTTLE_MASS)) < 1e-9
        assert ctrl.model.body_ipos[b][2] > 0  # marbles above the payload body origin
    finally:
        env.close()


@pytest.mark.slow
@pytest.mark.parametrize("task", sorted(DEFAULT_TASKS))
def test_oracle_pours_and_pd_spills_every_default_task(task):
    ora = _run(task, OracleController())
    pd = _run(task, PDController())
    assert not ora.unstable and not pd.unstable
    assert ora.in_jar >= 0.9, ora.summary()
    assert pd.tracking_rmse > 3 * ora.tracking_rmse
    assert pd.in_jar < 0.3, pd.summary()
