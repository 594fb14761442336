"""Wall time of the experiments with 1 vs N workers (and on Ray); a table and a JSON.

Usage::

    python -m scripts.bench_parallel --cases transfer-quick,study-max5 --json docs/bench/parallel.json
    python -m scripts.bench_parallel --cases transfer-quick --settings "--workers 1;--workers 2;--ray local --workers 2"

Cases and the cluster estimate: :mod:`cascgp_experiments.parallel_bench`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cascgp_experiments.cli.options import check_output
from cascgp_experiments.parallel_bench import CASES, run


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", default="transfer-quick", help=f"comma-separated, of {list(CASES)}")
    ap.add_argument("--settings", default="--workers 1;--workers 2",
                    help="';'-separated execution options of each run; the first one is the reference")
    ap.add_argument("--root", type=Path, default=Path("out/bench_parallel"), help="folder for the runs' outputs")
    ap.add_argument("--json", type=Path, default=None, help="write the results here (after every run)")
    a = ap.parse_args(argv)
    check_output(ap, a.root, "--root", "folder")
    check_output(ap, a.json, "--json", "file")
    cases = [c.strip() for c in a.cases.split(",") if c.strip()]
    bad = [c for c in cases if c not in CASES]
    if bad:
        ap.error(f"--cases: unknown {bad}; expected names from {list(CASES)}")
    settings = [s.split() for s in a.settings.split(";")]
    rep = run(cases, settings, a.root, a.json)
    print(rep["table"])


if __name__ == "__main__":
    main()
