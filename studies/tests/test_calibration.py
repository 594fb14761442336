"""Tests of the calibration study (``docs/studies/calibration.md``): the input-noise and torque-floor terms, the
calibration and recalibration scores, the comparison of arms, and the command lines' error paths. The collections
here are a few seconds of simulation (well under a second each)."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]

pytest.importorskip("jaco_env.excitation")

from cascgp_experiments.collect import CollectConfig, collect  # noqa: E402
from tests.test_collect_options import TINY  # noqa: E402  (its fixture ``arms``: studies/tests/conftest.py)


def test_cli_rejects_data_with_collection_options(tmp_path: Path) -> None:
    run = subprocess.run([sys.executable, "-m", "studies.commands.calibration", "--data", str(tmp_path),
                          "--out", str(tmp_path), "--sensor-noise", "none"], cwd=REPO, capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 2 and "leave out --data" in run.stderr


def test_sensor_input_var_from_the_sensor_model_and_the_filter() -> None:
    from studies.calibration import sensor_input_var

    v = sensor_input_var(asdict(CollectConfig()), 6)
    assert v.shape == (6, 3)
    # q 5e-4 rad, qd 5e-3 rad/s; qdd: window 9, order 2 at 100 Hz, gain 1 / (60 dt^2) = 166.7 s^-2
    np.testing.assert_allclose(v[0], [5e-4**2, 5e-3**2, 5e-3**2 / (60 * 0.01**2)], rtol=1e-12)
    assert not sensor_input_var(asdict(CollectConfig(sensor_noise="none")), 6).any()
    assert sensor_input_var(asdict(CollectConfig(qdd_source="true")), 6)[:, 2].max() == 0.0
    old = {k: v for k, v in asdict(CollectConfig()).items() if k not in ("sensor_noise", "qdd_source")}
    np.testing.assert_array_equal(sensor_input_var(old, 6), v)
    with pytest.raises(ValueError, match="collection"):
        sensor_input_var(None, 6)
    # The stored standard deviations win over the env's defaults (a file read right if the defaults change).
    stored = {"q_std": 1e-3, "qd_std": 2e-2, "tau_std": 0.3}
    w = sensor_input_var(asdict(CollectConfig()), 6, stored)
    np.testing.assert_allclose(w[0], [1e-6, 4e-4, 4e-4 / (60 * 0.01**2)], rtol=1e-12)
    for bad in ({"q_std": 1e-3}, "0.1", {"q_std": -1.0, "qd_std": 0.0, "tau_std": 0.0}):
        with pytest.raises((ValueError, TypeError), match="sensor_std|SensorNoise"):
            sensor_input_var(asdict(CollectConfig()), 6, bad)


def test_calibration_scores_the_input_noise_variance(arms) -> None:
    from studies.calibration import calibration, sensor_input_var, summary_table

    train, test = arms["noisy"]
    iv = sensor_input_var(train.meta["collection"], train.dof)
    res = calibration(train, test, seconds=(1.0,), n_subsets=1, models=("np-inward", "sp-outward"), n_restarts=1,
                      input_var=iv)
    assert res["input_var"] == iv.tolist() and res["collection"]["sensor_noise"] == "default"
    for row in res["rows"]:
        # more variance: the coverage can only rise
        assert np.all(np.array(row["coverage_input_noise"]) >= np.array(row["coverage_propagated"]))
        assert len(row["input_noise_std"]) == 6 and min(row["input_noise_std"]) >= 0
    assert "propagated + input noise" in summary_table(res) and "input-noise std" in summary_table(res)
    for row in res["rows"]:  # diagnostics: the rest of the training motion, the std factor for 95 %
        assert ("coverage_same_motion_rest" in row) == (row["n_same_motion_rest"] > 0)
        assert len(row["std_scale_for_level"]) == 6 and min(row["std_scale_for_level"]) >= 0
    plain = calibration(train, test, seconds=(1.0,), n_subsets=1, models=("np-inward",), n_restarts=1)
    assert "coverage_input_noise" not in plain["rows"][0] and "input noise" not in summary_table(plain)


def _fake_result(cov: list[list[float]]) -> dict:
    return {"summary": {f"m@{k}s": {"coverage_propagated": c, "coverage_mean_input": c} for k, c in enumerate(cov)}}


def test_compare_arms_counts_cells_in_the_band_and_paired_changes() -> None:
    from studies.calibration import combined_table, compare_arms

    a = _fake_result([[0.80, 0.85], [0.90, 0.99]])
    b = _fake_result([[0.90, 0.95], [0.91, 0.97]])
    lines = compare_arms({"a": a, "b": b}).splitlines()
    assert lines[2] == "| a | 4 | 0.875 | 0.800 - 0.990 | 1 | +0.000 |"
    assert lines[3] == "| b | 4 | 0.930 | 0.900 - 0.970 | 4 | +0.055 |"  # paired changes +.10 +.10 +.01 -.02
    assert "| m@1s | b | 0.910 | 0.970 |" in combined_table({"a": a, "b": b})
    with pytest.raises(ValueError, match="cells"):
        compare_arms({"a": a, "c": _fake_result([[0.9, 0.9]])})


def test_compare_cli_errors(tmp_path: Path) -> None:
    for args, msg in ((["noequals"], "NAME=DIR"), ([f"a={tmp_path}"], "no "),):
        run = subprocess.run([sys.executable, "-m", "studies.commands.calibration_compare", *args], cwd=REPO,
                             capture_output=True, text=True, timeout=120)
        assert run.returncode == 2 and msg in run.stderr, run.stderr


def test_sensor_torque_var_is_the_sensor_spec() -> None:
    from jaco_env import SensorNoise

    from studies.calibration import sensor_torque_var

    assert sensor_torque_var(asdict(CollectConfig())) == SensorNoise().tau_std ** 2 == pytest.approx(0.01)
    assert sensor_torque_var(asdict(CollectConfig()), {"q_std": 0.0, "qd_std": 0.0, "tau_std": 0.2}) == \
        pytest.approx(0.04)
    with pytest.raises(ValueError, match="noiseless"):
        sensor_torque_var(asdict(CollectConfig(sensor_noise="none")))
    with pytest.raises(ValueError, match="collection"):
        sensor_torque_var(None)


def test_calibration_with_the_sensor_noise_floor(arms) -> None:
    from studies.calibration import calibration, floor_effect, sensor_torque_var

    train, test = arms["noisy"]
    kw = dict(seconds=(1.0,), n_subsets=1, models=("np-inward",), n_restarts=1)
    base = calibration(train, test, **kw)
    fl = calibration(train, test, noise_var_floor=sensor_torque_var(train.meta["collection"]), **kw)
    assert fl["noise_var_floor"] == pytest.approx(0.01) and base["noise_var_floor"] is None
    assert min(fl["rows"][0]["noise_std"]) >= 0.1 * (1 - 1e-9)
    assert len(fl["rows"][0]["rmse"]) == 6 and min(fl["rows"][0]["rmse"]) > 0
    table = floor_effect(base, fl).splitlines()
    assert table[2].startswith("| all | 6 |") and len(table) == 5


def _fake_floor(cov: list[float], std: list[float], rmse: list[float]) -> dict:
    return {"summary": {"m@10s": {"coverage_propagated": cov, "rmse": rmse}},
            "rows": [{"model": "m", "seconds": 10.0, "subset": 0, "n_train": 100, "noise_std": std}]}


def test_floor_effect_splits_collapsed_and_other_cells() -> None:
    from studies.calibration import floor_effect

    base = _fake_floor([0.80, 0.85, 0.90], [0.001, 0.1, 0.1], [1.0, 2.0, 1.0])
    fl = _fake_floor([0.92, 0.85, 0.89], [0.1, 0.1, 0.1], [0.9, 2.0, 1.1])
    lines = floor_effect(base, fl).splitlines()
    assert lines[2] == "| all | 3 | 0.850 | 0.890 | 1 -> 1 | +0.000 | 1 / 1 / 1 | 1.000 (0.900 - 1.100) |"
    assert lines[3].startswith("| collapsed (a fit < 0.05 N m) | 1 | 0.800 | 0.920 | 0 -> 1 | +0.120 | 1 / 0 / 0 |")
    assert lines[4].startswith("| other | 2 | 0.875 | 0.870 | 1 -> 0 | -0.005 | 0 / 1 / 1 |")
    other = _fake_floor([0.8, 0.8, 0.8], [0.1, 0.1, 0.1], [1, 1, 1])
    other["rows"][0]["subset"] = 1
    with pytest.raises(ValueError, match="paired"):
        floor_effect(base, other)


def test_calibration_recalibrates_on_an_unseen_training_motion(arms, tmp_path: Path) -> None:
    from studies.calibration import calibration, recalibration_effect

    train, test, _ = collect(tmp_path, replace(TINY, n_subsets=10, subset_seconds=0.8), workers=1)
    res = calibration(train, test, seconds=(0.5,), n_subsets=2, models=("sp-inward",), n_restarts=1,
                      recalibrate=True)
    assert len(res["rows"]) == 2
    for row in res["rows"]:
        c = np.array(row["recal_scale"])
        prop, recal = np.array(row["coverage_propagated"]), np.array(row["coverage_recalibrated"])
        assert c.shape == (6,) and (c > 0).all()
        # a factor above 1 widens every interval (coverage cannot fall), below 1 narrows them
        assert (recal[c >= 1] >= prop[c >= 1]).all() and (recal[c <= 1] <= prop[c <= 1]).all()
    # the factor is fitted on the unseen motion n_subsets + k (not on the training motion k): recompute it with
    # the same fit (seeded, one thread) on each candidate motion
    from cascgp.gp import GPFitConfig
    from cascgp.metrics import std_scale_for_level
    from cascgp.models import make_model
    from cascgp.rbd import load_nominal
    from cascgp_experiments.collect import nominal_urdf_for

    rbd = load_nominal(nominal_urdf_for(train.meta))
    motions = train.split(10)
    for k, row in enumerate(res["rows"]):
        m = make_model("sp-inward", 6, rbd, gp_config=GPFitConfig(n_restarts=1)).fit(
            motions[k].subsample(10.0).first_seconds(0.5))

        def factor(motion, m=m):
            cal = motion.subsample(10.0)
            mean, var = m.predict(cal.q, cal.qd, cal.qdd, propagate=True)
            return std_scale_for_level(mean, var + m.noise_var, cal.tau)

        np.testing.assert_allclose(row["recal_scale"], factor(motions[2 + k]), rtol=1e-12)
        assert not np.allclose(row["recal_scale"], factor(motions[k]))
    table = recalibration_effect(res).splitlines()
    assert table[2].startswith("| propagated | 6 |") and table[3].startswith("| recalibrated | 6 |")
    for n_subsets, data in ((6, train), (1, arms["noisy"][0])):  # too few motions; one motion only
        with pytest.raises(ValueError, match="recalibrate"):
            calibration(data, test, seconds=(0.5,), n_subsets=n_subsets, models=("sp-inward",), n_restarts=1,
                        recalibrate=True)
    with pytest.raises(ValueError, match="recalibrated"):
        recalibration_effect(calibration(train, test, seconds=(0.5,), n_subsets=1, models=("sp-inward",),
                                         n_restarts=1))


def test_cli_recalibrate_needs_unseen_motions(tmp_path: Path) -> None:
    r = subprocess.run([sys.executable, "-m", "studies.commands.calibration", "--out", str(tmp_path), "--recalibrate",
                        "--subsets", "6"], cwd=REPO, capture_output=True, text=True)
    assert r.returncode == 2 and "--recalibrate" in r.stderr
