"""A URDF mimic joint of one of the model's joints moves with it (:attr:`cascgp.rbd.RigidBodyModel.coupled`): the
torque equals Pinocchio's own mimic joints' RNEA, the derivatives are the chain rule's, and a model file keeps the
coupling without the URDF file."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from tests.test_rbd_joints import _log, _mimic_gripper, arm_urdf, states

from cascgp.gp import GPFitConfig
from cascgp.logs import write_log
from cascgp.models import load_model, make_model
from cascgp.rbd import RigidBodyModel, load_nominal
from cascgp_experiments.cli.model_commands import fit_main

JOINTS = ["j1", "j2", "j3", "finger1"]


def _with_finger(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """States of the three arm joints and finger1 (within its limits [0, 0.04] m)."""
    q, qd, qdd = states(n, seed)
    rng = np.random.default_rng(seed + 100)
    return (np.column_stack([q, rng.uniform(0.0, 0.03, n)]), np.column_stack([qd, rng.uniform(-0.1, 0.1, n)]),
            np.column_stack([qdd, rng.uniform(-1.0, 1.0, n)]))


def test_a_coupled_mimic_joint_equals_pinocchios_mimic_joints(tmp_path: Path) -> None:
    urdf = _mimic_gripper(tmp_path)  # finger2 = 0.5 finger1 + 0.005
    rbd = RigidBodyModel.from_urdf(urdf, joints=JOINTS)
    assert rbd.dof == 4 and rbd.joint_names == tuple(JOINTS) and not rbd.locked
    assert rbd.coupled == {"finger2": ("finger1", 0.5, 0.005)} and rbd.pin_model.nv == 5
    ref = RigidBodyModel(pin.buildModelFromXML(arm_urdf(("revolute",) * 3, fingers="prismatic")))  # no mimic
    native = pin.buildModelFromXML(urdf.read_text().replace("continuous", "revolute"), mimic=True)
    data = native.createData()
    q, qd, qdd = _with_finger(8, seed=3)
    tau = rbd.inverse_dynamics(q, qd, qdd)
    for t in range(8):
        np.testing.assert_allclose(tau[t], pin.rnea(native, data, q[t], qd[t], qdd[t]), rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(rbd.inverse_dynamics(q[t], qd[t], qdd[t]), tau[t])  # one state: the same
        # the coupling by hand: finger2 at 0.5 finger1 + 0.005; its torque times 0.5 onto finger1's
        moved = ((q[t], 0.005), (qd[t], 0.0), (qdd[t], 0.0))
        full = ref.inverse_dynamics(*(np.append(x, 0.5 * x[3] + c) for x, c in moved))
        np.testing.assert_allclose(tau[t], np.append(full[:3], full[3] + 0.5 * full[4]), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(rbd.gravity_torque(q), rbd.inverse_dynamics(q, 0 * q, 0 * q), rtol=1e-12, atol=1e-12)
    M = rbd.mass_matrix(q[0])
    np.testing.assert_allclose(M @ qdd[0], tau[0] - rbd.inverse_dynamics(q[0], qd[0], 0 * q[0]), rtol=1e-9,
                               atol=1e-12)
    dq, dqd, dqdd = rbd.inverse_dynamics_derivatives(q[0], qd[0], qdd[0])
    np.testing.assert_allclose(dqdd, M, rtol=1e-12, atol=1e-12)
    h = 1e-6
    for d, which in ((dq, 0), (dqd, 1)):
        fd = np.empty((4, 4))
        for k in range(4):
            x = [q[0].copy(), qd[0].copy(), qdd[0].copy()]
            x[which][k] += h
            up = rbd.inverse_dynamics(*x)
            x[which][k] -= 2 * h
            fd[:, k] = (up - rbd.inverse_dynamics(*x)) / (2 * h)
        np.testing.assert_allclose(d, fd, rtol=1e-5, atol=1e-6)


def test_a_chain_of_mimic_joints_composes_and_armature_is_the_models_joints(tmp_path: Path) -> None:
    """finger1 mimics j3 and finger2 mimics finger1: both move with j3; armature (N,) sets the model's joints."""
    text = _mimic_gripper(tmp_path).read_text().replace(
        '<joint name="finger1" type="prismatic">',
        '<joint name="finger1" type="prismatic"><mimic joint="j3" multiplier="0.01" offset="0.02"/>')
    rbd = RigidBodyModel.from_urdf_text(text, joints=["j1", "j2", "j3"], armature=[0.1, 0.2, 0.3])
    assert {n: j for n, (j, *_) in rbd.coupled.items()} == {"finger1": "j3", "finger2": "j3"}
    np.testing.assert_allclose([rbd.coupled[n][1:] for n in ("finger1", "finger2")], [[0.01, 0.02], [0.005, 0.015]],
                               rtol=1e-15)
    np.testing.assert_array_equal(rbd.armature, [0.1, 0.2, 0.3])
    ref = RigidBodyModel(pin.buildModelFromXML(arm_urdf(("revolute",) * 3, fingers="prismatic")),
                         armature=[0.1, 0.2, 0.3, 0.0, 0.0])
    q, qd, qdd = states(5, seed=4, scale=1.0)
    E = np.vstack([np.eye(3), [0, 0, 0.01], [0, 0, 0.005]])
    full = ref.inverse_dynamics(q @ E.T + [0, 0, 0, 0.02, 0.015], qd @ E.T, qdd @ E.T)
    np.testing.assert_allclose(rbd.inverse_dynamics(q, qd, qdd), full @ E, rtol=1e-12, atol=1e-12)


