"""The paper's data-efficiency study, reproduced in simulation (and on SARCOS), in one command.

Usage::

    cascgp study --out out/study --sarcos PATH/ias_sarcos_data.mat   # full (under an hour, 2 cores)
    cascgp study --out out/quick --quick                             # a few minutes (no SARCOS file: Jaco only)
    cascgp study --out out/study --ray local                         # the same jobs on a local Ray instance

The steps, presets and outputs: :mod:`cascgp_experiments.study`.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

from cascgp_experiments.cli.options import check_output, check_sarcos_file, refuse_other_experiment, settings_error
from cascgp_experiments.common import SARCOS_ENV, VARIANTS, default_sarcos, default_sarcos_source, limit_threads
from cascgp_experiments.execution import add_execution_args, check_args
from cascgp_experiments.study import PRESETS, collection_config, reuse_note, run_study


def _refuse_other_collection(ap: argparse.ArgumentParser, out: Path, st: Any) -> None:
    """``ap.error`` when ``out/data`` holds a collection of other settings than the study's (it would be replaced
    while the folder's earlier results stay beside it until this run ends), as ``cascgp collect`` refuses one."""
    from cascgp.data import DynamicsData
    from cascgp_experiments import collect as col

    cfg = collection_config(st)
    for split in ("train", "test"):
        path = col.data_path(out / "data", split)
        if not path.is_file():
            continue
        try:
            stored = DynamicsData.load(path).meta.get("collection")
        except (OSError, ValueError) as exc:
            ap.error(f"--out: {path} cannot be read ({exc}); pass --overwrite to collect again there, or choose "
                     "another --out folder")
        if not col.same_collection(stored, cfg):
            what = col.collection_difference(stored, cfg)
            ap.error(f"--out: {path} holds a collection with other settings ({what}); pass --overwrite to collect "
                     "again there, or choose another --out folder")


