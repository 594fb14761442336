"""API-level tests of JacoPour-v0 / JacoPayload-v0: checker, rendering, determinism, pickling, bad input."""

from __future__ import annotations

import pickle
import warnings

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import jaco_env
from jaco_env import robot, scene
from jaco_env.envs import JacoPayloadEnv, JacoPourEnv
from jaco_env.excitation import JOINT_RANGES, SumOfSinusoids
from jaco_env.kinematics import home_pose
from jaco_env.tasks import DEFAULT_TASKS, PouringTask


@pytest.fixture(scope="module")
def pour_env():
    env = gym.make("JacoPour-v0", n_marbles=20)
    yield env
    env.close()


def test_dm_control_composes_and_mujoco_simulates():
    assert mujoco.__version__.startswith("3.17")
    root = scene.build_scene(kind="pour", n_marbles=20, control_mode="torque", timestep=0.002)
    m = scene.compile_model(root)
    d = mujoco.MjData(m)
    names = [m.joint(i).name for i in range(m.njnt)]
    assert names[:6] == [f"jaco_arm/joint_{i}" for i in range(1, 7)]
    assert m.nu == 6 and m.opt.timestep <= 0.002
    assert np.allclose(m.actuator_ctrlrange[:, 1], robot.TORQUE_LIMITS)
    d.qpos[:6] = home_pose()
    mujoco.mj_step(m, d, nstep=50)
    assert np.all(np.isfinite(d.qpos)) and d.time > 0.09


@pytest.mark.parametrize("env_id", ["JacoPour-v0", "JacoPayload-v0"])
def test_check_env(env_id):
    env = gym.make(env_id)
    check_env(env.unwrapped, skip_render_check=True)
    env.close()


def test_make_with_module_prefix_and_spaces():
    env = gym.make("jaco_env:JacoPayload-v0", control_mode="velocity")
    assert env.observation_space.shape == (19,)
    assert np.allclose(env.action_space.high, robot.VELOCITY_LIMITS)
    assert env.unwrapped.control_dt == pytest.approx(0.025)
    assert env.unwrapped.model.opt.timestep <= 0.002
    env.close()


def test_rgb_array_render_headless():
    env = gym.make("JacoPour-v0", render_mode="rgb_array", width=160, height=120, n_marbles=20)
    env.reset(seed=0, options={"task": "front"})
    img = env.render()
    env.close()
    assert img.shape == (120, 160, 3) and img.dtype == np.uint8
    assert img.std() > 5.0  # not blank


def _rollout(seed: int, n: int = 25) -> np.ndarray:
    env = gym.make("JacoPour-v0", n_marbles=20)
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(1)
    out = [obs]
    for _ in range(n):
        obs, *_ = env.step(rng.uniform(-5, 5, 6))
        out.append(obs)
    env.close()
    return np.array(out)


def test_same_seed_bit_identical():
    a, b = _rollout(7), _rollout(7)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, _rollout(8))


def test_pickle_and_async_vector_env():
    env = JacoPayloadEnv(payload_mass=0.5)
    env2 = pickle.loads(pickle.dumps(env))
    assert env2.default_payload == 0.5
    o1, _ = env.reset(seed=3)
    o2, _ = env2.reset(seed=3)
    assert np.array_equal(o1, o2)
    venv = gym.make_vec("JacoPour-v0", num_envs=2, vectorization_mode="async", n_marbles=20)
    obs, info = venv.reset(seed=[0, 1])
    assert obs.shape == (2, 22)
    obs, r, term, trunc, info = venv.step(np.zeros((2, 6), dtype=np.float32))
    assert obs.shape == (2, 22) and np.all(np.isfinite(obs)) and "payload_mass" in info
    venv.close()


