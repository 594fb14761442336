"""The sensing pipeline (jaco_env.signal_pipeline): each factor, the presets, validation, and ``ideal`` = today.

References are computed independently of the pipeline: closed forms (offset and drift statistics, the
filter's step response), the same physics stepped one physics step per control period (the skewed
reads and the differentiated velocity), and MuJoCo's inverse dynamics (the link-side torque).
"""

from __future__ import annotations

import math
from dataclasses import fields

import gymnasium as gym
import numpy as np
import pytest

import jaco_env
from jaco_env import excitation
from jaco_env.robot import N_JOINTS
from jaco_env.sensors import SensorNoise
from jaco_env.signal_pipeline import FACTORS, PipelineState, SignalPipeline
from tests.test_env_sensing import link_side_torque

DT = 0.025
TS = DT / 13  # the physics step at 40 Hz


def _state(**kw) -> PipelineState:
    return PipelineState(SignalPipeline(**kw), DT, TS, 13)


def _zeros():
    return np.zeros(N_JOINTS)


# ------------------------------------------------------------------ validation and presets
@pytest.mark.parametrize("field, value, exc, match", [
    ("q_lead_s", -0.001, ValueError, r"q_lead_s must be in \[0.0, 0.05\]"),
    ("qd_lead_s", 0.06, ValueError, r"qd_lead_s must be in \[0.0, 0.05\]"),
    ("q_lead_s", "0.004", TypeError, r"q_lead_s must be a real number in \[0.0, 0.05\]"),
    ("qd_lead_s", True, TypeError, "qd_lead_s"),
    ("velocity_source", "firmware", ValueError, r"velocity_source must be one of \('true', 'differentiated'\)"),
    ("velocity_window_s", 0.0, ValueError, r"velocity_window_s must be in \[0.0001, 0.1\]"),
    ("tau_offset_std", 11.0, ValueError, r"tau_offset_std must be in \[0.0, 10.0\]"),
    ("tau_offset_std", (0.1, 0.2), TypeError, "tau_offset_std must be a real number or 6 real numbers"),
    ("tau_drift_std", float("nan"), ValueError, r"tau_drift_std must be in \[0.0, 1.0\]"),
    ("tau_filter_hz", float("inf"), ValueError, r"tau_filter_hz must be in \[0.0, 1000.0\]"),
    ("tau_noise_scale", (1.0,) * 5 + (-1.0,), ValueError, r"tau_noise_scale must be in \[0.0, 10.0\]"),
])
def test_validation_names_the_field_and_its_range(field, value, exc, match):
    with pytest.raises(exc, match=match):
        SignalPipeline(**{field: value})


def test_per_joint_fields_accept_a_scalar_and_are_stored_as_tuples():
    p = SignalPipeline(tau_offset_std=0.2, tau_noise_scale=np.ones(6))
    assert p.tau_offset_std == (0.2,) * 6 and p.tau_noise_scale == (1.0,) * 6
    hash(p)  # frozen and hashable


def test_presets():
    assert SignalPipeline.ideal().is_ideal and SignalPipeline.resolve("ideal").is_ideal
    j = SignalPipeline.resolve("jaco2")
    assert j == SignalPipeline.jaco2() and not j.is_ideal
    assert j.tau_offset_std == (0.3,) * 3 + (0.07,) * 3 and j.tau_filter_hz == 10.0
    assert j.tau_noise_scale == (1.0,) * 3 + (0.25,) * 3 and j.velocity_source == "differentiated"


@pytest.mark.parametrize("env_id", ["JacoPayload-v0", "JacoPour-v0"])
@pytest.mark.parametrize("value, exc", [("real", ValueError), (3, TypeError), (None, TypeError)])
def test_env_rejects_bad_sensor_pipeline(env_id, value, exc):
    with pytest.raises(exc, match=r"sensor_pipeline must be one of \('ideal', 'jaco2'\), 'ideal\+' and factors"):
        gym.make(env_id, sensor_pipeline=value)


def test_named_factors_take_the_jaco2_values_of_their_fields_only():
    full, ideal = SignalPipeline.jaco2(), SignalPipeline.ideal()
    for factor, names in FACTORS.items():
        p = SignalPipeline.resolve(f"ideal+{factor}")
        assert p == SignalPipeline.with_factors(factor) and not p.is_ideal
        for f in fields(SignalPipeline):
            assert getattr(p, f.name) == getattr(full if f.name in names else ideal, f.name), (factor, f.name)
    assert SignalPipeline.resolve("ideal+" + "+".join(FACTORS)) == full
    assert SignalPipeline.resolve("ideal+torque+skew") == SignalPipeline.with_factors("skew", "torque")
    assert SignalPipeline.is_name("ideal+velocity") and not SignalPipeline.is_name(3)


