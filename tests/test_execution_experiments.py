"""The experiments on the parallel execution layer: their results must not depend on the worker count or the
backend, and a killed run resumes from the job cache with the same results.

Fast (default suite): a tiny study (``--smoke``, two models) and a tiny transfer (two controllers, one task) with
1 and 2 workers and ``--ray local``; the data collection in a vector env. Slow (``-m slow``): the same killed and
resumed, and the real ``--quick`` study and ``--quick`` transfer. Tests that need Ray skip where it is not
installed.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from execution_helpers import ray_token_outside_home  # noqa: F401 (autouse: Ray's token outside the home)
from execution_helpers import REPO, kill_when, needs_ray, subprocess_env

from cascgp.io import read_json


# --------------------------------------------------------------------------- experiments: helpers
def _cli(module: str, *args: str, timeout: float = 1200) -> subprocess.CompletedProcess:
    """Run ``python -m module args``; a failure shows the end of the command's stderr."""
    run = subprocess.run([sys.executable, "-m", module, *args], env=subprocess_env(), cwd=REPO, capture_output=True,
                         text=True, timeout=timeout)
    assert run.returncode == 0, f"{module} {' '.join(args)}: exit status {run.returncode}\n{run.stderr[-4000:]}"
    return run


def _study_numbers(out: Path) -> dict:
    """Everything in a study's results.json that is a number of the experiment (not a timing)."""
    res = read_json(out / "results.json")
    jaco = res["jaco"]
    keep = {"n_test_rows": jaco["n_test_rows"], "grid_s": jaco["grid_s"],
            "models": {m: {k: v[k] for k in ("nrmse_all", "n_train") if k in v} for m, v in jaco["models"].items()},
            "audit": [{k: r[k] for k in ("model", "subset", "seconds", "n_train", "nll", "nll_cold", "gap")}
                      for r in jaco["audit"]["records"]],
            "table": jaco["table"]}
    return keep


def _data_arrays(out: Path) -> dict[str, np.ndarray]:
    arrays = {}
    for split in ("train", "test"):
        with np.load(out / "data" / f"jaco_{split}.npz", allow_pickle=False) as z:
            arrays.update({f"{split}/{k}": z[k] for k in z.files})
    return arrays


def _assert_same_data(a: Path, b: Path) -> None:
    x, y = _data_arrays(a), _data_arrays(b)
    assert sorted(x) == sorted(y)
    for k in x:
        assert x[k].dtype == y[k].dtype and x[k].tobytes() == y[k].tobytes(), k


def _transfer_numbers(out: Path) -> dict:
    """The attempts of every controller without their timings."""
    res = read_json(out / "results.json")
    return {name: [{k: v for k, v in a.items() if k != "fit_seconds"} for a in attempts]
            for name, attempts in res["controllers"].items()}


def _cache_files(folder: Path, prefix: str) -> list[Path]:
    return list(folder.glob(f"{prefix}-*.json")) if folder.exists() else []


# --------------------------------------------------------------------------- tiny study (fast)
TINY_STUDY = ("--smoke", "--models", "np-standard,sp-inward-df", "--no-sarcos", "--no-iterations")


