"""The env's control period is MuJoCo's, bit for bit (jaco_env.envs.base.JacoMujocoEnv._simulate).

The step reuses the position and velocity stages of its sensing evaluation (``mj_forward`` at the
end of a period) for the next period's first physics step (``mj_step2`` alone). These tests replay
every step on a second ``MjData`` with the plain sequence ``mj_step(nstep=frame_skip)`` then
``mj_forward`` and require the same state, accelerations and sensor readings, bit for bit; also
when the state is changed between steps, and for the observation (noise off).
"""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import jaco_env  # noqa: F401
from jaco_env.sensors import OBS_Q, OBS_QD, OBS_TAU

SPEC = mujoco.mjtState.mjSTATE_INTEGRATION  # the whole state, warm start and controls included


def _twin(u) -> mujoco.MjData:
    """A second MjData of the env's model in the env's exact current state."""
    state = np.empty(mujoco.mj_stateSize(u.model, SPEC))
    mujoco.mj_getState(u.model, u.data, state, SPEC)
    d = mujoco.MjData(u.model)
    mujoco.mj_setState(u.model, d, state, SPEC)
    mujoco.mj_forward(u.model, d)
    return d


def _raw_period(u, d: mujoco.MjData, a: np.ndarray) -> None:
    """One control period as the env did before reusing its evaluation: mj_step, then mj_forward."""
    a = np.clip(a, u.action_space.low, u.action_space.high)
    d.ctrl[:6] = a
    if u.control_mode == "velocity":
        d.ctrl[6:12] = a
    mujoco.mj_step(u.model, d, nstep=u.frame_skip)
    mujoco.mj_forward(u.model, d)


def _assert_same(u, d: mujoco.MjData, obs: np.ndarray) -> None:
    for name in ("qpos", "qvel", "act", "qacc", "qacc_warmstart", "sensordata", "xpos", "xmat"):
        assert np.array_equal(getattr(u.data, name), getattr(d, name)), name
    assert u.data.time == d.time
    assert np.array_equal(obs[OBS_Q], d.qpos[u.arm_qpos_adr])
    assert np.array_equal(obs[OBS_QD], d.qvel[u.arm_dof_adr])
    assert np.array_equal(obs[OBS_TAU], d.sensordata[u._tau_sensor])


@pytest.mark.parametrize("env_id", ["JacoPayload-v0", "JacoPour-v0"])
@pytest.mark.parametrize("mode", ["torque", "velocity"])
def test_steps_equal_mj_step_then_mj_forward(env_id: str, mode: str) -> None:
    env = gym.make(env_id, control_mode=mode, sensor_noise=None, sensor_pipeline="ideal")
    try:
        env.reset(seed=3)
        u = env.unwrapped
        d = _twin(u)
        rng = np.random.default_rng(5)
        lim = env.action_space.high
        for _ in range(25):
            a = 0.3 * lim * rng.uniform(-1, 1, 6)
            obs, *_ = env.step(a)
            _raw_period(u, d, a)
            _assert_same(u, d, obs)
    finally:
        env.close()


@pytest.mark.parametrize("env_id", ["JacoPayload-v0", "JacoPour-v0"])
def test_state_changed_between_steps_is_stepped_from_scratch(env_id: str) -> None:
    env = gym.make(env_id, sensor_noise=None, sensor_pipeline="ideal")
    try:
        env.reset(seed=1)
        u = env.unwrapped
        d = _twin(u)
        a = np.full(6, 0.5)
        for k in range(12):
            if k in (3, 7):  # a push behind the env's back (no mj_forward): it must take effect in full
                u.data.qvel[u.arm_dof_adr[1]] += 0.25
                d.qvel[u.arm_dof_adr[1]] += 0.25
            if k == 9:  # MujocoEnv.set_state (which calls mj_forward)
                qpos, qvel = u.data.qpos.copy(), u.data.qvel.copy()
                qvel[u.arm_dof_adr[0]] -= 0.1
                u.set_state(qpos, qvel)
                d.qvel[:] = qvel
                mujoco.mj_forward(u.model, d)
            obs, *_ = env.step(a)
            _raw_period(u, d, a)
            _assert_same(u, d, obs)
    finally:
        env.close()
