"""The parallel execution layer (cascgp_experiments.execution) and the experiments that use it.

Results must not depend on the worker count or the backend, a failed job is retried once and then
reported with its inputs, and a killed run resumes from the job cache with the same results.

Fast (default suite): the layer on toy jobs; a tiny study (``--smoke``, two models) and a tiny
transfer (two controllers, one task) with 1 and 2 workers and ``--ray local``, and killed then
resumed; the Ray token helpers without a cluster. Slow (``-m slow``): the same on the real ``--quick``
study and ``--quick`` transfer, and a real Ray cluster (``ray start --head`` on 127.0.0.1, with token
authentication on) reached by ``--ray 127.0.0.1:PORT``.
Tests that need Ray skip where it is not installed (it is an optional extra). Ray 2.60 writes a token
to ``~/.ray/auth_token`` the first time it starts a local instance; here it reads one from a temporary
file instead (``RAY_AUTH_TOKEN_PATH``), so that running the tests leaves the user's home alone (a token
there turns token authentication on at the user's next ``ray start --head``).
"""

from __future__ import annotations

import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pytest

from cascgp.io import read_json
from cascgp_experiments.execution import JobError, job_key, run_jobs

REPO = Path(__file__).resolve().parents[1]
HERE = Path(__file__).resolve().parent


def _env() -> dict[str, str]:
    env = dict(os.environ)
    # the repo (scripts) and this folder (the toy jobs below, for Ray workers started from a subprocess)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), str(HERE), env.get("PYTHONPATH", "")])
    env.setdefault("MUJOCO_GL", "egl")
    return env


def _needs_ray():
    return pytest.importorskip("ray", exc_type=ImportError)  # also a broken install


#: Ray's variables that decide whether and which token a process sends (and RAY_ADDRESS, which ray.init reads).
RAY_AUTH_VARS = ("RAY_AUTH_MODE", "RAY_AUTH_TOKEN", "RAY_AUTH_TOKEN_PATH", "RAY_ADDRESS")


@pytest.fixture(scope="module", autouse=True)
def _ray_token_outside_home(tmp_path_factory) -> Iterator[None]:
    """Local Ray instances of this module (in this process and in the commands it runs) read their token
    from a temporary file, not ``~/.ray/auth_token`` (which Ray would otherwise create)."""
    if os.environ.get("RAY_AUTH_TOKEN") or os.environ.get("RAY_AUTH_TOKEN_PATH"):
        yield
        return
    token = tmp_path_factory.mktemp("ray_token") / "auth_token"
    token.write_text(secrets.token_hex(32))
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("RAY_AUTH_TOKEN_PATH", str(token))
        yield


# --------------------------------------------------------------------------- toy jobs (module level: picklable)
def seeded_job(x: int, seed: int) -> dict:
    """Pure in its inputs: numpy and torch random numbers from ``seed``, a Cholesky, a sum."""
    import torch

    rng = np.random.default_rng(seed)
    g = torch.Generator().manual_seed(seed)
    a = torch.randn(40, 40, generator=g, dtype=torch.float64)
    chol = torch.linalg.cholesky(a @ a.T + 40 * torch.eye(40, dtype=torch.float64))
    return {"x": x * x, "v": rng.standard_normal(5), "chol": float(chol.sum()), "t": (1, 2)}


def flaky_job(x: int, marker_dir: str) -> int:
    """Fails on its first call for each ``x`` (a marker file remembers), succeeds on the second."""
    marker = Path(marker_dir) / f"tried_{x}"
    if not marker.exists():
        marker.write_text("1")
        raise RuntimeError(f"transient failure of job {x}")
    return 10 * x


def failing_job(x: int) -> int:
    if x == 2:
        raise ValueError(f"job {x} always fails")
    return x


def slow_job(x: int, seconds: float) -> dict:
    time.sleep(seconds)
    return {"x": x, "y": float(np.sqrt(x))}


def endless_job(x: int, pid_dir: str) -> int:
    """Writes its process id, then waits for ever (a job that outlives its run)."""
    (Path(pid_dir) / f"{x}.pid").write_text(str(os.getpid()))
    while True:
        time.sleep(0.1)


def uncacheable_job(x: int, log_dir: str) -> Any:
    """Job 0 returns what JSON cannot hold (the run fails in this process, not in the job); the others
    take a while and leave a mark that they ran."""
    (Path(log_dir) / f"ran_{x}").write_text("")
    if x == 0:
        return {1j}
    time.sleep(0.5)
    return x


