"""One execution layer for the experiments: many pure jobs on all local cores, or on a Ray cluster.

A *job* is a call ``fn(**inputs)`` of a module-level function on a dict of inputs (model, subset,
seed, file paths, settings ...). Jobs are pure functions of their inputs: every random number is
seeded from them and every job runs with one torch / BLAS thread, so its result is the same
whichever process, machine or backend runs it, and :func:`run_jobs` returns the results in the
order of ``jobs`` whatever the order in which they finish.

Backends (the same jobs, the same results):

* ``workers=1``: in this process, one job after the other (torch and BLAS held to one thread while
  the jobs run, restored afterwards);
* ``workers=N`` (default: every core this process may use, :func:`default_workers`): a local
  :class:`concurrent.futures.ProcessPoolExecutor` (``spawn``) of ``N`` processes, each with one
  torch / BLAS thread (``OMP_NUM_THREADS`` ... and :func:`cascgp_experiments.common.limit_threads`);
* ``ray_address``: the jobs become Ray tasks of one CPU each on the cluster at that address
  (``ray.init(address=...)``); ``"local"`` starts a new local Ray instance with ``num_cpus=workers``
  (never a cluster already running here, nor ``RAY_ADDRESS``); ``"auto"``: the cluster this machine belongs to.
  Ray is an optional extra (``ray``); nothing else imports it. On a cluster, every node needs the project installed
  and the jobs' input files (and the transfer's buffer folders) at the same paths, e.g. on a shared file system;
  only this process writes the cache.

Ray token authentication: see :mod:`cascgp_experiments.ray_backend`.

Progress: one tqdm bar for the whole run, counted in *units* (one per job by default). A long job
reports units as it goes with :func:`report_progress` (a no-op outside :func:`run_jobs`), e.g. one
per episode; the bar's postfix shows the last note.

Failures: a job that raises is reported on stderr with its inputs and the error, and submitted once
more; if it fails again :class:`JobError` is raised naming the inputs (local processes: after the jobs
already running have finished and been cached, jobs not yet started are cancelled; Ray: ``ray.cancel``
interrupts the running jobs too, so only those that had finished are cached). Any other exception in
this process (Ctrl-C, a cache write that fails) cancels the jobs not yet started at once; Ctrl-C ends the pool
processes too, without a word. A local worker process that dies (a crash in native code, the out-of-memory killer)
ends the run with a ``RuntimeError`` naming a job it was running; the finished jobs are in the cache, so running the
command again resumes. On Ray a dead worker is a failed job like any other (Ray starts another worker): the job is
submitted again, as above. A job's numbers do not depend on the backend; how a crash is handled does.

Cache: with ``cache_dir``, every finished job's result is kept (:mod:`cascgp_experiments.job_cache`), and a run
started again with the same inputs skips the jobs already there.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import queue as queue_mod
import signal
import sys
import threading
import time
import traceback
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

from tqdm import tqdm

from cascgp.checks import check_count
from cascgp_experiments.cli.options import require_at_least
from cascgp_experiments.common import install_hint
from cascgp_experiments.job_cache import canonical_json, job_key, read_cached, write_cached
from cascgp_experiments.pool_exit import exit_with_parent, on_interrupt, run_job
from cascgp_experiments.ray_backend import RayAuthenticationError, import_ray, ray_connect, run_ray

__all__ = ["run_jobs", "report_progress", "session", "default_workers", "check_workers", "job_key", "JobError",
           "JobResults", "RayAuthenticationError", "add_execution_args", "check_args", "THREAD_ENV"]

#: Environment of every worker process: one thread for OpenMP / OpenBLAS / MKL.
THREAD_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


class JobError(RuntimeError):
    """A job failed twice (retried once). ``inputs``: its inputs; ``error``: the last error's text and traceback."""

    def __init__(self, message: str, inputs: Mapping[str, Any], error: str) -> None:
        super().__init__(message)
        self.inputs = dict(inputs)
        self.error = error