@pytest.mark.parametrize("name", ["ideal+", "jaco2+skew", "ideal+inertials", "ideal+skew+", "Ideal"])
def test_bad_factor_names_are_refused(name):
    with pytest.raises(ValueError, match="sensor_pipeline must be one of"):
        SignalPipeline.resolve(name)
    assert not SignalPipeline.is_name(name)
    with pytest.raises(ValueError, match="sensor_pipeline factor must be one of"):
        SignalPipeline.with_factors("inertials")


# ------------------------------------------------------------------ ideal is the earlier env
@pytest.mark.parametrize("env_id", ["JacoPayload-v0", "JacoPour-v0"])
def test_ideal_is_the_identity_pipeline_and_jaco2_the_default(env_id):
    """``"ideal"`` and ``SignalPipeline()`` skip the pipeline (the same observations, draw for draw; the pinned
    outputs test compares them with the earlier env); the default is the ``"jaco2"`` preset with Kinova's
    link inertials."""
    kw = {"n_marbles": 10} if env_id == "JacoPour-v0" else {}
    default = gym.make(env_id, **kw)
    assert default.unwrapped.sensor_pipeline == SignalPipeline.jaco2()
    assert default.unwrapped.link_inertials == "kinova" and default.unwrapped._signal is not None
    default.close()
    runs = []
    for sp in ("ideal", SignalPipeline()):
        env = gym.make(env_id, sensor_pipeline=sp, **kw)
        assert env.unwrapped._signal is None  # the pipeline is skipped
        obs, _ = env.reset(seed=5)
        seq = [obs]
        for k in range(30):
            seq.append(env.step(np.full(6, 0.5 * math.sin(0.3 * k), dtype=np.float32))[0])
        runs.append(np.array(seq))
        env.close()
    assert np.array_equal(runs[0], runs[1])


def test_ideal_without_noise_is_the_link_side_torque():
    env = gym.make("JacoPayload-v0", control_mode="velocity", sensor_noise=None, sensor_pipeline="ideal")
    env.reset(seed=1)
    u, cmd = env.unwrapped, excitation.make_command(seed=1)
    meas, ref = [], []
    for k in range(120):
        obs = env.step(cmd(k * u.control_dt))[0]
        meas.append(jaco_env.split_obs(obs)[2])
        ref.append(link_side_torque(u))
    meas, ref = np.array(meas), np.array(ref)
    assert np.all(np.abs(meas - ref).max(axis=0) <= 0.01 * meas.std(axis=0))
    env.close()


# ------------------------------------------------------------------ (c) torque: offset, drift, filter, noise
def test_offset_is_drawn_per_episode_with_its_std():
    std = (0.3, 0.3, 0.3, 0.07, 0.07, 0.07)
    st, rng = _state(tau_offset_std=std), np.random.default_rng(0)
    offsets = []
    for _ in range(4000):
        st.reset(rng)
        offsets.append(st.offset.copy())
    offsets = np.array(offsets)
    assert np.all(np.abs(offsets.mean(axis=0)) < 4 * np.array(std) / math.sqrt(4000))
    np.testing.assert_allclose(offsets.std(axis=0), std, rtol=0.05)
    # constant within an episode, added to the torque
    st.reset(rng)
    tau = np.arange(6.0)
    for _ in range(3):
        out = st.measure(rng, SensorNoise.none(), _zeros(), _zeros(), tau, True)
        np.testing.assert_allclose(out[12:18], tau + st.offset)


def test_drift_is_a_random_walk_with_its_rate():
    rate = np.array([0.01] * 3 + [0.0025] * 3)
    st, rng = _state(tau_drift_std=tuple(rate)), np.random.default_rng(1)
    n_ep, n_steps = 1000, 40
    final = []
    for _ in range(n_ep):
        st.reset(rng)
        assert not st.drift.any()
        for _ in range(n_steps):
            out = st.measure(rng, SensorNoise.none(), _zeros(), _zeros(), _zeros(), True)
        final.append(out[12:18])
    final = np.array(final)
    np.testing.assert_allclose(final.std(axis=0), rate * math.sqrt(n_steps * DT), rtol=0.08)
    assert np.all(np.abs(final.mean(axis=0)) < 4 * rate * math.sqrt(n_steps * DT / n_ep))