def test_info_keys_reward_sum_and_noise(pour_env):
    obs, info = pour_env.reset(seed=0, options={"task": "left", "payload_mass": 1.0})
    assert info["payload_mass"] == 1.0 and info["task"] == "left"
    assert np.allclose(obs[jaco_env.OBS_JAR], DEFAULT_TASKS["left"].jar_pos)
    q0 = DEFAULT_TASKS["left"].reference(0.0)[0]
    assert 0 < np.max(np.abs(jaco_env.split_obs(obs)[0] - q0)) < 5e-3  # noisy but close
    obs, r, term, trunc, info = pour_env.step(np.zeros(6))
    for k in ("time", "payload_mass", "marbles_in_jar", "marbles_spilled", "n_marbles", "tracking_error",
              "reward_tracking", "reward_pour", "unstable"):
        assert k in info
    assert r == pytest.approx(info["reward_tracking"] + info["reward_pour"])
    assert info["time"] == pytest.approx(0.025) and jaco_env.split_obs(obs)[3] == pytest.approx(0.025)
    assert not term and not trunc


def test_split_obs_is_the_observation_layout():
    # The idealised signal: the measurements differ from the true state by the sensor noise alone.
    pour_env = gym.make("JacoPour-v0", n_marbles=20, sensor_pipeline="ideal")
    obs, info = pour_env.reset(seed=0, options={"task": "left", "payload_mass": 1.0})
    obs, *_ = pour_env.step(np.zeros(6))
    q, qd, tau, t = jaco_env.split_obs(obs)
    assert q.shape == qd.shape == tau.shape == (robot.N_JOINTS,) and t == pytest.approx(0.025)
    assert obs.shape == (jaco_env.POUR_OBS_DIM,) and jaco_env.MEASUREMENT_DIM == jaco_env.OBS_TIME + 1
    q_true, qd_true = pour_env.unwrapped.arm_state()
    assert np.max(np.abs(q - q_true)) < 5e-3 and np.max(np.abs(qd - qd_true)) < 5e-2  # noisy measurements
    batch = np.stack([obs, obs])
    assert jaco_env.split_obs(batch)[2].shape == (2, robot.N_JOINTS)
    with pytest.raises(ValueError, match="at least"):
        jaco_env.split_obs(obs[:10])
    pour_env.close()


def test_reward_weights_are_constructor_arguments():
    env = JacoPourEnv(n_marbles=10, tracking_cost_weight=2.0, pour_reward_weight=0.0)
    env2 = pickle.loads(pickle.dumps(env))  # EzPickle carries the weights
    for e in (env, env2):
        e.reset(seed=0, options={"task": "front"})
        _, r, _, _, info = e.step(np.full(6, 1.0))
        assert info["reward_tracking"] == pytest.approx(-2.0 * e.control_dt * info["tracking_error"])
        assert info["reward_pour"] == 0.0 and r == info["reward_tracking"]
    with pytest.raises(ValueError, match="tracking_cost_weight"):
        JacoPourEnv(n_marbles=10, tracking_cost_weight=-1.0)


def test_payload_drawn_within_range(pour_env):
    masses = {pour_env.reset(seed=s)[1]["payload_mass"] for s in range(4)}
    assert len(masses) == 4
    assert all(0.6 <= m <= 1.5 for m in masses)


@pytest.mark.parametrize(
    "action, exc, match",
    [
        (np.array([0, 0, np.nan, 0, 0, 0]), ValueError, "finite"),
        (np.array([0, 0, 0, np.inf, 0, 0]), ValueError, "finite"),
        (np.array([np.inf, 0, -np.inf, 0, 0, 0]), ValueError, "finite"),  # a sum of them is NaN: no warning
        (np.array([-np.inf, np.inf, 0, 0, 0, 0], np.float32), ValueError, "finite"),
        (np.zeros(5), ValueError, r"shape \(6,\)"),
        (np.zeros((2, 6)), ValueError, r"shape \(6,\)"),
        ("torque", TypeError, "action must be an array"),
    ],
)
def test_bad_action_leaves_state_untouched(pour_env, action, exc, match):
    pour_env.reset(seed=0, options={"task": "front"})
    u = pour_env.unwrapped
    qpos, qvel, t = u.data.qpos.copy(), u.data.qvel.copy(), u.data.time
    with pytest.raises(exc, match=match), warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # the error alone, no NumPy warning before it
        pour_env.step(action)
    assert np.array_equal(qpos, u.data.qpos) and np.array_equal(qvel, u.data.qvel) and t == u.data.time