class JobResults(list):
    """The results of :func:`run_jobs`, in the order of the jobs, with run statistics:

    ``n_cached`` (jobs read from the cache), ``job_seconds`` (wall time of each job where it ran; for
    a cached job the time recorded when it ran), ``wall_s`` (the whole call), ``workers`` and
    ``backend`` (``"in-process"``, ``"processes"`` or ``"ray"``; ``"cache"`` with 0 workers when there were jobs
    and every one came from the cache)."""

    n_cached: int = 0
    job_seconds: list[float | None]
    wall_s: float = 0.0
    workers: int = 1
    backend: str = "in-process"

    def stats(self) -> dict[str, Any]:
        """JSON-ready summary: number of jobs, cached jobs, workers, backend, per-job seconds."""
        secs = [s for s in self.job_seconds if s is not None]
        return {"n_jobs": len(self), "n_cached": self.n_cached, "workers": self.workers, "backend": self.backend,
                "wall_s": self.wall_s, "job_seconds": list(self.job_seconds),
                "job_seconds_sum": float(sum(secs)), "job_seconds_max": float(max(secs)) if secs else None}


def default_workers() -> int:
    """Every core this process may run on (``os.sched_getaffinity`` where available, else ``os.cpu_count``)."""
    try:
        n = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        n = os.cpu_count() or 1
    return max(1, n)


def add_execution_args(parser: Any) -> None:
    """The ``--workers`` and ``--ray`` options, with the same meaning in every command line."""
    parser.add_argument("--workers", type=int, default=None,
                        help=f"parallel jobs: local processes with one torch/BLAS thread each, or the CPUs of a "
                             f"--ray local instance (default: every core, here {default_workers()}; 1: in this "
                             "process). Results do not depend on it.")
    parser.add_argument("--ray", default=None, metavar="ADDRESS",
                        help="submit the jobs to the Ray cluster at ADDRESS ('local': start a local Ray instance "
                             "with --workers CPUs; 'auto': the cluster this machine belongs to); needs the extra: "
                             f"{install_hint('ray')}")


def check_args(parser: Any, args: Any) -> None:
    """Validate ``--workers`` / ``--ray`` (``parser.error`` on a bad value or a missing Ray).

    With a cluster address (``--ray HOST:PORT`` or ``auto``, not ``local``) this also connects to the cluster, so
    that an unreachable cluster or a refused token ends the command at once with a one-line ``error:`` (exit status
    2) naming the fix, before any work and without Ray's traceback. The connection stays open for the run
    (:func:`run_jobs` and :func:`session` use it and leave it open; Ray closes it at exit)."""
    require_at_least(parser, args, 1, "workers")
    if args.ray is not None:
        try:
            import ray  # noqa: F401
        except ImportError:
            parser.error(f"--ray needs Ray, which is not installed: {install_hint('ray')}")
        if args.ray != "local":
            try:
                ray_connect(args.ray, check_workers(args.workers))
            except RayAuthenticationError as exc:
                parser.error(str(exc))
            except ConnectionError as exc:
                parser.error(f"--ray {args.ray}: could not connect to Ray ({exc}). Is the cluster running "
                             f"(`ray start --head` on the head node; `ray status` there lists it)?")


def check_workers(workers: int | None) -> int:
    if workers is None:
        return default_workers()
    return check_count(workers, "workers")


# --------------------------------------------------------------------------- inside a worker
_CHANNEL: Any = None          # where report_progress sends (a queue, or a callable in-process)
_CURRENT: tuple[int, int] | None = None  # (job index, attempt) of the job running in this process


def report_progress(units: int = 1, note: str = "") -> None:
    """Called by a running job: ``units`` more of its work are done (``note``: shown beside the bar); a no-op
    outside :func:`run_jobs`."""
    if _CHANNEL is None or _CURRENT is None:
        return
    msg = (_CURRENT[0], _CURRENT[1], int(units), str(note))
    try:
        if callable(_CHANNEL):
            _CHANNEL(msg)
        else:
            _CHANNEL.put(msg)
    except Exception:  # noqa: BLE001 - progress must never fail a job
        pass


def _limit_threads() -> None:
    """One thread in this worker process: the environment for libraries loaded later (torch reads
    ``OMP_NUM_THREADS`` when it is imported), threadpoolctl for those already loaded; torch is not
    imported here for jobs that do not need it (the collection's)."""
    for k, v in THREAD_ENV.items():
        os.environ[k] = v
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(1)


