"""Regenerate the data-efficiency study's figures, tables and CSVs from ``results.json`` alone: the same as
``cascgp plots`` (:mod:`cascgp_experiments.cli.plots`), kept for the research log's commands.

Usage::

    python -m scripts.study_plots --json out/study/results.json --out out/study
"""

from __future__ import annotations

from cascgp_experiments.cli.plots import main

if __name__ == "__main__":
    main()
