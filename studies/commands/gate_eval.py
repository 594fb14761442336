"""Multi-seed, paired evaluation of the gated feedforward (issue 10; protocol in
:mod:`studies.gate_eval`).

Usage::

    python -m studies.commands.gate_eval --out out/gate_eval              # the protocol: seeds 0-3, 4 tasks x 4
    python -m studies.commands.gate_eval --out out/gate_eval --seeds 0,1  # fewer seeds (a stopped run resumes)

Writes ``gate_eval.json`` (every attempt of every seed, the ratios and their summary), ``gate_eval.md``
(the tables) and ``gate_eval.png`` (every ratio, medians and criteria) to ``--out``; finished jobs are
cached under ``--out/cache``.
"""

from __future__ import annotations

import argparse

from cascgp_experiments.execution import add_execution_args, check_args, session
from studies.gate_eval import add_protocol_args, protocol_from_args, run_gate_eval


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_protocol_args(p)
    add_execution_args(p)
    a = p.parse_args(argv)
    check_args(p, a)
    cfg, seeds = protocol_from_args(p, a, min_attempts=1,
                                    two_tasks_why="the first attempt on a new task is compared with RBD")
    with session(a.ray, a.workers):
        res = run_gate_eval(a.out, cfg, seeds, workers=a.workers, ray_address=a.ray)
    print((a.out / "gate_eval.md").read_text())
    print(f"wall {res['wall_seconds']:.0f} s; results: {a.out / 'gate_eval.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
