"""The arm's link inertials (sensing factor (e), jaco_env.link_inertials): Kinova's URDF values against
dm_control's, in the compiled arm, the environments, the oracle and the nominal URDF."""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import jaco_env
from cascgp.rbd import load_nominal
from cascgp_experiments import nominal_urdf as gen
from jaco_env import link_inertials, robot
from jaco_env.oracle import OracleController

#: dm_control's link masses (jaco_arm.xml, jaco_hand.xml), which the default must keep.
DM_CONTROL_MASSES = {"b_1": 0.643205, "b_2": 1.16915, "b_3": 0.673443, "b_4": 0.221432, "b_5": 0.221432,
                     "jaco_hand/hand": 0.54719, "jaco_hand/b_finger_1": 0.0255204,
                     "jaco_hand/b_finger_tip_1": 0.0132655}


def _bare(li: str) -> mujoco.MjModel:
    arm = robot.build_arm_mjcf(armature=None, frictionloss=None, damping=None, link_inertials=li)
    return mujoco.MjModel.from_xml_string(arm.to_xml_string(), arm.get_assets())


def test_kinova_inertials_are_the_urdf_values():
    m = _bare("kinova")
    table = {**link_inertials.KINOVA, **{f: link_inertials.KINOVA_FINGER for f in link_inertials.FINGER_BODIES}}
    assert len(table) == 12
    for name, (mass, com, (h, r, axis, m_i)) in table.items():
        b = m.body(name).id
        assert m.body_mass[b] == pytest.approx(mass, rel=1e-12), name
        np.testing.assert_allclose(m.body_ipos[b], com, atol=1e-12, err_msg=name)
        # A diagonal inertia stays in the body's axes, up to MuJoCo ordering the principal moments.
        expected = link_inertials.cylinder_inertia(h, r, axis, m_i)
        np.testing.assert_allclose(np.sort(m.body_inertia[b]), np.sort(expected), rtol=1e-12, err_msg=name)
    # The cylinder formula: about its axis m r^2 / 2, across m (3 r^2 + h^2) / 12.
    across = 0.99 * (3 * 0.04**2 + 0.35**2) / 12
    np.testing.assert_allclose(link_inertials.cylinder_inertia(0.35, 0.04, "y", 0.99),
                               [across, 0.5 * 0.99 * 0.04**2, across])
    # The figures: each wrist link 0.426 kg, the hand with its fingers 0.99 + 6 x 0.01 kg.
    hand = [m.body(n).id for n in ("jaco_hand/hand", *link_inertials.FINGER_BODIES)]
    assert m.body_mass[hand].sum() == pytest.approx(1.05)


def test_default_keeps_dm_control_inertials():
    m, dm = _bare("dm_control"), _bare("kinova")
    for name, mass in DM_CONTROL_MASSES.items():
        assert m.body_mass[m.body(name).id] == pytest.approx(mass, rel=1e-6), name
    # The default model is the one built without the option (the pinned-output test holds its behaviour).
    arm = robot.build_arm_mjcf(armature=None, frictionloss=None, damping=None)
    assert arm.to_xml_string() == robot.build_arm_mjcf(armature=None, frictionloss=None, damping=None,
                                                       link_inertials="dm_control").to_xml_string()
    # Only the inertials differ: the kinematics are the same.
    np.testing.assert_array_equal(m.body_pos, dm.body_pos)
    np.testing.assert_array_equal(m.body_quat, dm.body_quat)
    assert not np.allclose(m.body_mass, dm.body_mass)


def test_nominal_kinova_urdf_equals_mujoco_inverse_dynamics(tmp_path):
    """e = 0: Pinocchio's RNEA of the exported Kinova-inertial model equals MuJoCo's of the simulated arm."""
    urdf, _ = gen.write(tmp_path / "kinova.urdf", error=0.0, seed=0, link_inertials="kinova")
    rbd = load_nominal(urdf)
    m = _bare("kinova")
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONSTRAINT
    d = mujoco.MjData(m)
    rng = np.random.default_rng(0)
    q, qd, qdd = rng.uniform(0, 2 * np.pi, (50, 6)), rng.uniform(-2, 2, (50, 6)), rng.uniform(-10, 10, (50, 6))
    ref = np.empty_like(q)
    for t in range(len(q)):
        d.qpos[:], d.qvel[:], d.qacc[:] = q[t], qd[t], qdd[t]
        mujoco.mj_inverse(m, d)
        ref[t] = d.qfrc_inverse
    np.testing.assert_allclose(rbd.inverse_dynamics(q, qd, qdd), ref, atol=1e-8)
    # ... and differs from the dm_control model's by more than round-off.
    other = load_nominal(gen.write(tmp_path / "dm.urdf", error=0.0, seed=0)[0])
    assert np.abs(other.inverse_dynamics(q, qd, qdd) - ref).max() > 0.1


