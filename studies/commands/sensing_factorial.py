"""Run the sensing factorial study (protocol: ``docs/studies/sensing_factorial.md``; code:
:mod:`studies.sensing_factorial`).

Usage::

    python -m studies.commands.sensing_factorial --out out/sensing_factorial --workers 2
    python -m studies.commands.sensing_factorial --out out/sf_quick --quick        # minutes; no verdicts
    python -m studies.commands.sensing_factorial --report out/sensing_factorial/factorial.json  # render again
    python -m studies.commands.sensing_factorial --report out/sensing_factorial/factorial.json \
        --slim docs/studies/sensing_factorial.json                                # the documentation's copy

Writes ``factorial.json`` (every arm's collection options, curves and effects, the verdicts, the run's provenance),
``factorial.md`` and ``factorial.png`` to ``--out``; each arm's data and cached fits go to ``--out/<arm>/``, so an
interrupted run resumes.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cascgp.io import read_json, write_json
from cascgp_experiments.cli.options import check_output
from cascgp_experiments.execution import add_execution_args, check_args, session
from studies.sensing_factorial import ARMS, run
from studies.sensing_factorial_report import figure, markdown, slim


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--out", type=Path, help="output folder")
    g.add_argument("--report", type=Path, help="a factorial.json: write its .md and .png beside it, run nothing")
    p.add_argument("--slim", type=Path, default=None,
                   help="with --report: also write the results without curve summaries and job statistics here")
    p.add_argument("--quick", action="store_true",
                   help="the quick collection, 2 subsets, one grid point per interval, 2 starts per fit; no verdicts")
    p.add_argument("--arms", default=",".join(ARMS), help=f"comma-separated arms (default all: {','.join(ARMS)})")
    add_execution_args(p)
    a = p.parse_args(argv)
    check_args(p, a)
    check_output(p, a.out, "--out", "folder")
    if a.report is not None:
        if not a.report.is_file():
            p.error(f"--report: no file {a.report}")
        res = read_json(a.report)
        a.report.with_suffix(".md").write_text(markdown(res), encoding="utf-8")
        figure(res, a.report.with_suffix(".png"))
        if a.slim is not None:
            write_json(a.slim, slim(res))
        return 0
    arms = [x for x in a.arms.split(",") if x]
    bad = [x for x in arms if x not in ARMS]
    if bad or not arms:
        p.error(f"--arms: expected names of {tuple(ARMS)} separated by commas, got {a.arms!r}")
    with session(a.ray, a.workers):
        res = run(a.out, quick=a.quick, workers=a.workers, ray_address=a.ray, arms=arms,
                  command=" ".join(["python -m studies.commands.sensing_factorial", *(argv or sys.argv[1:])]))
    print((a.out / "factorial.md").read_text(encoding="utf-8"))
    print(f"wrote {a.out / 'factorial.json'}, factorial.md, factorial.png ({res['meta']['wall_s']:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
