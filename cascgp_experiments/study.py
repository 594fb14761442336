"""The paper's data-efficiency study, reproduced in simulation (and on SARCOS), in one command.

Steps (each with progress bars; everything lands in ``--out``):

1. Collect the simulated Jaco data (:mod:`cascgp_experiments.collect`): 10 x 60 s of random
   sum-of-sinusoids velocity-commanded motion with a 0.8 kg payload unknown to the nominal model,
   3 x 60 s of test motion; measured (noisy) q, qd, tau at 100 Hz, qdd by a Savitzky-Golay filter.
   Cached in ``<out>/data``.
2. Curves (:mod:`cascgp_experiments.curves`): each of the 12 variants is trained on the first T
   seconds of each subset, subsampled to 10 Hz, for T on the grid; nRMSE per joint on the test
   set (all three test minutes, subsampled to 10 Hz: 1800 rows, minus the first 0.2 s of each
   test motion, where the derivative-free history is missing, for every model alike). The RBD
   baseline (nominal RNEA) is evaluated on the same rows.
3. Optimiser iteration counts per joint, NP standard / inward / outward, n = 500, 10 restarts
   (:func:`cascgp_experiments.analyses.iteration_counts`), with the wall time of each fit.
4. Spearman rank correlation of joint states and torques (:func:`cascgp_experiments.analyses.spearman_block`).
5. SARCOS NP curves (:func:`run_sarcos`, below).
6. ``results.json`` (every number shown), ``curves_jaco.csv``, ``curves_sarcos.csv``, ``table1.md``,
   the figures (:mod:`cascgp_experiments.plots`, from the JSON alone) and ``claims.md``.

Settings (``--quick`` / ``--smoke`` reduce everything; the defaults are the full study, sized for
a 2-core machine shared with other work to finish in under an hour: the grid has 15 points;
every grid fit has the paper's 10 starts, one of them warm-started from the previous grid point's
optimum after the first grid point; a seeded 5 % of the grid fits is audited against 10 cold starts
run to convergence (``results.json["jaco"]["audit"]``). Table I reports, per interval, the mean over its
grid points of the per-point median over the subsets, with the interquartile ranges summarised the same way.
Every cascade is scored with its chained predicted neighbour torque (``table``, the default) and with the measured
one (``table_measured``; :mod:`cascgp_experiments.curves`). The claims are judged with pooled paired tests,
Holm-corrected within families fixed in :mod:`cascgp_experiments.pooled_stats` (``["pooled"]`` of each block);
the per-cell sign tests are secondary (:mod:`cascgp_experiments.claims`). The iteration-count study uses 10 starts
per GP as in the paper.

SARCOS block (:func:`run_sarcos`, the paper's Fig. 5; alone: ``python -m scripts.sarcos_study``).
Data: the IAS SARCOS file (``ias_sarcos_data.mat``, path argument), the real 7-DOF SARCOS arm.
Training: the IAS training rows subsampled to 10 Hz (every 5th row of the nominal 50 Hz, restarting
at each recording boundary that :mod:`cascgp.sarcos` detects: 2803 rows) and
split into 9 time-contiguous subsets of equal row counts (about 31 s each). Test: the IAS test
rows whose inputs do NOT also stand in the training rows (to 8 decimals: 2785 of 5569 are
removed, :func:`cascgp.sarcos.load_ias` with ``dedup=True``), all 2784 kept rows, not
subsampled. Models: NP standard, inward and outward (derivative based), as in the paper.

This module owns the presets (:data:`PRESETS`), :func:`run_study` and :func:`run_sarcos`; the command
line is ``python -m scripts.data_efficiency``.
"""

from __future__ import annotations

import hashlib
import math
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

from cascgp.checks import MAX_RESTARTS, check_count, check_positive
from cascgp_experiments.common import (FULL_GRID, NP_DB, PAPER_TABLE, QUICK_GRID, RBD, SMOKE_GRID,
                                       VARIANTS, label, machine_info, make_table, median_curves,
                                       package_versions, read_json, write_json)
from cascgp_experiments.curves import CurveSpec, run_curves
from cascgp_experiments.execution import check_workers, session
from cascgp_experiments.pooled_stats import JACO_FAMILIES, SARCOS_FAMILIES, pooled_block


