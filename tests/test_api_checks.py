"""Inputs of the environments' helpers and of the retraining loop refused by name, before anything runs; shared
state that a caller's array must not reach."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import jaco_env  # noqa: F401  (registers the envs)
from cascgp.learning import Feedback, RetrainConfig, attempt_plan, make_controller, run_controller
from jaco_env.kinematics import HOME_APPROACH, HOME_MOUTH, bottle_pose, home_pose, solve_ik, target_rotation
from jaco_env.oracle import OracleController, PDController
from jaco_env.robot import TORQUE_LIMITS
from jaco_env.tasks import DEFAULT_TASKS


def test_home_pose_is_a_new_array_each_call():
    q = home_pose()
    q[0] += 0.5  # the caller's copy: the envs and tasks still start at the home pose
    assert home_pose()[0] == pytest.approx(q[0] - 0.5)
    env = gym.make("JacoPayload-v0")
    try:
        env.reset(seed=0)
        np.testing.assert_allclose(env.unwrapped.arm_state()[0], home_pose())
    finally:
        env.close()


@pytest.mark.parametrize("call, exc, match", [
    (lambda: bottle_pose([0.0] * 5), ValueError, r"q must have shape \(6,\)"),
    (lambda: bottle_pose([np.nan] + [0.0] * 5), ValueError, r"q must be finite; entries \[0\]"),
    (lambda: bottle_pose(["a"] * 6), TypeError, "q must be an array of real numbers"),
    (lambda: target_rotation([0.0, 0.0, 1.0], 0.0), ValueError, "approach must be a nonzero horizontal vector"),
    (lambda: target_rotation([0.0, 0.0, 0.0], 0.0), ValueError, "approach must be a nonzero horizontal vector"),
    (lambda: target_rotation([0.0, 1.0], 0.0), ValueError, r"approach must have shape \(3,\)"),
    (lambda: target_rotation(HOME_APPROACH, np.inf), ValueError, "tilt must be finite"),
    (lambda: target_rotation(HOME_APPROACH, "0.1"), TypeError, "tilt must be a real number"),
    (lambda: solve_ik(HOME_MOUTH[:2], np.eye(3), home_pose()), ValueError, r"p_target must have shape \(3,\)"),
    (lambda: solve_ik(HOME_MOUTH, np.full((3, 3), np.nan), home_pose()), ValueError, "R_target must be finite"),
    (lambda: solve_ik(HOME_MOUTH, np.eye(3), home_pose()[:5]), ValueError, r"q0 must have shape \(6,\)"),
])
def test_the_kinematics_helpers_check_their_arguments(call, exc, match):
    with pytest.raises(exc, match=match):
        call()


def test_the_kinematics_helpers_agree_with_each_other():
    # the home pose's IK solution puts the mouth at its target with the target's orientation (forward kinematics)
    p, R = bottle_pose(home_pose())
    np.testing.assert_allclose(p, HOME_MOUTH, atol=1e-6)
    np.testing.assert_allclose(R, target_rotation(HOME_APPROACH, 0.0), atol=1e-6)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.array_equal(target_rotation(HOME_APPROACH, np.array(0.3)), target_rotation(HOME_APPROACH, 0.3))


def test_payload_start_pose_within_the_joint_ranges():
    env = gym.make("JacoPayload-v0")
    q0 = home_pose()
    q0[1] = 0.0
    try:
        with pytest.raises(ValueError, match=r"options\['q0'\]\[1\]: joint 2's angle must be within \[0.820, 5.463\]"):
            env.reset(seed=0, options={"q0": q0})
    finally:
        env.close()


def test_oracle_and_pd_check_the_env_the_info_and_new_gains():
    pd = PDController()
    for bad in (np.nan, "x", -1.0):
        with pytest.raises((TypeError, ValueError), match="kp"):
            pd.kp = bad
    assert np.all(np.isfinite(pd.kp))  # a rejected gain changes nothing
    env = gym.make("JacoPayload-v0", control_mode="velocity")
    try:
        _, info = env.reset(seed=0)
        with pytest.raises(ValueError, match="control_mode='velocity'"):
            pd.start(env.unwrapped, info)
    finally:
        env.close()
    pour = gym.make("JacoPour-v0", n_marbles=5)
    try:
        _, info = pour.reset(seed=0)
        oracle = OracleController()
        oracle.start(pour, info)  # the wrapped env, as gym.make returns it: its marbles are followed
        assert oracle._env is pour.unwrapped
        for bad, exc, match in (({}, ValueError, "payload_mass"), ({"payload_mass": "1.0"}, TypeError, "kg"),
                                ({"payload_mass": np.nan}, ValueError, "payload_mass")):
            with pytest.raises(exc, match=match):
                oracle.start(pour, bad)
    finally:
        pour.close()


def test_retraining_plans_and_arguments_are_checked_before_anything_runs(tmp_path):
    with pytest.raises(ValueError, match="tasks: expected a list of task names, got 'front'"):
        attempt_plan("front", 1)
    with pytest.raises(ValueError, match="attempts: expected an integer >= 1, got 0"):
        attempt_plan(["front"], 0)
    assert attempt_plan(["front", "left"], 1) == [("front", 0, "train"), ("left", 0, "train"), ("front", 1, "revisit")]
    feedback = Feedback(kp=np.ones(6), kd=np.ones(6), torque_limits=np.asarray(TORQUE_LIMITS, float))
    with pytest.raises(ValueError, match="rbd: controller 'rbd' needs the nominal rigid-body model"):
        make_controller("rbd", None, None, feedback)
    env = object()  # never reached: every check comes first
    for plan, kwargs, exc, match in (
            ([("front", 0, "tran")], {}, ValueError, r"plan\[0\]: expected \(task name, attempt number, phase"),
            ([("front", 0)], {}, ValueError, r"plan\[0\]"),
            ([("front", 0, "train")], {"reset_options": {"task": "left"}}, ValueError, "leave 'task' out"),
            ([("front", 0, "train")], {"config": {"seed": 0}}, TypeError, "config: expected a RetrainConfig")):
        with pytest.raises(exc, match=match):
            run_controller("sp-inward", env, plan, None, feedback, buffer_dir=tmp_path / "buf", **kwargs)
        assert not (tmp_path / "buf").exists()  # nothing written
    assert isinstance(RetrainConfig(), RetrainConfig)


def test_run_controllers_checks_every_buffer_folder_before_any_controller_runs(tmp_path):
    """A later controller's folder holding data was refused only when its turn came, after the controllers before it
    had run (their records lost, and their own folders then refused on a rerun)."""
    from cascgp.buffer import DataBuffer
    from cascgp.learning import run_controllers
    from tests.conftest import make_arm, sinusoid_data

    DataBuffer(tmp_path / "np-inward").append(sinusoid_data(make_arm(2), 1.0, 10.0, seed=0))
    feedback = Feedback(kp=np.ones(6), kd=np.ones(6), torque_limits=np.asarray(TORQUE_LIMITS, float))

    def make_env():
        raise AssertionError("the env was made: a controller would have run")

    plan = [("front", 0, "train")]
    with pytest.raises(ValueError, match=r"^buffer_root: .*np-inward already holds data; use an empty folder"):
        run_controllers(["pd", "sp-inward", "np-inward"], make_env, plan, None, feedback, buffer_root=tmp_path)
    with pytest.raises(ValueError, match=r"^names: expected distinct controllers"):
        run_controllers(["pd", "pd"], make_env, plan, None, feedback, buffer_root=tmp_path / "other")
    assert not (tmp_path / "sp-inward").exists() or not any((tmp_path / "sp-inward").iterdir())


@pytest.mark.parametrize("change, exc, match", [
    ({"tilt": 0.0}, ValueError, r"tilt must be in \(0, pi\]"),
    ({"tilt": np.nan}, ValueError, "tilt must be finite"),
    ({"pour_height": np.nan}, ValueError, "pour_height must be finite"),
    ({"hold": np.inf}, ValueError, "hold must be finite"),
    ({"hold": "1"}, TypeError, "hold must be a finite real number"),
    ({"speed": "0.5"}, TypeError, "speed"),
    ({"speed": 1e-300}, ValueError, r"speed must be in \[0.01, 1\]"),
    ({"tip_speed": 0.0}, ValueError, r"tip_speed must be in \[0.01, 1\]"),
    ({"settle": 1e308}, ValueError, r"settle must be in \[0, 600\] s"),
    ({"jar_pos": [0.5 + 3j, 0.1, 0.0]}, TypeError, "jar_pos must be an array of real numbers, got dtype complex"),
    ({"jar_pos": [0.5, 0.1, np.nan]}, ValueError, "jar_pos must be finite"),
    ({"name": None}, TypeError, "PouringTask.name must be a non-empty string, got NoneType"),
])
def test_a_pouring_task_checks_its_fields(change, exc, match):
    with pytest.raises(exc, match=match):
        DEFAULT_TASKS["front"].replace(**change)


def test_a_reference_position_needs_a_finite_real_time():
    task = DEFAULT_TASKS["front"]
    for t, exc in ((np.nan, ValueError), (np.inf, ValueError), (None, TypeError), ("1", TypeError),
                   (True, TypeError), ([1.0], TypeError)):
        with pytest.raises(exc, match="reference_position: t must be"):
            task.reference_position(t)
    np.testing.assert_array_equal(task.reference_position(np.float64(1.5)), task.reference(1.5)[0])
    np.testing.assert_array_equal(task.reference_position(2), task.reference(2.0)[0])


def test_sensor_noise_is_bounded_so_that_measurements_stay_finite():
    from jaco_env.sensors import MAX_NOISE_STD, SensorNoise

    for field in ("q_std", "qd_std", "tau_std"):
        with pytest.raises(ValueError, match=rf"SensorNoise.{field} must be a number in \[0, 1000\]"):
            SensorNoise(**{field: 1e308})
    assert SensorNoise(MAX_NOISE_STD, MAX_NOISE_STD, MAX_NOISE_STD).tau_std == 1e3


@pytest.mark.parametrize("kwargs, exc, match", [
    ({"width": "480"}, TypeError, r"width must be an integer number of pixels in \[1, 16384\], got str '480'"),
    ({"width": 480.0}, TypeError, "width must be an integer"),
    ({"height": True}, TypeError, "height must be an integer"),
    ({"control_mode": None}, TypeError, "control_mode must be 'torque' or 'velocity', got NoneType"),
    ({"link_inertials": 3}, TypeError, r"link_inertials must be one of .* or None, got int 3"),
    ({"link_inertials": "urdf"}, ValueError, r"link_inertials must be one of .* or None, got .urdf."),
    ({"height": -5}, ValueError, "height must be an integer"),
    ({"camera_name": "nope"}, ValueError, r"camera_name: the scene has no camera 'nope'; its cameras are \["),
    ({"camera_name": 3}, TypeError, "camera_name must be a camera's name or None"),
])
def test_settings_are_checked_at_construction_with_their_type(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        gym.make("JacoPour-v0", n_marbles=5, render_mode="rgb_array", **kwargs)


@pytest.mark.parametrize("kwargs, match", [
    ({"max_excursion": np.nan}, "max_excursion must be a finite real number"),
    ({"max_excursion": 0.0}, "max_excursion must be > 0"),
    ({"freq_range": (0.1, np.inf)}, r"freq_range must satisfy 0 < low <= high < inf"),
    ({"freq_range": "fast"}, "freq_range must be two frequencies"),
    ({"speed": "1"}, "speed must be a finite real number"),
    ({"n_sines": 2.0}, "n_sines must be an integer >= 1"),
])
def test_an_excitation_checks_its_settings(kwargs, match):
    from jaco_env.excitation import SumOfSinusoids

    with pytest.raises(ValueError, match=match):
        SumOfSinusoids(home_pose(), **kwargs)


def test_array_settings_of_the_right_shape_are_accepted_and_others_named():
    from jaco_env.signal_pipeline import SignalPipeline

    env = gym.make("JacoPour-v0", payload_range=np.array([0.7, 1.0]))  # as a tuple
    env.close()
    for kwargs, match in (({"tau_offset_std": np.array(0.1)}, "tau_offset_std must be a real number or 6"),
                          ({"velocity_source": None}, "velocity_source must be one of"),
                          ({"velocity_source": np.array(["true"])}, "velocity_source must be one of")):
        with pytest.raises(TypeError, match=match):
            SignalPipeline(**kwargs)
    assert SignalPipeline(tau_offset_std=np.full(6, 0.1)).tau_offset_std == (0.1,) * 6
