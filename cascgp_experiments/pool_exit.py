"""How a pool process of :mod:`cascgp_experiments.execution` leaves: with the process that started it
(:func:`exit_with_parent`), or on Ctrl-C, silently (:func:`on_interrupt`, :func:`run_job`, :func:`interrupted`): the
run's main process reports either."""

from __future__ import annotations

import os
import sys
import time
from typing import Any, Callable

__all__ = ["exit_with_parent", "interrupted", "on_interrupt", "run_job"]

#: This process's Ctrl-C state: ``stop`` once one came, ``busy`` while :func:`run_job` runs a job.
_STATE = {"stop": False, "busy": False}


def exit_with_parent(parent_pid: int, period_s: float = 0.5) -> None:
    """Leave this worker process as soon as the process that started it is gone. A run killed with SIGKILL or
    SIGTERM sent to its main process alone (``kill PID``, a batch scheduler) runs no cleanup, and the pool processes
    went on with their jobs as orphans, holding a core and ~0.5 GB each. Polling the parent id is the portable check
    (Linux's PR_SET_PDEATHSIG is not); the job's result would have nowhere to go."""
    while True:
        time.sleep(period_s)
        if os.getppid() != parent_pid:
            os._exit(1)


def interrupted(*_: Any) -> None:
    """The SIGINT handler of a pool process (Ctrl-C reaches every process of the terminal's group): SystemExit, so
    that finalizers run (``os._exit`` left tqdm's semaphores for the resource tracker to warn about), with stderr sent
    to the null device first. A busy process returns to the executor's own loop when its job is interrupted, and
    that loop can fail on its queue as the main process shuts the pool down: 1 in 15 interrupted runs under load
    printed that traceback."""
    os.dup2(os.open(os.devnull, os.O_WRONLY), 2)
    sys.exit(130)


def on_interrupt(*_: Any) -> None:
    """The SIGINT handler of a pool process (Ctrl-C reaches every process of the terminal's group): leave the job
    that runs (:func:`interrupted`), or, between jobs, only remember it: an exception raised while the executor's own
    loop reads or writes its queues could leave half a message in them."""
    _STATE["stop"] = True
    if _STATE["busy"]:
        interrupted()


def run_job(fn: Callable[..., Any], inputs: dict[str, Any]) -> Any:
    """``fn(**inputs)``, which Ctrl-C may interrupt; after a Ctrl-C a job queued in this process leaves at once
    instead of running (the executor hands a process its next queued job after an interrupted one: a transfer's
    next controller ran on for half a minute after Ctrl-C, its result thrown away)."""
    outer = _STATE["busy"]  # a job that runs jobs itself (run_jobs in-process) stays interruptible after them
    _STATE["busy"] = True  # before the check: a Ctrl-C between the two is not missed
    try:
        if _STATE["stop"]:
            interrupted()
        return fn(**inputs)
    finally:
        _STATE["busy"] = outer
