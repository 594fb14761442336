"""Gate rules as learners on new seeds: the floor rule against the Wiener rule, and the innovation rule (issue 10;
protocols in :mod:`studies.gate_rule` and ``docs/studies/gate_rule.md``).

Usage::

    python -m studies.commands.gate_rule --out out/gate_rule --workers 2        # floor rule, seeds 12-19
    python -m studies.commands.gate_rule --rule innovation --out out/gate_rule_innovation --workers 2  # 20-27
    python -m studies.commands.gate_rule --out out/gate_rule_small --seeds 12   # fewer seeds

Writes ``gate_rule.json`` (every attempt of every learner, the ratios, the J4 split and the decision),
``gate_rule.md`` and ``gate_rule.png`` to ``--out``; finished jobs are cached under ``--out/cache`` (a stopped
run resumes).
"""

from __future__ import annotations

import argparse

from cascgp_experiments.execution import add_execution_args, check_args, session
from studies.gate_eval import add_protocol_args, protocol_from_args
from studies.gate_rule import GATE_RULE_CONFIG, PROTOCOLS, run_gate_rule


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_protocol_args(p)
    p.add_argument("--rule", choices=tuple(PROTOCOLS), default="floor",
                   help="which pre-registered protocol: the floor rule against the Wiener rule (seeds 12-19) or the "
                        "innovation rule (seeds 20-27); --seeds overrides the seeds")
    p.set_defaults(seeds=None, tasks=",".join(GATE_RULE_CONFIG.tasks))
    add_execution_args(p)
    a = p.parse_args(argv)
    if a.seeds is None:  # the protocol's own seeds
        a.seeds = ",".join(map(str, PROTOCOLS[a.rule][3]))
    check_args(p, a)
    cfg, seeds = protocol_from_args(p, a, min_attempts=2, two_tasks_why="the first task's data meet the new task")
    with session(a.ray, a.workers):
        res = run_gate_rule(a.out, cfg, seeds, protocol=a.rule, workers=a.workers, ray_address=a.ray)
    print((a.out / "gate_rule.md").read_text())
    print(f"wall {res['wall_seconds']:.0f} s; results: {a.out / 'gate_rule.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
