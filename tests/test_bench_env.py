"""``scripts.bench_env``: its bare Gymnasium reference env runs the raw loop's physics, and one tiny run reports
every ratio."""

from __future__ import annotations

import math

import gymnasium as gym
import mujoco
import numpy as np

from scripts.bench_env import BareGymnasiumEnv, bench


def test_bare_gymnasium_env_steps_the_raw_loops_physics():
    env = gym.make("JacoPayload-v0")
    env.reset(seed=0)
    u = env.unwrapped
    bare = BareGymnasiumEnv.like(u)
    try:
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        state = np.empty(mujoco.mj_stateSize(u.model, spec))
        mujoco.mj_getState(u.model, u.data, state, spec)
        raw = mujoco.MjData(u.model)
        mujoco.mj_setState(u.model, raw, state, spec)
        mujoco.mj_setState(bare.model, bare.data, state, spec)
        tau = np.linspace(-2.0, 2.0, 6)
        raw.ctrl[:6] = tau
        for _ in range(5):
            obs, *_ = bare.step(tau)
            mujoco.mj_step(u.model, raw, nstep=u.frame_skip)
        np.testing.assert_array_equal(bare.data.qpos, raw.qpos)
        np.testing.assert_array_equal(bare.data.qvel, raw.qvel)
        np.testing.assert_array_equal(obs[:6], raw.qpos[u.arm_qpos_adr])
        assert obs.shape == bare.observation_space.shape == (6 + 6 + len(u._tau_sensor),)
    finally:
        bare.close()
        env.close()


def test_a_tiny_run_reports_every_ratio():
    r = bench("JacoPayload-v0", steps=20, rounds=1)
    for key in ("env_cost_over_raw", "env_cost_over_raw_cpu", "bare_gymnasium_cost_over_raw", "env_steps_per_s",
                "raw_steps_per_s", "bare_gymnasium_steps_per_s"):
        assert math.isfinite(r[key]) and r[key] > 0, key
    b = r["breakdown"]
    assert b["physics_us"] > 0 and b["end_of_period_evaluation_us"] > 0 and b["raw_period_us"] > 0
