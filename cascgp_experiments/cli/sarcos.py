"""SARCOS part of the data-efficiency study (the paper's Fig. 5): NP standard / inward / outward curves.

Usage::

    cascgp sarcos --sarcos PATH/ias_sarcos_data.mat --out out/sarcos
    ... [--workers N | --ray ADDRESS]     # parallel fits (default: every core); same numbers

The SARCOS block of ``cascgp study`` (its preset's grid, subsets, restarts, seed and fit-audit fraction:
``--quick`` the quick preset's; the pooled tests included); data, subsets and models:
:mod:`cascgp_experiments.study` (SARCOS block).
Writes ``<out>/sarcos.json`` (per model the nRMSE of every subset, grid point and joint, their summaries, the
pooled tests, and ``meta``: the command, versions and machine), ``sarcos_table.md`` (each model's nRMSE per grid
point, median over subsets, mean over the 7 joints; also printed), ``fig_sarcos.png``, ``curves_sarcos.csv`` and
``sarcos_claims.md`` (the paper's SARCOS claims), as ``cascgp study`` writes its SARCOS part.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from cascgp.checks import MAX_RESTARTS
from cascgp.io import atomic_write_text, write_json
from cascgp_experiments.common import (SARCOS_ENV, default_sarcos, default_sarcos_source, limit_threads,
                                       machine_info, median_curves, package_versions)
from cascgp_experiments.cli.options import check_output, check_sarcos_file, refuse_other_experiment, require_at_least
from cascgp_experiments.execution import add_execution_args, check_args
from cascgp_experiments.study import PRESETS, Settings, run_sarcos


def main(argv: list[str] | None = None, prog: str | None = None) -> None:
    """``cascgp sarcos``: parse ``argv`` (``sys.argv[1:]`` when ``None``) and run the SARCOS curves."""
    ap = argparse.ArgumentParser(prog=prog, description="SARCOS NP standard/inward/outward data-efficiency curves")
    found = default_sarcos()
    ap.add_argument("--sarcos", default=None if found is None else str(found),
                    help=f"path of ias_sarcos_data.mat (default: ${SARCOS_ENV}, or a source checkout's ../shared copy)")
    ap.add_argument("--out", required=True, metavar="DIR",
                    help="output folder: sarcos.json, its table, figure and claims, the prepared data and the job "
                         "cache (a rerun resumes)")
    full, quick = PRESETS["full"], PRESETS["quick"]
    ap.add_argument("--quick", action="store_true",
                    help=f"the study's quick preset: {_preset(quick)}; default: the full preset: {_preset(full)}")
    ap.add_argument("--restarts", type=int, default=None,
                    help=f"optimiser starts per GP fit (default: the preset's, {full.n_restarts} or "
                         f"{quick.n_restarts} with --quick)")
    ap.add_argument("--seed", type=int, default=None,
                    help=f"seed of the random starts (default: the preset's, {full.seed})")
    add_execution_args(ap)
    a = ap.parse_args(argv)
    if a.sarcos is None:
        from cascgp.sarcos import IAS_SOURCE

        ap.error(f"--sarcos: expected the path of ias_sarcos_data.mat (or set ${SARCOS_ENV}); the file is not "
                 f"shipped: {IAS_SOURCE}")
    check_sarcos_file(ap, a.sarcos, "--sarcos" if a.sarcos != ap.get_default("sarcos") else default_sarcos_source())
    require_at_least(ap, a, 1, "restarts")
    if a.restarts is not None and a.restarts > MAX_RESTARTS:
        ap.error(f"--restarts: expected at most {MAX_RESTARTS} starts per GP, got {a.restarts}")
    require_at_least(ap, a, 0, "seed")
    check_output(ap, a.out, "--out", "folder")
    refuse_other_experiment(ap, a.out, "sarcos")
    check_args(ap, a)
    limit_threads(1)
    preset = PRESETS["quick" if a.quick else "full"]
    out = Path(a.out)
    meta = {"command": " ".join([prog or "cascgp sarcos"] + (argv if argv is not None else sys.argv[1:])),
            "versions": package_versions(), "machine": machine_info(), "started": time.strftime("%Y-%m-%d %H:%M:%S")}
    block = run_sarcos(a.sarcos, out, grid=preset.sarcos_grid, n_subsets=preset.sarcos_subsets,
                       n_restarts=preset.n_restarts if a.restarts is None else a.restarts,
                       seed=preset.seed if a.seed is None else a.seed, workers=a.workers, ray_address=a.ray,
                       audit_fraction=preset.audit_fraction)
    meta["finished"] = time.strftime("%Y-%m-%d %H:%M:%S")
    meta["reused"] = {"sarcos_jobs": [block["n_cached_jobs"], block["jobs"]["n_jobs"]]}  # an earlier run's, in --out
    block["meta"] = meta
    write_json(out / "sarcos.json", block)
    table = summary_table(block)
    atomic_write_text(out / "sarcos_table.md", table + "\n")
    from cascgp_experiments.plots import render_results

    render_results({"sarcos": block}, out, claims="sarcos_claims.md")  # fig_sarcos.png, curves_sarcos.csv
    print(table)
    print(f"wrote {out / 'sarcos.json'}, {out / 'sarcos_table.md'}, {out / 'fig_sarcos.png'}, "
          f"{out / 'curves_sarcos.csv'} and {out / 'sarcos_claims.md'}")
    if block["n_cached_jobs"]:
        print(f"({block['n_cached_jobs']} of {block['jobs']['n_jobs']} jobs came from an earlier run in this folder)")


def _preset(p: Settings) -> str:
    return (f"{len(p.sarcos_grid)} grid points ({p.sarcos_grid[0]:g}-{p.sarcos_grid[-1]:g} s of data), "
            f"{p.sarcos_subsets} subsets, {p.n_restarts} restarts")


def summary_table(block: dict) -> str:
    """Each model's nRMSE per grid point of a SARCOS block: the median over subsets, averaged over the joints."""
    curves = {m: np.asarray(c, dtype=float).mean(axis=1) for m, c in median_curves(block).items()}  # (G,) each
    lines = ["nRMSE (median over subsets, mean over joints)", "| seconds | " + " | ".join(curves) + " |",
             "|---" * (len(curves) + 1) + "|"]
    for g, sec in enumerate(block["grid_s"]):
        cells = [f"{c[g]:.4f}" for c in curves.values()]
        lines.append(f"| {sec:g} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