def main(argv: list[str] | None = None, prog: str | None = None) -> None:
    """``cascgp study``: parse ``argv`` (``sys.argv[1:]`` when ``None``) and run the study."""
    ap = argparse.ArgumentParser(prog=prog, description="Data-efficiency study of the 12 cascaded-GP variants "
                                                        "(paper sec. IV)")
    ap.add_argument("--out", required=True, help="output folder (data, cache, results.json, figures, tables)")
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--quick", action="store_true", help="reduced grid/data end to end (a few minutes)")
    g.add_argument("--smoke", action="store_true", help="tiny end-to-end run (for the default tests)")
    ap.add_argument("--sarcos", default=None,
                    help=f"IAS SARCOS .mat file (default: ${SARCOS_ENV}, or a source checkout's ../shared copy; "
                         "without one the SARCOS part is skipped)")
    ap.add_argument("--no-sarcos", action="store_true", help="skip the SARCOS part")
    ap.add_argument("--no-iterations", action="store_true", help="skip the iteration-count fits")
    ap.add_argument("--overwrite", action="store_true",
                    help="collect again into --out/data, replacing what is there (without it, a collection of "
                         "other settings, or one that cannot be read, is refused)")
    ap.add_argument("--models", default=None, help="comma-separated subset of the 12 variants")
    add_execution_args(ap)
    ap.add_argument("--restarts", type=int, default=None,
                    help="GP starts per fit (default 10, --quick 3, --smoke 2; one warm-started along the grid)")
    ap.add_argument("--subsets", type=int, default=None,
                    help="training subsets used (default 10, --quick 3, --smoke 2)")
    ap.add_argument("--grid", default=None, help="comma-separated seconds of data (default: the preset's)")
    ap.add_argument("--max-seconds", type=float, default=None,
                    help="drop grid points above this many seconds (Jaco and SARCOS), e.g. 10 for Table I's "
                         "intervals only: the 14-50 s points cost most of the fitting time")
    ap.add_argument("--seed", type=int, default=0,
                    help="seed of the data collection, the GP fits' random starts and the audit's sample (default: 0)")
    ap.add_argument("--sensor-pipeline", default="jaco2",
                    help="the simulated arm's sensing (CollectConfig.sensor_pipeline): jaco2 (default: the real Jaco "
                         "2's signal, Kinova's link inertials, causal q̈ filter), ideal or ideal+FACTOR[+FACTOR...]")
    a = ap.parse_args(argv)

    preset = "quick" if a.quick else "smoke" if a.smoke else "full"
    st = PRESETS[preset]
    kw: dict[str, Any] = {"seed": a.seed, "sensor_pipeline": a.sensor_pipeline}
    if a.restarts is not None:
        kw["n_restarts"] = a.restarts
    if a.subsets is not None:
        kw["n_subsets"] = a.subsets
    if a.grid is not None:
        try:
            kw["grid"] = tuple(float(x) for x in a.grid.split(","))
        except ValueError:
            ap.error(f"--grid: expected comma-separated seconds of data (e.g. 1,2,5), got {a.grid!r}")
    try:
        st = replace(st, **kw)
    except ValueError as exc:
        settings_error(ap, exc, {"n_restarts": "--restarts", "n_subsets": "--subsets", "grid": "--grid",
                                 "seed": "--seed", "sensor_pipeline": "--sensor-pipeline"})
    if a.max_seconds is not None:  # the grids checked above; what is left of them stays valid (SARCOS's may be empty)
        if not a.max_seconds >= st.grid[0]:
            ap.error(f"--max-seconds: expected at least the smallest grid point {st.grid[0]}, got {a.max_seconds}")
        st = replace(st, grid=tuple(g for g in st.grid if g <= a.max_seconds),
                     sarcos_grid=tuple(g for g in st.sarcos_grid if g <= a.max_seconds))
    models = None
    if a.models:
        models = [m.strip() for m in a.models.split(",") if m.strip()]
        bad = [m for m in models if m not in VARIANTS]
        if bad or not models:
            ap.error(f"--models: {f'unknown {bad}' if bad else 'no name'}; expected names from {list(VARIANTS)}")
    if a.no_sarcos and a.sarcos is not None:
        ap.error("--sarcos: the SARCOS part is skipped (--no-sarcos): give one of the two")
    sarcos, skip_note = None, None
    if not a.no_sarcos:
        found = default_sarcos()
        sarcos = a.sarcos or (None if found is None else str(found))  # $CASCGP_SARCOS is checked like --sarcos
        if sarcos is not None and st.sarcos_grid:
            check_sarcos_file(ap, sarcos, "--sarcos" if a.sarcos else default_sarcos_source())
        if sarcos is None:
            from cascgp.sarcos import IAS_SOURCE

            skip_note = (f"no SARCOS file (--sarcos or ${SARCOS_ENV}): the SARCOS part is skipped "
                         f"(the file: {IAS_SOURCE})")
        elif not st.sarcos_grid:
            skip_note = f"--max-seconds {a.max_seconds:g} is below every SARCOS grid point: the SARCOS part is skipped"
    check_output(ap, a.out, "--out", "folder")
    refuse_other_experiment(ap, a.out, "study")
    if not a.overwrite:
        _refuse_other_collection(ap, Path(a.out), st)
    check_args(ap, a)
    if skip_note:  # after every check: a refused command prints its error alone
        print(skip_note, file=sys.stderr)
    limit_threads(1)
    res = run_study(a.out, st, models=models, workers=a.workers, ray_address=a.ray, sarcos=sarcos,
                    do_iterations=not a.no_iterations, collect_again=a.overwrite,
                    command=" ".join([prog or "cascgp study"] + (argv if argv is not None else sys.argv[1:])))
    t = res["meta"]["timings"]
    print("timings (s): " + ", ".join(f"{k}={v:.1f}" for k, v in t.items()))
    note = reuse_note(res["meta"])
    if note:
        print(note)
    if res["meta"].get("sarcos_skipped"):
        print(f"SARCOS part skipped ({res['meta']['sarcos_skipped']}): claims.md has no SARCOS claims")
    print(f"results: {Path(a.out) / 'results.json'}; table: {Path(a.out) / 'table1.md'}")


if __name__ == "__main__":
    main()