def _init_process(channel: Any, parent_pid: int | None = None) -> None:
    """Initializer of every pool process: one thread, the progress channel, exit with the parent (``parent_pid``:
    the run's id, passed by it, so that a parent already gone is noticed too), and on Ctrl-C (sent to every process
    of the terminal's group) exit without a traceback: the run's main process reports it."""
    global _CHANNEL
    _limit_threads()
    signal.signal(signal.SIGINT, on_interrupt)
    _CHANNEL = channel
    pid = os.getppid() if parent_pid is None else int(parent_pid)
    threading.Thread(target=exit_with_parent, args=(pid,), name="exit-with-parent", daemon=True).start()


def _call(fn: Callable, inputs: dict, index: int, attempt: int, channel: Any = None) -> tuple:
    """Run one job; never raises: ``("ok", result, seconds)`` or ``("error", text, seconds)``."""
    global _CURRENT, _CHANNEL
    if channel is not None:  # Ray: the channel travels with the task
        _limit_threads()
        _CHANNEL = channel
    _CURRENT = (index, attempt)
    t0 = time.perf_counter()
    try:
        result = run_job(fn, inputs)
        return ("ok", result, time.perf_counter() - t0)
    except Exception as exc:  # noqa: BLE001 - reported with the inputs by the caller
        return ("error", f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}", time.perf_counter() - t0)
    finally:
        _CURRENT = None


@contextmanager
def _one_thread_here() -> Iterator[None]:
    """Hold torch and BLAS to one thread in this process (as in a worker); restore afterwards."""
    import torch
    from threadpoolctl import threadpool_limits

    prev = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        with threadpool_limits(1):
            yield
    finally:
        torch.set_num_threads(prev)


# --------------------------------------------------------------------------- progress
class _Progress:
    """The aggregated bar: units per job; messages of an earlier (failed) attempt are ignored."""

    def __init__(self, bar: tqdm, units: list[int]) -> None:
        self.bar, self.units = bar, units
        self.reported = [0] * len(units)
        self.attempt = [0] * len(units)
        self.done: set[int] = set()
        self.lock = threading.Lock()

    def tick(self, msg: tuple) -> None:
        """One ``(job index, attempt, units, note)`` message; anything malformed or out of range is ignored
        (progress never fails a run)."""
        try:
            i, attempt, n, note = msg
            i, n = int(i), int(n)
        except (TypeError, ValueError):
            return
        with self.lock:
            if not 0 <= i < len(self.units) or i in self.done or attempt != self.attempt[i]:
                return
            add = max(0, min(n, self.units[i] - self.reported[i]))
            self.reported[i] += add
            if add:
                self.bar.update(add)
            if note:
                self.bar.set_postfix_str(note, refresh=False)

    def finish(self, i: int, note: str = "") -> None:
        with self.lock:
            self.done.add(i)
            self.bar.update(self.units[i] - self.reported[i])
            self.reported[i] = self.units[i]
            if note:
                self.bar.set_postfix_str(note)

    def retry(self, i: int) -> None:
        with self.lock:
            self.bar.update(-self.reported[i])
            self.reported[i] = 0
            self.attempt[i] += 1


class _Drain(threading.Thread):
    """Moves progress messages from a queue to the bar until stopped."""

    def __init__(self, q: Any, progress: _Progress, get: Callable[[], Any]) -> None:
        super().__init__(daemon=True)
        self.q, self.progress, self.get = q, progress, get
        self.stopped = threading.Event()

    def run(self) -> None:
        while not self.stopped.is_set():
            try:
                msg = self.get()
            except (queue_mod.Empty, EOFError, OSError):
                continue
            except Exception:  # noqa: BLE001 - e.g. Ray's Empty, or the queue actor gone
                if self.stopped.is_set():
                    return
                time.sleep(0.1)
                continue
            self.progress.tick(msg)

    def stop(self) -> None:
        self.stopped.set()
        self.join(timeout=5)


