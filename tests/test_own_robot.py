"""End to end on a robot that is not the Jaco: a 3-joint URDF arm without sidecar JSON, its logs as CSV, and the
``cascgp fit`` / ``evaluate`` / ``predict`` commands run as subprocesses from a scratch folder.

The "real" robot differs from its URDF the way real robots do: a payload on the last link and joint friction
(viscous + smoothed Coulomb), plus measurement noise. The semi-parametric model must beat the URDF's rigid-body
model on held-out data.
"""

from __future__ import annotations

import csv
import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from cascgp.data import DynamicsData
from cascgp.logs import read_log, write_log
from cascgp.rbd import load_nominal

REPO = Path(__file__).resolve().parents[1]

_LINK = """  <link name="{name}">
    <inertial><origin xyz="{cx} 0 {cz}"/><mass value="{m}"/>
      <inertia ixx="{i}" iyy="{i}" izz="{i}" ixy="0" ixz="0" iyz="0"/></inertial>
  </link>"""
_JOINT = """  <joint name="{name}" type="revolute">
    <parent link="{parent}"/><child link="{child}"/><origin xyz="{x} 0 {z}"/><axis xyz="{axis}"/>
    <limit lower="-3" upper="3" effort="{effort}" velocity="4"/>
  </joint>"""


def arm_urdf() -> str:
    """A 3-joint arm: yaw at the base, then two pitch joints (links along x), masses 2 / 1.5 / 1 kg."""
    parts = ['<?xml version="1.0"?>', '<robot name="three_link_arm">', '  <link name="base"/>',
             _LINK.format(name="link1", cx=0, cz=0.15, m=2.0, i=0.02),
             _LINK.format(name="link2", cx=0.2, cz=0, m=1.5, i=0.02),
             _LINK.format(name="link3", cx=0.15, cz=0, m=1.0, i=0.01),
             _JOINT.format(name="yaw", parent="base", child="link1", x=0, z=0.1, axis="0 0 1", effort=40),
             _JOINT.format(name="shoulder", parent="link1", child="link2", x=0, z=0.3, axis="0 1 0", effort=40),
             _JOINT.format(name="elbow", parent="link2", child="link3", x=0.4, z=0, axis="0 1 0", effort=20),
             "</robot>"]
    return "\n".join(parts) + "\n"


PAYLOAD_KG, VISCOUS, COULOMB = 0.8, np.array([0.4, 0.6, 0.3]), np.array([0.3, 0.5, 0.2])