@pytest.fixture(scope="module")
def tiny_study_serial(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("study") / "w1"
    _cli("scripts.data_efficiency", "--out", str(out), *TINY_STUDY, "--workers", "1")
    return out


def test_tiny_study_two_workers_identical(tiny_study_serial: Path, tmp_path: Path) -> None:
    out = tmp_path / "w2"
    _cli("scripts.data_efficiency", "--out", str(out), *TINY_STUDY, "--workers", "2")
    assert read_json(out / "results.json")["jaco"]["jobs"]["backend"] == "processes"
    _assert_same_data(tiny_study_serial, out)  # collected side by side in an AsyncVectorEnv
    assert _study_numbers(out) == _study_numbers(tiny_study_serial)
    assert (out / "table1.md").read_text() == (tiny_study_serial / "table1.md").read_text()


def test_tiny_study_ray_local_identical(tiny_study_serial: Path, tmp_path: Path) -> None:
    needs_ray()
    out = tmp_path / "ray"
    _cli("scripts.data_efficiency", "--out", str(out), *TINY_STUDY, "--ray", "local", "--workers", "2")
    assert read_json(out / "results.json")["jaco"]["jobs"]["backend"] == "ray"
    _assert_same_data(tiny_study_serial, out)  # one job per motion on Ray
    assert _study_numbers(out) == _study_numbers(tiny_study_serial)


def test_collection_in_a_vector_env_identical(tiny_study_serial: Path, tmp_path: Path) -> None:
    from cascgp_experiments.collect import PRESETS, collect

    collect(tmp_path / "vec" / "data", PRESETS["smoke"], workers=2, vector_env=True)
    _assert_same_data(tiny_study_serial, tmp_path / "vec")


@pytest.mark.slow  # end to end through a killed command (15-25 s); the job layer's resume is tested fast above
def test_tiny_study_killed_and_resumed_identical(tiny_study_serial: Path, tmp_path: Path) -> None:
    out = tmp_path / "killed"
    # first the data (so that the kill lands among the fits), then a run killed after its first fit job
    _cli("scripts.collect_jaco_data", "--out", str(out / "data"), "--smoke")
    cache = out / "cache" / "jaco"
    p = subprocess.Popen([sys.executable, "-m", "scripts.data_efficiency", "--out", str(out), *TINY_STUDY,
                          "--workers", "1"],
                         env=subprocess_env(), cwd=REPO, start_new_session=True, stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL)
    kill_when(p, lambda: len(_cache_files(cache, "curve_job")) >= 1)
    n_done = len(_cache_files(cache, "curve_job"))
    assert 1 <= n_done < 4 and not (out / "results.json").exists()
    _cli("scripts.data_efficiency", "--out", str(out), *TINY_STUDY, "--workers", "2")
    res = read_json(out / "results.json")
    assert res["jaco"]["n_cached_jobs"] == n_done
    assert _study_numbers(out) == _study_numbers(tiny_study_serial)


# --------------------------------------------------------------------------- tiny transfer (fast)
TINY_TRANSFER = ("--controllers", "sp-inward,rbd", "--tasks", "front", "--attempts", "2", "--no-revisit",
                 "--restarts", "1", "--cap", "200")


@pytest.fixture(scope="module")
def tiny_transfer_serial(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("transfer") / "w1"
    _cli("scripts.task_transfer", "--out", str(out), *TINY_TRANSFER, "--workers", "1")
    return out


def test_tiny_transfer_two_workers_identical(tiny_transfer_serial: Path, tmp_path: Path) -> None:
    out = tmp_path / "w2"
    run = _cli("scripts.task_transfer", "--out", str(out), *TINY_TRANSFER, "--workers", "2")
    res = read_json(out / "results.json")
    assert res["jobs"]["backend"] == "processes"
    from cascgp.models.fastkernel import jit_enabled

    prov = res["provenance"]  # which kernel path ran (the fast extra's compiled loops or NumPy), versions, machine
    assert prov["compiled_kernels"] == jit_enabled() and "cascgp-jaco" in prov["versions"] and prov["machine"]["cpus"]
    assert prov["command"] == " ".join(["cascgp transfer", "--out", str(out), *TINY_TRANSFER, "--workers", "2"])
    assert _transfer_numbers(out) == _transfer_numbers(tiny_transfer_serial)
    assert (out / "summary.md").read_text() == (tiny_transfer_serial / "summary.md").read_text()
    assert (out / "summary.md").read_text() in run.stdout
    # the buffers are written by the workers, the same episodes
    assert sorted(p.name for p in (out / "buffers" / "sp-inward").iterdir()) == \
        sorted(p.name for p in (tiny_transfer_serial / "buffers" / "sp-inward").iterdir())


def test_tiny_transfer_ray_local_identical(tiny_transfer_serial: Path, tmp_path: Path) -> None:
    needs_ray()
    out = tmp_path / "ray"
    _cli("scripts.task_transfer", "--out", str(out), *TINY_TRANSFER, "--ray", "local", "--workers", "2")
    assert read_json(out / "results.json")["jobs"]["backend"] == "ray"
    assert _transfer_numbers(out) == _transfer_numbers(tiny_transfer_serial)


@pytest.mark.slow  # end to end through a killed command (15-25 s); the job layer's resume is tested fast above
def test_tiny_transfer_killed_and_resumed_identical(tiny_transfer_serial: Path, tmp_path: Path) -> None:
    out = tmp_path / "killed"
    cache = out / "cache" / "transfer"
    args = [sys.executable, "-m", "scripts.task_transfer", "--out", str(out), *TINY_TRANSFER, "--workers", "1"]
    # one worker: sp-inward (a learning controller, submitted first), then rbd; killed once sp-inward is cached
    p = subprocess.Popen(args, env=subprocess_env(), cwd=REPO, start_new_session=True, stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL)
    kill_when(p, lambda: len(_cache_files(cache, "controller_job")) >= 1)
    assert len(_cache_files(cache, "controller_job")) == 1 and not (out / "results.json").exists()
    run = subprocess.run(args, env=subprocess_env(), cwd=REPO, capture_output=True, text=True, timeout=600, check=True)
    assert "resuming" in run.stderr
    res = read_json(out / "results.json")
    assert res["jobs"]["n_cached"] == 1
    assert _transfer_numbers(out) == _transfer_numbers(tiny_transfer_serial)
    # the buffer of the controller that was cut off was rebuilt from no data: two episodes, as uninterrupted
    for name in ("sp-inward",):
        assert sorted(p.name for p in (out / "buffers" / name).iterdir()) == \
            sorted(p.name for p in (tiny_transfer_serial / "buffers" / name).iterdir())


def test_transfer_refuses_other_settings_in_the_same_folder(tiny_transfer_serial: Path, tmp_path: Path) -> None:
    import shutil

    out = tmp_path / "copy"
    shutil.copytree(tiny_transfer_serial, out)
    bad = subprocess.run([sys.executable, "-m", "scripts.task_transfer", "--out", str(out), *TINY_TRANSFER,
                          "--seed", "5"], env=subprocess_env(), cwd=REPO, capture_output=True, text=True, timeout=300)
    assert bad.returncode != 0 and "earlier run with other settings" in bad.stderr


def test_ray_option_without_ray_is_a_clear_error(tmp_path: Path) -> None:
    fake = tmp_path / "noray" / "ray"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("raise ImportError('no ray here')\n")
    env = subprocess_env()
    env["PYTHONPATH"] = os.pathsep.join([str(tmp_path / "noray"), env["PYTHONPATH"]])
    for module in ("scripts.task_transfer", "scripts.collect_jaco_data"):
        run = subprocess.run([sys.executable, "-m", module, "--out", str(tmp_path / "o"), "--ray", "local"],
                             env=env, cwd=REPO, capture_output=True, text=True, timeout=300)
        assert run.returncode == 2 and "py3-none-any.whl[ray]'" in run.stderr, (module, run.stderr[-2000:])


# --------------------------------------------------------------------------- the --quick runs (slow)
def _backend_args(backend: str) -> list[str]:
    """The command-line options of a ``--quick`` rerun on ``backend`` (``workers2`` or ``ray``: skipped without Ray)."""
    if backend == "ray":
        needs_ray()
        return ["--ray", "local", "--workers", "2"]
    return ["--workers", "2"]


@pytest.fixture(scope="module")
def quick_study_serial(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("quick_study") / "w1"
    _cli("scripts.data_efficiency", "--out", str(out), "--quick", "--workers", "1")
    return out


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["workers2", "ray"])
def test_quick_study_identical_across_backends(quick_study_serial: Path, tmp_path: Path, backend: str) -> None:
    extra = _backend_args(backend)
    out = tmp_path / backend
    _cli("scripts.data_efficiency", "--out", str(out), "--quick", *extra)
    _assert_same_data(quick_study_serial, out)
    assert _study_numbers(out) == _study_numbers(quick_study_serial)
    res, ref = read_json(out / "results.json"), read_json(quick_study_serial / "results.json")
    assert ("sarcos" in res) == ("sarcos" in ref)
    if "sarcos" in res:  # the SARCOS curves (not their timings)
        assert {m: (v["nrmse_all"], v["n_train"]) for m, v in res["sarcos"]["models"].items()} == \
            {m: (v["nrmse_all"], v["n_train"]) for m, v in ref["sarcos"]["models"].items()}
    assert res["iterations"]["models"].keys() == ref["iterations"]["models"].keys()


@pytest.mark.slow
def test_quick_study_killed_and_resumed_identical(quick_study_serial: Path, tmp_path: Path) -> None:
    out = tmp_path / "killed"
    cache = out / "cache" / "jaco"
    args = [sys.executable, "-m", "scripts.data_efficiency", "--out", str(out), "--quick", "--workers", "2"]
    p = subprocess.Popen(args, env=subprocess_env(), cwd=REPO, start_new_session=True, stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL)
    kill_when(p, lambda: len(_cache_files(cache, "curve_job")) >= 4)
    n_done = len(_cache_files(cache, "curve_job"))
    assert n_done < 12  # 4 jobs per subset (a standard model with its two cascades) x 3 subsets
    _cli("scripts.data_efficiency", "--out", str(out), "--quick", "--workers", "2")
    assert read_json(out / "results.json")["jaco"]["n_cached_jobs"] >= n_done
    assert _study_numbers(out) == _study_numbers(quick_study_serial)


@pytest.fixture(scope="module")
def quick_transfer_serial(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("quick_transfer") / "w1"
    _cli("scripts.task_transfer", "--quick", "--overwrite", "--out", str(out), "--workers", "1")
    return out


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["workers2", "ray"])
def test_quick_transfer_identical_across_backends(quick_transfer_serial: Path, tmp_path: Path, backend: str) -> None:
    extra = _backend_args(backend)
    out = tmp_path / backend
    _cli("scripts.task_transfer", "--quick", "--overwrite", "--out", str(out), *extra)
    assert _transfer_numbers(out) == _transfer_numbers(quick_transfer_serial)
    assert (out / "summary.md").read_text() == (quick_transfer_serial / "summary.md").read_text()


@pytest.mark.slow
def test_quick_transfer_killed_and_resumed_identical(quick_transfer_serial: Path, tmp_path: Path) -> None:
    out = tmp_path / "killed"
    cache = out / "cache" / "transfer"
    args = [sys.executable, "-m", "scripts.task_transfer", "--quick", "--out", str(out), "--workers", "1"]
    p = subprocess.Popen(args, env=subprocess_env(), cwd=REPO, start_new_session=True, stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL)
    kill_when(p, lambda: len(_cache_files(cache, "controller_job")) >= 1)
    assert not (out / "results.json").exists()
    run = subprocess.run(args, env=subprocess_env(), cwd=REPO, capture_output=True, text=True, timeout=1200, check=True)
    assert "resuming" in run.stderr
    assert read_json(out / "results.json")["jobs"]["n_cached"] >= 1
    assert _transfer_numbers(out) == _transfer_numbers(quick_transfer_serial)
    assert (out / "summary.md").read_text() == (quick_transfer_serial / "summary.md").read_text()