def counting_job(x: int, log_dir: str) -> int:
    (Path(log_dir) / f"ran_{x}_{time.monotonic_ns()}").write_text("")
    return x + 1


# --------------------------------------------------------------------------- the layer
def test_same_results_with_one_and_two_workers_in_job_order() -> None:
    jobs = [{"x": x, "seed": 100 + x} for x in range(6)]
    one = run_jobs(seeded_job, jobs, workers=1, show_progress=False)
    two = run_jobs(seeded_job, jobs, workers=2, show_progress=False)
    assert one.backend == "in-process" and two.backend == "processes" and two.workers == 2
    assert [r["x"] for r in one] == [x * x for x in range(6)]
    for a, b in zip(one, two):
        assert a["chol"] == b["chol"] and a["x"] == b["x"]
        np.testing.assert_array_equal(a["v"], b["v"])


def test_ray_local_gives_the_same_results(monkeypatch) -> None:
    _needs_ray()
    monkeypatch.setenv("PYTHONPATH", _env()["PYTHONPATH"])  # the Ray workers import this module
    monkeypatch.delenv("RAY_AUTH_MODE", raising=False)  # ray.init sets it to "token" here: restored afterwards
    jobs = [{"x": x, "seed": 100 + x} for x in range(4)]
    one = run_jobs(seeded_job, jobs, workers=1, show_progress=False)
    ray = run_jobs(seeded_job, jobs, workers=2, ray_address="local", show_progress=False)
    assert ray.backend == "ray"
    for a, b in zip(one, ray):
        assert a["chol"] == b["chol"]
        np.testing.assert_array_equal(a["v"], b["v"])


@pytest.mark.parametrize("workers", [1, 2])
def test_failed_job_is_retried_once_and_reported_with_its_inputs(tmp_path: Path, workers: int, capfd) -> None:
    jobs = [{"x": x, "marker_dir": str(tmp_path)} for x in range(3)]
    res = run_jobs(flaky_job, jobs, workers=workers, show_progress=False)
    assert list(res) == [0, 10, 20]
    err = capfd.readouterr().err
    for x in range(3):
        assert f"transient failure of job {x}" in err
        assert f'"x":{x}' in err  # the inputs
    assert err.count("retrying (1/1)") == 3


def test_an_error_in_the_run_itself_cancels_the_queued_jobs(tmp_path: Path) -> None:
    """An exception that is not a job's (here: a result that cannot be stored) stops the run at once: the
    jobs still queued never run (they all used to run, uncached, before the error came out)."""
    n = 12
    with pytest.raises((TypeError, ValueError)):
        run_jobs(uncacheable_job, [{"x": x, "log_dir": str(tmp_path)} for x in range(n)], workers=2,
                 cache_dir=tmp_path / "cache", show_progress=False)
    assert len(list(tmp_path.glob("ran_*"))) < n


@pytest.mark.parametrize("workers", [1, 2])
def test_second_failure_raises_with_the_inputs(tmp_path: Path, workers: int, capfd) -> None:
    jobs = [{"x": x} for x in range(4)]
    with pytest.raises(JobError) as info:
        run_jobs(failing_job, jobs, workers=workers, cache_dir=tmp_path / "cache", show_progress=False)
    e = info.value
    assert e.inputs == {"x": 2} and "always fails" in e.error and "failed 2 times" in str(e)
    assert '{"x":2}' in str(e)
    assert "job 2 always fails" in capfd.readouterr().err  # the first failure was reported
    # the jobs that succeeded are cached: a rerun after fixing nothing computes only the failing one again
    if workers == 1:  # in-process: the jobs after the failing one never ran
        assert len(list((tmp_path / "cache").glob("*.json"))) == 2


