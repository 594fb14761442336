"""A manufacturer's URDF as the rigid-body model: continuous joints as angles, joints the log lacks locked.

References: the same arm written with ``revolute`` joints (continuous joints), Pinocchio's own model of the
continuous joints at :math:`(\\cos q, \\sin q)`, and the same arm with the locked joints written as ``fixed``
joints at the locked positions (locked joints).
"""

from __future__ import annotations

import csv
import json
import warnings
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from cascgp.data import DynamicsData
from cascgp.gp import GPFitConfig
from cascgp.models import load_model, make_model
from cascgp.rbd import RigidBodyModel, load_nominal
from cascgp.rbd_joints import angle_joints
from cascgp_experiments.cli.model_commands import fit_main

_INERTIAL = ('<inertial><origin xyz="{c}"/><mass value="{m}"/>'
             '<inertia ixx="{i}" ixy="{o}" ixz="0" iyy="{i2}" iyz="{o2}" izz="{i}"/></inertial>')


def _inertial(c: str, m: float, i: float, i2: float) -> str:
    """A link's inertial with small products of inertia (a positive definite inertia)."""
    return _INERTIAL.format(c=c, m=m, i=i, i2=i2, o=0.1 * i, o2=0.05 * i)
# (name, parent, child, origin xyz, origin rpy, axis, link mass, link centre of mass)
_ARM = [("j1", "base", "l1", "0 0 0.1", "0 0 0", "0 0 1", 1.2, "0 0.01 0.1"),
        ("j2", "l1", "l2", "0 0 0.2", "1.5707963 0 0", "0 0.6 0.8", 0.9, "0.1 0 0.02"),  # an unaligned axis
        ("j3", "l2", "l3", "0.3 0 0", "0 0 0.3", "1 0 0", 0.6, "0.05 0.01 0")]


def arm_urdf(types: tuple[str, str, str], fingers: str | None = None, at: tuple[float, float] = (0.0, 0.0),
             axes: tuple[str, str, str] | None = None) -> str:
    """Three joints of ``types`` (and ``axes``, default ``_ARM``'s); ``fingers``: None, ``"prismatic"`` (two
    finger joints) or ``"fixed"`` (the fingers welded at positions ``at``, the reference of locking them there)."""
    parts = ['<?xml version="1.0"?>', '<robot name="arm">', '<link name="base"/>']
    arm = _ARM if axes is None else [(*j[:5], a, *j[6:]) for j, a in zip(_ARM, axes)]
    for (name, parent, child, xyz, rpy, axis, m, c), kind in zip(arm, types):
        limit = '<limit effort="30" velocity="2"/>' if kind == "continuous" else \
            '<limit effort="30" velocity="2" lower="-3" upper="3"/>'
        parts += [f'<link name="{child}">{_inertial(c, m, 0.01 * m, 0.02 * m)}</link>',
                  f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
                  f'<origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="{axis}"/>{limit}</joint>']
    if fingers:
        for k, (sign, q) in enumerate(((1, at[0]), (-1, at[1])), start=1):
            parts.append(f'<link name="f{k}">{_inertial(f"0 {0.02 * sign} 0", 0.1, 1e-4, 2e-4)}'
                         '</link>')
            if fingers == "fixed":
                parts.append(f'<joint name="finger{k}" type="fixed"><parent link="l3"/><child link="f{k}"/>'
                             f'<origin xyz="0.1 {sign * q} 0"/></joint>')
            else:
                parts.append(f'<joint name="finger{k}" type="prismatic"><parent link="l3"/><child link="f{k}"/>'
                             f'<origin xyz="0.1 0 0"/><axis xyz="0 {sign} 0"/>'
                             '<limit effort="20" velocity="0.2" lower="0" upper="0.04"/></joint>')
    return "\n".join([*parts, "</robot>"]) + "\n"


def write(folder: Path, name: str, text: str) -> Path:
    path = folder / name
    path.write_text(text)
    return path