# --------------------------------------------------------------------------- the run
def run_jobs(fn: Callable[..., Any], jobs: Sequence[Mapping[str, Any]], *, workers: int | None = None,
             ray_address: str | None = None, cache_dir: str | os.PathLike | None = None, desc: str = "jobs",
             units: Sequence[int] | None = None, priority: Sequence[float] | None = None,
             label: Callable[[Mapping[str, Any]], str] | None = None, show_progress: bool = True,
             unit: str | None = None, retries: int = 1) -> JobResults:
    """Run ``fn(**job)`` for every job; return the results in the order of ``jobs``.

    Args:
        fn: a module-level function (it is pickled by reference), pure in its inputs.
        jobs: the inputs of each call (keyword arguments).
        workers: parallel jobs (default :func:`default_workers`; 1: in this process). Above 1, a script must call
            this under ``if __name__ == "__main__":`` (each worker process imports the script again).
        ray_address: run on the Ray cluster at this address (``"local"``: a local instance with ``workers`` CPUs)
            instead of local processes.
        cache_dir: folder of the job cache (resume); ``None``: no cache.
        desc: the progress bar's title.
        units: progress units of each job (default 1 each; see :func:`report_progress`).
        priority: jobs with a higher priority are submitted first (e.g. the longest first, so that
            the tail of the run is short); ties keep the order of ``jobs``.
        label: short text naming a job in the bar and in messages (default: its inputs).
        show_progress: draw the bar (on stderr).
        unit: what the bar counts (default ``"job"``, or ``"unit"`` with ``units``).
        retries: how often a failed job is submitted again (1).
    """
    t_start = time.perf_counter()
    jobs = [dict(j) for j in jobs]
    n = len(jobs)
    workers = check_workers(workers)
    units_l = [max(1, int(u)) for u in units] if units is not None else [1] * n
    if len(units_l) != n:
        raise ValueError(f"units: expected {n} values (one per job), got {len(units_l)}")
    if priority is not None and len(priority) != n:
        raise ValueError(f"priority: expected {n} values (one per job), got {len(priority)}")
    retries = check_count(retries, "retries", 0)
    label = label or (lambda job: ", ".join(f"{k}={v!r}" for k, v in job.items() if not isinstance(v, dict)))
    name = fn.__name__
    if cache_dir is not None and "<" in getattr(fn, "__qualname__", "<"):  # <lambda>, <locals>: one name for many
        raise ValueError(f"fn: a cached job's function is named in its cache key, so it must be a module-level "
                         f"function; got {getattr(fn, '__qualname__', fn)!r}")
    cache = Path(cache_dir) if cache_dir is not None else None
    results = JobResults([None] * n)
    results.job_seconds = [None] * n
    todo: list[int] = []
    if cache is not None:
        cache.mkdir(parents=True, exist_ok=True)
    for i, job in enumerate(jobs):
        rec = read_cached(cache, fn, job) if cache is not None else None
        if rec is None:
            todo.append(i)
        else:
            results[i] = rec["result"]
            results.job_seconds[i] = rec.get("wall_s")
    results.n_cached = n - len(todo)
    if priority is not None:
        pr = list(priority)
        todo.sort(key=lambda i: -pr[i])
    todo_set = set(todo)
    bar = tqdm(total=sum(units_l), initial=sum(units_l[i] for i in range(n) if i not in todo_set),
               desc=desc, unit=unit or ("job" if units is None else "unit"), disable=not show_progress, file=sys.stderr,
               dynamic_ncols=True)
    progress = _Progress(bar, units_l)
    for i in set(range(n)) - todo_set:
        progress.done.add(i)
        progress.reported[i] = units_l[i]
    failures = [0] * n

    def finished(i: int, out: tuple) -> bool:
        """Record one job's outcome; True when it is to be submitted again."""
        status, value, secs = out
        if status == "ok":
            if cache is not None:
                value = write_cached(cache, fn, jobs[i], value, secs)
            results[i] = value
            results.job_seconds[i] = secs
            progress.finish(i, f"{label(jobs[i])} done in {secs:.0f} s")
            return False
        failures[i] += 1
        head = value.splitlines()[0] if value else "?"
        if failures[i] <= retries:
            tqdm.write(f"{desc}: job {name}({label(jobs[i])}) failed: {head}; inputs: {_short(jobs[i])}; "
                       f"retrying ({failures[i]}/{retries})", file=sys.stderr)
            progress.retry(i)
            return True
        raise JobError(f"{desc}: job {name}({label(jobs[i])}) failed {failures[i]} times; inputs: "
                       f"{_short(jobs[i])}\nlast error: {value}", jobs[i], value)

    backend, used = ("cache", 0) if jobs and not todo else ("in-process", 1)
    try:
        if todo:
            if ray_address is not None:
                backend, used = "ray", workers
                run_ray(fn, jobs, todo, workers, ray_address, progress, finished)
            elif min(workers, len(todo)) <= 1:
                _run_here(fn, jobs, todo, progress, finished)
            else:
                backend, used = "processes", min(workers, len(todo))
                _run_pool(fn, jobs, todo, used, progress, finished)
    finally:
        bar.close()
    results.wall_s = time.perf_counter() - t_start
    results.workers, results.backend = used, backend
    return results


