"""The parallel execution layer (cascgp_experiments.execution) on toy jobs.

Results must not depend on the worker count or the backend, a failed job is retried once and then reported with
its inputs, a killed run resumes from the job cache with the same results, and a pool's workers leave with a
killed run. The experiments that use the layer are tested in test_execution_experiments.py, Ray clusters in
test_execution_ray.py. Tests that need Ray skip where it is not installed (it is an optional extra); local Ray
instances read their token from a temporary file, not the user's home (``execution_helpers``).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from execution_helpers import ray_token_outside_home  # noqa: F401 (autouse: Ray's token outside the home)
from execution_helpers import REPO, kill_when, needs_ray, subprocess_env

from cascgp_experiments.execution import JobError, job_key, run_jobs


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


def endless_or_quick_job(x: int, pid_dir: str) -> int:
    """Job 0 waits for ever; the others write their process id and return (their worker then waits idle)."""
    if x == 0:
        endless_job(x, pid_dir)
    (Path(pid_dir) / f"{x}.pid").write_text(str(os.getpid()))
    return x


def marked_slow_job(x: int, pid_dir: str) -> int:
    """Leaves a mark that it started, then takes 3 s."""
    (Path(pid_dir) / f"{x}.started").write_text(str(os.getpid()))
    time.sleep(3.0)
    return x


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


def echo_job(v: Any) -> Any:
    return {"v": v}


def test_inputs_that_json_would_merge_are_distinct_jobs(tmp_path: Path) -> None:
    """The cache key was the inputs' JSON, in which NaN, inf and None are all null and every dict key a string: a job
    on NaN got the cached result of the job on None; an input written as the key's own tags shared the key of what
    they tag. A tuple and a list of the same items stay one input."""
    groups = [[None, float("nan"), float("inf"), -np.inf, np.float64("nan"), {"__float__": "nan"}],
              [{1: "a"}, {"1": "a"}, {"__items__": [[1, "a"]]}], [[1, 2], [1.0, 2.0]]]
    for i, group in enumerate(groups):
        cache = tmp_path / f"c{i}"
        for k, v in enumerate(group):
            res = run_jobs(echo_job, [{"v": v}], workers=1, cache_dir=cache, show_progress=False)
            assert res.n_cached == (1 if (i, k) in ((0, 4),) else 0), (v, res.n_cached)  # nan twice: one job
    same = run_jobs(echo_job, [{"v": (1, 2)}], workers=1, cache_dir=tmp_path / "c2", show_progress=False)
    assert same.n_cached == 1
    # an unchanged key for an ordinary input: the record an earlier version wrote is still found
    from cascgp_experiments.job_cache import canonical_json

    assert canonical_json({"x": 1, "grid": (1.0, 2.5), "name": "a"}) == '{"grid":[1.0,2.5],"name":"a","x":1}'


def test_run_jobs_refuses_bad_arguments_before_any_job(tmp_path: Path) -> None:
    log = tmp_path / "log"
    log.mkdir()
    jobs = [{"x": x, "log_dir": str(log)} for x in range(3)]
    for kwargs, exc, match in (({"priority": [1.0]}, ValueError, r"^priority: expected 3 values"),
                               ({"priority": [1.0] * 4}, ValueError, r"^priority: expected 3 values"),
                               ({"retries": -1}, ValueError, r"^retries: expected an integer >= 0"),
                               ({"retries": 2.5}, ValueError, r"^retries: expected an integer >= 0")):
        with pytest.raises(exc, match=match):
            run_jobs(counting_job, jobs, workers=1, show_progress=False, **kwargs)
    with pytest.raises(ValueError, match=r"^fn: a cached job's function .* module-level function; got '.*<lambda>'"):
        run_jobs(lambda x, log_dir: x, jobs, workers=1, cache_dir=tmp_path / "c", show_progress=False)
    assert not list(log.iterdir())


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
    needs_ray()
    monkeypatch.setenv("PYTHONPATH", subprocess_env()["PYTHONPATH"])  # the Ray workers import this module
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
    assert (again.workers, again.backend) == (1, "in-process")
    # every job from the cache: no worker ran, and the statistics say so
    cached = run_jobs(counting_job, jobs, workers=2, cache_dir=tmp_path / "c", show_progress=False)
    assert cached.n_cached == 4 and (cached.stats()["workers"], cached.stats()["backend"]) == (0, "cache")
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


def test_killed_run_resumes_from_the_cache(tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    cmd = [sys.executable, "-c", _KILL_SCRIPT, str(cache)]
    p = subprocess.Popen(cmd, env=subprocess_env(), cwd=REPO, start_new_session=True)
    kill_when(p, lambda: len(list(cache.glob("slow_job-*.json"))) >= 3)
    done = len(list(cache.glob("slow_job-*.json")))
    assert 3 <= done < 8
    out = subprocess.run(cmd, env=subprocess_env(), cwd=REPO, capture_output=True, text=True, timeout=120, check=True)
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


def _all_gone(pids: list[int]) -> bool:
    """Whether the processes ``pids`` have all exited; waits up to 60 s (a hang guard, not a speed limit)."""
    deadline = time.monotonic() + 60
    while any(_alive(pid) for pid in pids) and time.monotonic() < deadline:
        time.sleep(0.1)
    return not any(_alive(pid) for pid in pids)


def _kill_all(pids: list[int]) -> None:
    for pid in pids:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads process states from /proc")
def test_pool_workers_exit_when_the_run_is_killed_alone(tmp_path: Path) -> None:
    """SIGKILL to the run's main process only (not its group, as `kill PID` or a scheduler does): the pool
    processes, busy with jobs that would never end, leave too instead of running on as orphans."""
    p = subprocess.Popen([sys.executable, "-c", _ORPHAN_SCRIPT, str(tmp_path)], env=subprocess_env(), cwd=REPO,
                         start_new_session=True)
    pids: list[int] = []
    try:
        while len(pids) < 2:  # both workers busy: no clock, the run's state
            assert p.poll() is None, "the run ended before its workers started"
            pids = [int(f.read_text()) for f in tmp_path.glob("*.pid") if f.read_text()]
            time.sleep(0.05)
        os.kill(p.pid, signal.SIGKILL)
        p.wait(timeout=60)
        assert _all_gone(pids), "pool workers outlived the killed run"
    finally:
        _kill_all(pids)


_CTRL_C_SCRIPT = """
import sys
from cascgp_experiments.execution import run_jobs
from test_execution import endless_or_quick_job
try:
    run_jobs(endless_or_quick_job, [{"x": x, "pid_dir": sys.argv[1]} for x in range(2)], workers=2,
             show_progress=False)
