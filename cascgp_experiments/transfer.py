"""Task-transfer pouring episodes on ``JacoPour-v0``: data accumulates, the model is retrained between attempts.

For every controller, a sequence of pouring tasks in different parts of the workspace is attempted
several times each, then the first task is revisited once. After every attempt of a learning
controller, the measured episode joins a persistent data buffer and the model is retrained on
everything seen so far (:mod:`cascgp.learning`: subsampled to ``rate_hz``, at most ``cap`` samples,
warm-started from the previous hyperparameters). The payload (bottle + marbles + extra mass) is the
same unknown mass throughout, as when a robot keeps holding the same bottle.

This module owns what is Jaco-specific about the experiment: the env (``JacoPour-v0``), its reset
options (``payload_mass``), the gains and torque limits (``jaco_env``), the nominal URDF, the
presets (:data:`FULL_CONTROLLERS` ...), the summary table and the figure. The command line is
``python -m scripts.task_transfer``.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym  # noqa: E402
from tqdm import tqdm  # noqa: E402

import jaco_env  # noqa: E402  (registers the environments)
from cascgp.io import atomic_write_text, write_json  # noqa: E402
from cascgp.learning import (Attempt, ControllerRun, Feedback, RetrainConfig, attempt_plan,  # noqa: E402
                             check_controller, run_controllers)
from cascgp.rbd import load_nominal  # noqa: E402
from cascgp_experiments.common import NOMINAL_URDF, save_figure  # noqa: E402

ENV_ID = "JacoPour-v0"
FULL_CONTROLLERS = ("pd", "rbd", "sp-standard", "sp-inward", "sp-outward", "np-inward")
FULL_TASKS = ("front", "left", "right", "far")
QUICK_CONTROLLERS = ("pd", "rbd", "sp-inward")
QUICK_TASKS = ("front", "left")


def jaco_feedback() -> Feedback:
    """The Jaco 2's PD gains (``jaco_env.DEFAULT_KP``/``DEFAULT_KD``) and torque limits."""
    return Feedback(jaco_env.DEFAULT_KP, jaco_env.DEFAULT_KD, jaco_env.robot.TORQUE_LIMITS)


@dataclass
class TransferConfig:
    """Settings of one task-transfer run (see ``--help`` of ``scripts/task_transfer.py`` for each)."""

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

    def plan(self) -> list[Attempt]:
        """Every attempt, in order (:func:`cascgp.learning.attempt_plan`)."""
        return attempt_plan(self.tasks, self.attempts, self.revisit)

    def retrain(self) -> RetrainConfig:
        """The seeds and refit settings of :mod:`cascgp.learning`."""
        return RetrainConfig(seed=self.seed, rate_hz=self.rate_hz, cap=self.cap, restarts=self.restarts)

    def reset_options(self) -> dict[str, Any]:
        """Reset options besides the task: the unknown payload."""
        return {"payload_mass": self.payload_mass}

    def make_env(self) -> gym.Env:
        return gym.make(ENV_ID, n_marbles=self.n_marbles)


def run_transfer(cfg: TransferConfig, out: Path | None = None, show_progress: bool = True) -> list[ControllerRun]:
    """Run the whole experiment; ``out`` (if given) receives the data buffers under ``out/buffers/<controller>``."""
    for name in cfg.controllers:
        check_controller(name)
    rbd = load_nominal(NOMINAL_URDF)
    plan = cfg.plan()
    with tqdm(total=len(cfg.controllers) * len(plan), desc="attempts", disable=not show_progress,
              file=sys.stderr) as bar:
        def progress(name: str, record: dict[str, Any]) -> None:
            bar.set_postfix_str(f"{name} {record['task']}#{record['task_attempt']} "
                                f"rmse={record['tracking_rmse']:.3f} jar={record['in_jar']:.2f}")
            bar.update(1)

        return run_controllers(cfg.controllers, cfg.make_env, plan, rbd, jaco_feedback(), cfg.retrain(),
                               reset_options=cfg.reset_options(),
                               buffer_root=None if out is None else out / "buffers", on_attempt=progress)


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
    save_figure(fig, path, dpi=120)
    plt.close(fig)


def write_outputs(runs: list[ControllerRun], cfg: TransferConfig, out: Path, wall_s: float) -> dict[str, Any]:
    """Write ``results.json``, ``summary.md`` and ``transfer.png`` into ``out``; returns the results dict."""
    results = {
        "config": {**cfg.__dict__, "controllers": list(cfg.controllers), "tasks": list(cfg.tasks)},
        "wall_seconds": wall_s,
        "controllers": {run.name: run.attempts for run in runs},
    }
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "results.json", results, indent=2)
    atomic_write_text(out / "summary.md", summary_table(runs) + "\n")
    plot(results, out / "transfer.png")
    return results
