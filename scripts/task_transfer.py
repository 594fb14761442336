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
data buffers under ``--out/buffers``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym  # noqa: E402
from tqdm import tqdm  # noqa: E402

import jaco_env  # noqa: E402,F401  (registers the environments)
from cascgp.buffer import DataBuffer  # noqa: E402
from cascgp.controller import FeedforwardController  # noqa: E402
from cascgp.episodes import EpisodeResult, run_episode  # noqa: E402
from cascgp.gp import GPFitConfig  # noqa: E402
from cascgp.io import write_json  # noqa: E402
from cascgp.models import MODEL_NAMES, make_model  # noqa: E402
from cascgp.rbd import load_nominal  # noqa: E402
from jaco_env.gains import DEFAULT_KD, DEFAULT_KP  # noqa: E402
from jaco_env.robot import TORQUE_LIMITS  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
NOMINAL_URDF = REPO / "assets" / "jaco2_nominal.urdf"
FULL_CONTROLLERS = ("pd", "rbd", "sp-standard", "sp-inward", "sp-outward", "np-inward")
FULL_TASKS = ("front", "left", "right", "far")
QUICK_CONTROLLERS = ("pd", "rbd", "sp-inward")
QUICK_TASKS = ("front", "left")


@dataclass
class TransferConfig:
    """Settings of one task-transfer run (see ``--help`` for each)."""

    controllers: tuple[str, ...] = FULL_CONTROLLERS
    tasks: tuple[str, ...] = FULL_TASKS
    attempts: int = 3
    revisit: bool = True
    payload_mass: float = 1.2
    seed: int = 0
    rate_hz: float = 10.0
    cap: int = 500
    restarts: int = 3
    n_marbles: int = 30


@dataclass
class ControllerRun:
    """One controller's sequence of attempts."""

    name: str
    attempts: list[dict[str, Any]] = field(default_factory=list)


def _check_controller(name: str) -> None:
    if name not in ("pd", "rbd") and name not in MODEL_NAMES:
        raise ValueError(f"unknown controller {name!r}; expected 'pd', 'rbd' or one of {list(MODEL_NAMES)}")


def make_controller(name: str, rbd: Any, model: Any | None) -> FeedforwardController:
    """The controller for ``name`` given the current (possibly unfitted/None) learned model."""
    _check_controller(name)
    if name == "pd":
        feedforward = None
    elif name == "rbd":
        feedforward = rbd
    elif model is not None and model.fitted:
        feedforward = model
    else:  # no data yet: an SP model's mean is the RBD model, an NP model's mean is zero
        feedforward = rbd if name.startswith("sp") else None
    return FeedforwardController(feedforward, DEFAULT_KP, DEFAULT_KD, TORQUE_LIMITS, fallback=rbd)


def attempt_plan(cfg: TransferConfig) -> list[tuple[str, int, str]]:
    """(task, attempt index within the task, phase) for every attempt, in order."""
    plan = [(task, k, "train") for task in cfg.tasks for k in range(cfg.attempts)]
    if cfg.revisit and cfg.tasks:
        plan.append((cfg.tasks[0], cfg.attempts, "revisit"))
    return plan


def run_controller(name: str, cfg: TransferConfig, env: gym.Env, rbd: Any,
                   buffer_dir: Path | None = None, progress: tqdm | None = None,
                   plan: list[tuple[str, int, str]] | None = None) -> ControllerRun:
    """Run every attempt of ``plan`` (default :func:`attempt_plan`) with one controller.

    A learning controller is retrained after every ``"train"`` attempt on all data so far.
    """
    learns = name not in ("pd", "rbd")
    buffer = DataBuffer(buffer_dir) if learns else None
    if buffer is not None and len(buffer):
        raise ValueError(f"buffer folder {buffer_dir} already holds data; use an empty --out folder")
    model = None
    run = ControllerRun(name)
    for i, (task, k, phase) in enumerate(attempt_plan(cfg) if plan is None else plan):
        controller = make_controller(name, rbd, model)
        result: EpisodeResult = run_episode(
            env, controller, seed=cfg.seed * 1000 + i,
            options={"task": task, "payload_mass": cfg.payload_mass},
            meta={"attempt": i, "phase": phase})
        record = {"attempt": i, "task": task, "task_attempt": k, "phase": phase,
                  "n_train": 0 if model is None else int(model.n_train), **result.summary()}
        if learns and phase == "train":
            buffer.append(result.data)
            t0 = time.perf_counter()
            new = make_model(name, rbd.dof, rbd=rbd if name.startswith("sp") else None,
                             gp_config=GPFitConfig(n_restarts=cfg.restarts, seed=cfg.seed + i))
            model = new.fit(buffer.training_set(cfg.rate_hz, cfg.cap), init=model)
            record["fit_seconds"] = time.perf_counter() - t0
        run.attempts.append(record)
        if progress is not None:
            progress.set_postfix_str(f"{name} {task}#{k} rmse={record['tracking_rmse']:.3f} jar={record['in_jar']:.2f}")
            progress.update(1)
    return run