def test_shipped_nominal_urdfs():
    assert jaco_env.nominal_urdf() == jaco_env.NOMINAL_URDF
    kin = load_nominal(jaco_env.nominal_urdf("kinova"), dof=6)
    assert "link_inertials='kinova'" in kin.meta["source"] and kin.meta["calibration_error"] == 0.1
    with pytest.raises(ValueError, match="link_inertials must be one of"):
        jaco_env.nominal_urdf("urdf")
    with pytest.raises(TypeError, match=r"link_inertials must be one of \('dm_control', 'kinova'\), got NoneType"):
        jaco_env.nominal_urdf(None)  # no "or None" here: only the envs take None


def test_experiments_name_the_same_nominal_urdfs():
    # cascgp_experiments.common finds the shipped files without importing jaco_env (MuJoCo); its paths must stay
    # those of jaco_env.nominal_urdf, the one rule.
    from cascgp_experiments import common

    assert common.NOMINAL_URDF == jaco_env.nominal_urdf("kinova").resolve()
    assert common.NOMINAL_URDF_DM_CONTROL == jaco_env.nominal_urdf("dm_control").resolve()
    assert common.NOMINAL_URDF.is_file() and common.NOMINAL_URDF_DM_CONTROL.is_file()


@pytest.mark.parametrize("env_id", ["JacoPayload-v0", "JacoPour-v0"])
def test_env_option(env_id):
    kw = {"n_marbles": 5} if env_id == "JacoPour-v0" else {}
    for pipeline, option, expected in (("ideal", None, "dm_control"), ("jaco2", None, "kinova"),
                                       ("ideal+torque", None, "dm_control"), ("ideal", "kinova", "kinova"),
                                       ("jaco2", "dm_control", "dm_control")):
        env = gym.make(env_id, sensor_pipeline=pipeline, link_inertials=option, **kw)
        u = env.unwrapped
        assert u.link_inertials == expected, (pipeline, option)
        b4 = u.model.body_mass[u.model.body("jaco_arm/b_4").id]
        assert b4 == pytest.approx(0.426367 if expected == "kinova" else 0.221432)
        env.close()
    for bad, exc in (("urdf", ValueError), ("", ValueError), (1, TypeError)):
        with pytest.raises(exc, match="link_inertials must be one of"):
            gym.make(env_id, link_inertials=bad, **kw)


def test_the_oracle_follows_the_env_link_inertials():
    """The oracle started on an env builds its rigid model with the env's inertials (the sensed torque under
    Kinova's inertials is the link-side torque: test_env_sensing)."""
    for li, b4 in (("kinova", 0.426367), ("dm_control", 0.221432)):
        env = gym.make("JacoPayload-v0", link_inertials=li)
        _, info = env.reset(seed=0)
        ctrl = OracleController()
        ctrl.start(env.unwrapped, info)
        assert ctrl.model is not None
        assert ctrl.model.body_mass[ctrl.model.body("jaco_arm/b_4").id] == pytest.approx(b4)
        env.close()


def test_the_oracle_built_before_start_has_the_default_arm_unless_told():
    """``OracleController(payload_mass)`` builds its model before any env: the default environments' arm
    (Kinova's inertials), or the one named; a bad name is refused before anything is built."""
    b4 = {"kinova": 0.426367, "dm_control": 0.221432}
    ctrl = OracleController(1.0)
    assert ctrl.model is not None
    assert ctrl.model.body_mass[ctrl.model.body("jaco_arm/b_4").id] == pytest.approx(b4["kinova"])
    ctrl = OracleController(1.0, link_inertials="dm_control")
    assert ctrl.model is not None
    assert ctrl.model.body_mass[ctrl.model.body("jaco_arm/b_4").id] == pytest.approx(b4["dm_control"])
    with pytest.raises(ValueError, match="link_inertials must be one of"):
        OracleController(1.0, link_inertials="urdf")
