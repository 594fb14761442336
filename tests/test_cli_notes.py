"""The notes of ``cascgp fit`` / ``evaluate`` / ``predict`` that point at likely mistakes without stopping the command
(positions in degrees, a log far outside the training positions, too few rows, a ``-df`` model's rows without
history, a --rate-hz above the log's rate), and :mod:`cascgp.models.coverage` under them."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from tests.conftest import make_arm
from tests.test_own_robot import arm_urdf, cascgp, simulate

from cascgp.data import DynamicsData
from cascgp.gp import GPFitConfig
from cascgp.features import history_from_data
from cascgp.logs import read_log
from cascgp.models import MODEL_NAMES, load_model, make_model
from cascgp.models.coverage import fraction_in_training, fraction_outside, training_position_range, training_positions


def _write(path: Path, data: DynamicsData, degrees: bool = False) -> None:
    """``t, q1..q3, tau1..tau3`` (positions in degrees if asked: the mistake the notes catch)."""
    q = np.degrees(data.q) if degrees else data.q
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t", "q1", "q2", "q3", "tau1", "tau2", "tau3"])
        w.writerows(np.column_stack([data.t, q, data.tau]).tolist())


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("notes")
    text = arm_urdf()
    (folder / "robot.urdf").write_text(text)
    run = simulate(text, 12.0, 50.0, seed=1)  # train on its first 8 s, test on the last 4 s: the same motions
    train, test = run.take(np.arange(400)), run.take(np.arange(400, 600))
    _write(folder / "train.csv", train)
    _write(folder / "train_deg.csv", train, degrees=True)
    _write(folder / "test.csv", test)
    _write(folder / "test_deg.csv", test, degrees=True)
    _write(folder / "few.csv", train.take(np.arange(5)))
    with (folder / "two_joints.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t", "q1", "q2", "tau1", "tau2"])
        w.writerows(np.column_stack([train.t, train.q[:, :2], train.tau[:, :2]]).tolist())
    return folder


def test_training_position_range_and_fraction_outside(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    T = 50
    q = rng.uniform([-1.0, 0.0], [1.0, 0.5], (T, 2))
    d = DynamicsData(q=q, qd=rng.normal(size=(T, 2)), qdd=rng.normal(size=(T, 2)), tau=rng.normal(size=(T, 2)),
                     t=np.arange(T) * 0.02)
    arm = make_arm(2)
    for name in MODEL_NAMES:  # every variant, and the cascades fitted one joint at a time on predicted torques
        for predicted in (False, True) if "standard" not in name else (False,):
            m = make_model(name, 2, arm if name.startswith("sp") else None, train_on_predicted=predicted,
                           gp_config=GPFitConfig(n_restarts=1, max_iter=5)).fit(d)
            used = q[history_from_data(d, m.df_delta)[1]] if name.endswith("-df") else q  # rows with history
            np.testing.assert_array_equal(training_position_range(m), np.stack([used.min(0), used.max(0)], axis=1))
            if name == "sp-inward":
                m.save(tmp_path / "m.npz")  # read from the banks: a loaded model has it too
                np.testing.assert_array_equal(training_position_range(load_model(tmp_path / "m.npz", rbd=arm)),
                                              training_position_range(m))
    lo, hi = q.min(0), q.max(0)
    w = hi - lo
    probe = np.array([[lo[0] - 0.05 * w[0], hi[1]], [hi[0] + 0.2 * w[0], lo[1] - 2.0 * w[1]]])
    m = make_model("np-inward", 2, gp_config=GPFitConfig(n_restarts=1, max_iter=5)).fit(d)
    np.testing.assert_array_equal(fraction_outside(m, probe), [0.5, 0.5])  # a tenth of the width is inside
    np.testing.assert_array_equal(fraction_outside(m, probe, margin=1.0), [0.0, 0.5])
    with pytest.raises(ValueError, match=r"^q: expected shape \(T, 2\)"):
        fraction_outside(m, q[:, :1])
    np.testing.assert_array_equal(training_positions(m), q)  # in training order
    assert fraction_in_training(m, q[:10]) == 1.0 and fraction_in_training(m, q[:10] + 1e-15) == 0.0
    assert fraction_in_training(m, np.vstack([q[:1], q[:3] + 1.0])) == 0.25
    still = DynamicsData(q=np.column_stack([q[:, 0], np.full(T, 0.3)]), qd=d.qd, qdd=d.qdd, tau=d.tau, t=d.t)
    m = make_model("np-inward", 2, gp_config=GPFitConfig(n_restarts=1, max_iter=5)).fit(still)
    np.testing.assert_array_equal(fraction_outside(m, [[0.0, 0.3 + 1e-12]]), [0.0, 0.0])  # a joint held still


def test_fit_notes_degrees_and_a_rate_above_the_logs(logs: Path) -> None:
    r = cascgp("fit", "--data", "train_deg.csv", "--urdf", "robot.urdf", "--model", "sp-inward", "--out", "deg.npz",
               "--rate-hz", "1000", "--max-samples", "60", "--restarts", "1", cwd=logs)
    assert r.returncode == 0, r.stderr
    assert "note: --rate-hz 1000 keeps every row (the log's rate: about 50 Hz): all 400 rows kept" in r.stderr
    note = next(line for line in r.stderr.splitlines() if "outside the URDF's position limits" in line)
    assert all(f"q{j} " in note for j in (1, 2, 3)) and "([-3, 3])" in note and "must be in rad" in note
    r = cascgp("fit", "--data", "train.csv", "--urdf", "robot.urdf", "--model", "sp-inward", "--out", "rad.npz",
               "--max-samples", "60", "--restarts", "1", cwd=logs)
    assert r.returncode == 0 and "position limits" not in r.stderr and "note: --rate" not in r.stderr, r.stderr
    r = cascgp("evaluate", "--model", "rad.npz", "--data", "test_deg.csv", "--json", "deg.json", cwd=logs)
    assert r.returncode == 0, r.stderr  # a test log in degrees against a model fitted in radians: both notes
    notes = json.loads((logs / "deg.json").read_text())["notes"]
    assert [n.split(":")[0] for n in notes] == ["rows outside the URDF's position limits",
                                                "rows far outside the positions the model was trained on (more than "
                                                "the range's width beyond it)"]


def test_evaluate_and_predict_note_a_log_far_outside_the_training_positions(logs: Path) -> None:
    r = cascgp("fit", "--data", "train.csv", "--model", "np-inward", "--out", "np.npz", "--max-samples", "60",
               "--restarts", "1", cwd=logs)
    assert r.returncode == 0, r.stderr
    far = "far outside the positions the model was trained on"
    r = cascgp("evaluate", "--model", "np.npz", "--data", "test.csv", cwd=logs)
    assert r.returncode == 0 and far not in r.stderr and "in-sample" not in r.stderr, r.stderr  # no note
    r = cascgp("evaluate", "--model", "np.npz", "--data", "train.csv", "--json", "in.json", cwd=logs)
    assert r.returncode == 0 and "note: 60 of the log's 400 rows (15.0%) are the model's training rows" in r.stderr, (
        r.stderr)
    notes = json.loads((logs / "in.json").read_text())["notes"]  # the scores' file keeps what was noted
    assert len(notes) == 1 and notes[0].startswith("60 of the log's 400 rows (15.0%) are the model's training rows")
    # a model fitted on a few of the log's rows (10 of 400: under 5 % of them) holds all its training rows there
    r = cascgp("fit", "--data", "train.csv", "--model", "np-inward", "--out", "np10.npz", "--max-samples", "10",
               "--restarts", "1", cwd=logs)
    assert r.returncode == 0, r.stderr
    r = cascgp("evaluate", "--model", "np10.npz", "--data", "train.csv", cwd=logs)
    assert r.returncode == 0 and ("note: 10 of the log's 400 rows (2.5%) are the model's training rows (the same "
                                  "positions, bit for bit; 100% of its training rows are in the log)") in r.stderr, (
        r.stderr)
    for command, out in (("evaluate", ()), ("predict", ("--out", "pred.csv"))):
        r = cascgp(command, "--model", "np.npz", "--data", "test_deg.csv", *out, cwd=logs)
        assert r.returncode == 0, r.stderr
        note = next(line for line in r.stderr.splitlines() if far in line)
        assert "q1 " in note and "mean torque of the training log" in note and "another unit" in note


def test_fit_notes_few_rows_and_rows_without_history(logs: Path) -> None:
    r = cascgp("fit", "--data", "few.csv", "--model", "np-standard", "--out", "few.npz", "--restarts", "1", cwd=logs)
    assert r.returncode == 0, r.stderr
    assert "note: 5 rows for GPs of up to 9 inputs: too few to learn from" in r.stderr and "log more" in r.stderr
    r = cascgp("fit", "--data", "train.csv", "--model", "np-standard", "--out", "few.npz", "--max-samples", "4",
               "--restarts", "1", cwd=logs)
    assert r.returncode == 0 and "note: 4 rows for GPs of up to 9 inputs" in r.stderr, r.stderr
    assert "raise --max-samples" in r.stderr
    r = cascgp("fit", "--data", "train.csv", "--model", "np-inward-df", "--out", "df.npz", "--rate-hz", "25",
               "--restarts", "1", cwd=logs)
    assert r.returncode == 0, r.stderr
    n_train = load_model(logs / "df.npz").n_train
    log = read_log(logs / "train.csv")  # the rows without history are those of the whole log, left out first
    assert f"note: {(~history_from_data(log, 0.1)[1]).sum()} row(s) lack 0.2 s of history within their segment and " \
           "are left out" in r.stderr
    assert f"n_train={n_train})" in r.stdout and n_train == log.take(history_from_data(log, 0.1)[1]).subsample(
        25.0).n_samples  # every row kept has its history: none left out after subsampling
    r = cascgp("evaluate", "--model", "df.npz", "--data", "test.csv", cwd=logs)
    assert r.returncode == 0, r.stderr
    assert "190 rows of test.csv (10 row(s) without 0.2 s of history left out)" in r.stdout  # 0.2 s at 50 Hz


def test_a_urdf_with_more_joints_names_both_ways_out(logs: Path) -> None:
    r = cascgp("fit", "--data", "two_joints.csv", "--urdf", "robot.urdf", "--model", "sp-inward", "--out", "m.npz",
               cwd=logs)
    assert r.returncode == 2, r.stderr
    assert "name the log's joints with --joints, or lock the others with --lock NAME=Q" in r.stderr


def test_fit_takes_a_kernel_that_the_model_file_keeps(logs: Path) -> None:
    """``--kernel`` reaches every GP of the model and its file; an unknown one is refused before any work."""
    r = cascgp("fit", "--data", "train.csv", "--urdf", "robot.urdf", "--model", "sp-inward", "--out", "m32.npz",
               "--max-samples", "60", "--restarts", "1", "--kernel", "matern32", cwd=logs)
    assert r.returncode == 0, r.stderr
    model = load_model(logs / "m32.npz")
    assert model.gp_config.kernel == "matern32" and {P.kernel for P in model.posteriors()} == {"matern32"}
    r = cascgp("fit", "--data", "train.csv", "--urdf", "robot.urdf", "--model", "sp-inward", "--out", "m12.npz",
               "--kernel", "matern12", cwd=logs)
    assert r.returncode == 2 and "--kernel: expected one of ('matern52', 'matern32', 'rbf'), got 'matern12'" \
        in r.stderr and not (logs / "m12.npz").exists()


def test_an_npz_logs_derivatives_are_noted_as_computed_when_it_was_read(logs: Path) -> None:
    """A saved log holds qd and qdd; the note said they were computed because the file had "no such columns"."""
    read_log(logs / "train.csv").save(logs / "train.npz")
    r = cascgp("fit", "--data", "train.npz", "--urdf", "robot.urdf", "--model", "sp-standard", "--out", "npz.npz",
               "--max-samples", "40", "--restarts", "1", cwd=logs)
    assert r.returncode == 0, r.stderr
    assert "computed qd and qdd when the log was read with Savitzky-Golay" in r.stderr, r.stderr
    r = cascgp("fit", "--data", "train.csv", "--urdf", "robot.urdf", "--model", "sp-standard", "--out", "csv.npz",
               "--max-samples", "40", "--restarts", "1", cwd=logs)
    assert "computed qd and qdd (no such columns) with Savitzky-Golay" in r.stderr, r.stderr


def test_torques_beyond_twice_the_effort_limits_are_noted(logs: Path) -> None:
    """Torques logged in N mm were fitted without a word, and evaluate then showed an nRMSE of about 485."""
    train = read_log(logs / "train.csv")
    mm = DynamicsData(q=train.q, qd=train.qd, qdd=train.qdd, tau=1000.0 * train.tau, t=train.t)
    _write(logs / "train_mm.csv", mm)
    r = cascgp("fit", "--data", "train_mm.csv", "--urdf", "robot.urdf", "--model", "sp-standard", "--out", "mm.npz",
               "--max-samples", "40", "--restarts", "1", cwd=logs)
    assert r.returncode == 0, r.stderr
    note = next(line for line in r.stderr.splitlines() if "beyond twice the URDF's effort limits" in line)
    assert "tau1 " in note and "torques must be in N m" in note, note
    r = cascgp("evaluate", "--model", "mm.npz", "--data", "train_mm.csv", "--json", "mm.json", cwd=logs)
    assert r.returncode == 0, r.stderr
    notes = json.loads((logs / "mm.json").read_text())["notes"]
    assert any("beyond twice the URDF's effort limits" in n for n in notes), notes
    r = cascgp("fit", "--data", "train.csv", "--urdf", "robot.urdf", "--model", "sp-standard", "--out", "nm.npz",
               "--max-samples", "40", "--restarts", "1", cwd=logs)
    assert r.returncode == 0 and "effort limits" not in r.stderr, r.stderr
