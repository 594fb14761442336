"""Regenerate the data-efficiency study's figures, tables and CSVs from ``results.json`` alone.

Usage::

    python -m scripts.study_plots --json out/study/results.json --out out/study

What is written: :mod:`cascgp_experiments.plots`.
"""

from __future__ import annotations

import argparse

from cascgp_experiments.plots import render


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description="Regenerate the study's figures and tables from results.json")
    ap.add_argument("--json", required=True)
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    for p in render(a.json, a.out):
        print(p)


if __name__ == "__main__":
    main()