@dataclass(frozen=True)
class Settings:
    """One preset of the study (all of it is written to ``results.json``)."""

    collection: str = "full"           # preset of cascgp_experiments.collect
    grid: tuple[float, ...] = FULL_GRID
    n_subsets: int = 10
    n_restarts: int = 10
    warm_start: bool = True
    audit_fraction: float = 0.05
    iter_n: int = 500
    iter_restarts: int = 10
    #: The SARCOS part's grid (seconds of data); empty: no SARCOS part.
    sarcos_grid: tuple[float, ...] = (1.0, 1.5, 2.0, 3.0, 4.0, 4.5, 5.0, 7.0, 9.0, 9.5, 10.0, 14.0, 20.0, 30.0)
    sarcos_subsets: int = 9
    test_hz: float = 10.0
    seed: int = 0
    #: The collection's ``sensor_pipeline`` (:class:`cascgp_experiments.collect.CollectConfig`); the SP models'
    #: nominal URDF follows the simulated arm's link inertials.
    sensor_pipeline: str = "jaco2"

    def __post_init__(self) -> None:
        """Every field checked now, so that a bad setting is refused before any work (``ValueError`` naming it)."""
        from cascgp_experiments import collect as col

        col.check_pipeline(self.sensor_pipeline)
        if self.collection not in col.PRESETS:
            raise ValueError(f"collection: expected one of {tuple(col.PRESETS)}, got {self.collection!r}")
        data = col.PRESETS[self.collection]
        object.__setattr__(self, "grid", _check_grid("grid", self.grid, data.subset_seconds))
        object.__setattr__(self, "sarcos_grid", _check_grid("sarcos_grid", self.sarcos_grid, None, empty=True))
        for name, least in (("n_subsets", 1), ("n_restarts", 1), ("iter_n", 2), ("iter_restarts", 1),
                            ("sarcos_subsets", 1), ("seed", 0)):  # as Python ints: the settings go into JSON
            object.__setattr__(self, name, check_count(getattr(self, name), name, least))
        for name in ("n_restarts", "iter_restarts"):
            if getattr(self, name) > MAX_RESTARTS:
                raise ValueError(f"{name}: expected at most {MAX_RESTARTS} starts per GP, got {getattr(self, name)}")
        if self.n_subsets > data.n_subsets:
            raise ValueError(f"n_subsets: expected at most the {self.collection!r} collection's {data.n_subsets} "
                             f"training subsets, got {self.n_subsets}")
        object.__setattr__(self, "test_hz", check_positive(self.test_hz, "test_hz", "Hz"))
        if isinstance(self.audit_fraction, bool) or not isinstance(self.audit_fraction, (int, float)) \
                or not 0 <= self.audit_fraction <= 1:
            raise ValueError(f"audit_fraction: expected a number in [0, 1], got {self.audit_fraction!r}")
        if not isinstance(self.warm_start, bool):
            raise ValueError(f"warm_start: expected True or False, got {self.warm_start!r}")


def _check_grid(name: str, grid: Any, most: float | None, empty: bool = False) -> tuple[float, ...]:
    """``grid`` as a tuple if it is a strictly ascending sequence of seconds of data above 0 (at most ``most``, the
    length of a training subset), non-empty unless ``empty``; else ``ValueError`` naming ``name``."""
    ok = isinstance(grid, (tuple, list)) and (empty or len(grid) > 0) and all(
        not isinstance(g, bool) and isinstance(g, (int, float)) and math.isfinite(g) and g > 0 for g in grid)
    if not ok or any(b <= a for a, b in zip(grid, grid[1:])):
        raise ValueError(f"{name}: expected a{'' if empty else ' non-empty,'} strictly ascending sequence of seconds "
                         f"> 0, got {grid!r}")
    if most is not None and grid[-1] > most:
        raise ValueError(f"{name}: expected seconds of data at most the training subsets' {most:g} s, got {grid!r}")
    return tuple(grid)


PRESETS: dict[str, Settings] = {
    "full": Settings(),
    "quick": Settings(collection="quick", grid=QUICK_GRID, n_subsets=3, n_restarts=3, audit_fraction=0.1, iter_n=100,
                      iter_restarts=3, sarcos_grid=(1.0, 2.0, 5.0, 10.0), sarcos_subsets=3),
    "smoke": Settings(collection="smoke", grid=SMOKE_GRID, n_subsets=2, n_restarts=2, audit_fraction=0.25, iter_n=20,
                      iter_restarts=2, sarcos_grid=(1.0, 2.0), sarcos_subsets=2),
}


