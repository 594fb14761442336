"""SARCOS part of the data-efficiency study (the paper's Fig. 5): NP standard / inward / outward curves.

Usage::

    cascgp sarcos --sarcos PATH/ias_sarcos_data.mat --out out/sarcos
    ... [--workers N | --ray ADDRESS]     # parallel fits (default: every core); same numbers

Data, subsets and models: :mod:`cascgp_experiments.study` (SARCOS block). Writes ``<out>/sarcos.json``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cascgp.io import write_json
from cascgp_experiments.common import SARCOS_ENV, default_sarcos, limit_threads
from cascgp_experiments.execution import add_execution_args, check_args
from cascgp_experiments.study import SARCOS_FULL_GRID, SARCOS_QUICK_GRID, run_sarcos


def main(argv: list[str] | None = None, prog: str | None = None) -> None:
    """``cascgp sarcos``: parse ``argv`` (``sys.argv[1:]`` when ``None``) and run the SARCOS curves."""
    ap = argparse.ArgumentParser(prog=prog, description="SARCOS NP standard/inward/outward data-efficiency curves")
    found = default_sarcos()
    ap.add_argument("--sarcos", default=None if found is None else str(found), required=found is None,
                    help=f"path of ias_sarcos_data.mat (default: ${SARCOS_ENV}, or a source checkout's ../shared copy)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--restarts", type=int, default=1)
    add_execution_args(ap)
    a = ap.parse_args(argv)
    if not Path(a.sarcos).is_file():
        ap.error(f"--sarcos: file not found: {a.sarcos}")
    check_args(ap, a)
    limit_threads(1)
    block = run_sarcos(a.sarcos, a.out, grid=SARCOS_QUICK_GRID if a.quick else SARCOS_FULL_GRID,
                       n_restarts=a.restarts, workers=a.workers, ray_address=a.ray)
    write_json(Path(a.out) / "sarcos.json", block)
    print(f"wrote {Path(a.out) / 'sarcos.json'}")


if __name__ == "__main__":
    main()
