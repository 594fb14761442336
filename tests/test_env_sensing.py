"""Link-side joint torque sensing and the emulated firmware torque loop (jaco_env.robot).

References are computed independently of the env's sensor path: MuJoCo's own inverse dynamics
(``mj_inverse``) of the same scene and state with the joint-level terms (rotor inertia, gear
friction, damping) removed, i.e. the torque the links need.
"""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import jaco_env
from jaco_env import excitation, robot, scene
from jaco_env.tasks import DEFAULT_TASKS


def link_side_torque(u) -> np.ndarray:
    """mj_inverse of the env's current state without armature, frictionloss and damping."""
    m = u.model
    saved = m.dof_armature.copy(), m.dof_frictionloss.copy(), m.dof_damping.copy()
    try:
        m.dof_armature[:] = 0.0
        m.dof_frictionloss[:] = 0.0
        m.dof_damping[:] = 0.0
        d = mujoco.MjData(m)
        d.qpos[:], d.qvel[:], d.qacc[:], d.act[:] = u.data.qpos, u.data.qvel, u.data.qacc, u.data.act
        mujoco.mj_inverse(m, d)
        return d.qfrc_inverse[u.arm_dof_adr].copy()
    finally:
        m.dof_armature[:], m.dof_frictionloss[:], m.dof_damping[:] = saved


def _run(env, policy, n, check):
    obs, _ = env.reset(seed=3)
    u = env.unwrapped
    meas, ref = [], []
    for k in range(n):
        obs, _, term, trunc, info = env.step(policy(k, obs, u))
        assert not info.get("unstable", False)
        meas.append(jaco_env.split_obs(obs)[2])
        ref.append(link_side_torque(u))
        if term or trunc:
            break
    meas, ref = np.array(meas), np.array(ref)
    spread = meas.std(axis=0)
    check(meas, ref, spread)
    return meas


def _within_one_percent(meas, ref, spread):
    err = np.abs(meas - ref).max(axis=0)
    assert np.all(err <= 0.01 * spread), (err, spread)


@pytest.mark.parametrize("seed", [1, 2])
def test_payload_velocity_mode_measures_link_side_torque(seed):
    """Noise off: measured torque = link-side torque of the same state (sum-of-sinusoids motions)."""
    env = gym.make("JacoPayload-v0", control_mode="velocity", sensor_noise=None, control_freq=100.0,
                   max_episode_steps=10**6, sensor_pipeline="ideal")
    cmd = excitation.make_command(seed=seed)
    _run(env, lambda k, obs, u: cmd(k * u.control_dt), 250, _within_one_percent)
    env.close()


@pytest.mark.parametrize("payload, link_inertials", [(0.4, "dm_control"), (1.5, "dm_control"), (1.0, "kinova")])
def test_payload_torque_mode_measures_link_side_torque(payload, link_inertials):
    """Torque mode, other poses/payloads and both link-inertial sets: a PD torque around a drifting pose."""
    env = gym.make("JacoPayload-v0", sensor_noise=None, payload_mass=payload, link_inertials=link_inertials,
                   sensor_pipeline="ideal")
    q0 = DEFAULT_TASKS["left"].reference(4.0)[0]

    def pd(k, obs, u):
        q_d = q0 + 0.3 * np.sin(0.2 * k + np.arange(6))
        q, qd, _, _ = jaco_env.split_obs(obs)
        return jaco_env.DEFAULT_KP * (q_d - q) - jaco_env.DEFAULT_KD * qd

    _run(env, pd, 80, _within_one_percent)
    env.close()


def test_pour_env_measures_link_side_torque_with_marbles():
    """JacoPour-v0 while pouring (marble contacts on the bottle are part of the link torque)."""
    from jaco_env.oracle import OracleController

    env = gym.make("JacoPour-v0", sensor_noise=None, n_marbles=10, task="near", sensor_pipeline="ideal")
    obs, info = env.reset(seed=0, options={"payload_mass": 1.0})
    u = env.unwrapped
    ctrl = OracleController()
    ctrl.start(u, info)
    meas, ref = [], []
    t0, t1 = u.task.pour_window
    while True:
        q, qd, _, t = jaco_env.split_obs(obs)
        obs, _, term, trunc, info = env.step(ctrl(t, q, qd, u.task.reference))
        if t0 - 0.5 <= info["time"] <= t1:
            meas.append(jaco_env.split_obs(obs)[2])
            ref.append(link_side_torque(u))
        if term or trunc or info["time"] > t1:
            break
    meas, ref = np.array(meas), np.array(ref)
    assert len(meas) > 20
    _within_one_percent(meas, ref, meas.std(axis=0))
    env.close()


