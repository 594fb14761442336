"""``cascgp fit`` / ``cascgp evaluate`` on real data: a slice of the IAS SARCOS set (7 joints, no URDF, NP model),
converted to the log formats of :mod:`cascgp.logs` (training log as CSV with segments, test log as ``.npz``).
Skipped when ``../shared/data/sarcos/ias_sarcos_data.mat`` is absent."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from tests.conftest import write_tiny_ias

from cascgp.logs import read_log, write_log
from cascgp.metrics import nrmse
from cascgp.sarcos import load_ias

REPO = Path(__file__).resolve().parents[1]


def cascgp(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    """Run the installed ``cascgp`` console script (``python -m cascgp_experiments.cli`` if it is not installed)."""
    exe = Path(sys.executable).with_name("cascgp")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "cascgp_experiments.cli"]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(REPO)}
    return subprocess.run([*cmd, *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=300)


def test_np_model_on_a_sarcos_slice(sarcos_dir: Path, tmp_path: Path) -> None:
    train, test = load_ias(sarcos_dir / "ias_sarcos_data.mat")
    train = train.take(np.arange(0, train.n_samples, 10))  # every 10th row: 5 Hz, segments kept
    test = test.take(np.linspace(0, test.n_samples - 1, 500).astype(int))
    write_log(tmp_path / "train.csv", train)
    write_log(tmp_path / "test.npz", test)
    back = read_log(tmp_path / "train.csv")
    np.testing.assert_array_equal(back.tau, train.tau)
    np.testing.assert_array_equal(back.segment, train.segment)

    fit = cascgp("fit", "--data", "train.csv", "--model", "np-inward", "--out", "model.npz", "--restarts", "2",
                 "--max-samples", "300", "--threads", "1", "--seed", "3", cwd=tmp_path)
    assert fit.returncode == 0, fit.stderr
    assert "computed" not in fit.stderr  # the log has qd and qdd columns: nothing to differentiate
    ev = cascgp("evaluate", "--model", "model.npz", "--data", "test.npz", "--json", "scores.json", cwd=tmp_path)
    assert ev.returncode == 0, ev.stderr
    scores = json.loads((tmp_path / "scores.json").read_text())
    model = np.array(scores["nrmse"]["model"])
    assert scores["nrmse"]["nominal"] is None and scores["model"]["name"] == "np-inward"
    assert model.shape == (7,) and np.all(np.isfinite(model))
    # baseline: predicting every joint's training-mean torque; the GP must at least halve its error on every joint
    baseline = nrmse(np.broadcast_to(train.tau.mean(0), test.tau.shape), test.tau)
    assert np.all(model < 0.5 * baseline), (model, baseline)
    assert np.all(model < 0.15), model


def test_fit_refuses_a_urdf_for_np_models(tmp_path: Path) -> None:
    (tmp_path / "robot.urdf").write_text("<robot name='x'/>")
    r = cascgp("fit", "--data", "x.csv", "--urdf", "robot.urdf", "--model", "np-standard", "--out", "m.npz",
               cwd=tmp_path)
    assert r.returncode == 2 and "--urdf" in r.stderr and "non-parametric" in r.stderr


def test_sarcos_command_runs_the_study_presets_sarcos_block(monkeypatch, tmp_path: Path, capsys) -> None:
    """``cascgp sarcos`` passes the study preset's SARCOS settings (``--quick``: the quick preset's), so that it
    computes the block ``cascgp study`` does; ``--restarts`` and ``--seed`` override them; it prints the table."""
    import cascgp_experiments.cli.sarcos as cli
    from cascgp_experiments.study import PRESETS

    seen: list[dict] = []

    def fake_run(path, out, **kw):
        seen.append(kw)
        scores = (("np-standard", 0.1), ("np-inward", 0.2))
        return {"grid_s": list(kw["grid"]), "n_cached_jobs": 0, "jobs": {"n_jobs": 9},
                "models": {m: {"nrmse_median": np.full((len(kw["grid"]), 7), v)} for m, v in scores}}

    rendered: list[dict] = []
    monkeypatch.setattr(cli, "run_sarcos", fake_run)
    monkeypatch.setattr(cli, "limit_threads", lambda n=1: None)  # the command's; not for the rest of the session
    monkeypatch.setattr("cascgp_experiments.plots.render_results", lambda res, out, claims: rendered.append(res) or [])
    mat = write_tiny_ias(tmp_path / "x.mat")
    for args, preset in ((["--quick"], PRESETS["quick"]), ([], PRESETS["full"])):
        cli.main(["--sarcos", str(mat), "--out", str(tmp_path / "o"), "--workers", "1", *args])
        kw = seen[-1]
        assert (kw["grid"], kw["n_subsets"], kw["n_restarts"], kw["seed"], kw["audit_fraction"]) == (
            preset.sarcos_grid, preset.sarcos_subsets, preset.n_restarts, preset.seed, preset.audit_fraction)
        out = capsys.readouterr().out
        assert f"| {preset.sarcos_grid[-1]:g} | 0.1000 | 0.2000 |" in out
        written = json.loads((tmp_path / "o" / "sarcos.json").read_text())
        assert written["grid_s"] == list(preset.sarcos_grid)
        # provenance like the study's results.json, the table as a file, the figure and claims from the block
        assert {"command", "versions", "machine", "started", "finished"} <= set(written["meta"])
        assert written["meta"]["reused"] == {"sarcos_jobs": [0, 9]}
        assert f"| {preset.sarcos_grid[-1]:g} | 0.1000 | 0.2000 |" in (tmp_path / "o" / "sarcos_table.md").read_text()
        assert rendered[-1]["sarcos"]["grid_s"] == list(preset.sarcos_grid)
    cli.main(["--sarcos", str(mat), "--out", str(tmp_path / "o"), "--workers", "1", "--restarts", "2", "--seed", "7"])
    assert (seen[-1]["n_restarts"], seen[-1]["seed"]) == (2, 7)


def test_sarcos_command_without_a_path_names_the_option_and_the_variable(monkeypatch, tmp_path: Path, capsys) -> None:
    """With no ``--sarcos``, no ``$CASCGP_SARCOS`` and no checkout copy, the error says how to give the file."""
    import cascgp_experiments.cli.sarcos as cli
    from cascgp_experiments.common import SARCOS_ENV

    monkeypatch.setattr(cli, "default_sarcos", lambda: None)
    with pytest.raises(SystemExit) as exc:
        cli.main(["--out", str(tmp_path / "o")])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "--sarcos: expected the path of ias_sarcos_data.mat" in err and f"${SARCOS_ENV}" in err
    assert "github.com/hanyas/mimo" in err  # where to get it
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("command", ["study", "sarcos"])
def test_a_file_that_is_not_the_ias_one_stops_the_command_before_it_runs(command: str, monkeypatch, tmp_path: Path,
                                                                        capsys) -> None:
    """A GPML SARCOS file or a file that is not MATLAB's, given by ``--sarcos`` or ``$CASCGP_SARCOS``: exit status 2
    and one line naming where the path came from and what was expected, before anything is written (the study
    used to fail with a traceback after its Jaco part)."""
    import importlib

    from scipy.io import savemat

    from cascgp_experiments.common import SARCOS_ENV

    cli = importlib.import_module(f"cascgp_experiments.cli.{command}")
    gpml = tmp_path / "sarcos_inv.mat"
    savemat(gpml, {"sarcos_inv": np.zeros((4, 28))})
    text = tmp_path / "train.csv"
    text.write_text("t,q1,tau1\n0,0,0\n")
    preset = ["--smoke"] if command == "study" else ["--quick"]
    cases = [(["--sarcos", str(gpml)], {}, ["--sarcos: ", "missing variable(s)", "'sarcos_inv' (T x 28)",
                                            "cascgp.load_gpml"]),
             (["--sarcos", str(text)], {}, ["--sarcos: ", "train.csv: not a readable MATLAB .mat file"]),
             ([], {SARCOS_ENV: str(gpml)}, [f"${SARCOS_ENV}: ", "expected the IAS SARCOS format"]),
             ([], {SARCOS_ENV: str(tmp_path / "nowhere.mat")}, [f"${SARCOS_ENV}: file not found: "])]
    for args, env, expected in cases:
        monkeypatch.delenv(SARCOS_ENV, raising=False)
        for k, v in env.items():
            monkeypatch.setenv(k, v)
        with pytest.raises(SystemExit) as exc:
            cli.main([*preset, "--out", str(tmp_path / "o"), *args])
        assert exc.value.code == 2
        err = capsys.readouterr().err
        for part in expected:
            assert part in err, (args, env, err)
        assert "Traceback" not in err and not (tmp_path / "o").exists()

