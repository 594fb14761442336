"""Gated vs ungated learners: a null comparison, a decomposition and a test of the divergence hypothesis
(issue 10; protocol in :mod:`studies.learner_divergence`).

Usage::

    # the protocol
    python -m studies.commands.learner_divergence --out out/divergence --reference docs/studies/gate_eval.json
    python -m studies.commands.learner_divergence --out out/divergence --seeds 0  # fewer seeds

Writes ``learner_divergence.json`` (every attempt of every learner with the uncertainty along the reference,
the ratios, the tests), ``learner_divergence.md`` and ``learner_divergence.png`` to ``--out``; finished jobs are
cached under ``--out/cache`` (a stopped run resumes).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cascgp.io import read_json
from cascgp_experiments.execution import add_execution_args, check_args, session
from studies.gate_eval import add_protocol_args, protocol_from_args
from studies.learner_divergence import run_divergence


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_protocol_args(p)
    p.add_argument("--reference", type=Path, default=None,
                   help="the gate evaluation's JSON (docs/studies/gate_eval.json) to check the reproduction against")
    add_execution_args(p)
    a = p.parse_args(argv)
    check_args(p, a)
    cfg, seeds = protocol_from_args(p, a, min_attempts=2, two_tasks_why="the early attempts on a new task are compared")
    if a.reference is not None and not a.reference.is_file():
        p.error(f"--reference: no file {a.reference}")
    reference = read_json(a.reference) if a.reference is not None else None
    with session(a.ray, a.workers):
        res = run_divergence(a.out, cfg, seeds, workers=a.workers, ray_address=a.ray, reference=reference)
    print((a.out / "learner_divergence.md").read_text())
    print(f"wall {res['wall_seconds']:.0f} s; results: {a.out / 'learner_divergence.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