def cached_iteration_counts(out: Path, train, settings: Settings) -> dict[str, Any]:
    """Iteration counts (step 3) on the first training subset at 10 Hz, cached in
    ``<out>/cache/iterations.json`` (keyed by the settings that matter); ``"reused"`` says whether they came from
    that cache (their ``"wall_s"`` is then the time of the run that computed them)."""
    from cascgp_experiments.analyses import iteration_counts

    key = {"n": settings.iter_n, "n_restarts": settings.iter_restarts, "seed": settings.seed,
           "collection": settings.collection, "sensor_pipeline": settings.sensor_pipeline}
    path = Path(out) / "cache" / "iterations.json"
    if path.exists():
        cached = read_json(path)
        if cached.get("key") == key:
            return {**cached, "reused": True}
    t0 = time.perf_counter()
    d10 = train.subsample(10.0)
    first = d10.take(d10.segment == d10.segments[0])
    src = first if first.n_samples >= settings.iter_n else d10
    res = iteration_counts(src, n=settings.iter_n, n_restarts=settings.iter_restarts, seed=settings.seed)
    res["data"] = "first training subset (10 Hz)" if src is first else "training set (10 Hz)"
    res["key"] = key
    res["wall_s"] = time.perf_counter() - t0
    write_json(path, res)
    return {**res, "reused": False}


def reuse_note(meta: dict[str, Any]) -> str | None:
    """What a study run took from an earlier run's files in its folder, as one line (``None``: nothing)."""
    reused = meta.get("reused", {})
    parts = ["the collection"] if reused.get("collection") else []
    for key, what in (("jaco_jobs", "Jaco jobs"), ("sarcos_jobs", "SARCOS jobs")):
        done, total = reused.get(key) or (0, 0)
        if done:
            parts.append(f"{done} of {total} {what}")
    if reused.get("iterations"):
        parts.append("the iteration counts")
    if not parts:
        return None
    return (f"reused from an earlier run in this folder: {', '.join(parts)}; the timings are this run's (a job's "
            f"own time stays in results.json)")


def collection_config(settings: Settings) -> Any:
    """The :class:`cascgp_experiments.collect.CollectConfig` of the data a study of ``settings`` collects (its
    preset's, with the study's seed and sensing pipeline), in ``<out>/data``."""
    from cascgp_experiments import collect as col

    return replace(col.PRESETS[settings.collection], seed=settings.seed, sensor_pipeline=settings.sensor_pipeline)


def run_study(out: str | Path, settings: Settings, *, models: list[str] | None = None, workers: int | None = None,
              ray_address: str | None = None, sarcos: str | Path | None = None, do_iterations: bool = True,
              do_plots: bool = True, command: str = "", collect_again: bool = False) -> dict[str, Any]:
    """Run the whole study into ``out``; returns the results dict (also ``out/results.json``).

    ``workers`` / ``ray_address``: where the collection's motions and the curve fits run
    (:mod:`cascgp_experiments.execution`; default every local core); the numbers do not depend on them.
    ``collect_again``: collect into ``out/data`` even where a collection of the same settings is there (``force``
    of :func:`cascgp_experiments.collect.collect`); one of other settings is replaced either way."""
    with session(ray_address, workers):
        return _run_study(out, settings, models=models, workers=workers, ray_address=ray_address, sarcos=sarcos,
                          do_iterations=do_iterations, do_plots=do_plots, command=command,
                          collect_again=collect_again)


