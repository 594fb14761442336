"""Multi-seed, paired evaluation of the gated feedforward (issue 10; protocol in
:mod:`cascgp_experiments.gate_eval`).

Usage::

    python -m scripts.gate_eval --out out/gate_eval                  # the protocol: seeds 0-3, 4 tasks x 4 attempts
    python -m scripts.gate_eval --out out/gate_eval --seeds 0,1      # fewer seeds (a stopped run resumes)

Writes ``gate_eval.json`` (every attempt of every seed, the ratios and their summary), ``gate_eval.md``
(the tables) and ``gate_eval.png`` (every ratio, medians and criteria) to ``--out``; finished jobs are
cached under ``--out/cache``.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

from cascgp_experiments.execution import add_execution_args, check_args, session
from cascgp_experiments.gate_eval import GATE_EVAL_CONFIG, GATE_EVAL_SEEDS, run_gate_eval


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--seeds", type=str, default=",".join(map(str, GATE_EVAL_SEEDS)), help="comma-separated seeds")
    p.add_argument("--tasks", type=str, default=None, help="comma-separated tasks (default: the full transfer's)")
    p.add_argument("--attempts", type=int, default=GATE_EVAL_CONFIG.attempts, help="attempts per task")
    p.add_argument("--restarts", type=int, default=GATE_EVAL_CONFIG.restarts, help="GP restarts per retraining")
    p.add_argument("--cap", type=int, default=GATE_EVAL_CONFIG.cap, help="maximum training-set size")
    add_execution_args(p)
    a = p.parse_args(argv)
    check_args(p, a)
    try:
        seeds = tuple(int(s) for s in a.seeds.split(","))
    except ValueError:
        p.error(f"--seeds: expected comma-separated integers, got {a.seeds!r}")
    if a.attempts < 1:
        p.error("--attempts must be at least 1")
    cfg = replace(GATE_EVAL_CONFIG, attempts=a.attempts, restarts=a.restarts, cap=a.cap,
                  **({"tasks": tuple(a.tasks.split(","))} if a.tasks else {}))
    if len(cfg.tasks) < 2:
        p.error("--tasks: at least two tasks (the first attempt on a new task is compared with RBD)")
    with session(a.ray, a.workers):
        res = run_gate_eval(a.out, cfg, seeds, workers=a.workers, ray_address=a.ray)
    print((a.out / "gate_eval.md").read_text())
    print(f"wall {res['wall_seconds']:.0f} s; results: {a.out / 'gate_eval.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