def _short(job: Mapping[str, Any], limit: int = 600) -> str:
    """The job's inputs for a message (JSON where it can be, else ``repr``), cut at ``limit`` characters."""
    try:
        s = canonical_json(job)
    except TypeError:
        s = repr(dict(job))
    return s if len(s) <= limit else s[:limit] + "..."


def _run_here(fn, jobs, todo, progress, finished) -> None:
    global _CHANNEL
    prev = _CHANNEL
    _CHANNEL = progress.tick
    try:
        with _one_thread_here():
            for i in todo:
                while finished(i, _call(fn, jobs[i], i, progress.attempt[i])):
                    pass
    finally:
        _CHANNEL = prev


def _run_pool(fn, jobs, todo, workers, progress, finished) -> None:
    ctx = mp.get_context("spawn")
    channel = ctx.Queue()
    drain = _Drain(channel, progress, lambda: channel.get(timeout=0.2))
    drain.start()
    try:
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_init_process,
                                 initargs=(channel, os.getpid())) as pool:
            try:
                _drive_pool(pool, fn, jobs, todo, progress, finished)
            except BaseException:
                # Not a JobError (handled inside): Ctrl-C, a failed cache write... Leaving the `with` would
                # wait for every queued job to run (uncached) before the error surfaced.
                pool.shutdown(wait=False, cancel_futures=True)
                raise
    finally:
        drain.stop()
        channel.close()


def _drive_pool(pool: ProcessPoolExecutor, fn, jobs, todo, progress, finished) -> None:
    """Submit the jobs, collect them, resubmit a failed one once; a JobError is raised after the running jobs
    have finished (the ones not started are cancelled)."""
    error: BaseException | None = None
    running: dict[Future, int] = {pool.submit(_call, fn, jobs[i], i, 0): i for i in todo}
    while running:
        done, _ = wait(running, return_when=FIRST_COMPLETED)
        for fut in done:
            i = running.pop(fut)
            if fut.cancelled():
                continue
            try:
                out = fut.result()
            except BrokenProcessPool as exc:
                lost = [i] + [j for j in running.values()]
                raise RuntimeError(
                    "a worker process died (crashed or killed, e.g. out of memory) while these jobs were "
                    "running or waiting: " + "; ".join(f"{fn.__name__}({_short(jobs[j], 300)})" for j in lost[:8])
                    + ("; ..." if len(lost) > 8 else "")
                    + ". The finished jobs are cached (with a cache folder): run again to resume. (A script that "
                    "runs jobs in worker processes must do so under if __name__ == \"__main__\": each worker "
                    "imports the script again)") from exc
            try:
                again = finished(i, out)
            except JobError as exc:
                if error is None:
                    error = exc
                    for f in running:  # jobs not started yet; the running ones finish and are cached
                        f.cancel()
                continue
            if again and error is None:
                running[pool.submit(_call, fn, jobs[i], i, progress.attempt[i])] = i
    if error is not None:
        raise error


@contextmanager
def session(ray_address: str | None, workers: int | None = None) -> Iterator[None]:
    """Keep one Ray connection (``"local"``: one local instance) for several :func:`run_jobs` calls, e.g. the
    steps of the study; without it each call connects and disconnects. Nothing to do for local processes."""
    if ray_address is None:
        yield
        return
    started = ray_connect(ray_address, check_workers(workers))
    try:
        yield
    finally:
        if started:
            import_ray().shutdown()
