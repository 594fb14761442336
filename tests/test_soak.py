"""The soak (issue 12): a short real run (slow set) and its failure paths (fast: one short cycle each)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from cascgp_experiments.soak import SoakConfig, run_soak

# One short cycle: a few short episodes per env, one retrain.
TINY = dict(minutes=1e-4, max_steps=20, max_marbles=3, progress_s=0.0)


def test_tiny_budget_runs_one_cycle_and_reports(tmp_path: Path) -> None:
    res = run_soak(SoakConfig(**TINY), tmp_path, log=lambda s: None)
    assert res.passed and res.failure is None, res.failure
    assert res.cycles == 1 and res.makes == 2 and res.closes == 2
    assert res.episodes >= 2 and res.resets == res.episodes and res.steps >= res.episodes
    assert res.retrains == 1 and res.samples_appended > 0
    assert res.rss_start_mib > 0 and res.rss_peak_mib >= res.rss_end_mib > 0
    assert res.rss_after_warmup_mib is None  # shorter than the warm-up: growth not judged
    on_disk = json.loads((tmp_path / "soak.json").read_text())
    for key in ("steps", "episodes", "resets", "makes", "retrains", "rss_start_mib", "rss_end_mib", "rss_peak_mib"):
        assert on_disk[key] == getattr(res, key)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["soak.json"]  # scratch buffer and model removed


@pytest.mark.parametrize("fault, message", [
    ("nan-obs", r"non-finite observation \(Jaco\w+-v0 step"),
    ("nan-prediction", r"non-finite prediction mean \(retrain 1"),
    ("exception", r"RuntimeError: injected exception"),
])
def test_injected_failures_are_reported(tmp_path: Path, fault: str, message: str) -> None:
    res = run_soak(SoakConfig(**TINY, fault=fault), tmp_path, log=lambda s: None)
    assert not res.passed and res.failure
    assert re.search(message, res.failure), res.failure
    assert res.traceback and json.loads((tmp_path / "soak.json").read_text())["passed"] is False


def test_memory_growth_beyond_the_bound_fails(tmp_path: Path) -> None:
    """In a fresh process (the command line): inside the suite's long-lived process, memory that earlier tests
    freed can be returned to the system during the cycle and hide part of the injected 80 MiB."""
    r = _soak_cli(["--minutes", "0.0001", "--max-steps", "20", "--fault", "leak", "--rss-bound-mib", "40",
                   "--warmup-cycles", "0", "--out", str(tmp_path / "leak")])
    assert r.returncode == 1, r.stderr
    assert "resident memory grew by" in r.stderr and "bound of 40 MiB" in r.stderr, r.stderr


REPO = Path(__file__).resolve().parents[1]


def _soak_cli(args: list[str]) -> subprocess.CompletedProcess:
    """The command line, as a user runs it (tests do not import scripts/)."""
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    return subprocess.run([sys.executable, "-m", "scripts.soak", *args], cwd=REPO, env=env, capture_output=True,
                          text=True, timeout=300)


def test_cli_exit_codes_and_argument_errors(tmp_path: Path) -> None:
    ok = _soak_cli(["--minutes", "0.0001", "--max-steps", "20", "--out", str(tmp_path / "ok")])
    assert ok.returncode == 0 and "soak PASSED" in ok.stdout, ok.stderr
    bad = _soak_cli(["--minutes", "0.0001", "--max-steps", "20", "--fault", "nan-obs", "--out", str(tmp_path / "b")])
    assert bad.returncode == 1 and "soak FAILED: non-finite observation" in bad.stderr
    for args in (["--minutes", "0"], ["--minutes", "nan"], ["--minutes", "1", "--rss-bound-mib", "-5"]):
        r = _soak_cli(args + ["--out", str(tmp_path / "x")])
        assert r.returncode == 2
        assert re.search(r"--(minutes|rss-bound-mib) must be", r.stderr)


def test_config_errors_name_the_field() -> None:
    with pytest.raises(ValueError, match="SoakConfig.minutes"):
        SoakConfig(minutes=-1)
    with pytest.raises(ValueError, match="SoakConfig.max_steps"):
        SoakConfig(minutes=1, max_steps=True)
    with pytest.raises(ValueError, match="SoakConfig.fault"):
        SoakConfig(minutes=1, fault="meteor")


@pytest.mark.slow
def test_short_soak_passes(tmp_path: Path) -> None:
    """About 30 s of the real soak: no NaN, no exception, memory flat after the warm-up."""
    res = run_soak(SoakConfig(minutes=0.5, progress_s=0.0), tmp_path, log=lambda s: None)
    assert res.passed, res.failure
    assert res.cycles > 2 and res.makes == 2 * res.cycles and res.retrains == res.cycles
    assert res.rss_growth_after_warmup_mib is not None and res.rss_growth_after_warmup_mib < 150.0
