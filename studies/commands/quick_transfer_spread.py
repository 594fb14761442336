"""How far the quick task-transfer test's ratios move from one draw to the next: the bounds of
``tests/test_task_transfer_quick.py`` from several seeds instead of one.

Usage::

    python -m studies.commands.quick_transfer_spread --out out/quick_spread --seeds 0-7 --workers 2

Why: the learning loop is chaotic (each retraining's model decides the next episode's data), so a change of the fit
at round-off level, such as another CPU's BLAS kernels (``.ci/other_kernels``), moves the learner's attempts as
much as another seed does. A bound measured on one seed can then fail on another CPU.

Protocol (fixed before the run): the test's own configuration (``sensor_pipeline="ideal"``, 1.2 kg payload, 2
restarts, cap 300; PD and RBD attempt "front" and "left" once; the demo's learner ``sp-inward-igated-online``
attempts "front" twice and "left" once, retrained after each), for each seed in ``--seeds``. Per seed the four
ratios the test asserts: ``rbd_over_pd`` on each task, ``learner_front_1_over_rbd`` (second attempt on the task it
has seen) and ``learner_left_0_over_rbd`` (first attempt on a new task). Decision rule: a bound that the largest
value over the seeds does not reach stays; else it becomes that largest value times 1.25, rounded up to a multiple
of 0.05, if that is still at most 0.75 (a learner no better than RBD gives about 1, so the test still fails for a
broken learner); else the test asserts only that the learner beats RBD (< 1) and the write-up says so.

Addendum (fixed before its run, after the runs above): the same configuration, seeds and decision rule under the
default sensing, ``--sensor-pipeline jaco2`` (the real Jaco 2's signal and link inertials), over seeds 0-7 and seed
0 under ``.ci/other_kernels``; the bounds the rule gives are then those of the quick test, which moves from the
idealised signal to the default sensing, the path the package ships. ``--sensor-pipeline`` defaults to
``ideal``, the protocol's first population.

Writes ``quick_transfer_spread.json`` (every attempt, the ratios per seed, their range) to ``--out`` and prints a
table.
"""

from __future__ import annotations

import argparse
import json
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from cascgp_experiments.cli.options import check_output

TASK_A, TASK_B = "front", "left"
LEARNER = "sp-inward-igated-online"
RATIOS = ("rbd_over_pd_front", "rbd_over_pd_left", "learner_front_1_over_rbd", "learner_left_0_over_rbd")


def run_seed(seed: int, sensor_pipeline: str = "ideal") -> dict:
    """The test fixture's runs for one seed (under ``sensor_pipeline``): every attempt's tracking RMSE and share of
    marbles in the jar."""
    import torch

    from cascgp.learning import run_controller
    from cascgp.rbd import load_nominal
    from cascgp_experiments.transfer import TransferConfig, jaco_feedback
    from jaco_env import nominal_urdf

    torch.set_num_threads(1)
    cfg = TransferConfig(controllers=("pd", "rbd", LEARNER), tasks=(TASK_A, TASK_B), attempts=2, payload_mass=1.2,
                         seed=seed, restarts=2, cap=300, sensor_pipeline=sensor_pipeline)
    env = cfg.make_env()
    rbd = load_nominal(nominal_urdf(env.unwrapped.link_inertials))
    try:
        once = [(TASK_A, 0, "eval"), (TASK_B, 0, "eval")]
        learn = [(TASK_A, 0, "train"), (TASK_A, 1, "train"), (TASK_B, 0, "train")]
        args = (rbd, jaco_feedback(), cfg.retrain())
        opts = cfg.reset_options()
        runs = {name: run_controller(name, env, once, *args, reset_options=opts) for name in ("pd", "rbd")}
        runs[LEARNER] = run_controller(LEARNER, env, learn, *args, reset_options=opts)
    finally:
        env.close()
    attempts = {name: [{k: a[k] for k in ("task", "task_attempt", "tracking_rmse", "in_jar")} for a in run.attempts]
                for name, run in runs.items()}
    return {"seed": seed, "sensor_pipeline": sensor_pipeline, "attempts": attempts, "ratios": ratios(attempts)}


def _rmse(attempts: list[dict], task: str, k: int = 0) -> float:
    sel = [a for a in attempts if a["task"] == task and a["task_attempt"] == k]
    if len(sel) != 1:
        raise ValueError(f"expected one attempt {k} on {task!r}, got {len(sel)}")
    return float(sel[0]["tracking_rmse"])


def ratios(attempts: dict[str, list[dict]]) -> dict[str, float]:
    """The four ratios the quick test asserts, from one seed's attempts (see the module docstring)."""
    pd, rbd, learner = attempts["pd"], attempts["rbd"], attempts[LEARNER]
    return {"rbd_over_pd_front": _rmse(rbd, TASK_A) / _rmse(pd, TASK_A),
            "rbd_over_pd_left": _rmse(rbd, TASK_B) / _rmse(pd, TASK_B),
            "learner_front_1_over_rbd": _rmse(learner, TASK_A, 1) / _rmse(rbd, TASK_A),
            "learner_left_0_over_rbd": _rmse(learner, TASK_B, 0) / _rmse(rbd, TASK_B)}


def _seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        out.extend(range(int(lo), int(hi or lo) + 1))
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--seeds", default="0-7", help="e.g. 0-7 or 0,3,5")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--sensor-pipeline", default="ideal", choices=("ideal", "jaco2"),
                   help="the env's sensing (default ideal: the protocol's first population; jaco2: its addendum)")
    a = p.parse_args(argv)
    check_output(p, a.out, "--out", "folder")
    try:
        seeds = _seeds(a.seeds)
    except ValueError:
        p.error(f"--seeds: expected integers and ranges like 0-7, got {a.seeds!r}")
    a.out.mkdir(parents=True, exist_ok=True)
    with ProcessPoolExecutor(a.workers) as ex:
        per_seed = list(ex.map(run_seed, seeds, [a.sensor_pipeline] * len(seeds)))
    spread = {r: {"min": min(s["ratios"][r] for s in per_seed), "max": max(s["ratios"][r] for s in per_seed)}
              for r in RATIOS}
    out = {"seeds": seeds, "sensor_pipeline": a.sensor_pipeline, "per_seed": per_seed, "spread": spread}
    tmp = a.out / "quick_transfer_spread.json.tmp"
    tmp.write_text(json.dumps(out, indent=1))
    tmp.replace(a.out / "quick_transfer_spread.json")
    print("| seed | " + " | ".join(RATIOS) + " |")
    print("|---|" + "---|" * len(RATIOS))
    for s in per_seed:
        print(f"| {s['seed']} | " + " | ".join(f"{s['ratios'][r]:.3f}" for r in RATIOS) + " |")
    print("| range | " + " | ".join(f"{spread[r]['min']:.3f}-{spread[r]['max']:.3f}" for r in RATIOS) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