def true_torques(urdf_text: str, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
    """The "real" robot: the URDF plus a point-like payload at the tip of link 3 and joint friction."""
    model = pin.buildModelFromXML(urdf_text)
    model.inertias[3] = model.inertias[3] + pin.Inertia(PAYLOAD_KG, np.array([0.3, 0.0, 0.0]), 1e-4 * np.eye(3))
    data = model.createData()
    tau = np.array([pin.rnea(model, data, q[t], qd[t], qdd[t]) for t in range(len(q))])
    return tau + VISCOUS * qd + COULOMB * np.tanh(qd / 0.05)


def simulate(urdf_text: str, seconds: float, rate_hz: float, seed: int) -> DynamicsData:
    """Sum-of-sinusoid motions (exact qd, qdd), noisy measured positions and torques."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * rate_hz)) / rate_hz
    A = rng.uniform(0.2, 0.5, (3, 3))
    w = rng.uniform(0.3, 1.2, (3, 3)) * np.pi
    ph = rng.uniform(0, 2 * np.pi, (3, 3))
    arg = w[None] * t[:, None, None] + ph[None]
    q = rng.uniform(-0.5, 0.5, 3) + (A * np.sin(arg)).sum(1)
    qd = (A * w * np.cos(arg)).sum(1)
    qdd = (-A * w**2 * np.sin(arg)).sum(1)
    tau = true_torques(urdf_text, q, qd, qdd) + 0.02 * rng.standard_normal(q.shape)
    return DynamicsData(q=q + 1e-5 * rng.standard_normal(q.shape), qd=qd, qdd=qdd, tau=tau, t=t)


def cascgp(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    """Run the installed ``cascgp`` console script (``python -m cascgp_experiments.cli`` if it is not installed)."""
    exe = Path(sys.executable).with_name("cascgp")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "cascgp_experiments.cli"]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(REPO)}
    return subprocess.run([*cmd, *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def robot(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A scratch folder with robot.urdf (no sidecar), train.csv (no qd/qdd columns) and test.csv (all columns)."""
    folder = tmp_path_factory.mktemp("own_robot")
    text = arm_urdf()
    (folder / "robot.urdf").write_text(text)
    train = simulate(text, 40.0, 50.0, seed=1)
    with (folder / "train.csv").open("w", newline="") as f:  # what a robot's logger would write: t, q, tau
        w = csv.writer(f)
        w.writerow(["t", *(f"q{j}" for j in (1, 2, 3)), *(f"tau{j}" for j in (1, 2, 3))])
        w.writerows(np.column_stack([train.t, train.q, train.tau]).tolist())
    write_log(folder / "test.csv", simulate(text, 12.0, 50.0, seed=2))
    return folder


def test_urdf_without_sidecar_loads_with_a_warning(robot: Path) -> None:
    with pytest.warns(UserWarning, match=r"robot\.urdf.*no sidecar.*zero armature"):
        rbd = load_nominal(robot / "robot.urdf")
    assert rbd.dof == 3 and rbd.meta["sidecar"] is None
    np.testing.assert_array_equal(rbd.armature, np.zeros(3))
    np.testing.assert_array_equal(rbd.torque_limits, [40.0, 40.0, 20.0])
    np.testing.assert_array_equal(rbd.velocity_limits, [4.0, 4.0, 4.0])


def test_filled_derivatives_are_close_to_the_true_ones(robot: Path) -> None:
    text = (robot / "robot.urdf").read_text()
    exact = simulate(text, 40.0, 50.0, seed=1)
    log = read_log(robot / "train.csv")
    assert log.meta["qd_source"] == log.meta["qdd_source"] == "computed"
    inner = slice(10, -10)  # the Savitzky-Golay ends are less accurate
    for name in ("qd", "qdd"):
        err = getattr(log, name)[inner] - getattr(exact, name)[inner]
        scale = np.ptp(getattr(exact, name), axis=0)
        assert np.all(np.sqrt(np.mean(err**2, axis=0)) < 0.02 * scale), name


def test_fit_evaluate_predict_commands(robot: Path) -> None:
    fit = cascgp("fit", "--data", "train.csv", "--urdf", "robot.urdf", "--model", "sp-inward", "--out", "model.npz",
                 "--restarts", "2", "--rate-hz", "10", "--max-samples", "300", "--threads", "1", cwd=robot)
    assert fit.returncode == 0, fit.stderr
    assert "computed qd and qdd" in fit.stderr and "Savitzky-Golay" in fit.stderr  # the filter is reported
    assert "no sidecar" in fit.stderr

    moved = robot / "elsewhere"  # the model file embeds the URDF: evaluate from another folder, URDF gone
    moved.mkdir()
    (robot / "model.npz").rename(moved / "model.npz")
    (moved / "test.csv").write_bytes((robot / "test.csv").read_bytes())
    ev = cascgp("evaluate", "--model", "model.npz", "--data", "test.csv", "--json", "scores.json", cwd=moved)
    assert ev.returncode == 0, ev.stderr
    scores = json.loads((moved / "scores.json").read_text())
    sp, nominal = np.array(scores["nrmse"]["model"]), np.array(scores["nrmse"]["nominal"])
    assert sp.shape == nominal.shape == (3,) and np.all(np.isfinite(sp))
    assert np.all(sp < nominal), (sp, nominal)  # learning the payload and friction helps on every joint ...
    assert sp.mean() < 0.5 * nominal.mean(), (sp, nominal)  # ... and by a wide margin overall
    assert scores["data"]["n_scored"] == 600 and scores["model"]["name"] == "sp-inward"
    assert scores["notes"] == []  # a held-out log in the training log's units: nothing noted
    assert scores["command"][:2] == ["cascgp", "evaluate"] and scores["cascgp_version"]
    assert scores["model"]["saved_by"] == scores["cascgp_version"]  # the version that wrote the model file
    trained = scores["model"]["trained_on"]  # what the fit recorded: its command line, the log and the URDF
    assert trained["command"][:2] == ["cascgp", "fit"] and "--rate-hz" in trained["command"]
    assert trained["data"]["file"] == "train.csv" and trained["data"]["sha256"] == hashlib.sha256(
        (robot / "train.csv").read_bytes()).hexdigest()
    assert trained["data"]["n_rows"] > trained["data"]["n_used"] == 300  # --max-samples 300 kept 300 of the rows
    assert trained["urdf"] == {"file": "robot.urdf",
                               "sha256": hashlib.sha256((robot / "robot.urdf").read_bytes()).hexdigest()}
    assert "mean" in ev.stdout.splitlines()[-1]
    with (moved / "test.csv").open() as f:  # a joint whose test torque is constant: nRMSE undefined, named
        rows = list(csv.reader(f))
    col = rows[0].index("tau2")
    body = [",".join(r[:col] + ["1.5"] + r[col + 1:]) for r in rows[1:]]
    (moved / "flat.csv").write_text("\n".join([",".join(rows[0]), *body]) + "\n")
    flat = cascgp("evaluate", "--model", "model.npz", "--data", "flat.csv", cwd=moved)
    assert flat.returncode == 2 and "flat.csv: column 'tau2' is constant (1.5)" in flat.stderr, flat.stderr

    states = moved / "states.csv"  # predict needs no torque columns
    with states.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t", "q1", "q2", "q3"])
        w.writerows([[0.02 * k, 0.1, 0.2 + 0.01 * k, -0.3] for k in range(20)])
    pr = cascgp("predict", "--model", "model.npz", "--data", "states.csv", "--out", "pred.csv", cwd=moved)
    assert pr.returncode == 0, pr.stderr
    rows = list(csv.reader((moved / "pred.csv").open()))
    assert rows[0] == ["t", "tau1", "tau2", "tau3", "var1", "var2", "var3"]
    pred = np.array(rows[1:], dtype=float)
    assert pred.shape == (20, 7) and np.all(np.isfinite(pred)) and np.all(pred[:, 4:] >= 0)


def test_command_errors_are_one_line_with_status_2(robot: Path) -> None:
    (robot / "bad.csv").write_text("t,q1,q2,q3,tau1,tau2,tau3\n0,0,0,0,1,2,3\n0.02,0,zero,0,1,2,3\n")
    r = cascgp("fit", "--data", "bad.csv", "--model", "np-inward", "--out", "m.npz", cwd=robot)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith("cascgp fit: error: ") and "bad.csv" in last and "row 3" in last and "'q2'" in last
    assert not (robot / "m.npz").exists()
    r = cascgp("fit", "--data", "train.csv", "--model", "sp-inward", "--out", "m.npz", cwd=robot)
    assert r.returncode == 2 and "--urdf" in r.stderr and "Traceback" not in r.stderr
    r = cascgp("evaluate", "--model", "missing.npz", "--data", "test.csv", cwd=robot)
    assert r.returncode == 2 and r.stderr.startswith("cascgp evaluate: error: ") and "missing.npz" in r.stderr


def test_help() -> None:
    top = cascgp("--help", cwd=REPO)
    assert top.returncode == 0
    for name in ("fit", "evaluate", "predict"):
        assert f"  {name} " in top.stdout
        h = cascgp(name, "--help", cwd=REPO)
        assert h.returncode == 0 and h.stdout.startswith(f"usage: cascgp {name}"), h.stderr
    assert "RMSE_i / (max_i - min_i)" in " ".join(cascgp("evaluate", "--help", cwd=REPO).stdout.split())
    for name in ("evaluate", "predict", "fit"):  # the description wrapped to the terminal's usual width
        assert max(map(len, cascgp(name, "--help", cwd=REPO).stdout.splitlines())) <= 100
    from cascgp.gp import GPFitConfig

    fit_help = " ".join(cascgp("fit", "--help", cwd=REPO).stdout.split())
    assert f"(default: {GPFitConfig().n_restarts}, the library's" in fit_help


def test_module_form_runs_the_same_command() -> None:
    """``python -m cascgp_experiments.cli`` is the command without its console script."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    r = subprocess.run([sys.executable, "-m", "cascgp_experiments.cli", "--version"], cwd=REPO, env=env,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and r.stdout == cascgp("--version", cwd=REPO).stdout and r.stdout.startswith("cascgp ")
    r = subprocess.run([sys.executable, "-m", "cascgp_experiments.cli", "nonsense"], cwd=REPO, env=env,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "unknown command 'nonsense'" in r.stderr