def test_a_model_with_a_coupled_joint_saves_loads_and_fits_from_the_command(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    urdf = _mimic_gripper(tmp_path)
    arm = _log(arm_urdf(("revolute",) * 3), 50, seed=8)
    q, qd, qdd = (np.column_stack([x, 0.02 + 0.01 * np.sin(arm.t)]) for x in (arm.q, arm.qd, arm.qdd))
    qd[:, 3], qdd[:, 3] = 0.01 * np.cos(arm.t), -0.01 * np.sin(arm.t)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # no sidecar
        rbd = load_nominal(urdf, joints=JOINTS)
    assert rbd.torque_limits is not None and rbd.torque_limits.shape == (4,)
    np.testing.assert_array_equal(rbd.position_limits[3], [0.0, 0.04])
    data = type(arm)(q=q, qd=qd, qdd=qdd, tau=rbd.inverse_dynamics(q, qd, qdd) + 0.2 * qd, t=arm.t)
    model = make_model("sp-standard", 4, rbd, gp_config=GPFitConfig(n_restarts=1, max_iter=30)).fit(data)
    model.save(tmp_path / "m.npz")
    urdf.rename(tmp_path / "gone.urdf")  # the file embeds the URDF and the model's joints: the coupling follows
    loaded = load_model(tmp_path / "m.npz")
    assert loaded.rbd.coupled == rbd.coupled and loaded.rbd.joint_names == tuple(JOINTS)
    np.testing.assert_array_equal(loaded.predict(q[:5], qd[:5], qdd[:5])[0], model.predict(q[:5], qd[:5], qdd[:5])[0])
    (tmp_path / "gone.urdf").rename(urdf)
    log = tmp_path / "train.csv"
    write_log(log, data)
    assert fit_main(["--data", str(log), "--urdf", str(urdf), "--model", "sp-standard", "--restarts", "1",
                     "--out", str(tmp_path / "cli.npz"), "--joints", ",".join(JOINTS)]) == 0
    err = capsys.readouterr().err
    assert "finger2 moves with finger1 (0.5 x finger1 + 0.005)" in err and "position limits" not in err
    (tmp_path / "far").mkdir()
    far = _mimic_gripper(tmp_path / "far", 'multiplier="1" offset="0.03"')  # finger2 beyond its 0.04 m limit
    assert fit_main(["--data", str(log), "--urdf", str(far), "--model", "sp-standard", "--restarts", "1",
                     "--out", str(tmp_path / "far.npz"), "--joints", ",".join(JOINTS)]) == 0
    note = next(line for line in capsys.readouterr().err.splitlines() if "position limits" in line)
    assert "finger2 (moving with finger1)" in note and "q4" not in note  # finger1 (q4) is within its own


def test_a_mimic_joint_mid_chain_with_armature_and_limits(tmp_path: Path) -> None:
    """j2 mimics j1 (-0.7 j1 + 0.3) in the middle of the chain and finger2 mimics finger1: the model's joints are
    j1, j3 and finger1, not the first three of Pinocchio's; armature, limits and the batched derivatives follow."""
    text = _mimic_gripper(tmp_path).read_text().replace(
        '<joint name="j2" type="revolute">', '<joint name="j2" type="revolute"><mimic joint="j1" multiplier="-0.7" '
        'offset="0.3"/>')
    urdf = tmp_path / "mid.urdf"
    urdf.write_text(text)
    kept = ["j1", "j3", "finger1"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # no sidecar
        rbd = load_nominal(urdf, joints=kept)
    assert rbd.joint_names == tuple(kept) and set(rbd.coupled) == {"j2", "finger2"}
    np.testing.assert_array_equal(rbd.torque_limits, [30.0, 30.0, 20.0])  # the kept joints' efforts
    np.testing.assert_array_equal(rbd.velocity_limits, [2.0, 2.0, 0.2])
    np.testing.assert_array_equal(rbd.position_limits, [[-np.inf, np.inf], [-3.0, 3.0], [0.0, 0.04]])
    arm = RigidBodyModel.from_urdf(urdf, joints=kept, armature=[0.1, 0.2, 0.3])
    np.testing.assert_array_equal(arm.armature, [0.1, 0.2, 0.3])
    native = pin.buildModelFromXML(text.replace("continuous", "revolute"), mimic=True)
    native.armature = np.array([0.1, 0.2, 0.3])
    data = native.createData()
    rng = np.random.default_rng(9)
    q = np.column_stack([rng.uniform(-1, 1, (4, 2)), rng.uniform(0.0, 0.03, 4)])
    qd, qdd = rng.normal(size=(4, 3)), rng.normal(size=(4, 3))
    tau = arm.inverse_dynamics(q, qd, qdd)
    derivs = arm.inverse_dynamics_derivatives(q, qd, qdd)
    for t in range(4):
        np.testing.assert_allclose(tau[t], pin.rnea(native, data, q[t], qd[t], qdd[t]), rtol=1e-12, atol=1e-12)
        for batched, single in zip(derivs, arm.inverse_dynamics_derivatives(q[t], qd[t], qdd[t])):
            np.testing.assert_array_equal(batched[t], single)
        np.testing.assert_allclose(derivs[2][t], arm.mass_matrix(q[t]), rtol=1e-12, atol=1e-12)
    with pytest.raises(ValueError, match=r"no position of their own \(Pinocchio mimic joints"):
        RigidBodyModel(native)
