"""Task-transfer pouring episodes: data accumulates across tasks and the model is retrained between attempts.

For every controller, a sequence of pouring tasks in different parts of the workspace
is attempted several times each, then the first task is revisited once. After every
attempt of a learning controller, the measured episode joins a persistent data buffer
(:class:`cascgp.buffer.DataBuffer`) and the model is retrained on everything seen so
far (subsampled to ``--rate`` Hz, at most ``--cap`` samples, warm-started from the
previous hyperparameters). The payload (bottle + marbles + extra mass) is the same
unknown mass throughout, as when a robot keeps holding the same bottle.

Controllers: ``pd`` (feedback only), ``rbd`` (nominal rigid-body feedforward) and any
of the twelve model names of :mod:`cascgp.models`. Before a learning controller has
any data, an SP model is its RBD mean (RBD feedforward) and an NP model is zero (PD).

Usage::

    python -m scripts.task_transfer --out out/transfer            # full run
    python -m scripts.task_transfer --out out/demo --quick        # README demo (a few minutes)

Writes ``results.json`` (every attempt's metrics), ``summary.md`` (the summary table),
``transfer.png`` (tracking RMSE and marbles in the jar per attempt) to ``--out``, and the
data buffers under ``--out/buffers``. The loop: :mod:`cascgp.learning`; the Jaco experiment:
:mod:`cascgp_experiments.transfer`.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import time
from pathlib import Path

from cascgp_experiments.transfer import (FULL_CONTROLLERS, FULL_TASKS, QUICK_CONTROLLERS, QUICK_TASKS,
                                         TransferConfig, run_transfer, write_outputs)


def parse_args(argv: list[str] | None = None) -> tuple[TransferConfig, Path, bool]:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, required=True, help="output folder (created; should be new or empty)")
    p.add_argument("--quick", action="store_true",
                   help=f"short demo: controllers {QUICK_CONTROLLERS}, tasks {QUICK_TASKS}, 3 attempts each")
    p.add_argument("--controllers", type=str, default=None, help="comma-separated controller names")
    p.add_argument("--tasks", type=str, default=None, help="comma-separated task names (JacoPour-v0 defaults)")
    p.add_argument("--attempts", type=int, default=3, help="attempts per task")
    p.add_argument("--no-revisit", action="store_true", help="do not revisit the first task at the end")
    p.add_argument("--payload", type=float, default=1.2, help="unknown payload mass in the hand (kg)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--rate", type=float, default=10.0, help="training data rate (Hz)")
    p.add_argument("--cap", type=int, default=500, help="maximum training-set size")
    p.add_argument("--restarts", type=int, default=3, help="GP optimiser restarts per retraining")
    p.add_argument("--overwrite", action="store_true", help="delete the data buffers of an earlier run in --out")
    a = p.parse_args(argv)
    cfg = TransferConfig(
        controllers=tuple(a.controllers.split(",")) if a.controllers else
        (QUICK_CONTROLLERS if a.quick else FULL_CONTROLLERS),
        tasks=tuple(a.tasks.split(",")) if a.tasks else (QUICK_TASKS if a.quick else FULL_TASKS),
        attempts=a.attempts,
        revisit=not a.no_revisit, payload_mass=a.payload, seed=a.seed, rate_hz=a.rate, cap=a.cap,
        restarts=a.restarts)
    if cfg.attempts < 1:
        p.error("--attempts must be at least 1")
    return cfg, a.out, a.overwrite


def main(argv: list[str] | None = None) -> None:
    cfg, out, overwrite = parse_args(argv)
    buffers = out / "buffers"
    if buffers.exists() and any(buffers.iterdir()):
        if not overwrite:
            sys.exit(f"error: {buffers} holds data from an earlier run; choose a new --out folder or pass --overwrite")
        shutil.rmtree(buffers)
    t0 = time.perf_counter()
    runs = run_transfer(cfg, out)
    write_outputs(runs, cfg, out, time.perf_counter() - t0)
    print((out / "summary.md").read_text())
    print(f"results: {out / 'results.json'}\nplot:    {out / 'transfer.png'}\n"
          f"wall time {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