def _run_study(out: str | Path, settings: Settings, *, models: list[str] | None, workers: int | None,
               ray_address: str | None, sarcos: str | Path | None, do_iterations: bool, do_plots: bool,
               command: str, collect_again: bool) -> dict[str, Any]:
    from cascgp_experiments import collect as col
    from cascgp_experiments.analyses import spearman_block

    t_all = time.perf_counter()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    models = list(models or VARIANTS)
    workers = check_workers(workers)
    timings: dict[str, float] = {}
    results: dict[str, Any] = {"meta": {
        "command": command, "settings": asdict(settings), "models": models, "workers": workers, "ray": ray_address,
        "versions": package_versions(), "started": time.strftime("%Y-%m-%d %H:%M:%S"),
        "machine": machine_info()}}

    # 1. data
    ccfg = collection_config(settings)
    t0 = time.perf_counter()
    train, test, cinfo = col.collect(out / "data", ccfg, force=collect_again, workers=workers, ray_address=ray_address)
    timings["collect_s"] = time.perf_counter() - t0
    # what this run took from an earlier run's files (a resumed or repeated run; None: a part not run): the
    # timings are this run's own
    reused: dict[str, Any] = {"collection": bool(cinfo["reused"]), "jaco_jobs": None, "iterations": None,
                              "sarcos_jobs": None}
    results["meta"]["reused"] = reused
    results["meta"]["complete"] = False  # until every part is written
    results["meta"]["collection"] = {**asdict(ccfg), "reused": cinfo["reused"],
                                     "train_rows": train.n_samples, "test_rows": test.n_samples,
                                     "train_total_seconds": train.duration, "test_total_seconds": test.duration,
                                     "qdd": train.meta.get("qdd_source"),
                                     # what the settings' None (follow the sensing pipeline) resolved to
                                     "qdd_filter_used": "causal" if ccfg.smoothing.causal else "centred",
                                     "link_inertials_used": ccfg.nominal_link_inertials}

    # 2. curves (12 variants + RBD)
    spec = CurveSpec(train_path=str(col.data_path(out / "data", "train")),
                     test_path=str(col.data_path(out / "data", "test")), n_subsets=settings.n_subsets,
                     grid=list(settings.grid), train_hz=10.0,
                     test_hz=settings.test_hz, split_by="segment", urdf=str(col.nominal_urdf_for(train.meta)),
                     n_restarts=settings.n_restarts, warm_start=settings.warm_start, seed=settings.seed,
                     audit_fraction=settings.audit_fraction)
    results["meta"]["nominal_urdf"] = Path(spec.urdf).name if spec.urdf else None
    jaco = run_curves(spec, models + [RBD], workers=workers, ray_address=ray_address, cache_dir=out / "cache" / "jaco",
                      desc="Jaco fits")
    timings["jaco_curves_s"] = jaco["wall_s"]
    reused["jaco_jobs"] = [jaco["n_cached_jobs"], jaco["jobs"]["n_jobs"]]
    jaco["dof"] = train.dof
    jaco["labels"] = {m: label(m) for m in jaco["models"]}
    # Table I: per grid point the median over subsets (errors are heavy-tailed), averaged over the interval's
    # grid points; the IQR beside it; means and standard deviations stay in the JSON.
    jaco["table"] = make_table(jaco["grid_s"], median_curves(jaco))
    if any("measured" in v for v in jaco["models"].values()):
        jaco["table_measured"] = make_table(jaco["grid_s"], median_curves(jaco, "measured"))
    jaco["pooled"] = pooled_block(jaco, JACO_FAMILIES)
    jaco["table_q25"] = make_table(jaco["grid_s"], {m: v["nrmse_q25"] for m, v in jaco["models"].items()})["rows"]
    jaco["table_q75"] = make_table(jaco["grid_s"], {m: v["nrmse_q75"] for m, v in jaco["models"].items()})["rows"]
    jaco["table_mean"] = make_table(jaco["grid_s"], {m: v["nrmse_mean"] for m, v in jaco["models"].items()})["rows"]
    jaco["table_std"] = make_table(jaco["grid_s"], {m: v["nrmse_std"] for m, v in jaco["models"].items()})["rows"]
    results["jaco"] = jaco
    results["paper_table"] = {"intervals": [[1, 2], [4, 5], [9, 10]], "rows": PAPER_TABLE}
    write_json(out / "results.json", results)

    # 3. iteration counts (timings are this run's; a count from the cache keeps its own wall_s)
    if do_iterations:
        t0 = time.perf_counter()
        results["iterations"] = cached_iteration_counts(out, train, settings)
        timings["iterations_s"] = time.perf_counter() - t0
        reused["iterations"] = results["iterations"].pop("reused")
        write_json(out / "results.json", results)

    # 4. correlation
    t0 = time.perf_counter()
    results["correlation"] = spearman_block(train.subsample(10.0))
    results["correlation"]["data"] = "Jaco training set, 10 Hz"
    timings["correlation_s"] = time.perf_counter() - t0

    # 5. SARCOS (an empty sarcos_grid skips it)
    if sarcos is not None and settings.sarcos_grid:
        s = run_sarcos(sarcos, out / "sarcos", grid=settings.sarcos_grid, n_subsets=settings.sarcos_subsets,
                       n_restarts=settings.n_restarts, workers=workers, ray_address=ray_address, seed=settings.seed,
                       audit_fraction=settings.audit_fraction)
        results["sarcos"] = s
        timings["sarcos_s"] = s["wall_s_total"]
        reused["sarcos_jobs"] = [s["n_cached_jobs"], s["jobs"]["n_jobs"]]
    results["meta"]["sarcos_skipped"] = None if "sarcos" in results else (
        "no SARCOS file given, or --no-sarcos" if sarcos is None else "no SARCOS grid point within the grid")

    timings["total_s"] = time.perf_counter() - t_all
    results["meta"]["timings"] = timings
    results["meta"]["finished"] = time.strftime("%Y-%m-%d %H:%M:%S")
    results["meta"]["complete"] = True
    write_json(out / "results.json", results)

    # 6. tables, figures, claims (from the JSON alone)
    if do_plots:
        from cascgp_experiments.plots import render

        render(out / "results.json", out)
    return results