def test_torque_loop_residual():
    """Torque mode: the link torque follows the loop's output up to the documented residual, and
    the loop's output follows the command with the documented first-order lag."""
    env = gym.make("JacoPayload-v0", sensor_noise=None, sensor_pipeline="ideal")
    env.reset(seed=0)
    u = env.unwrapped
    d = u.data
    rng = np.random.default_rng(0)
    tau_prev = np.zeros(6)
    act_prev = d.act[:6].copy()
    for _ in range(60):
        g = d.qfrc_bias[u.arm_dof_adr].copy()
        cmd = np.clip(g + rng.normal(0, 0.03, 6) * robot.TORQUE_LIMITS, -robot.TORQUE_LIMITS, robot.TORQUE_LIMITS)
        obs, *_ = env.step(cmd)
        _, qd, tau_s, _ = jaco_env.split_obs(obs)
        qdd = d.qacc[u.arm_dof_adr]
        delivered = d.actuator_force[:6]
        # Residual: tau_delivered - tau_link = J_res qdd + b_res qd + dry friction (|.| <= FRICTIONLOSS).
        fric = delivered - tau_s - robot.ARMATURE * qdd - robot.DAMPING * qd
        # (MuJoCo's soft friction constraint may exceed frictionloss by a fraction of a percent.)
        assert np.all(np.abs(fric) <= 1.005 * robot.FRICTIONLOSS + 1e-6), fric
        # Lag: over one control period the delivered torque moves toward the held command by
        # 1 - exp(-dt / TORQUE_LOOP_TAU).
        a = np.exp(-u.control_dt / robot.TORQUE_LOOP_TAU)
        assert np.allclose(delivered, cmd + (act_prev - cmd) * a, atol=1e-6)
        act_prev = delivered.copy()
        tau_prev = tau_s
    assert np.all(np.isfinite(tau_prev))
    env.close()


def test_loop_parameters_follow_their_derivation():
    np.testing.assert_allclose(robot.ROTOR_INERTIA, robot.MOTOR_INERTIA * robot.GEAR_RATIO**2)
    k = 1.0 + robot.TORQUE_LOOP_GAIN
    np.testing.assert_allclose(robot.ARMATURE * k, robot.ROTOR_INERTIA)
    np.testing.assert_allclose(robot.FRICTIONLOSS * k, robot.GEAR_FRICTION)
    np.testing.assert_allclose(robot.DAMPING * k, robot.GEAR_DAMPING)
    # The compiled scene carries the residual values on the arm joints.
    env = gym.make("JacoPayload-v0")
    u = env.unwrapped
    np.testing.assert_allclose(u.model.dof_armature[u.arm_dof_adr], robot.ARMATURE)
    np.testing.assert_allclose(u.model.dof_frictionloss[u.arm_dof_adr], robot.FRICTIONLOSS)
    env.close()
    # The design inertia is the links' joint-space inertia at home with a 1 kg payload (two digits).
    from jaco_env.kinematics import home_pose

    m = mujoco.MjModel.from_xml_string(*(lambda r: (r.to_xml_string(), r.get_assets()))(
        scene.build_scene(kind="payload", control_mode=None)))
    m.dof_armature[:] = 0.0
    m.body_mass[m.body(scene.PAYLOAD_BODY).id] = 1.0
    d = mujoco.MjData(m)
    d.qpos[:6] = home_pose()
    mujoco.mj_forward(m, d)
    M = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M)
    np.testing.assert_allclose(robot.DESIGN_INERTIA - robot.ARMATURE, np.diag(M)[:6], rtol=0.03)
    # Gains: designed natural frequencies and damping.
    from jaco_env import gains

    I = robot.DESIGN_INERTIA
    np.testing.assert_allclose(np.sqrt(gains.DEFAULT_KP / I), gains.NATURAL_FREQUENCY)
    np.testing.assert_allclose(gains.DEFAULT_KD / (2 * np.sqrt(gains.DEFAULT_KP * I)), gains.DAMPING_RATIO)
    np.testing.assert_allclose(np.sqrt(scene.FIRMWARE_KI / I), 15.0)