def test_cache_is_keyed_by_the_inputs_and_normalises_results(tmp_path: Path) -> None:
    log = tmp_path / "log"
    log.mkdir()
    jobs = [{"x": x, "log_dir": str(log)} for x in range(4)]
    first = run_jobs(counting_job, jobs, workers=1, cache_dir=tmp_path / "c", show_progress=False)
    assert first.n_cached == 0 and len(list(log.iterdir())) == 4
    again = run_jobs(counting_job, jobs + [{"x": 9, "log_dir": str(log)}], workers=1, cache_dir=tmp_path / "c",
                     show_progress=False)
    assert again.n_cached == 4 and list(again) == [1, 2, 3, 4, 10] and len(list(log.iterdir())) == 5
    assert again.job_seconds[0] == first.job_seconds[0]  # the time recorded when the job ran
    assert job_key(counting_job, {"x": 1, "log_dir": "a"}) != job_key(counting_job, {"x": 2, "log_dir": "a"})
    assert job_key(counting_job, {"x": 1, "log_dir": "a"}) == job_key(counting_job, {"log_dir": "a", "x": 1})
    # a computed result goes through JSON like a cached one: both are the same objects
    fresh = run_jobs(seeded_job, [{"x": 1, "seed": 1}], workers=1, cache_dir=tmp_path / "s", show_progress=False)
    cached = run_jobs(seeded_job, [{"x": 1, "seed": 1}], workers=1, cache_dir=tmp_path / "s", show_progress=False)
    assert cached.n_cached == 1 and fresh[0] == cached[0] and fresh[0]["t"] == [1, 2]


def test_a_cache_record_of_another_version_is_not_used(tmp_path: Path) -> None:
    import json

    log = tmp_path / "log"
    log.mkdir()
    jobs = [{"x": x, "log_dir": str(log)} for x in range(2)]
    run_jobs(counting_job, jobs, workers=1, cache_dir=tmp_path / "c", show_progress=False)
    rec_path = sorted((tmp_path / "c").glob("counting_job-*.json"))[0]
    rec = json.loads(rec_path.read_text())
    rec["version"] = rec["version"] + 1
    rec["result"] = -1  # what an incompatible record could hold
    rec_path.write_text(json.dumps(rec))
    again = run_jobs(counting_job, jobs, workers=1, cache_dir=tmp_path / "c", show_progress=False)
    assert again.n_cached == 1 and list(again) == [1, 2] and len(list(log.iterdir())) == 3


def test_workers_must_be_positive() -> None:
    with pytest.raises(ValueError, match="workers"):
        run_jobs(counting_job, [], workers=0)


_KILL_SCRIPT = """
import sys
from cascgp_experiments.execution import run_jobs
from test_execution import slow_job
res = run_jobs(slow_job, [{"x": x, "seconds": 0.4} for x in range(8)], workers=1, cache_dir=sys.argv[1],
               show_progress=False)
print("cached", res.n_cached)
"""


def _kill_when(proc: subprocess.Popen, ready) -> None:
    """SIGKILL ``proc``'s process group as soon as ``ready()`` is true (fails if it ends first). No clock:
    the wait ends when the run reaches the state or ends."""
    while not ready():
        assert proc.poll() is None, "the run finished before it could be killed"
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(timeout=60)