@pytest.mark.parametrize("f_c", [2.0, 10.0])
def test_filter_step_response_is_the_first_order_closed_form(f_c):
    st, rng = _state(tau_filter_hz=f_c), np.random.default_rng(2)
    st.reset(rng)
    st.measure(rng, SensorNoise.none(), _zeros(), _zeros(), _zeros(), True)  # primes at 0
    tau_c = 1.0 / (2 * math.pi * f_c)
    for k in range(1, 30):
        out = st.measure(rng, SensorNoise.none(), _zeros(), _zeros(), np.ones(6), True)
        np.testing.assert_allclose(out[12:18], 1.0 - math.exp(-k * DT / tau_c), rtol=1e-12, atol=1e-15)


def test_noise_is_scaled_per_actuator_with_the_same_draws():
    scale = (1.0,) * 3 + (0.25,) * 3
    st = _state(tau_noise_scale=scale)
    st.reset(np.random.default_rng(0))
    noise, tau = SensorNoise(), np.full(6, 2.0)
    out = st.measure(np.random.default_rng(7), noise, _zeros(), _zeros(), tau, True)
    ref = noise.measurement(np.random.default_rng(7), _zeros(), _zeros(), tau, 0.0)
    np.testing.assert_array_equal(out[:12], ref[:12])
    np.testing.assert_allclose(out[12:18] - tau, (ref[12:18] - tau) * np.array(scale), rtol=1e-13)


# ------------------------------------------------------------------ (a) skew and (b) velocity, on the env
def _fine_run(actions, sp):
    """The same physics stepped one physics step per control period (520 Hz): true q, qd after each step."""
    env = gym.make("JacoPayload-v0", sensor_noise=None, control_freq=520.0, max_episode_steps=10**6,
                   sensor_pipeline="ideal")
    env.reset(seed=0)
    u = env.unwrapped
    qs, qds = [u.arm_state()[0]], [u.arm_state()[1]]
    for a in actions:
        for _ in range(13):
            env.step(a)
            q, qd = u.arm_state()
            qs.append(q)
            qds.append(qd)
    env.close()
    return np.array(qs), np.array(qds)


def test_skewed_reads_and_differentiated_velocity():
    rng = np.random.default_rng(3)
    actions = [rng.uniform(-3, 3, 6).astype(np.float32) for _ in range(12)]
    sp = SignalPipeline(q_lead_s=0.0077, qd_lead_s=0.0038, velocity_source="differentiated", velocity_window_s=0.01)
    env = gym.make("JacoPayload-v0", sensor_noise=None, sensor_pipeline=sp)
    ideal = gym.make("JacoPayload-v0", sensor_noise=None, sensor_pipeline="ideal")
    env.reset(seed=0)
    ideal.reset(seed=0)
    st = env.unwrapped._signal
    assert (st.q_step, st.qd_step, st.qw_step) == (9, 11, 6)  # 7.7 / 3.8 / 10 ms = 4 / 2 / 5 steps of 1.92 ms
    qs, _ = _fine_run(actions, sp)
    for k, a in enumerate(actions):
        obs = env.step(a)[0]
        obs_i = ideal.step(a)[0]
        q, qd, tau, _ = jaco_env.split_obs(obs)
        np.testing.assert_array_equal(tau, jaco_env.split_obs(obs_i)[2])  # tau read last: unchanged
        np.testing.assert_array_equal(env.unwrapped.arm_state()[0], ideal.unwrapped.arm_state()[0])  # same physics
        base = 13 * k
        np.testing.assert_allclose(q, qs[base + 9], rtol=0, atol=1e-12)
        np.testing.assert_allclose(qd, (qs[base + 11] - qs[base + 6]) / (5 * TS), rtol=0, atol=1e-9)
    env.close()
    ideal.close()