def states(n: int, seed: int, scale: float = 3.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.uniform(-scale, scale, (n, 3)), rng.uniform(-2, 2, (n, 3)), rng.uniform(-5, 5, (n, 3))


@pytest.mark.parametrize("axes", [None, ("0 0 -1", "0 -1.2 -1.6", "-1 -1 -1")])  # signs, unnormalised axes
def test_continuous_joints_are_revolute_joints_in_their_angle(tmp_path: Path, axes: tuple[str, ...] | None) -> None:
    cont = write(tmp_path, "cont.urdf", arm_urdf(("continuous", "continuous", "revolute"), axes=axes))
    ref = RigidBodyModel.from_urdf(write(tmp_path, "rev.urdf", arm_urdf(("revolute",) * 3, axes=axes)))
    rbd = RigidBodyModel.from_urdf(cont)
    assert rbd.dof == 3 and rbd.joint_names == ("j1", "j2", "j3") and rbd.locked == {}
    q, qd, qdd = states(20, seed=0, scale=7.0)  # beyond +-pi: angles of any range
    np.testing.assert_allclose(rbd.inverse_dynamics(q, qd, qdd), ref.inverse_dynamics(q, qd, qdd),
                               rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(rbd.inverse_dynamics(q + 2 * np.pi, qd, qdd), rbd.inverse_dynamics(q, qd, qdd),
                               rtol=1e-9, atol=1e-9)  # a turn later, the same torque
    for a, b in zip(rbd.inverse_dynamics_derivatives(q[:3], qd[:3], qdd[:3]),
                    ref.inverse_dynamics_derivatives(q[:3], qd[:3], qdd[:3])):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(rbd.mass_matrix(q[0]), ref.mass_matrix(q[0]), rtol=1e-12, atol=1e-12)

    # Pinocchio's own model of the continuous joints, at (cos q, sin q)
    native = pin.buildModelFromUrdf(str(cont))
    assert (native.nq, native.nv) == (5, 3)
    data = native.createData()
    for t in range(len(q)):
        x = np.array([np.cos(q[t, 0]), np.sin(q[t, 0]), np.cos(q[t, 1]), np.sin(q[t, 1]), q[t, 2]])
        np.testing.assert_allclose(rbd.inverse_dynamics(q[t], qd[t], qdd[t]), pin.rnea(native, data, x, qd[t], qdd[t]),
                                   rtol=1e-12, atol=1e-12)
    # limits and frames kept; a continuous joint has no position limits
    np.testing.assert_array_equal(rbd.pin_model.effortLimit, [30.0, 30.0, 30.0])
    np.testing.assert_array_equal(rbd.pin_model.lowerPositionLimit, [-np.inf, -np.inf, -3.0])
    assert [f.name for f in rbd.pin_model.frames] == [f.name for f in native.frames]
    for f, g in zip(rbd.pin_model.frames, native.frames):
        assert (f.parentJoint, f.type) == (g.parentJoint, g.type) and f.placement.isApprox(g.placement, 1e-15)


def test_angle_joints_keeps_the_model_and_leaves_the_callers(tmp_path: Path) -> None:
    native = pin.buildModelFromUrdf(str(write(tmp_path, "c.urdf", arm_urdf(("continuous", "revolute", "revolute")))))
    native.armature = np.array([0.1, 0.2, 0.3])
    native.damping = np.array([0.4, 0.5, 0.6])
    native.upperDryFrictionLimit = np.array([0.7, 0.8, 0.9])
    out = angle_joints(native)
    assert out.nq == out.nv == 3 and native.nq == 4
    for name in ("armature", "damping", "upperDryFrictionLimit", "effortLimit", "velocityLimit"):
        np.testing.assert_array_equal(getattr(out, name), getattr(native, name), err_msg=name)
    np.testing.assert_array_equal(out.gravity.linear, native.gravity.linear)
    # a rejected construction changes nothing of the caller's model, whatever its joints
    for model in (native, pin.buildModelFromUrdf(str(write(tmp_path, "r.urdf", arm_urdf(("revolute",) * 3))))):
        before = np.array(model.armature)
        with pytest.raises(ValueError, match=r"gravity must have shape \(3,\) \(x, y, z in m/s\^2\)"):
            RigidBodyModel(model, armature=[1.0, 2.0, 3.0], gravity=[1.0, 2.0])
        for bad in ("30", [True, 1.0, 2.0], [30.0, "abc", 1.0]):  # a sidecar's strings and booleans: not converted
            with pytest.raises(ValueError, match="torque_limits: expected numbers"):
                RigidBodyModel(model, torque_limits=bad)
        for good in ([np.array(30.0)] * 3, [np.float32(30), np.int64(30), 30], np.full(3, 30, np.int16), 30):
            np.testing.assert_array_equal(RigidBodyModel(model, torque_limits=good).torque_limits, [30.0] * 3)
        np.testing.assert_array_equal(model.armature, before)
        assert RigidBodyModel(model, armature=[1.0, 2.0, 3.0]).pin_model is not model
        np.testing.assert_array_equal(model.armature, before)


def test_locked_joints_are_welded_at_their_positions(tmp_path: Path) -> None:
    urdf = write(tmp_path, "gripper.urdf", arm_urdf(("continuous", "revolute", "revolute"), fingers="prismatic"))
    assert RigidBodyModel.from_urdf(urdf).dof == 5
    q, qd, qdd = states(15, seed=1)
    for locked, at in ((None, (0.0, 0.0)), ({"finger1": 0.03, "finger2": 0.01}, (0.03, 0.01))):
        welded = RigidBodyModel.from_urdf(write(tmp_path, "welded.urdf",
                                                arm_urdf(("revolute",) * 3, fingers="fixed", at=at)))
        with pytest.warns(UserWarning, match="no sidecar"):
            rbd = load_nominal(urdf, joints=["j1", "j2", "j3"], locked=locked)
        assert rbd.dof == 3 and rbd.joint_names == ("j1", "j2", "j3")
        assert rbd.locked == {"finger1": at[0], "finger2": at[1]}
        np.testing.assert_allclose(rbd.inverse_dynamics(q, qd, qdd), welded.inverse_dynamics(q, qd, qdd),
                                   rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(rbd.torque_limits, [30.0] * 3)  # the kept joints' <limit>s
        assert "locked={'finger1'" in repr(rbd)
    with pytest.warns(UserWarning, match="no sidecar"):  # locked= alone: the model's joints are the others
        alone = load_nominal(urdf, locked={"finger1": 0.03, "finger2": 0.01})
    assert alone.joint_names == ("j1", "j2", "j3")
    np.testing.assert_array_equal(alone.inverse_dynamics(q, qd, qdd), rbd.inverse_dynamics(q, qd, qdd))


def test_a_joint_with_equal_limits_locks_anywhere(tmp_path: Path) -> None:
    """lower = upper (URDF's default of 0 and 0: no limits stated) is no limit, as for the fit's limits note; a
    joint with limits is still held within them."""
    text = arm_urdf(("revolute",) * 3).replace('lower="-3" upper="3"', 'lower="0" upper="0"', 1)
    assert text.count('lower="0" upper="0"') == 1
    urdf = write(tmp_path, "zero.urdf", text)
    assert RigidBodyModel.from_urdf(urdf, joints=["j2", "j3"], locked={"j1": 0.5}).locked == {"j1": 0.5}
    with pytest.raises(ValueError, match=r"locked: 'j2': expected a finite position within the joint's limits"):
        RigidBodyModel.from_urdf(urdf, joints=["j1", "j3"], locked={"j2": 3.5})


def test_a_joint_with_inverted_limits_is_named_and_unchecked(tmp_path: Path) -> None:
    """lower > upper (a mistake in the URDF, which Pinocchio keeps): a warning names the file and the joint, and
    its limits are not checked, as for equal limits; a URDF without such a joint says nothing."""
    text = arm_urdf(("revolute",) * 3).replace('lower="-3" upper="3"', 'lower="1" upper="-1"', 1)
    urdf = write(tmp_path, "inverted.urdf", text)
    with pytest.warns(UserWarning, match=r"inverted\.urdf'.*lower limit > upper limit.*'j1' \(1 > -1\)$"):
        rbd = RigidBodyModel.from_urdf(urdf, joints=["j2", "j3"], locked={"j1": 2.0})
    assert rbd.locked == {"j1": 2.0}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        RigidBodyModel.from_urdf(write(tmp_path, "arm.urdf", arm_urdf(("revolute",) * 3)))


def test_a_joint_locked_mid_chain_is_held_still(tmp_path: Path) -> None:
    """Locking j2 at 0.4 rad: the other joints' torques are the full model's with j2 at 0.4, at rest."""
    urdf = write(tmp_path, "arm.urdf", arm_urdf(("continuous", "revolute", "revolute")))
    full = RigidBodyModel.from_urdf(urdf)
    rbd = RigidBodyModel.from_urdf(urdf, joints=["j1", "j3"], locked={"j2": 0.4})
    assert rbd.joint_names == ("j1", "j3") and rbd.locked == {"j2": 0.4}
    q, qd, qdd = states(10, seed=4)
    ins = np.column_stack
    ref = full.inverse_dynamics(ins([q[:, 0], np.full(10, 0.4), q[:, 2]]), ins([qd[:, 0], np.zeros(10), qd[:, 2]]),
                                ins([qdd[:, 0], np.zeros(10), qdd[:, 2]]))
    np.testing.assert_allclose(rbd.inverse_dynamics(q[:, [0, 2]], qd[:, [0, 2]], qdd[:, [0, 2]]), ref[:, [0, 2]],
                               rtol=1e-12, atol=1e-12)


def test_joint_selection_errors(tmp_path: Path) -> None:
    urdf = write(tmp_path, "gripper.urdf", arm_urdf(("revolute",) * 3, fingers="prismatic"))
    bad = [
        ({"joints": ["j1", "j2", "nope"]}, r"joints: \['nope'\] are not joints of the URDF"),
        ({"joints": ["j2", "j1", "j3"]}, r"in the URDF model's order \(depth first from the base\), "
                                         r"\['j1', 'j2', 'j3'\]; got \['j2', 'j1', 'j3'\]"),
        ({"joints": "j1"}, "joints: expected a list of joint names, got the string 'j1'"),
        ({"joints": ["j1", "j2"], "locked": {"j3": 5.0}}, r"locked: 'j3': expected a finite position within the "
                                                         r"joint's limits \[-3, 3\], got 5.0"),
        ({"locked": [("finger1", 0.0)]}, "locked: expected a mapping"),
        ({"joints": ["j1", "j1"]}, "distinct joint names"),
        ({"joints": []}, "distinct joint names"),
        ({"joints": ["j1", "j2", "j3"], "locked": {"j3": 0.1}}, "locked: 'j3' is one of the model's joints"),
        ({"joints": ["j1", "j2", "j3"], "locked": {"hand": 0.1}}, r"locked: \['hand'\] are not joints of the URDF"),
        ({"joints": ["j1", "j2", "j3"], "locked": {"finger1": float("nan")}}, "locked: 'finger1': expected a finite"),
        ({"joints": ["j1", "j2", "j3"], "locked": {"finger1": "open"}}, "locked: 'finger1': expected a number"),
    ]
    for kwargs, match in bad:
        with pytest.raises(ValueError, match=match):
            RigidBodyModel.from_urdf(urdf, **kwargs)
    with pytest.raises(ValueError, match=r"expected 3 joints, URDF .* has 5 \(j1, j2, j3, finger1, finger2\); "
                                         r"name the model's joints with joints="):
        RigidBodyModel.from_urdf(urdf, dof=3)
    with pytest.raises(ValueError, match=r"expected 3 joints, URDF .* less its locked joints \(j3, finger1, finger2\) "
                                         r"has 2 \(j1, j2\)"):
        RigidBodyModel.from_urdf(urdf, dof=3, joints=["j1", "j2"])

    floating = write(tmp_path, "floating.urdf", arm_urdf(("revolute",) * 3).replace(
        '<joint name="j1" type="revolute">', '<joint name="j1" type="floating">'))
    with pytest.raises(ValueError, match=r"URDF '.*floating.urdf': joints \['j1'\] have more than one position"):
        RigidBodyModel.from_urdf(floating)
    welded = write(tmp_path, "welded.urdf", '<robot name="w"><link name="a"/><link name="b"/><joint name="f" '
                   'type="fixed"><parent link="a"/><child link="b"/></joint></robot>')
    with pytest.raises(ValueError, match=r"welded\.urdf': no degrees of freedom \(no revolute, continuous or"):
        RigidBodyModel.from_urdf(welded)


def _log(urdf_text: str, n: int, seed: int) -> DynamicsData:
    """Torques of the arm of ``urdf_text`` along smooth motions (segments of n rows at 20 Hz)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 20.0
    w, ph = rng.uniform(0.5, 1.5, 3), rng.uniform(0, 6, 3)
    q = 0.8 * np.sin(w * t[:, None] + ph)
    qd = 0.8 * w * np.cos(w * t[:, None] + ph)
    qdd = -0.8 * w**2 * np.sin(w * t[:, None] + ph)
    ref = RigidBodyModel(pin.buildModelFromXML(urdf_text))
    tau = ref.inverse_dynamics(q, qd, qdd) + 0.3 * qd + 0.01 * rng.standard_normal(q.shape)
    return DynamicsData(q=q, qd=qd, qdd=qdd, tau=tau, t=t)


def test_a_model_with_locked_joints_saves_and_loads(tmp_path: Path) -> None:
    urdf = write(tmp_path, "gripper.urdf", arm_urdf(("continuous", "revolute", "revolute"), fingers="prismatic"))
    data = _log(arm_urdf(("revolute",) * 3, fingers="fixed", at=(0.02, 0.02)), 60, seed=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rbd = load_nominal(urdf, joints=["j1", "j2", "j3"], locked={"finger1": 0.02, "finger2": 0.02})
    model = make_model("sp-standard", 3, rbd, gp_config=GPFitConfig(n_restarts=1, seed=0))
    model.fit(data)
    model.save(tmp_path / "m.npz")
    urdf.unlink()  # the file embeds the URDF and the locked joints
    loaded = load_model(tmp_path / "m.npz")
    assert loaded.rbd.locked == {"finger1": 0.02, "finger2": 0.02} and loaded.rbd.joint_names == ("j1", "j2", "j3")
    q, qd, qdd = data.q[:10], data.qd[:10], data.qdd[:10]
    np.testing.assert_allclose(loaded.predict(q, qd, qdd)[0], model.predict(q, qd, qdd)[0], rtol=1e-12, atol=1e-12)

    z = dict(np.load(tmp_path / "m.npz"))
    for damaged, match in (("{", "rbd/joints_json: not valid JSON"), ("[]", "rbd/joints_json: expected an object")):
        np.savez(tmp_path / "bad.npz", **{**z, "rbd/joints_json": np.array(damaged)})
        with pytest.raises(ValueError, match=match):
            load_model(tmp_path / "bad.npz")
    # every damaged rbd/* entry is named (a JSON error, or an attribute error of a list, named nothing)
    for key, damaged, match in (("rbd/limits_json", np.array("{x"), "rbd/limits_json: not valid JSON"),
                                ("rbd/limits_json", np.array("[1]"), "rbd/limits_json: expected a JSON object"),
                                ("rbd/meta_json", np.array("[1]"), "rbd/meta_json: expected a JSON object"),
                                ("rbd/armature", np.array(["a", "b", "c"]), "rbd/armature: expected real numbers"),
                                ("rbd/gravity", np.array([0.0, 0.0]), r"rbd/\*: the embedded .*grav")):
        np.savez(tmp_path / "bad.npz", **{**z, key: damaged})
        with pytest.raises(ValueError, match=f"bad.npz: {match}"):
            load_model(tmp_path / "bad.npz")
    # config fields of the wrong kind: named, not converted ("no" was True, 5.7 was 5)
    cfg = json.loads(str(z["config_json"]))
    for field, value in (("train_on_predicted", "no"), ("dof", 3.0), ("where", [[0, 5.7]] * len(cfg["where"]))):
        np.savez(tmp_path / "bad.npz", **{**z, "config_json": np.array(json.dumps({**cfg, field: value}))})
        with pytest.raises(ValueError, match=f"config_json: .*{field}: expected"):
            load_model(tmp_path / "bad.npz")
    np.savez(tmp_path / "bad.npz", **{**z, "config_json": np.array(json.dumps({**cfg, "dof": 4}))})
    with pytest.raises(ValueError, match=r"config_json.dof: 4 joints, but the embedded rigid-body model \(rbd/urdf\) "
                                         r"has 3 \(j1, j2, j3\)"):
        load_model(tmp_path / "bad.npz")


def _csv_log(folder: Path, data: DynamicsData) -> Path:
    log = folder / "train.csv"
    with log.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t", *(f"{g}{j}" for g in ("q", "qd", "qdd", "tau") for j in (1, 2, 3))])
        w.writerows(np.column_stack([data.t, data.q, data.qd, data.qdd, data.tau]).tolist())
    return log


def test_fit_command_takes_joints_and_lock(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    urdf = write(tmp_path, "gripper.urdf", arm_urdf(("continuous", "revolute", "revolute"), fingers="prismatic"))
    log = _csv_log(tmp_path, _log(arm_urdf(("revolute",) * 3, fingers="fixed", at=(0.04, 0.04)), 60, seed=3))
    base = ["--data", str(log), "--urdf", str(urdf), "--model", "sp-standard", "--restarts", "1"]

    assert fit_main([*base, "--out", str(tmp_path / "m0.npz")]) == 2
    err = capsys.readouterr().err
    assert "the URDF has 5 joints" in err and "the log" in err and "name the log's joints with --joints" in err

    out = tmp_path / "m.npz"
    assert fit_main([*base, "--out", str(out), "--joints", "j1,j2,j3", "--lock", "finger1=0.04,finger2=0.04"]) == 0
    err = capsys.readouterr().err
    assert "3 joints: j1, j2, j3; finger1 locked at 0.04; finger2 locked at 0.04" in err
    assert load_model(out).rbd.locked == {"finger1": 0.04, "finger2": 0.04}

    for extra, match in ((["--lock", "finger1:0.04"], "--lock: expected NAME=Q pairs"),  # argparse: exit 2
                         (["--lock", "finger1=inf"], "--lock: expected NAME=Q pairs"),
                         (["--lock", "finger1=0.01,finger1=0.02"], "--lock: 'finger1' is given twice"),
                         (["--joints", "j1,,j3"], "--joints: expected joint names")):
        with pytest.raises(SystemExit) as exit_info:
            fit_main([*base, "--out", str(tmp_path / "x.npz"), *extra])
        assert exit_info.value.code == 2 and match in capsys.readouterr().err
    assert fit_main([*base, "--out", str(tmp_path / "x.npz"), "--joints", "j3,j2,j1"]) == 2  # the library's check
    assert "--joints: list them in the URDF model's order" in capsys.readouterr().err
    assert fit_main([*base, "--out", str(tmp_path / "x.npz"), "--joints", "j1,j2,j3", "--lock", "j3=0"]) == 2
    assert "--lock: 'j3' is one of the model's joints (--joints names them)" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        fit_main(["--data", str(log), "--model", "np-standard", "--out", str(tmp_path / "x.npz"),
                  "--joints", "j1,j2,j3"])
    assert "--joints: chooses joints of the URDF; it needs --urdf" in capsys.readouterr().err
    assert not (tmp_path / "x.npz").exists()


def _mimic_gripper(tmp_path: Path, relation: str = 'multiplier="0.5" offset="0.005"') -> Path:
    """The gripper arm with finger2 a URDF mimic joint of finger1."""
    text = arm_urdf(("continuous", "revolute", "revolute"), fingers="prismatic")
    head = '<joint name="finger2" type="prismatic">'
    return write(tmp_path, "mimic.urdf", text.replace(head, f'{head}<mimic joint="finger1" {relation}/>'))


def test_a_locked_mimic_joint_follows_its_primary(tmp_path: Path) -> None:
    """finger2 = 0.5 finger1 + 0.005: locking finger1 at 0.02 puts finger2 at 0.015, the welded reference's."""
    urdf = _mimic_gripper(tmp_path)
    welded = RigidBodyModel.from_urdf(write(tmp_path, "welded.urdf",
                                            arm_urdf(("revolute",) * 3, fingers="fixed", at=(0.02, 0.015))))
    q, qd, qdd = states(12, seed=5)
    for locked in ({"finger1": 0.02}, {"finger1": 0.02, "finger2": 0.015}):  # left out, or given as it follows
        rbd = RigidBodyModel.from_urdf(urdf, joints=["j1", "j2", "j3"], locked=locked)
        assert rbd.locked == pytest.approx({"finger1": 0.02, "finger2": 0.015}, abs=1e-15)
        np.testing.assert_allclose(rbd.inverse_dynamics(q, qd, qdd), welded.inverse_dynamics(q, qd, qdd),
                                   rtol=1e-12, atol=1e-12)
    # a model file keeps the locked positions and loads them again, without the URDF file
    model = make_model("sp-standard", 3, rbd, gp_config=GPFitConfig(n_restarts=1, seed=0))
    model.fit(_log(arm_urdf(("revolute",) * 3, fingers="fixed", at=(0.02, 0.015)), 40, seed=6))
    model.save(tmp_path / "m.npz")
    urdf.unlink()
    assert load_model(tmp_path / "m.npz").rbd.locked == rbd.locked
    # the URDF's defaults: multiplier 1, offset 0
    from cascgp.rbd_joints import mimic_joints

    assert mimic_joints(_mimic_gripper(tmp_path, "").read_text()) == {"finger2": ("finger1", 1.0, 0.0)}
    assert mimic_joints(None) == {} and mimic_joints("not xml") == {}


_HALF = 'multiplier="0.5" offset="0.005"'


def test_a_mimic_joint_follows_without_joints_and_in_a_namespaced_urdf(tmp_path: Path) -> None:
    """locked= alone: the mimic joint of a locked joint is locked too; a URDF with a default XML namespace too."""
    urdf = _mimic_gripper(tmp_path)
    alone = RigidBodyModel.from_urdf(urdf, locked={"finger1": 0.02})
    assert alone.joint_names == ("j1", "j2", "j3")
    assert alone.locked == pytest.approx({"finger1": 0.02, "finger2": 0.015}, abs=1e-15)
    spaced = urdf.read_text().replace('<robot name="arm">', '<robot name="arm" xmlns="http://example.org/urdf">')
    from cascgp.rbd_joints import mimic_joints

    assert mimic_joints(spaced) == {"finger2": ("finger1", 0.5, 0.005)}
    assert RigidBodyModel.from_urdf_text(spaced, joints=["j1", "j2", "j3"], locked={"finger1": 0.02}).locked == \
        alone.locked


@pytest.mark.parametrize("kwargs, match, locked", [
    # a position given otherwise than the relation says is used, with a warning (model files saved before)
    ({"joints": ["j1", "j2", "j3"], "locked": {"finger1": 0.02, "finger2": 0.03}},
     r"locked: 'finger2' mimics 'finger1' \(multiplier 0.5, offset 0.005\), which puts it at 0.015; it is locked "
     r"at 0.03 as given", {"finger1": 0.02, "finger2": 0.03}),
    ({"joints": ["j1", "j2", "j3", "finger1"], "locked": {"finger2": 0.01}},
     r"locked: 'finger2' mimics 'finger1', one of the model's joints, so it moves with it; it is locked at 0.01",
     {"finger2": 0.01}),
    ({"locked": {"finger2": 0.01}}, r"'finger2' mimics 'finger1', one of the model's joints", {"finger2": 0.01}),
])
def test_a_mimic_position_given_otherwise_is_used_with_a_warning(tmp_path: Path, kwargs: dict, match: str,
                                                                 locked: dict) -> None:
    with pytest.warns(UserWarning, match=match):
        rbd = RigidBodyModel.from_urdf(_mimic_gripper(tmp_path), **kwargs)
    assert rbd.locked == locked


@pytest.mark.parametrize("relation, kwargs, match", [
    ('multiplier="1" offset="0.01"', {"joints": ["j1", "j2", "j3"], "locked": {"finger1": 0.035}},  # 0.045 > 0.04
     r"locked: 'finger2': expected a finite position within the joint's limits \[0, 0.04\], got 0.045 \(from "
     r"'finger1', which it mimics\)"),
])
def test_mimic_joint_errors(tmp_path: Path, relation: str, kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        RigidBodyModel.from_urdf(_mimic_gripper(tmp_path, relation), **kwargs)


def test_fit_command_notes_a_mimic_position_given_otherwise(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                                            ) -> None:
    log = _csv_log(tmp_path, _log(arm_urdf(("revolute",) * 3, fingers="fixed", at=(0.02, 0.03)), 40, seed=7))
    args = ["--data", str(log), "--urdf", str(_mimic_gripper(tmp_path)), "--model", "sp-standard", "--restarts", "1",
            "--out", str(tmp_path / "m.npz"), "--joints", "j1,j2,j3"]
    assert fit_main([*args, "--lock", "finger1=0.02,finger2=0.03"]) == 0
    err = capsys.readouterr().err
    assert "note: --lock: 'finger2' mimics 'finger1' (multiplier 0.5, offset 0.005), which puts it at 0.015" in err
    assert "finger1 locked at 0.02; finger2 locked at 0.03" in err
    assert fit_main([*args, "--lock", "finger1=0.02"]) == 0
    assert "finger1 locked at 0.02; finger2 locked at 0.015)" in capsys.readouterr().err