def test_killed_run_resumes_from_the_cache(tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    cmd = [sys.executable, "-c", _KILL_SCRIPT, str(cache)]
    p = subprocess.Popen(cmd, env=_env(), cwd=REPO, start_new_session=True)
    _kill_when(p, lambda: len(list(cache.glob("slow_job-*.json"))) >= 3)
    done = len(list(cache.glob("slow_job-*.json")))
    assert 3 <= done < 8
    out = subprocess.run(cmd, env=_env(), cwd=REPO, capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.strip() == f"cached {done}"
    resumed = run_jobs(slow_job, [{"x": x, "seconds": 0.4} for x in range(8)], workers=1, cache_dir=cache,
                       show_progress=False)
    assert resumed.n_cached == 8
    assert list(resumed) == [{"x": x, "y": float(np.sqrt(x))} for x in range(8)]


_ORPHAN_SCRIPT = """
import sys
from cascgp_experiments.execution import run_jobs
from test_execution import endless_job
run_jobs(endless_job, [{"x": x, "pid_dir": sys.argv[1]} for x in range(2)], workers=2, show_progress=False)
"""


def _alive(pid: int) -> bool:
    """The process exists and is not a zombie (an orphan's exit may wait for PID 1 to reap it)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError, IndexError):
        return False
    return state != "Z"


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads process states from /proc")
def test_pool_workers_exit_when_the_run_is_killed_alone(tmp_path: Path) -> None:
    """SIGKILL to the run's main process only (not its group, as `kill PID` or a scheduler does): the pool
    processes, busy with jobs that would never end, leave too instead of running on as orphans."""
    p = subprocess.Popen([sys.executable, "-c", _ORPHAN_SCRIPT, str(tmp_path)], env=_env(), cwd=REPO,
                         start_new_session=True)
    pids: list[int] = []
    try:
        while len(pids) < 2:  # both workers busy: no clock, the run's state
            assert p.poll() is None, "the run ended before its workers started"
            pids = [int(f.read_text()) for f in tmp_path.glob("*.pid") if f.read_text()]
            time.sleep(0.05)
        os.kill(p.pid, signal.SIGKILL)
        p.wait(timeout=60)
        deadline = time.monotonic() + 60  # a hang guard, not a speed limit: without the fix they never exit
        while any(_alive(pid) for pid in pids) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not any(_alive(pid) for pid in pids), "pool workers outlived the killed run"
    finally:
        for pid in pids:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass


# --------------------------------------------------------------------------- experiments: helpers
def _cli(module: str, *args: str, timeout: float = 1200) -> subprocess.CompletedProcess:
    """Run ``python -m module args``; a failure shows the end of the command's stderr."""
    run = subprocess.run([sys.executable, "-m", module, *args], env=_env(), cwd=REPO, capture_output=True,
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
    _needs_ray()
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
                         env=_env(), cwd=REPO, start_new_session=True, stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL)
    _kill_when(p, lambda: len(_cache_files(cache, "curve_job")) >= 1)
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
    assert read_json(out / "results.json")["jobs"]["backend"] == "processes"
    assert _transfer_numbers(out) == _transfer_numbers(tiny_transfer_serial)
    assert (out / "summary.md").read_text() == (tiny_transfer_serial / "summary.md").read_text()
    assert (out / "summary.md").read_text() in run.stdout
    # the buffers are written by the workers, the same episodes
    assert sorted(p.name for p in (out / "buffers" / "sp-inward").iterdir()) == \
        sorted(p.name for p in (tiny_transfer_serial / "buffers" / "sp-inward").iterdir())


def test_tiny_transfer_ray_local_identical(tiny_transfer_serial: Path, tmp_path: Path) -> None:
    _needs_ray()
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
    p = subprocess.Popen(args, env=_env(), cwd=REPO, start_new_session=True, stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL)
    _kill_when(p, lambda: len(_cache_files(cache, "controller_job")) >= 1)
    assert len(_cache_files(cache, "controller_job")) == 1 and not (out / "results.json").exists()
    run = subprocess.run(args, env=_env(), cwd=REPO, capture_output=True, text=True, timeout=600, check=True)
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
                          "--seed", "5"], env=_env(), cwd=REPO, capture_output=True, text=True, timeout=300)
    assert bad.returncode != 0 and "earlier run with other settings" in bad.stderr


def test_ray_option_without_ray_is_a_clear_error(tmp_path: Path) -> None:
    fake = tmp_path / "noray" / "ray"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("raise ImportError('no ray here')\n")
    env = _env()
    env["PYTHONPATH"] = os.pathsep.join([str(tmp_path / "noray"), env["PYTHONPATH"]])
    for module in ("scripts.task_transfer", "scripts.collect_jaco_data"):
        run = subprocess.run([sys.executable, "-m", module, "--out", str(tmp_path / "o"), "--ray", "local"],
                             env=env, cwd=REPO, capture_output=True, text=True, timeout=300)
        assert run.returncode == 2 and "pip install 'cascgp-jaco[ray]'" in run.stderr, (module, run.stderr[-2000:])


# --------------------------------------------------------------------------- Ray token authentication
def test_ray_address_host_and_this_machine() -> None:
    from cascgp_experiments.ray_backend import _address_host, _is_this_machine

    assert _address_host("127.0.0.1:6379") == "127.0.0.1"
    assert _address_host("ray://head.example:10001") == "head.example"
    assert _address_host("[::1]:6379") == "::1"
    assert _address_host(":6379") is None
    assert _is_this_machine("127.0.0.1") and _is_this_machine("localhost")
    assert not _is_this_machine("198.51.100.7")  # TEST-NET-2: never an address of this machine
    assert not _is_this_machine("no-such-host.invalid")