@pytest.mark.parametrize("big", [1e3, 1e200, np.finfo(np.float64).max])
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_out_of_range_action_is_clipped(big, dtype):
    env = gym.make("JacoPour-v0", n_marbles=20, sensor_noise=None)
    env.reset(seed=0, options={"task": "front"})
    action = np.full(6, min(big, float(np.finfo(dtype).max)), dtype=dtype)
    action[1] *= -1
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a huge finite action is clipped without an overflow warning
        env.step(action)
    u = env.unwrapped
    sign = np.array([1, -1, 1, 1, 1, 1])
    assert np.allclose(u.data.ctrl[:6], sign * robot.TORQUE_LIMITS)
    # The torque loop delivers the clipped command after its first-order lag (from 0 at reset).
    lag = 1.0 - np.exp(-u.control_dt / robot.TORQUE_LOOP_TAU)
    assert np.allclose(u.data.actuator_force[:6], sign * robot.TORQUE_LIMITS * lag)
    env.close()


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_tiny_action_passes_under_strict_floating_point_errors(pour_env, dtype):
    """The action check neither overflows nor underflows for ordinary finite actions (1e-9 N m here)."""
    pour_env.reset(seed=0, options={"task": "front"})
    with np.errstate(all="raise"):
        pour_env.step(np.full(6, 1e-9, dtype=dtype))
    np.testing.assert_allclose(pour_env.unwrapped.data.ctrl[:6], np.full(6, 1e-9), rtol=1e-6)


@pytest.mark.parametrize(
    "options, exc, match",
    [
        ({"task": "moon"}, ValueError, "unknown task 'moon'"),
        ({"task": 3}, TypeError, "task must be"),
        ({"payload_mass": 2.5}, ValueError, "payload_mass"),
        ({"payload_mass": 5.0}, ValueError, "payload_mass"),
        ({"payload_mass": "heavy"}, TypeError, "payload_mass"),
        ({"payload_mass": "1.2"}, TypeError, "payload_mass"),
        ({"payload_mass": True}, TypeError, "payload_mass"),
        ({"colour": "red"}, ValueError, "unknown reset option"),
    ],
)
def test_bad_reset_options(pour_env, options, exc, match):
    pour_env.reset(seed=0, options={"task": "front"})
    pour_env.step(np.zeros(6))
    u = pour_env.unwrapped
    qpos, mass = u.data.qpos.copy(), u.payload_mass
    with pytest.raises(exc, match=match):
        pour_env.reset(seed=0, options=options)
    # Options are checked before the simulation is touched.
    assert np.array_equal(qpos, u.data.qpos) and u.payload_mass == mass


@pytest.mark.parametrize("env_id", ["JacoPour-v0", "JacoPayload-v0"])
def test_a_changed_observation_changes_nothing_the_env_returns_later(env_id):
    """``reset`` (both envs) and ``JacoPour-v0``'s ``step`` returned the env's own array: a caller that normalised it
    in place changed the last finite observation that an unstable step returns."""
    env = gym.make(env_id, **({"n_marbles": 5} if env_id == "JacoPour-v0" else {}))
    try:
        for n_steps in (0, 2):  # the reset observation, then a step's
            obs, _ = env.reset(seed=0)
            for _ in range(n_steps):
                obs, *_ = env.step(np.full(6, 2.0))
            kept = obs.copy()
            obs *= 0.0
            u = env.unwrapped
            u.data.qvel[u.arm_dof_adr] = 1e6
            unstable_obs, _, _, truncated, info = env.step(np.zeros(6))
            assert truncated and info["unstable"]
            np.testing.assert_array_equal(unstable_obs, kept)
    finally:
        env.close()