def test_skewed_reads_stay_exact_over_a_long_episode():
    """The reads are MuJoCo's delayed sensors, looked up by time: after 20 s (800 periods, 10,400 physics
    steps of accumulated time) they are still the states of their physics steps, and the model of ``ideal``
    has no such sensors."""
    from jaco_env.oracle import OracleController

    sp = SignalPipeline(q_lead_s=0.0083, qd_lead_s=0.0028, velocity_source="differentiated")  # jaco2's reads
    env = gym.make("JacoPayload-v0", sensor_noise=None, sensor_pipeline=sp, max_episode_steps=10**6)
    _, info = env.reset(seed=0)
    u = env.unwrapped
    st = u._signal
    assert (st.q_step, st.qd_step, st.qw_step) == (9, 12, 7)
    ideal = gym.make("JacoPayload-v0", sensor_pipeline="ideal")
    assert u.model.nsensor == ideal.unwrapped.model.nsensor + 18  # q, q at the qd read, q at the window start
    ideal.close()
    oracle = OracleController(follow_marbles=False)
    oracle.start(env, info)
    rng = np.random.default_rng(5)
    actions, reads = [], []
    for _ in range(800):  # gravity held, a small random torque on top: the arm moves and stays in range
        q, qd = u.arm_state()
        a = np.clip(oracle.feedforward(q, qd, np.zeros(6)) - 2.0 * qd + rng.normal(0.0, 0.5, 6),
                    -u.torque_limits, u.torque_limits).astype(np.float32)
        obs, _, _, trunc, _ = env.step(a)
        assert not trunc
        actions.append(a)
        reads.append(jaco_env.split_obs(obs)[:2])
    env.close()
    qs, _ = _fine_run(actions, sp)
    for k in (0, 1, 399, 798, 799):
        q, qd = reads[k]
        np.testing.assert_array_equal(q, qs[13 * k + 9])
        np.testing.assert_array_equal(qd, (qs[13 * k + 12] - qs[13 * k + 7]) / st.velocity_window)
    assert np.ptp(qs[:, 0]) > 0.05  # the arm moved


def test_skewed_true_velocity_is_read_before_the_torque():
    rng = np.random.default_rng(4)
    actions = [rng.uniform(-3, 3, 6).astype(np.float32) for _ in range(6)]
    env = gym.make("JacoPayload-v0", sensor_noise=None, sensor_pipeline=SignalPipeline(qd_lead_s=0.004))
    env.reset(seed=0)
    fine = gym.make("JacoPayload-v0", sensor_noise=None, control_freq=520.0, max_episode_steps=10**6,
                    sensor_pipeline="ideal")
    fine.reset(seed=0)
    qds = []
    for a in actions:
        for _ in range(13):
            fine.step(a)
            qds.append(fine.unwrapped.arm_state()[1])
        obs = env.step(a)[0]
        np.testing.assert_allclose(jaco_env.split_obs(obs)[1], qds[-1 - 2], rtol=0, atol=1e-12)
    env.close()
    fine.close()


# ------------------------------------------------------------------ jaco2 on both envs, non-finite values
@pytest.mark.parametrize("env_id", ["JacoPayload-v0", "JacoPour-v0"])
def test_jaco2_runs_and_is_reproducible(env_id):
    kw = {"n_marbles": 10} if env_id == "JacoPour-v0" else {}
    runs = []
    for _ in range(2):
        env = gym.make(env_id, sensor_pipeline="jaco2", **kw)
        obs, _ = env.reset(seed=11)
        seq = [obs]
        for _k in range(20):
            obs, _, _, trunc, info = env.step(np.zeros(6, dtype=np.float32))
            assert not trunc and np.all(np.isfinite(obs))
            seq.append(obs)
        runs.append(np.array(seq))
        env.close()
    np.testing.assert_array_equal(runs[0], runs[1])
    assert runs[0][-1][jaco_env.OBS_TIME] == pytest.approx(20 * 0.025)


@pytest.mark.parametrize("env_id", ["JacoPayload-v0", "JacoPour-v0"])
def test_non_finite_measurement_truncates_as_unstable(env_id):
    kw = {"n_marbles": 10} if env_id == "JacoPour-v0" else {}
    env = gym.make(env_id, sensor_pipeline="jaco2", **kw)
    obs0, _ = env.reset(seed=0)
    obs1 = env.step(np.zeros(6, dtype=np.float32))[0]
    env.unwrapped._signal.offset[2] = np.nan
    obs, _, _, trunc, info = env.step(np.zeros(6, dtype=np.float32))
    assert trunc and info["unstable"] and np.all(np.isfinite(obs))
    np.testing.assert_array_equal(obs, obs1)
    env.close()


