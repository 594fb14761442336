"""Tests of cascgp.rbd (Pinocchio RNEA wrapper), cascgp_experiments.urdf_export and the nominal URDF
(cascgp_experiments.nominal_urdf, written by ``python -m scripts.generate_urdf``).

Reference: MuJoCo's inverse dynamics (``mj_inverse``) of the bare simulated arm with
armature, zero friction/damping and the constraint solver disabled (so joint limits and
self-contacts add nothing), i.e. pure rigid-body dynamics plus rotor inertia.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from cascgp.rbd import RigidBodyModel, load_nominal
from cascgp_experiments.urdf_export import sidecar_text
from cascgp_experiments import nominal_urdf as gen
from jaco_env import robot

REPO = Path(__file__).resolve().parents[1]
ASSET = REPO / "jaco_env" / "assets" / "jaco2_nominal.urdf"
TOL = 1e-8


def _write(tmp: Path, error: float, seed: int) -> Path:
    out = tmp / f"jaco_e{error}_s{seed}.urdf"
    gen.write(out, error=error, seed=seed)
    return out


@pytest.fixture(scope="module")
def tmp(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("rbd")


@pytest.fixture(scope="module")
def exact_urdf(tmp) -> Path:
    return _write(tmp, 0.0, 0)


@pytest.fixture(scope="module")
def exact(exact_urdf) -> RigidBodyModel:
    return load_nominal(exact_urdf)


@pytest.fixture(scope="module")
def mj():
    """Bare arm as the link-side torque sensors see it (the nominal sidecar's armature is zero): no
    armature, no friction, no damping, constraints off."""
    arm = robot.build_arm_mjcf(armature=None, frictionloss=None, damping=None)
    m = mujoco.MjModel.from_xml_string(arm.to_xml_string(), arm.get_assets())
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONSTRAINT
    return m, mujoco.MjData(m)


def _states(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    q = rng.uniform(0.0, 2 * np.pi, (n, 6))
    qd = rng.uniform(-2.0, 2.0, (n, 6))
    qdd = rng.uniform(-10.0, 10.0, (n, 6))
    return q, qd, qdd


def _mj_inverse(mj, q, qd, qdd) -> np.ndarray:
    m, d = mj
    out = np.empty_like(q)
    for t in range(q.shape[0]):
        d.qpos[:], d.qvel[:], d.qacc[:] = q[t], qd[t], qdd[t]
        mujoco.mj_inverse(m, d)
        out[t] = d.qfrc_inverse
    return out


# ---------------------------------------------------------------------------- reference equality
def test_rnea_equals_mujoco_inverse_dynamics(exact, mj):
    q, qd, qdd = _states(200)
    ref = _mj_inverse(mj, q, qd, qdd)
    tau = exact.inverse_dynamics(q, qd, qdd)
    assert tau.shape == (200, 6)
    assert np.max(np.abs(tau - ref)) < TOL
    # single-row path agrees with the batch path
    for t in range(5):
        np.testing.assert_array_equal(exact.inverse_dynamics(q[t], qd[t], qdd[t]), tau[t])


def test_gravity_matches_mujoco_bias_at_zero_velocity(exact, mj):
    m, d = mj
    q, _, _ = _states(50, seed=1)
    g = exact.gravity_torque(q)
    for t in range(q.shape[0]):
        d.qpos[:], d.qvel[:] = q[t], 0.0
        mujoco.mj_forward(m, d)
        assert np.max(np.abs(g[t] - d.qfrc_bias)) < TOL
    np.testing.assert_allclose(exact.inverse_dynamics(q, 0 * q, 0 * q), g, atol=1e-12)
    assert exact.gravity_torque(q[0]).shape == (6,)


def test_pinocchio_rnea_includes_armature(exact_urdf):
    """pin 4.1.0's rnea adds armature * qdd itself; the wrapper relies on it."""
    bare = RigidBodyModel.from_urdf(exact_urdf)
    arm = RigidBodyModel.from_urdf(exact_urdf, armature=robot.ARMATURE)
    np.testing.assert_array_equal(bare.armature, 0.0)
    np.testing.assert_array_equal(arm.armature, robot.ARMATURE)
    q, qd, qdd = _states(20, seed=2)
    diff = arm.inverse_dynamics(q, qd, qdd) - bare.inverse_dynamics(q, qd, qdd)
    np.testing.assert_allclose(diff, robot.ARMATURE * qdd, rtol=1e-12, atol=1e-10)
    # scalar armature broadcasts
    np.testing.assert_array_equal(RigidBodyModel.from_urdf(exact_urdf, armature=0.5).armature, 0.5)


def test_inverse_dynamics_derivatives_equal_central_differences(exact_urdf):
    """Pinocchio's analytic RNEA derivatives (armature included) against central differences of the torque."""
    arm = RigidBodyModel.from_urdf(exact_urdf, armature=robot.ARMATURE)
    q, qd, qdd = _states(4, seed=5)
    D = arm.inverse_dynamics_derivatives(q, qd, qdd)
    h = 1e-6
    for c in range(3):
        assert D[c].shape == (4, 6, 6)
        for k in range(6):
            hi, lo = [list((q, qd, qdd)) for _ in range(2)]
            step = np.zeros_like(q)
            step[:, k] = h
            hi[c], lo[c] = hi[c] + step, lo[c] - step
            fd = (arm.inverse_dynamics(*hi) - arm.inverse_dynamics(*lo)) / (2 * h)
            np.testing.assert_allclose(D[c][:, :, k], fd, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(D[2][0], arm.mass_matrix(q[0]), atol=1e-12)  # M(q) + diag(armature)
    single = arm.inverse_dynamics_derivatives(q[1], qd[1], qdd[1])
    for c in range(3):
        np.testing.assert_array_equal(single[c], D[c][1])
    with pytest.raises(ValueError, match="same shape"):
        arm.inverse_dynamics_derivatives(q, qd[:2], qdd)


def test_mass_matrix_consistent_with_rnea(exact, mj):
    m, d = mj
    q, qd, qdd = _states(5, seed=3)
    for t in range(5):
        M = exact.mass_matrix(q[t])
        np.testing.assert_allclose(M, M.T, atol=0)
        h = exact.inverse_dynamics(q[t], qd[t], 0 * qdd[t])
        np.testing.assert_allclose(M @ qdd[t] + h, exact.inverse_dynamics(q[t], qd[t], qdd[t]), atol=1e-10)
        d.qpos[:] = q[t]
        mujoco.mj_forward(m, d)
        full = np.empty((6, 6))
        mujoco.mj_fullM(m, d, full)
        np.testing.assert_allclose(M, full, atol=TOL)


def test_kinematics_agree_with_simulation(exact, mj):
    """Site frames of the URDF (Pinocchio frames) sit where MuJoCo puts the sites."""
    m, d = mj
    model, data = exact.pin_model, exact.pin_model.createData()
    q, _, _ = _states(10, seed=4)
    for t in range(10):
        d.qpos[:] = q[t]
        mujoco.mj_kinematics(m, d)
        pin.framesForwardKinematics(model, data, q[t])
        for s in range(m.nsite):
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SITE, s)
            oMf = data.oMf[model.getFrameId(name)]
            np.testing.assert_allclose(oMf.translation, d.site_xpos[s], atol=1e-12)
            np.testing.assert_allclose(oMf.rotation, d.site_xmat[s].reshape(3, 3), atol=1e-12)


def test_metadata(exact, exact_urdf):
    assert exact.dof == 6
    assert exact.joint_names == robot.JOINT_NAMES
    np.testing.assert_array_equal(exact.torque_limits, robot.TORQUE_LIMITS)
    np.testing.assert_array_equal(exact.velocity_limits, robot.VELOCITY_LIMITS)
    np.testing.assert_array_equal(exact.gravity, [0.0, 0.0, -9.81])
    assert exact.meta["calibration_error"] == 0.0 and exact.meta["seed"] == 0
    assert exact.meta["urdf"] == exact_urdf.name


# ---------------------------------------------------------------------------- calibration error
def _link_inertials(text: str) -> dict[str, tuple[float, np.ndarray]]:
    out = {}
    for link in ET.fromstring(text.split("\n", 1)[1]).iter("link"):
        inertial = link.find("inertial")
        if inertial is not None:
            com = np.array([float(x) for x in inertial.find("origin").get("xyz").split()])
            out[link.get("name")] = (float(inertial.find("mass").get("value")), com)
    return out


def test_calibration_error_is_bounded_seeded_and_changes_dynamics(tmp, exact):
    text0, _ = gen.generate(error=0.0, seed=0)
    text_a, side_a = gen.generate(error=0.1, seed=0)
    text_b, _ = gen.generate(error=0.1, seed=0)
    text_c, _ = gen.generate(error=0.1, seed=1)
    assert text_a == text_b  # deterministic for a fixed seed
    assert text_c != text_a
    assert side_a["calibration_error"] == 0.1 and side_a["seed"] == 0

    exact_links, err_links = _link_inertials(text0), _link_inertials(text_a)
    assert exact_links.keys() == err_links.keys()
    for name, (mass, com) in exact_links.items():
        mass_e, com_e = err_links[name]
        assert abs(mass_e / mass - 1.0) <= 0.1 + 1e-12, name
        assert np.all(np.abs(com_e - com) <= 0.1 * np.linalg.norm(com) + 1e-15), name
    assert any(abs(err_links[n][0] / m - 1) > 0.02 for n, (m, _) in exact_links.items())

    nominal = load_nominal(_write(tmp, 0.1, 0))
    (tmp / "again").mkdir()
    again = load_nominal(_write(tmp / "again", 0.1, 0))
    q, qd, qdd = _states(50, seed=5)
    tau_exact = exact.inverse_dynamics(q, qd, qdd)
    tau_nom = nominal.inverse_dynamics(q, qd, qdd)
    np.testing.assert_array_equal(tau_nom, again.inverse_dynamics(q, qd, qdd))
    g_exact, g_nom = exact.gravity_torque(q), nominal.gravity_torque(q)
    # differs by a calibration-sized amount: a few per cent of gravity torque, not noise, not 100%
    rel = np.abs(g_nom - g_exact)[:, :3].max() / np.abs(g_exact)[:, :3].max()
    assert 1e-3 < rel < 0.3
    assert np.max(np.abs(tau_nom - tau_exact)) > 1e-3


# ---------------------------------------------------------------------------- committed asset
def _numbers_and_skeleton(text: str) -> tuple[np.ndarray, str]:
    pattern = r"-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?"
    return np.array([float(x) for x in re.findall(pattern, text)]), re.sub(pattern, "#", text)


@pytest.mark.parametrize("link_inertials", sorted(gen.OUT_NAMES))
@pytest.mark.parametrize("suffix", [".urdf", ".json"])
def test_committed_asset_equals_regeneration(suffix, link_inertials):
    """The committed nominal models are what the script writes (error 0.1, seed 0): nobody hand-edits them."""
    asset = ASSET.with_name(gen.OUT_NAMES[link_inertials])
    text, sidecar = gen.generate(error=0.1, seed=0, urdf_name=asset.name, link_inertials=link_inertials)
    fresh = text if suffix == ".urdf" else sidecar_text(sidecar)
    committed = asset.with_suffix(suffix).read_text(encoding="utf-8")
    if committed != fresh:  # tolerate last-digit libm differences between machines, nothing else
        num_c, skel_c = _numbers_and_skeleton(committed)
        num_f, skel_f = _numbers_and_skeleton(fresh)
        assert skel_c == skel_f, f"{asset.with_suffix(suffix)} differs from `python -m scripts.generate_urdf`"
        np.testing.assert_allclose(num_c, num_f, rtol=1e-13, atol=1e-15)


def test_committed_asset_loads():
    rbd = load_nominal(ASSET, dof=6)
    assert rbd.dof == 6 and rbd.joint_names == robot.JOINT_NAMES
    # Link-side torque sensors: the nominal model of the sensed torque has no rotor inertia.
    np.testing.assert_array_equal(rbd.armature, np.zeros(robot.N_JOINTS))
    assert rbd.meta["calibration_error"] == 0.1 and rbd.meta["seed"] == 0
    meta = json.loads(ASSET.with_suffix(".json").read_text())
    assert meta == rbd.meta


# ---------------------------------------------------------------------------- error paths
def test_input_errors(exact):
    q = np.zeros(6)
    with pytest.raises(ValueError, match=r"q must have shape \(6,\) or \(T, 6\), got \(7,\)"):
        exact.inverse_dynamics(np.zeros(7), np.zeros(7), np.zeros(7))
    with pytest.raises(ValueError, match=r"qd must have shape"):
        exact.inverse_dynamics(q, np.zeros((2, 3, 6)), q)
    with pytest.raises(ValueError, match=r"same shape"):
        exact.inverse_dynamics(q, np.zeros((2, 6)), q)
    bad = q.copy()
    bad[3] = np.nan
    with pytest.raises(ValueError, match=r"qdd must be finite; first non-finite entry at index \(3,\)"):
        exact.inverse_dynamics(q, q, bad)
    with pytest.raises(ValueError, match=r"q must be finite.*\(1, 2\)"):
        exact.gravity_torque(np.array([[0.0] * 6, [0, 0, np.inf, 0, 0, 0]]))
    with pytest.raises(ValueError, match="q must have shape"):
        exact.gravity_torque(np.zeros((3, 5)))
    with pytest.raises(ValueError, match="mass_matrix"):
        exact.mass_matrix(np.zeros((2, 6)))


def test_construction_errors(tmp, exact_urdf):
    with pytest.raises(FileNotFoundError, match="URDF file not found"):
        RigidBodyModel.from_urdf(tmp / "missing.urdf")
    with pytest.raises(FileNotFoundError, match="URDF file not found"):
        load_nominal(tmp / "missing.urdf")
    with pytest.raises(ValueError, match="dof mismatch: expected 7 joints.*has 6"):
        RigidBodyModel.from_urdf(exact_urdf, dof=7)
    with pytest.raises(ValueError, match="dof mismatch"):
        load_nominal(exact_urdf, dof=7)
    with pytest.raises(ValueError, match=r"armature must have shape \(6,\)"):
        RigidBodyModel.from_urdf(exact_urdf, armature=[1.0, 2.0])
    with pytest.raises(ValueError, match="armature must be finite"):
        RigidBodyModel.from_urdf(exact_urdf, armature=[np.nan] * 6)
    with pytest.raises(ValueError, match=r"armature must be >= 0 \(rotor inertia"):
        RigidBodyModel.from_urdf(exact_urdf, armature=-0.1)
    rbd = RigidBodyModel.from_urdf(exact_urdf)
    for field in ("torque_limits", "velocity_limits"):
        with pytest.raises(ValueError, match=f"{field} must be > 0"):
            RigidBodyModel(rbd.pin_model, **{field: [1.0, 1.0, 0.0, 1.0, 1.0, 1.0]})

    lone = tmp / "lone" / "arm.urdf"
    lone.parent.mkdir()
    lone.write_text(exact_urdf.read_text())
    with pytest.warns(UserWarning, match=r"arm\.urdf.*has no sidecar JSON .*arm\.json.*zero armature"):
        bare = load_nominal(lone)
    assert bare.meta["sidecar"] is None and not bare.armature.any()
    lone.with_suffix(".json").write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        load_nominal(lone)
    side = json.loads(exact_urdf.with_suffix(".json").read_text())
    lone.with_suffix(".json").write_text(json.dumps({k: v for k, v in side.items() if k != "armature"}))
    with pytest.raises(ValueError, match="lacks the field 'armature'; a sidecar holds format_version"):
        load_nominal(lone)
    lone.with_suffix(".json").write_text(json.dumps({"armature": side["armature"]}))  # every missing field at once
    with pytest.raises(ValueError, match=r"lacks the fields 'format_version', 'torque_limits', 'velocity_limits', "
                                         r"'joint_names'; a sidecar holds"):
        load_nominal(lone)
    minimal = {k: side[k] for k in ("format_version", "joint_names", "armature")}
    lone.with_suffix(".json").write_text(json.dumps({**minimal, "torque_limits": None, "velocity_limits": None}))
    plain = load_nominal(lone)  # null limits: unknown; gravity: Pinocchio's default
    assert plain.torque_limits is None and plain.velocity_limits is None
    np.testing.assert_array_equal(plain.armature, side["armature"])
    np.testing.assert_array_equal(plain.gravity, [0.0, 0.0, -9.81])
    lone.with_suffix(".json").write_text(json.dumps({**side, "armature": [1.0] * 7}))
    with pytest.raises(ValueError, match=r"armature must have shape \(6,\)"):
        load_nominal(lone)
    lone.with_suffix(".json").write_text(json.dumps({**side, "format_version": 99}))
    with pytest.raises(ValueError, match="format_version"):
        load_nominal(lone)
    lone.with_suffix(".json").write_text(json.dumps({"format_version": 2, "joints": []}))  # a later layout
    with pytest.raises(ValueError, match=r"format_version must be one of \(1,\), got 2$"):
        load_nominal(lone)
    lone.with_suffix(".json").write_text(json.dumps({**side, "dof": 7}))
    with pytest.raises(ValueError, match="dof 7 does not match"):
        load_nominal(lone)
    # a sidecar of the whole arm with a joint locked: it said the URDF had 5 joints
    lone.with_suffix(".json").write_text(json.dumps({**side, "dof": 6}))
    first = side["joint_names"][0]
    with pytest.raises(ValueError, match=rf"dof 6 does not match the model's 5 joints \(the URDF's with {first} "
                                         r"locked: a sidecar lists the model's joints only\)"):
        load_nominal(lone, locked={first: 0.1})

    garbage = tmp / "garbage.urdf"
    garbage.write_text("<robot name='x'><link name='a'>")
    with pytest.raises(ValueError, match="cannot parse URDF"):
        RigidBodyModel.from_urdf(garbage)


def test_the_parsers_reason_is_in_the_error_not_on_stderr(tmp, exact_urdf, capfd):
    """urdfdom prints why it refuses a file to the process's stderr (a raw C++ line); the error message carries it
    (the line of the XML error) and nothing reaches stderr. A URDF that parses prints nothing extra."""
    bad = tmp / "bad.urdf"
    bad.write_text("<robot name='x'><link name='a'/>\n<oops\n")
    for build in (lambda: RigidBodyModel.from_urdf(bad), lambda: RigidBodyModel.from_urdf_text(bad.read_text())):
        with pytest.raises(ValueError, match=r"cannot parse .*\(urdfdom: .*XML_ERROR.*Line number=2"):
            build()
    assert capfd.readouterr().err == ""
    assert RigidBodyModel.from_urdf(exact_urdf).dof == RigidBodyModel.from_urdf_text(exact_urdf.read_text()).dof == 6
    assert capfd.readouterr().err == ""
    latin = tmp / "latin1.urdf"
    latin.write_bytes(b"<robot name='\xe9'/>")  # not UTF-8: an error naming the file, before any parse
    with pytest.raises(ValueError, match="cannot parse URDF .*latin1.urdf"):
        RigidBodyModel.from_urdf(latin)


def test_parses_in_threads_take_turns_and_leave_stderr_as_it_was(tmp, exact_urdf, monkeypatch):
    """fd 2 is the process's: parses in several threads, failing and succeeding, leave it where it pointed; where
    no temporary file can be made the parse runs uncaptured (same model, same error type)."""
    import os
    import tempfile
    from concurrent.futures import ThreadPoolExecutor

    bad = tmp / "bad_threads.urdf"
    bad.write_text("<robot name='x'><link name='a'/>\n<oops\n")
    before = os.fstat(2)

    def parse(i: int) -> str:
        try:
            return str(RigidBodyModel.from_urdf(exact_urdf if i % 2 else bad).dof)
        except ValueError as exc:
            return "urdfdom" if "urdfdom:" in str(exc) else str(exc)

    with ThreadPoolExecutor(4) as pool:
        assert sorted(set(pool.map(parse, range(16)))) == ["6", "urdfdom"]
    after = os.fstat(2)
    assert (after.st_dev, after.st_ino) == (before.st_dev, before.st_ino)

    def no_tmp(*args, **kwargs):
        raise OSError("no temporary folder")

    monkeypatch.setattr(tempfile, "TemporaryFile", no_tmp)
    assert RigidBodyModel.from_urdf(exact_urdf).dof == 6
    with pytest.raises(ValueError, match="cannot parse URDF"):
        RigidBodyModel.from_urdf(bad)


def test_generator_errors(tmp):
    for error in (-0.1, 1.0, float("nan")):
        with pytest.raises(ValueError, match="error must be a finite relative error"):
            gen.generate(error=error, seed=0)
    with pytest.raises(ValueError, match="seed must be a non-negative int"):
        gen.generate(error=0.1, seed=-1)
    with pytest.raises(ValueError, match=r"out must end in \.urdf"):
        gen.write(tmp / "x.xml", error=0.1, seed=0)


def test_generator_cli(tmp):
    out = tmp / "cli" / "arm.urdf"
    run = subprocess.run([sys.executable, "-m", "scripts.generate_urdf", "--out", str(out), "--error", "0.1",
                          "--seed", "0"], check=True, cwd=REPO, capture_output=True, text=True, timeout=120)
    assert "wrote" in run.stdout
    text, sidecar = gen.generate(error=0.1, seed=0, urdf_name="arm.urdf")
    assert out.read_text() == text
    assert json.loads(out.with_suffix(".json").read_text()) == sidecar


def test_single_state_fast_path_equals_the_checked_path_and_refuses_bad_input(exact):
    """A (N,) float64 state skips the input checks unless the torque is not finite: the same bits as the checked
    path (a list, or a strided view, goes through the checks), and NaN or inf still raise naming the field."""
    q, qd, qdd = _states(20, seed=3)
    for t in range(20):
        fast = exact.inverse_dynamics(q[t], qd[t], qdd[t])
        checked = exact.inverse_dynamics(q[t].tolist(), qd[t].tolist(), qdd[t].tolist())
        np.testing.assert_array_equal(fast, checked)
    wide = np.zeros((exact.dof, 2))
    wide[:, 0] = q[0]
    np.testing.assert_array_equal(exact.inverse_dynamics(wide[:, 0], qd[0], qdd[0]),
                                  exact.inverse_dynamics(q[0], qd[0], qdd[0]))
    for k, name in enumerate(("q", "qd", "qdd")):
        for bad in (np.nan, np.inf, -np.inf):
            args = [q[0].copy(), qd[0].copy(), qdd[0].copy()]
            args[k][1] = bad
            with pytest.raises(ValueError, match=rf"^{name} must be finite"):
                exact.inverse_dynamics(*args)
    # finite input whose products overflow (qd^2 of 1e600): a ValueError naming q, qd, qdd, not a NaN torque
    for huge in (qd[0] * 0 + 1e300, np.tile(qd[0] * 0 + 1e300, (2, 1))):
        zeros = np.zeros_like(huge)
        with pytest.raises(ValueError, match=r"^q, qd, qdd: the torque overflowed \(largest \|q\|, \|qd\|, \|qdd\|: "
                                             r"0, 1e\+300, 0\)"):
            exact.inverse_dynamics(zeros, huge, zeros)