@pytest.mark.parametrize("freq", [8.5, 19.5, 49.5])
def test_a_half_integer_control_freq_builds(freq):
    """MujocoEnv asserts render_fps == round(1 / dt); at these frequencies dt rounds to the other side of the half
    (19.5 Hz: 20), and the env raised a bare AssertionError."""
    env = JacoPayloadEnv(control_freq=freq)
    try:
        assert env.metadata["render_fps"] == int(np.round(1.0 / env.dt)) and abs(env.dt - 1.0 / freq) < 1e-12
    finally:
        env.close()


def test_reset_options_with_keys_of_several_types_are_refused_by_name(pour_env):
    with pytest.raises(ValueError, match=r"unknown reset option\(s\) \['colour', 1\]"):
        pour_env.reset(seed=0, options={1: 2, "colour": 3, "task": "front"})


def test_bad_constructor_arguments():
    with pytest.raises(ValueError, match="control_mode"):
        JacoPayloadEnv(control_mode="position")
    with pytest.raises(ValueError, match="control_freq"):
        JacoPayloadEnv(control_freq=0.0)
    with pytest.raises(ValueError, match="payload_mass"):
        JacoPayloadEnv(payload_mass=1.7)
    with pytest.raises(ValueError, match="jar_pos"):
        PouringTask("x", jar_pos=[0.5, 0.0])


def test_jar_must_stand_clear_of_the_base_and_on_the_table(pour_env):
    """A task's jar inside the robot's base or sunk into the table is refused, naming jar_pos; the clearance is
    the base mesh's extent plus the jar's outer radius."""
    model = pour_env.unwrapped.model
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    g = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "jaco_arm/base")
    mesh = model.geom_dataid[g]
    verts = model.mesh_vert[model.mesh_vertadr[mesh]:model.mesh_vertadr[mesh] + model.mesh_vertnum[mesh]]
    world = verts @ data.geom_xmat[g].reshape(3, 3).T + data.geom_xpos[g]
    reach = np.hypot(world[:, 0], world[:, 1]).max()
    assert 0.9 * scene.BASE_RADIUS < reach <= scene.BASE_RADIUS
    clearance = scene.BASE_RADIUS + scene.JAR_INNER_RADIUS + scene.JAR_WALL
    for pos in ([0.0, 0.0, 0.0], [0.05, 0.02, 0.0], [0.0, -0.99 * clearance, 0.1]):
        with pytest.raises(ValueError, match="jar_pos.*inside the robot's base"):
            PouringTask("x", jar_pos=pos)
    with pytest.raises(ValueError, match="jar_pos.*table top"):
        PouringTask("x", jar_pos=[0.5, 0.0, -0.01])
    assert PouringTask("x", jar_pos=[0.0, 1.01 * clearance, 0.0]).jar_pos[1] > clearance
    with pytest.raises(ValueError, match="inside the robot's base"):
        DEFAULT_TASKS["front"].replace(jar_pos=np.array([0.06, 0.0, 0.0]))


def test_unstable_simulation_truncates_without_nan(pour_env):
    obs0, _ = pour_env.reset(seed=0, options={"task": "front"})
    u = pour_env.unwrapped
    u.data.qvel[u.arm_dof_adr] = 1e6
    obs, r, term, trunc, info = pour_env.step(np.zeros(6))
    assert trunc and info["unstable"] and np.all(np.isfinite(obs)) and np.isfinite(r)


@pytest.mark.parametrize("env_id", ["JacoPour-v0", "JacoPayload-v0"])
def test_an_unstable_step_reports_the_last_finite_state(env_id):
    """The unstable step returns the last finite observation with that step's time and, for the pour, its tracking
    error, marble counts and tracking cost as the reward (a reward of 0 there paid a learner to go unstable); a step
    after it returns the same and warns once per episode."""
    env = gym.make(env_id, **({"n_marbles": 5} if env_id == "JacoPour-v0" else {}))
    try:
        for _ in range(2):  # the second episode warns again
            _check_unstable_episode(env, env_id)
    finally:
        env.close()