def test_times_are_capped_within_the_period():
    st = PipelineState(SignalPipeline(q_lead_s=0.05, qd_lead_s=0.05, velocity_source="differentiated"), DT, TS, 13)
    assert (st.q_step, st.qd_step, st.qw_step) == (1, 1, 0)
    st = PipelineState(SignalPipeline(q_lead_s=0.05, velocity_source="differentiated"), 0.002, 0.002, 1)
    assert (st.q_step, st.qd_step, st.qw_step) == (1, 1, 0)


def test_times_are_capped_within_the_period_at_the_collection_rate():
    """100 Hz (the collection's rate): 5 physics steps of 2 ms; the 10 ms window is cut to what is left."""
    env = gym.make("JacoPayload-v0", control_mode="velocity", control_freq=100.0, sensor_pipeline="jaco2")
    st = env.unwrapped._signal
    assert (st.q_step, st.qd_step, st.qw_step) == (1, 4, 0)  # 8.3 / 2.8 ms = 4 / 1 steps of 2 ms
    assert st.velocity_window == pytest.approx(0.008)  # 10 ms cut to the 4 steps before the qd read
    env.close()


def test_env_with_a_pipeline_pickles():
    import pickle

    env = gym.make("JacoPayload-v0", sensor_pipeline=SignalPipeline(tau_filter_hz=5.0))
    clone = pickle.loads(pickle.dumps(env.unwrapped))
    assert clone.sensor_pipeline == SignalPipeline(tau_filter_hz=5.0)
    clone.close()
    env.close()


def test_collection_passes_the_pipeline_through():
    from cascgp_experiments.collect import CollectConfig, make_env, same_collection

    with pytest.raises(ValueError, match=r"sensor_pipeline: expected one of \('ideal', 'jaco2'\)"):
        CollectConfig(sensor_pipeline="real")
    with pytest.raises(ValueError, match="sensor_pipeline"):
        make_env(100.0, 0.8, "default", "real")
    env = make_env(100.0, 0.8, "default", "jaco2")
    assert env.unwrapped.sensor_pipeline == SignalPipeline.jaco2()
    env.close()
    cfg = CollectConfig()
    assert cfg.sensor_pipeline == "jaco2" and cfg.nominal_link_inertials == "kinova"
    # A file from before the option was recorded under "ideal": the same collection as an "ideal" config only.
    ideal = CollectConfig(sensor_pipeline="ideal")
    stored = {k: v for k, v in vars(ideal).items() if k != "sensor_pipeline"}
    assert same_collection(stored, ideal) and not same_collection(stored, cfg)


def test_env_offset_is_redrawn_per_episode_and_added_to_the_torque():
    sp = SignalPipeline(tau_offset_std=(0.3,) * 3 + (0.07,) * 3)
    env = gym.make("JacoPayload-v0", sensor_noise=None, sensor_pipeline=sp)
    ideal = gym.make("JacoPayload-v0", sensor_noise=None, sensor_pipeline="ideal")
    offsets = []
    for seed in range(3):
        env.reset(seed=seed)
        ideal.reset(seed=seed)
        offsets.append(env.unwrapped._signal.offset.copy())
        for k in range(3):
            a = np.full(6, 0.2 * k, dtype=np.float32)
            tau = jaco_env.split_obs(env.step(a)[0])[2]
            np.testing.assert_allclose(tau, jaco_env.split_obs(ideal.step(a)[0])[2] + offsets[-1], rtol=0, atol=1e-12)
    assert not np.allclose(offsets[0], offsets[1]) and not np.allclose(offsets[1], offsets[2])
    env.reset(seed=0)
    np.testing.assert_array_equal(env.unwrapped._signal.offset, offsets[0])  # seeded
    env.close()
    ideal.close()


def test_the_episode_draws_are_the_same_under_any_pipeline():
    """Task, payload and marbles are drawn before the pipeline's offset: the same start for one seed."""
    starts = []
    for sp in ("ideal", "jaco2"):
        env = gym.make("JacoPour-v0", n_marbles=10, sensor_pipeline=sp)
        _, info = env.reset(seed=21)
        starts.append((info["payload_mass"], info["task"], env.unwrapped.marble_positions()))
        env.close()
    assert starts[0][:2] == starts[1][:2]
    np.testing.assert_array_equal(starts[0][2], starts[1][2])
