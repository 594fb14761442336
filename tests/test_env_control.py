"""Controller-level tests: the oracle pours, PD-only feedback at 40 Hz tracks clearly worse and spills."""

from __future__ import annotations

import gymnasium as gym
import pytest

import jaco_env  # noqa: F401
from jaco_env import oracle
from jaco_env.tasks import DEFAULT_TASKS


def _run(task: str, factory, n_marbles: int = 20, payload: float = 1.2):
    env = gym.make("JacoPour-v0", n_marbles=n_marbles)
    try:
        return oracle.run_episode(env, factory, task=task, payload_mass=payload, seed=0)
    finally:
        env.close()


def test_oracle_pours_and_pd_is_worse_one_task():
    ora = _run("front", oracle.oracle_factory)
    pd = _run("front", oracle.pd_factory)
    assert not ora["unstable"] and not pd["unstable"]
    assert ora["in_jar"] >= 0.9
    assert pd["rmse"] > 3 * ora["rmse"]
    assert pd["in_jar"] < ora["in_jar"]


@pytest.mark.slow
@pytest.mark.parametrize("task", sorted(DEFAULT_TASKS))
def test_oracle_pours_every_default_task(task):
    ora = _run(task, oracle.oracle_factory, n_marbles=30)
    assert not ora["unstable"]
    assert ora["in_jar"] >= 0.9, ora


_PD_TASKS = [
    pytest.param(t, marks=pytest.mark.xfail(strict=True, reason="near: the folded arm sags mostly vertically "
                                            "(1.4 cm horizontal at the mouth), PD still pours into the jar"))
    if t == "near" else t
    for t in sorted(DEFAULT_TASKS)
]


@pytest.mark.slow
@pytest.mark.parametrize("task", _PD_TASKS)
def test_pd_only_clearly_worse(task):
    ora = _run(task, oracle.oracle_factory, n_marbles=30)
    pd = _run(task, oracle.pd_factory, n_marbles=30)
    assert pd["rmse"] > 3 * ora["rmse"]
    assert pd["in_jar"] <= ora["in_jar"] - 0.3