def test_the_local_token_is_never_sent_unasked(monkeypatch) -> None:
    """RAY_AUTH_MODE is set to token only for an explicit address of this machine with the mode unset: not for
    another machine's address, not over a mode the user set, not for 'auto'/'local' (Ray's own business)."""
    import cascgp_experiments.ray_backend as ex

    monkeypatch.setattr(ex, "_ray_has_token", lambda: True)
    monkeypatch.delenv("RAY_AUTH_MODE", raising=False)
    for address in ("198.51.100.7:6379", "no-such-host.invalid:6379", "auto", "local"):
        assert ex._use_local_token(address) is None
        assert "RAY_AUTH_MODE" not in os.environ
    monkeypatch.setenv("RAY_AUTH_MODE", "disabled")
    assert ex._use_local_token("127.0.0.1:6379") is None
    assert os.environ["RAY_AUTH_MODE"] == "disabled"


# ray.init's error for a refused token, as Ray 2.60 raises it: a ConnectionError from a RuntimeError that holds
# the traceback of the last attempt as text
_RAY_REFUSED = ("Failed to connect to GCS. Last connection error: Traceback (most recent call last):\n"
                "  File \"python/ray/includes/common.pxi\", line 119, in ray._raylet.check_status\n"
                "ray.exceptions.AuthenticationError: RPC error: InvalidAuthToken: Authentication token is missing or "
                "incorrect. Note: RAY_AUTH_MODE is currently 'disabled' (not 'token'). Ensure that the token for the "
                "cluster is available in a local file\n")


def _ray_style_error(text: str) -> ConnectionError:
    try:
        try:
            raise RuntimeError(text)
        except RuntimeError as inner:
            raise ConnectionError("Failed to connect to Ray cluster at 192.0.2.9:6379") from inner
    except ConnectionError as exc:
        return exc


def test_refused_token_is_recognised_and_the_message_names_the_fix(monkeypatch) -> None:
    import cascgp_experiments.ray_backend as ex

    err = ex._auth_failure(_ray_style_error(_RAY_REFUSED))
    assert err == "RPC error: InvalidAuthToken: Authentication token is missing or incorrect"
    assert ex._auth_failure(_ray_style_error("Failed to connect to GCS. Last connection error: timed out")) is None
    assert ex._auth_failure(ConnectionError("Could not find any running Ray instance")) is None

    monkeypatch.setattr(ex, "_is_this_machine", lambda host: False)
    monkeypatch.setattr(ex, "_ray_has_token", lambda: True)
    monkeypatch.delenv("RAY_AUTH_MODE", raising=False)  # the reported case: a cluster elsewhere, no mode set
    msg = ex._auth_message("10.1.2.3:6379", err)
    assert msg.startswith("--ray 10.1.2.3:6379: the Ray cluster refused this process")
    assert "RAY_AUTH_MODE is unset" in msg and "RAY_AUTH_MODE=token" in msg and "--ray auto" in msg
    assert "Traceback" not in msg and "\n" not in msg
    monkeypatch.setenv("RAY_AUTH_MODE", "token")
    assert "not this cluster's" in ex._auth_message("10.1.2.3:6379", err)
    monkeypatch.setattr(ex, "_ray_has_token", lambda: False)
    assert "no token was found" in ex._auth_message("10.1.2.3:6379", err)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _ray_env(home: Path) -> dict[str, str]:
    """The environment of a process of the test cluster: its own HOME (with or without a token), none of Ray's
    token or address variables of the caller."""
    env = _env()
    for k in RAY_AUTH_VARS:
        env.pop(k, None)
    env["HOME"] = str(home)
    env["RAY_USAGE_STATS_ENABLED"] = "0"
    return env