def _check_unstable_episode(env, env_id):
    env.reset(seed=0)
    for _ in range(3):
        last_obs, last_r, _, _, last = env.step(np.full(6, 2.0))
    u = env.unwrapped
    u.data.qvel[u.arm_dof_adr] = 1e6
    for n in range(3):  # the unstable step, a step after it (warned) and one more (not warned again)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            obs, r, term, trunc, info = env.step(np.zeros(6))
        warned = [str(w.message) for w in caught if "unstable simulation" in str(w.message)]
        assert len(warned) == (n == 1) and all("Call 'reset()'" in w for w in warned)
        assert trunc and not term and info["unstable"]
        np.testing.assert_array_equal(obs, last_obs)
        assert info["time"] == last["time"] == obs[jaco_env.OBS_TIME]
        if env_id == "JacoPour-v0":
            assert info["tracking_error"] == last["tracking_error"] > 0
            assert r == info["reward_tracking"] == last["reward_tracking"] < 0 and info["reward_pour"] == 0
            for key in ("marbles_in_jar", "marbles_in_bottle", "marbles_spilled"):
                assert info[key] == last[key]
        else:
            assert r == 0.0 and np.isnan(info["qacc"]).all()


def test_velocity_mode_tracks_command():
    env = gym.make("JacoPayload-v0", control_mode="velocity", sensor_noise=None)
    env.reset(seed=0)
    cmd = np.array([0.2, -0.2, 0.2, 0.3, -0.3, 0.3])
    for _ in range(40):
        obs, *_ = env.step(cmd)
    # The PI loop (15 rad/s) follows a ramp under changing gravity and coupling within a few 0.01 rad/s.
    _, qd, tau, _ = jaco_env.split_obs(obs)
    assert np.allclose(qd, cmd, atol=0.08)
    assert np.all(np.abs(tau) <= robot.TORQUE_LIMITS + 1e-9)
    env.close()


def test_velocity_mode_torque_is_instantaneous_sample():
    """The firmware loop's torque at an observation's instant follows its q, qd (noiseless, the idealised
    signal), and the measured (link-side) torque is that torque less the residual rotor inertia, damping and
    friction."""
    env = gym.make("JacoPayload-v0", control_mode="velocity", sensor_noise=None, sensor_pipeline="ideal")
    env.reset(seed=0)
    u = env.unwrapped
    for k in range(12):
        cmd = 0.5 * robot.VELOCITY_LIMITS * np.sin(0.3 * k + np.arange(6))
        obs, *_ = env.step(cmd)
        q, qd, tau, _ = jaco_env.split_obs(obs)
        q_ref = u.data.act[u.velocity_ref_act_adr]
        law = np.clip(scene.FIRMWARE_KV * (cmd - qd) + scene.FIRMWARE_KI * (q_ref - q), -robot.TORQUE_LIMITS,
                      robot.TORQUE_LIMITS)
        assert np.allclose(u.data.qfrc_actuator[u.arm_dof_adr], law, atol=1e-9)
        fric = law - tau - robot.ARMATURE * u.data.qacc[u.arm_dof_adr] - robot.DAMPING * qd
        assert np.all(np.abs(fric) <= 1.005 * robot.FRICTIONLOSS + 1e-6)
        # ... and equals MuJoCo's actuator force evaluated afresh at that state and command.
        d = mujoco.MjData(u.model)
        mujoco.mj_setState(u.model, d, np.concatenate([[u.data.time], u.data.qpos, u.data.qvel, u.data.act]),
                           mujoco.mjtState.mjSTATE_PHYSICS | mujoco.mjtState.mjSTATE_TIME)
        d.ctrl[:] = u.data.ctrl
        mujoco.mj_forward(u.model, d)
        assert np.allclose(d.qfrc_actuator[u.arm_dof_adr], law, atol=1e-9)
    env.close()