except KeyboardInterrupt:
    print("interrupted", file=sys.stderr)
    sys.exit(130)
"""


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads process states from /proc")
def test_ctrl_c_ends_the_pool_processes_without_a_traceback(tmp_path: Path) -> None:
    """Ctrl-C reaches every process of the terminal's group: the run's main process reports it, and its pool
    processes, one busy and one idle, leave without printing a traceback of their own."""
    p = subprocess.Popen([sys.executable, "-c", _CTRL_C_SCRIPT, str(tmp_path)], env=subprocess_env(), cwd=REPO,
                         start_new_session=True, stderr=subprocess.PIPE, text=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    pids: list[int] = []
    try:
        while len(pids) < 2:  # job 0 running, job 1 done: one busy worker and one idle
            assert p.poll() is None, "the run ended before its workers started"
            pids = [int(f.read_text()) for f in tmp_path.glob("*.pid") if f.read_text()]
            time.sleep(0.05)
        time.sleep(0.5)  # job 1's result back, its worker waiting for work
        os.killpg(p.pid, signal.SIGINT)
        _, err = p.communicate(timeout=60)
        assert p.returncode == 130 and err.strip() == "interrupted", err
        assert _all_gone(pids), "pool workers outlived the interrupted run"
    finally:
        _kill_all(pids)
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)


def dying_job(x: int) -> int:
    if x == 1:
        os._exit(3)  # a worker process that dies (as in a native crash)
    time.sleep(0.2)
    return x


def test_dead_worker_process_is_a_clear_error(tmp_path: Path) -> None:
    died = r"a worker process died .* dying_job\(.*\"x\":1.*under if __name__ == \"__main__\""
    with pytest.raises(RuntimeError, match=died):
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


_QUEUED_SCRIPT = """
import sys
from cascgp_experiments.execution import run_jobs
from test_execution import marked_slow_job
try:
    run_jobs(marked_slow_job, [{"x": x, "pid_dir": sys.argv[1]} for x in range(5)], workers=2, show_progress=False)
except KeyboardInterrupt:
    print("interrupted", file=sys.stderr)
    sys.exit(130)
"""


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads process states from /proc")
def test_after_ctrl_c_a_job_queued_in_a_pool_process_does_not_run(tmp_path: Path) -> None:
    """The executor hands a pool process its next queued job after an interrupted one: that job ran to its end
    (a transfer's next controller, for half a minute) before the run could stop, its result thrown away."""
    p = subprocess.Popen([sys.executable, "-c", _QUEUED_SCRIPT, str(tmp_path)], env=subprocess_env(), cwd=REPO,
                         start_new_session=True, stderr=subprocess.PIPE, text=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        while len(list(tmp_path.glob("*.started"))) < 2:  # jobs 0 and 1 running, the next ones queued
            assert p.poll() is None, "the run ended before its workers started"
            time.sleep(0.05)
        pids = [int(f.read_text()) for f in tmp_path.glob("*.started")]
        os.killpg(p.pid, signal.SIGINT)
        _, err = p.communicate(timeout=60)
        assert p.returncode == 130 and err.strip() == "interrupted", err
        started = sorted(f.name for f in tmp_path.glob("*.started"))
        assert started == ["0.started", "1.started"], f"jobs queued before Ctrl-C ran after it: {started}"
        assert _all_gone(pids)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)


_RUN_JOB_SCRIPT = """
import sys
from cascgp_experiments import pool_exit
ran = []
def inner():
    ran.append("inner")
def outer():
    pool_exit.run_job(inner, {})  # a job that runs a job of its own: still interruptible afterwards
    pool_exit.on_interrupt()       # Ctrl-C in the outer job: leaves it
    ran.append("outer went on")
pool_exit.on_interrupt()            # between jobs: remembered, nothing raised
assert pool_exit._STATE == {"stop": True, "busy": False}, pool_exit._STATE
pool_exit._STATE["stop"] = False
try:
    pool_exit.run_job(outer, {})
except SystemExit as exc:
    assert exc.code == 130 and ran == ["inner"], ran
else:
    raise AssertionError("the outer job ran on after Ctrl-C")
try:
    pool_exit.run_job(inner, {})   # queued after the Ctrl-C: leaves before it runs
except SystemExit:
    assert ran == ["inner"], ran
    sys.stdout.write("ok")
"""


def test_a_pool_process_leaves_only_a_running_job_on_ctrl_c() -> None:
    """pool_exit's rules, in a process of their own (interrupted() sends stderr to the null device): between jobs a
    Ctrl-C is only remembered; a running job leaves, also after a job it ran itself; a later job leaves at once."""
    out = subprocess.run([sys.executable, "-c", _RUN_JOB_SCRIPT], env=subprocess_env(), cwd=REPO,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout == "ok", out.stderr
