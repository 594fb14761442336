"""Regenerate the data-efficiency study's figures, tables and CSVs from ``results.json`` alone.

Usage::

    python -m scripts.study_plots --json out/study/results.json --out out/study

What is written: :mod:`cascgp_experiments.plots`.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from cascgp_experiments.cli.options import check_input, check_output
from cascgp_experiments.plots import render


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description="Regenerate the study's figures and tables from results.json")
    ap.add_argument("--json", required=True)
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    check_input(ap, a.json, "--json", "file")
    check_output(ap, a.out, "--out", "folder")
    try:
        run = json.loads(Path(a.json).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        ap.error(f"--json: {a.json}: expected a study's results.json ({exc})")
    if not isinstance(run, dict) or not ({"jaco", "sarcos"} & set(run)):
        ap.error(f"--json: {a.json}: expected a study's results.json (no 'jaco' or 'sarcos' results)")
    for p in render(a.json, a.out):
        print(p)


if __name__ == "__main__":
    main()