def test_reference_properties():
    dt = 1e-3
    for task in DEFAULT_TASKS.values():
        t = np.arange(0.0, task.duration + 1.0, dt)
        q, qd, qdd = task.reference(t)
        assert q.shape == (len(t), 6)
        assert np.all(np.abs(qd) <= robot.VELOCITY_LIMITS + 1e-9)
        # qd is the derivative of q, qdd the derivative of qd (finite differences)
        assert np.allclose(np.gradient(q, dt, axis=0)[1:-1], qd[1:-1], atol=2e-3)
        assert np.allclose(np.gradient(qd, dt, axis=0)[1:-1], qdd[1:-1], atol=2e-2)
        assert np.array_equal(task.reference(-1.0)[0], task.reference(0.0)[0])
        assert np.allclose(task.reference(task.duration + 5)[1], 0.0)
    q, qd, qdd = DEFAULT_TASKS["front"].reference(1.0)
    assert q.shape == qd.shape == qdd.shape == (6,)


def test_default_tasks_spread_over_workspace():
    pos = np.array([t.jar_pos[:2] for t in DEFAULT_TASKS.values()])
    assert len(pos) >= 5
    dists = np.linalg.norm(pos[:, None] - pos[None], axis=2)
    assert np.min(dists[np.triu_indices(len(pos), 1)]) > 0.1


def test_excitation_within_limits():
    q0 = home_pose()
    gen = SumOfSinusoids(q0, seed=4)
    t = np.linspace(0, 600, 60001)
    q, qd = gen.position(t), gen.velocity(t)
    assert np.allclose(q[0], q0)
    assert np.all(np.abs(qd) <= 0.8 * robot.VELOCITY_LIMITS + 1e-12)
    for j, r in enumerate(JOINT_RANGES):
        if r is not None:
            assert r[0] < q[:, j].min() and q[:, j].max() < r[1]
    assert np.allclose(np.gradient(q, t, axis=0)[1:-1], qd[1:-1], atol=1e-3)
    assert not np.allclose(SumOfSinusoids(q0, seed=5).amplitudes, gen.amplitudes)


def test_an_env_with_its_own_task_object_pickles():
    """A task's reference is cached as closures; a pickled task (and an env holding one, Gymnasium's ``EzPickle``)
    drops the cache and rebuilds it, the same bit for bit."""
    task = PouringTask("mine", jar_pos=np.array([0.5, 0.1, 0.0]))
    t = np.linspace(0.0, task.duration, 7)  # the duration builds the cache
    twin = pickle.loads(pickle.dumps(task))
    for a, b in zip(task.reference(t), twin.reference(t)):
        np.testing.assert_array_equal(a, b)
    env = gym.make("JacoPour-v0", n_marbles=5, task=task)
    env.reset(seed=1)
    env2 = pickle.loads(pickle.dumps(env))
    shared = gym.make("JacoPour-v0", n_marbles=5, task=DEFAULT_TASKS["front"])  # a module-level task, used
    shared.reset(seed=1)
    pickle.loads(pickle.dumps(shared)).close()
    try:
        obs = [e.reset(seed=1)[0] for e in (env, env2)]
        obs += [e.step(np.full(6, 0.5))[0] for e in (env, env2)]
        np.testing.assert_array_equal(obs[0], obs[1])
        np.testing.assert_array_equal(obs[2], obs[3])
        assert env2.unwrapped.task == task and task != task.replace(jar_pos=np.array([0.5, 0.1, 0.01]))
    finally:
        for e in (env, env2, shared):
            e.close()


@pytest.mark.parametrize("env_id, options", [
    ("JacoPour-v0", {"task": None, "payload_mass": None}),
    ("JacoPayload-v0", {"payload_mass": None, "q0": None}),
])
def test_reset_options_given_as_none_are_as_if_absent(env_id, options):
    kw = {"n_marbles": 5, "task": "left"} if env_id == "JacoPour-v0" else {"payload_mass": 0.5}
    env = gym.make(env_id, **kw)
    try:
        a, info_a = env.reset(seed=2)
        b, info_b = env.reset(seed=2, options=options)
        np.testing.assert_array_equal(a, b)
        assert info_a.keys() == info_b.keys()
        for key in info_a:
            np.testing.assert_array_equal(info_a[key], info_b[key])
    finally:
        env.close()
