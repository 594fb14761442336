"""The paper's data-efficiency study, reproduced in simulation (and on SARCOS), in one command.

Steps (each with progress bars; everything lands in ``--out``):

1. Collect the simulated Jaco data (:mod:`scripts.collect_jaco_data`): 10 x 60 s of random
   sum-of-sinusoids velocity-commanded motion with a 0.8 kg payload unknown to the nominal model,
   3 x 60 s of test motion; measured (noisy) q, qd, tau at 100 Hz, qdd by central differences.
   Cached in ``<out>/data``.
2. Curves (:mod:`scripts._study_curves`): each of the 12 variants is trained on the first T
   seconds of each subset, subsampled to 10 Hz, for T on the grid; nRMSE per joint on the test
   set (all three test minutes, subsampled to 10 Hz: 1800 rows, minus the first 0.2 s of each
   test motion, where the derivative-free history is missing, for every model alike). The RBD
   baseline (nominal RNEA) is evaluated on the same rows.
3. Optimiser iteration counts per joint, NP standard / inward / outward, n = 500, 10 restarts
   (:mod:`scripts.iteration_counts`), with the wall time of each fit.
4. Spearman rank correlation of joint states and torques (:mod:`scripts.correlation`).
5. SARCOS NP curves (:mod:`scripts.sarcos_study`).
6. ``results.json`` (every number shown), ``curves_jaco.csv``, ``curves_sarcos.csv``, ``table1.md``,
   the figures (:mod:`scripts.study_plots`, from the JSON alone) and ``claims.md``.

Settings (``--quick`` / ``--smoke`` reduce everything; the defaults are the full study, sized for
a 2-core machine shared with other work to finish in under an hour: the grid has 15 points; the
every grid fit has the paper's 10 starts, one of them warm-started from the previous grid point's
optimum after the first grid point; a seeded 5 % of the grid fits is audited against 10 cold starts
run to convergence (``results.json["jaco"]["audit"]``). Table I reports medians over the subsets
with their interquartile ranges; the claims are judged with paired per-subset comparisons (wins
out of the subsets and a two-sided sign-test p-value, :mod:`scripts.study_claims`). The
iteration-count study uses 10 starts per GP as in the paper.

Usage::

    python -m scripts.data_efficiency --out out/study            # full (under an hour, 2 cores)
    python -m scripts.data_efficiency --out out/quick --quick    # a few minutes
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

from scripts._study_common import (DEFAULT_SARCOS, FULL_GRID, NOMINAL_URDF, PAPER_TABLE, QUICK_GRID, RBD,
                                   SMOKE_GRID, VARIANTS, label, limit_threads, make_table, write_json)


@dataclass(frozen=True)
class Settings:
    """One preset of the study (all of it is written to ``results.json``)."""

    collection: str = "full"           # preset of scripts.collect_jaco_data
    grid: tuple[float, ...] = FULL_GRID
    n_subsets: int = 10
    n_restarts: int = 10
    warm_start: bool = True
    audit_fraction: float = 0.05
    iter_n: int = 500
    iter_restarts: int = 10
    sarcos_grid: tuple[float, ...] = (1.0, 1.5, 2.0, 3.0, 4.0, 4.5, 5.0, 7.0, 9.0, 9.5, 10.0, 14.0, 20.0, 30.0)
    sarcos_subsets: int = 9
    test_hz: float = 10.0
    seed: int = 0


PRESETS: dict[str, Settings] = {
    "full": Settings(),
    "quick": Settings(collection="quick", grid=QUICK_GRID, n_subsets=3, n_restarts=3, audit_fraction=0.1, iter_n=100,
                      iter_restarts=3, sarcos_grid=(1.0, 2.0, 5.0, 10.0), sarcos_subsets=3),
    "smoke": Settings(collection="smoke", grid=SMOKE_GRID, n_subsets=2, n_restarts=2, audit_fraction=0.25, iter_n=20,
                      iter_restarts=2, sarcos_grid=(1.0, 2.0), sarcos_subsets=2),
}


def _versions() -> dict[str, str]:
    import importlib.metadata as md

    out = {"python": platform.python_version()}
    for p in ("numpy", "scipy", "torch", "mujoco", "gymnasium", "pin"):
        try:
            out[p] = md.version(p)
        except md.PackageNotFoundError:
            pass
    return out


def cached_iteration_counts(out: Path, train, settings: Settings) -> dict[str, Any]:
    """Iteration counts (step 3) on the first training subset at 10 Hz, cached in
    ``<out>/cache/iterations.json`` (keyed by the settings that matter)."""
    from scripts._study_common import read_json
    from scripts.iteration_counts import iteration_counts

    key = {"n": settings.iter_n, "n_restarts": settings.iter_restarts, "seed": settings.seed,
           "collection": settings.collection}
    path = Path(out) / "cache" / "iterations.json"
    if path.exists():
        cached = read_json(path)
        if cached.get("key") == key:
            return cached
    t0 = time.perf_counter()
    d10 = train.subsample(10.0)
    first = d10.take(d10.segment == d10.segments[0])
    src = first if first.n_samples >= settings.iter_n else d10
    res = iteration_counts(src, n=settings.iter_n, n_restarts=settings.iter_restarts, seed=settings.seed)
    res["data"] = "first training subset (10 Hz)" if src is first else "training set (10 Hz)"
    res["key"] = key
    res["wall_s"] = time.perf_counter() - t0
    write_json(path, res)
    return res


def run_study(out: str | Path, settings: Settings, *, models: list[str] | None = None, workers: int = 2,
              sarcos: str | Path | None = None, do_iterations: bool = True, do_plots: bool = True,
              command: str = "") -> dict[str, Any]:
    """Run the whole study into ``out``; returns the results dict (also ``out/results.json``)."""
    from cascgp.data import DynamicsData

    from scripts import collect_jaco_data as col
    from scripts._study_curves import CurveSpec, run_curves
    from scripts.correlation import spearman_block

    t_all = time.perf_counter()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    models = list(models or VARIANTS)
    timings: dict[str, float] = {}
    results: dict[str, Any] = {"meta": {
        "command": command, "settings": asdict(settings), "models": models, "workers": workers,
        "versions": _versions(), "started": time.strftime("%Y-%m-%d %H:%M:%S"),
        "machine": {"cpus": __import__("os").cpu_count(), "platform": platform.platform()}}}

    # 1. data
    ccfg = replace(col.PRESETS[settings.collection], seed=settings.seed)
    train, test, cinfo = col.collect(out / "data", ccfg)
    timings["collect_s"] = cinfo["wall_s"]
    results["meta"]["collection"] = {**asdict(ccfg), "reused": cinfo["reused"],
                                     "train_rows": train.n_samples, "test_rows": test.n_samples,
                                     "train_total_seconds": train.duration, "test_total_seconds": test.duration,
                                     "qdd": train.meta.get("qdd_source")}

    # 2. curves (12 variants + RBD)
    spec = CurveSpec(train_path=str(out / "data" / "jaco_train.npz"), test_path=str(out / "data" / "jaco_test.npz"),
                     n_subsets=settings.n_subsets, grid=list(settings.grid), train_hz=10.0,
                     test_hz=settings.test_hz, split_by="segment", urdf=str(NOMINAL_URDF),
                     n_restarts=settings.n_restarts, warm_start=settings.warm_start, seed=settings.seed,
                     audit_fraction=settings.audit_fraction)
    jaco = run_curves(spec, models + [RBD], workers=workers, cache_dir=out / "cache" / "jaco", desc="Jaco fits")
    timings["jaco_curves_s"] = jaco["wall_s"]
    jaco["dof"] = train.dof
    jaco["labels"] = {m: label(m) for m in jaco["models"]}
    # Table I from the medians over subsets (errors are heavy-tailed); the IQR beside it; means and
    # standard deviations stay in the JSON.
    jaco["table"] = make_table(jaco["grid_s"], {m: v["nrmse_median"] for m, v in jaco["models"].items()})
    jaco["table_q25"] = make_table(jaco["grid_s"], {m: v["nrmse_q25"] for m, v in jaco["models"].items()})["rows"]
    jaco["table_q75"] = make_table(jaco["grid_s"], {m: v["nrmse_q75"] for m, v in jaco["models"].items()})["rows"]
    jaco["table_mean"] = make_table(jaco["grid_s"], {m: v["nrmse_mean"] for m, v in jaco["models"].items()})["rows"]
    jaco["table_std"] = make_table(jaco["grid_s"], {m: v["nrmse_std"] for m, v in jaco["models"].items()})["rows"]
    results["jaco"] = jaco
    results["paper_table"] = {"intervals": [[1, 2], [4, 5], [9, 10]], "rows": PAPER_TABLE}
    write_json(out / "results.json", results)

    # 3. iteration counts
    if do_iterations:
        results["iterations"] = cached_iteration_counts(out, train, settings)
        timings["iterations_s"] = results["iterations"]["wall_s"]
        write_json(out / "results.json", results)

    # 4. correlation
    t0 = time.perf_counter()
    results["correlation"] = spearman_block(train.subsample(10.0))
    results["correlation"]["data"] = "Jaco training set, 10 Hz"
    timings["correlation_s"] = time.perf_counter() - t0

    # 5. SARCOS
    if sarcos is not None:
        from scripts.sarcos_study import run_sarcos

        s = run_sarcos(sarcos, out / "sarcos", grid=settings.sarcos_grid, n_subsets=settings.sarcos_subsets,
                       n_restarts=settings.n_restarts, workers=workers, seed=settings.seed)
        s["labels"] = {m: label(m) for m in s["models"]}
        results["sarcos"] = s
        timings["sarcos_s"] = s["wall_s_total"]

    timings["total_s"] = time.perf_counter() - t_all
    results["meta"]["timings"] = timings
    results["meta"]["finished"] = time.strftime("%Y-%m-%d %H:%M:%S")
    write_json(out / "results.json", results)

    # 6. tables, figures, claims (from the JSON alone)
    if do_plots:
        from scripts import study_plots

        study_plots.render(out / "results.json", out)
    return results


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description="Data-efficiency study of the 12 cascaded-GP variants (paper sec. IV)")
    ap.add_argument("--out", required=True, help="output folder (data, cache, results.json, figures, tables)")
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--quick", action="store_true", help="reduced grid/data end to end (a few minutes)")
    g.add_argument("--smoke", action="store_true", help="tiny end-to-end run (for the default tests)")
    ap.add_argument("--sarcos", default=None,
                    help=f"IAS SARCOS .mat file (default {DEFAULT_SARCOS} when it exists)")
    ap.add_argument("--no-sarcos", action="store_true", help="skip the SARCOS part")
    ap.add_argument("--no-iterations", action="store_true", help="skip the iteration-count fits")
    ap.add_argument("--models", default=None, help="comma-separated subset of the 12 variants")
    ap.add_argument("--workers", type=int, default=None, help="processes for the fits (default: min(2, cpus))")
    ap.add_argument("--restarts", type=int, default=None,
                    help="GP starts per fit (default 10, one warm-started along the grid)")
    ap.add_argument("--subsets", type=int, default=None, help="training subsets used (default 10)")
    ap.add_argument("--grid", default=None, help="comma-separated seconds of data (default: the preset's)")
    ap.add_argument("--max-seconds", type=float, default=None,
                    help="drop grid points above this many seconds (Jaco and SARCOS), e.g. 10 for Table I's "
                         "intervals only: the 14-50 s points cost most of the fitting time")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)

    preset = "quick" if a.quick else "smoke" if a.smoke else "full"
    st = PRESETS[preset]
    kw: dict[str, Any] = {"seed": a.seed}
    if a.restarts is not None:
        kw["n_restarts"] = a.restarts
    if a.subsets is not None:
        kw["n_subsets"] = a.subsets
    if a.grid is not None:
        kw["grid"] = tuple(float(x) for x in a.grid.split(","))
    st = replace(st, **kw)
    if a.max_seconds is not None:
        if not a.max_seconds >= min(st.grid):
            ap.error(f"--max-seconds: expected at least the smallest grid point {min(st.grid)}, got {a.max_seconds}")
        st = replace(st, grid=tuple(g for g in st.grid if g <= a.max_seconds),
                     sarcos_grid=tuple(g for g in st.sarcos_grid if g <= a.max_seconds))
    models = None
    if a.models:
        models = [m.strip() for m in a.models.split(",") if m.strip()]
        bad = [m for m in models if m not in VARIANTS]
        if bad:
            ap.error(f"--models: unknown {bad}; expected names from {list(VARIANTS)}")
    sarcos = None
    if not a.no_sarcos:
        sarcos = a.sarcos or (str(DEFAULT_SARCOS) if DEFAULT_SARCOS.exists() else None)
        if a.sarcos and not Path(a.sarcos).exists():
            ap.error(f"--sarcos: file not found: {a.sarcos}")
    from scripts._study_curves import default_workers

    workers = a.workers if a.workers is not None else (1 if preset == "smoke" else default_workers())
    limit_threads(1)
    res = run_study(a.out, st, models=models, workers=workers, sarcos=sarcos, do_iterations=not a.no_iterations,
                    command=" ".join(["python -m scripts.data_efficiency"] + (argv if argv is not None else sys.argv[1:])))
    t = res["meta"]["timings"]
    print("timings (s): " + ", ".join(f"{k}={v:.1f}" for k, v in t.items()))
    print(f"results: {Path(a.out) / 'results.json'}; table: {Path(a.out) / 'table1.md'}")


if __name__ == "__main__":
    main()