# --------------------------------------------------------------------------- SARCOS block
SARCOS_FULL_GRID = (1.0, 1.5, 2.0, 3.0, 4.0, 4.5, 5.0, 7.0, 9.0, 9.5, 10.0, 14.0, 20.0, 30.0)
SARCOS_QUICK_GRID = (1.0, 2.0, 5.0, 10.0)
SARCOS_SMOKE_GRID = (1.0, 2.0)


def prepare_files(sarcos_path: str | Path, out: str | Path) -> tuple[Path, Path, dict[str, Any]]:
    """Write the IAS train / de-duplicated test sets as DynamicsData files under ``out``."""
    from cascgp.sarcos import load_ias

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    train, test = load_ias(sarcos_path, dedup=True)
    tr, te = out / "sarcos_train.npz", out / "sarcos_test.npz"
    train.save(tr)
    test.save(te)
    with open(sarcos_path, "rb") as f:  # the file's own digest, to check against the published one
        digest = hashlib.file_digest(f, "sha256").hexdigest()
    info = {"file": str(sarcos_path), "file_sha256": digest, "n_train_rows_file": train.n_samples,
            "n_test_rows_file": int(test.meta["n_rows_in_file"]),
            "n_test_duplicates_removed": int(test.meta["n_duplicates_removed"]),
            "n_test_rows": test.n_samples,
            "test_set": "IAS X_test/Y_test rows whose inputs do not stand in X_train (8 decimals)"}
    return tr, te, info


def run_sarcos(sarcos_path: str | Path, out: str | Path, *, grid=SARCOS_FULL_GRID, n_subsets: int = 9,
               n_restarts: int = 1, workers: int | None = None, ray_address: str | None = None, seed: int = 0,
               gp_overrides: dict | None = None, audit_fraction: float = 0.05) -> dict[str, Any]:
    """The SARCOS block of the results JSON (curves of NP standard / inward / outward, their labels and pooled
    tests), for ``cascgp study`` and ``cascgp sarcos``; ``audit_fraction`` of its fits audited, as the Jaco
    curves' (the preset's: 5 % in the full study)."""
    t0 = time.perf_counter()
    out = Path(out)
    tr, te, info = prepare_files(sarcos_path, out / "data")
    spec = CurveSpec(train_path=str(tr), test_path=str(te), n_subsets=n_subsets, grid=list(grid),
                     train_hz=10.0, test_hz=None, split_by="rows", urdf=None, n_restarts=n_restarts,
                     seed=seed, gp_overrides=dict(gp_overrides or {}), audit_fraction=audit_fraction)
    block = run_curves(spec, list(NP_DB), workers=workers, ray_address=ray_address,
                       cache_dir=out / "cache" / "sarcos", desc="SARCOS fits")
    block.update(info)
    block["seed"], block["dof"] = seed, 7
    block["labels"] = {m: label(m) for m in block["models"]}
    block["pooled"] = pooled_block(block, SARCOS_FAMILIES)
    block["wall_s_total"] = time.perf_counter() - t0
    return block