def run_transfer(cfg: TransferConfig, out: Path | None = None, show_progress: bool = True) -> list[ControllerRun]:
    """Run the whole experiment; ``out`` (if given) receives the data buffers."""
    for name in cfg.controllers:
        _check_controller(name)
    rbd = load_nominal(NOMINAL_URDF)
    env = gym.make("JacoPour-v0", n_marbles=cfg.n_marbles)
    runs = []
    total = len(cfg.controllers) * len(attempt_plan(cfg))
    with tqdm(total=total, desc="attempts", disable=not show_progress, file=sys.stderr) as bar:
        for name in cfg.controllers:
            buffer_dir = None if out is None else out / "buffers" / name
            runs.append(run_controller(name, cfg, env, rbd, buffer_dir, bar))
    env.close()
    return runs


def summary_table(runs: list[ControllerRun]) -> str:
    """Markdown table: per controller, tracking RMSE and marbles in the jar on first/last attempts."""
    def fmt(attempt: dict[str, Any] | None, key: str, spec: str) -> str:
        return "-" if attempt is None else format(attempt[key], spec)

    lines = ["| controller | first attempt RMSE (rad) | last train attempt RMSE (rad) | revisit RMSE (rad) "
             "| mean in jar | last train in jar | revisit in jar |",
             "|---|---|---|---|---|---|---|"]
    for run in runs:
        train = [a for a in run.attempts if a["phase"] == "train"]
        revisit = next((a for a in run.attempts if a["phase"] == "revisit"), None)
        mean_jar = np.mean([a["in_jar"] for a in run.attempts])
        lines.append(f"| {run.name} | {fmt(train[0], 'tracking_rmse', '.4f')} | {fmt(train[-1], 'tracking_rmse', '.4f')} "
                     f"| {fmt(revisit, 'tracking_rmse', '.4f')} | {mean_jar:.2f} | {fmt(train[-1], 'in_jar', '.2f')} "
                     f"| {fmt(revisit, 'in_jar', '.2f')} |")
    return "\n".join(lines)


def plot(results: dict[str, Any], path: Path) -> None:
    """Tracking RMSE and fraction of marbles in the jar against attempt number (from the JSON alone)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    for name, attempts in results["controllers"].items():
        x = [a["attempt"] + 1 for a in attempts]
        axes[0].plot(x, [a["tracking_rmse"] for a in attempts], "o-", label=name)
        axes[1].plot(x, [a["in_jar"] for a in attempts], "o-", label=name)
    first = next(iter(results["controllers"].values()))
    for a in first:
        if a["task_attempt"] == 0 or a["phase"] == "revisit":
            for ax in axes:
                ax.axvline(a["attempt"] + 0.5, color="0.85", lw=1, zorder=0)
            axes[0].annotate(a["task"] + (" (revisit)" if a["phase"] == "revisit" else ""),
                             (a["attempt"] + 0.6, 1.0), xycoords=("data", "axes fraction"),
                             va="top", fontsize=8, color="0.4")
    axes[0].set_yscale("log")
    axes[0].set_ylabel("tracking RMSE (rad)")
    axes[1].set_ylabel("fraction of marbles in jar")
    axes[1].set_ylim(-0.05, 1.05)
    axes[1].set_xlabel("attempt")
    axes[0].legend(fontsize=8, ncol=3)
    fig.suptitle(f"Task transfer, unknown payload {results['config']['payload_mass']} kg")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def write_outputs(runs: list[ControllerRun], cfg: TransferConfig, out: Path, wall_s: float) -> dict[str, Any]:
    results = {
        "config": {**cfg.__dict__, "controllers": list(cfg.controllers), "tasks": list(cfg.tasks)},
        "wall_seconds": wall_s,
        "controllers": {run.name: run.attempts for run in runs},
    }
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "results.json", results, indent=2)
    table = summary_table(runs)
    (out / "summary.md").write_text(table + "\n")
    plot(results, out / "transfer.png")
    return results


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