@pytest.fixture(scope="module")
def ray_head() -> Iterator[dict[str, Any]]:
    """A real Ray head on this machine (``ray start --head --block``, 127.0.0.1, its own process group and temp
    folder) whose HOME holds ``~/.ray/auth_token``, so that Ray 2.60 turns token authentication on, as it does
    for a user who once ran a local Ray instance. Stopped afterwards by killing its process group (``ray stop``
    would stop every Ray process on the machine, other users' too)."""
    _needs_ray()
    ray_cli = Path(sys.executable).with_name("ray")
    if not ray_cli.exists():
        ray_cli = Path(shutil.which("ray") or "ray")
    root = Path(tempfile.mkdtemp(prefix="cgray", dir="/tmp"))  # short: Ray's socket paths must fit in 107 bytes
    home = root / "home"
    (home / ".ray").mkdir(parents=True)
    (home / ".ray" / "auth_token").write_text(secrets.token_hex(32))
    port = _free_port()
    log_path = root / "head.log"
    with open(log_path, "w") as log:
        head = subprocess.Popen(
            [str(ray_cli), "start", "--head", "--node-ip-address=127.0.0.1", f"--port={port}", "--num-cpus=2",
             "--include-dashboard=false", "--disable-usage-stats", f"--temp-dir={root / 'ray'}", "--block"],
            env=_ray_env(home), cwd=REPO, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while "Ray runtime started" not in log_path.read_text():
            if head.poll() is not None or time.monotonic() > deadline:
                pytest.fail(f"ray start --head did not start (exit status {head.poll()}):\n"
                            f"{log_path.read_text()[-3000:]}")
            time.sleep(0.2)
        yield {"address": f"127.0.0.1:{port}", "home": home, "root": root}
    finally:
        try:
            os.killpg(head.pid, signal.SIGKILL)  # the head and every process it started (SIGTERM: a 30 s drain)
        except ProcessLookupError:
            pass
        head.wait(timeout=60)
        shutil.rmtree(root, ignore_errors=True)


_RAY_DRIVER = """
import json, os, sys
import cascgp_experiments.execution as ex
import cascgp_experiments.ray_backend as rb
from test_execution import seeded_job
if sys.argv[2] == "elsewhere":
    rb._is_this_machine = lambda host: False  # stands for a cluster on another machine
try:
    res = ex.run_jobs(seeded_job, [{"x": x, "seed": 100 + x} for x in range(3)], ray_address=sys.argv[1],
                      show_progress=False)
except ex.RayAuthenticationError as exc:
    print(json.dumps({"error": str(exc), "auth_mode": exc.auth_mode, "env_mode": os.environ.get("RAY_AUTH_MODE")}))
else:
    print(json.dumps({"backend": res.backend, "chol": [r["chol"] for r in res], "x": [r["x"] for r in res]}))
"""


def _driver(head: dict[str, Any], where: str, **env_vars: str) -> tuple[dict, subprocess.CompletedProcess]:
    import json

    env = _ray_env(head["home"]) | env_vars
    run = subprocess.run([sys.executable, "-c", _RAY_DRIVER, head["address"], where], env=env, cwd=REPO,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    return json.loads(run.stdout.strip().splitlines()[-1]), run


@pytest.mark.slow
def test_ray_cluster_here_with_token_auth_runs_the_jobs(ray_head) -> None:
    """The reported failure: --ray HOST:PORT to a head started with a token in ~/.ray/auth_token, RAY_AUTH_MODE
    unset. Raw Ray (an explicit address) sends no token and is refused; here it connects and runs the jobs."""
    out, run = _driver(ray_head, "here")
    assert out.get("backend") == "ray", out
    ref = run_jobs(seeded_job, [{"x": x, "seed": 100 + x} for x in range(3)], workers=1, show_progress=False)
    assert out["x"] == [r["x"] for r in ref] and out["chol"] == [r["chol"] for r in ref]
    assert "connecting with RAY_AUTH_MODE=token" in run.stderr


@pytest.mark.slow
def test_ray_cluster_elsewhere_with_token_auth_is_a_clear_error(ray_head) -> None:
    """The same cluster seen as another machine's: the local token is not sent unasked, and the error says to
    set RAY_AUTH_MODE=token (or use --ray auto on the head) instead of Ray's traceback."""
    out, run = _driver(ray_head, "elsewhere", RAY_gcs_server_port_wait_time_s="5")  # Ray retries 20 s by default
    assert "error" in out, out
    assert out["auth_mode"] is None and out["env_mode"] is None
    assert "RAY_AUTH_MODE=token" in out["error"] and "--ray auto" in out["error"]
    assert "InvalidAuthToken" in out["error"]  # Ray's own reason, kept
    assert "Traceback" not in run.stderr


@pytest.mark.slow
@pytest.mark.parametrize("case", ["mode-disabled", "wrong-token"])
def test_ray_cluster_refusing_the_command_is_a_one_line_error(ray_head, tmp_path: Path, case: str) -> None:
    """A command line (here: the data collection) that the cluster refuses ends at argument checking, exit
    status 2, with one ``error:`` line naming the fix: no traceback, nothing written."""
    env = _ray_env(ray_head["home"]) | {"RAY_gcs_server_port_wait_time_s": "5"}
    if case == "mode-disabled":
        env["RAY_AUTH_MODE"] = "disabled"
        expect = ["RAY_AUTH_MODE=disabled is set", "unset RAY_AUTH_MODE"]
    else:
        env |= {"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": secrets.token_hex(32)}
        expect = ["not this cluster's", "ray get-auth-token"]
    address = ray_head["address"]
    run = subprocess.run([sys.executable, "-m", "scripts.collect_jaco_data", "--out", str(tmp_path / "data"),
                          "--smoke", "--ray", address], env=env, cwd=REPO, capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 2, run.stderr[-3000:]
    assert f"error: --ray {address}: the Ray cluster refused this process" in run.stderr
    for text in expect:
        assert text in run.stderr, run.stderr[-3000:]
    assert "Traceback" not in run.stderr
    assert not (tmp_path / "data").exists()


# --------------------------------------------------------------------------- the --quick runs (slow)
@pytest.fixture(scope="module")
def quick_study_serial(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("quick_study") / "w1"
    _cli("scripts.data_efficiency", "--out", str(out), "--quick", "--workers", "1")
    return out


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["workers2", "ray"])
def test_quick_study_identical_across_backends(quick_study_serial: Path, tmp_path: Path, backend: str) -> None:
    extra = ["--workers", "2"] if backend == "workers2" else ["--ray", "local", "--workers", "2"]
    if backend == "ray":
        _needs_ray()
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
    p = subprocess.Popen(args, env=_env(), cwd=REPO, start_new_session=True, stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL)
    _kill_when(p, lambda: len(_cache_files(cache, "curve_job")) >= 4)
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
    extra = ["--workers", "2"] if backend == "workers2" else ["--ray", "local", "--workers", "2"]
    if backend == "ray":
        _needs_ray()
    out = tmp_path / backend
    _cli("scripts.task_transfer", "--quick", "--overwrite", "--out", str(out), *extra)
    assert _transfer_numbers(out) == _transfer_numbers(quick_transfer_serial)
    assert (out / "summary.md").read_text() == (quick_transfer_serial / "summary.md").read_text()


@pytest.mark.slow
def test_quick_transfer_killed_and_resumed_identical(quick_transfer_serial: Path, tmp_path: Path) -> None:
    out = tmp_path / "killed"
    cache = out / "cache" / "transfer"
    args = [sys.executable, "-m", "scripts.task_transfer", "--quick", "--out", str(out), "--workers", "1"]
    p = subprocess.Popen(args, env=_env(), cwd=REPO, start_new_session=True, stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL)
    _kill_when(p, lambda: len(_cache_files(cache, "controller_job")) >= 1)
    assert not (out / "results.json").exists()
    run = subprocess.run(args, env=_env(), cwd=REPO, capture_output=True, text=True, timeout=1200, check=True)
    assert "resuming" in run.stderr
    assert read_json(out / "results.json")["jobs"]["n_cached"] >= 1
    assert _transfer_numbers(out) == _transfer_numbers(quick_transfer_serial)
    assert (out / "summary.md").read_text() == (quick_transfer_serial / "summary.md").read_text()


def dying_job(x: int) -> int:
    if x == 1:
        os._exit(3)  # a worker process that dies (as in a native crash)
    time.sleep(0.2)
    return x


def test_dead_worker_process_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(RuntimeError, match=r"a worker process died .* dying_job\(.*\"x\":1"):
        run_jobs(dying_job, [{"x": x} for x in range(2)], workers=2, cache_dir=tmp_path, show_progress=False)


def test_progress_ignores_malformed_and_out_of_range_messages() -> None:
    import io

    from tqdm import tqdm

    from cascgp_experiments.execution import _Progress

    with tqdm(total=5, file=io.StringIO()) as bar:
        p = _Progress(bar, [2, 3])
        for msg in ((2, 0, 1, ""), (-1, 0, 1, ""), (0, 1, 1, ""), ("x", 0, 1, ""), (0, 0), None):
            p.tick(msg)  # out of range, negative, a stale attempt, not a number, too short, not a tuple
        assert p.reported == [0, 0] and bar.n == 0
        p.tick((1, 0, 5, "note"))  # capped at the job's units
        assert p.reported == [0, 3] and bar.n == 3
