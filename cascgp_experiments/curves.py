"""nRMSE-versus-seconds-of-data curves: the engine shared by the Jaco and SARCOS studies.

One *job* is (model, subset): the model is trained on the first ``T`` seconds of the subset for
every ``T`` of the grid (ascending) and evaluated on the test set after each fit.

Protocol (the paper's): every fit has ``n_restarts`` (10) starts; after the first grid point one
of them is warm-started from the previous grid point's hyperparameters (``init=``), the others are
seeded random starts around the data-driven default, optimised with the library's default
:class:`cascgp.gp.GPFitConfig` (its stall rule for the non-leading starts included).

Equivalence audit: a seeded random ``audit_fraction`` (default 5 %) of the grid fits is fitted a
second time with ``n_restarts`` *cold* starts, each run to convergence (no warm start, no
early stopping: :func:`cascgp.fit_audit.cold_config`), and the per-joint gap of the best negative log marginal likelihood
(protocol minus cold, nats; <= 0 means the protocol found an equal or better optimum) is recorded.

Same rows for every variant: the derivative-free (-df) models cannot use the first
``2 * df_delta`` of each segment (no history), so the derivative-based models drop those rows
too, in training and (``prepare``) in scoring.

Jobs run in a process pool (``workers``), each process with one torch/BLAS thread.

The RBD baseline is not trained: its test prediction is the nominal RNEA torque, the same for
every subset and ``T``.
"""

from __future__ import annotations

import importlib
import os
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from cascgp_experiments.common import RBD, limit_threads, read_json, write_json


@dataclass
class CurveSpec:
    """Everything a worker process needs (picklable)."""

    train_path: str            # DynamicsData .npz; subsets = its segments, or split(n_subsets)
    test_path: str
    n_subsets: int
    grid: list[float]
    train_hz: float = 10.0     # training data subsampled to this rate
    test_hz: float | None = 10.0  # test data subsampled to this rate (None: as recorded)
    split_by: str = "segment"  # "segment" (one subset per segment) or "rows" (split(n_subsets))
    urdf: str | None = None    # nominal URDF for SP models and the RBD baseline
    n_restarts: int = 10
    warm_start: bool = True
    seed: int = 0
    audit_fraction: float = 0.05
    df_delta: float = 0.1
    factory: str = "cascgp.models:make_model"
    gp_overrides: dict = field(default_factory=dict)


_STATE: dict[str, Any] = {}


def _resolve(path: str):
    mod, _, name = path.partition(":")
    return getattr(importlib.import_module(mod), name)


def prepare(spec: CurveSpec) -> dict[str, Any]:
    """Load and subsample the data, build the subsets and the evaluation mask (rows of the test
    set whose derivative-free history of ``2 * df_delta`` lies inside their segment, so that all
    models are scored on the same rows)."""
    from cascgp.data import DynamicsData
    from cascgp.features import history_from_data

    train = DynamicsData.load(spec.train_path).subsample(spec.train_hz)
    test = DynamicsData.load(spec.test_path)
    if spec.test_hz is not None:
        test = test.subsample(spec.test_hz)
    if spec.split_by == "segment":
        segs = train.segments
        if len(segs) < spec.n_subsets:
            raise ValueError(f"n_subsets: {spec.n_subsets} requested but the training file has "
                             f"{len(segs)} segments")
        subsets = [train.take(train.segment == s) for s in segs[:spec.n_subsets]]
    elif spec.split_by == "rows":
        subsets = train.split(spec.n_subsets)
    else:
        raise ValueError(f"split_by: expected 'segment' or 'rows', got {spec.split_by!r}")
    _, mask = history_from_data(test, spec.df_delta)
    rbd = None
    if spec.urdf:
        from cascgp.rbd import load_nominal

        rbd = load_nominal(spec.urdf)
    return {"subsets": subsets, "test": test, "mask": mask, "rbd": rbd, "spec": spec}


def _init_worker(spec: CurveSpec) -> None:
    limit_threads(1)
    _STATE.clear()
    _STATE.update(prepare(spec))


def _gp_config(spec: CurveSpec, subset: int):
    from cascgp.gp import GPFitConfig

    return GPFitConfig(n_restarts=spec.n_restarts, seed=spec.seed * 1000 + subset, **spec.gp_overrides)


def _cold_config(spec: CurveSpec, subset: int):
    """The audit's reference: ``n_restarts`` cold starts, each run to convergence (no screening,
    dropping or stall stopping: :func:`cascgp.fit_audit.cold_config`), with other seeds than the
    protocol's."""
    from cascgp.fit_audit import cold_config

    base = _gp_config(spec, subset)
    return cold_config(base, n_cold=spec.n_restarts, seed=base.seed + 7919)


def audited(spec: CurveSpec, model: str, subset: int, grid_index: int) -> bool:
    """Whether grid fit ``(model, subset, grid_index)`` is in the audit sample (seeded, stable)."""
    import zlib

    u = np.random.default_rng([spec.seed, zlib.crc32(model.encode()), subset, grid_index]).random()
    return bool(u < spec.audit_fraction)


def run_job(model: str, subset: int) -> dict[str, Any]:
    """Train ``model`` on growing prefixes of subset ``subset``; nRMSE per joint after each fit."""
    from cascgp.metrics import nrmse

    st = _STATE
    spec: CurveSpec = st["spec"]
    data = st["subsets"][subset]
    test, mask = st["test"], st["mask"]
    make = _resolve(spec.factory)
    from cascgp.features import history_from_data

    rows, walls, ntrain, audits = [], [], [], []
    prev = None
    for gi, T in enumerate(spec.grid):
        d = data.first_seconds(T)
        if not model.endswith("-df"):
            # The rows a -df model cannot use (no history yet): dropped for every variant alike.
            d = d.take(history_from_data(d, spec.df_delta)[1])
        sp = model.startswith("sp")
        m = make(model, data.dof, rbd=st["rbd"] if sp else None, gp_config=_gp_config(spec, subset),
                 df_delta=spec.df_delta)
        t0 = time.perf_counter()
        m.fit(d, init=prev if spec.warm_start else None)
        walls.append(time.perf_counter() - t0)
        mean, _ = m.predict_data(test)
        rows.append(nrmse(np.asarray(mean)[mask], test.tau[mask]).tolist())
        ntrain.append(d.n_samples)
        if audited(spec, model, subset, gi):
            ref = make(model, data.dof, rbd=st["rbd"] if sp else None, gp_config=_cold_config(spec, subset),
                       df_delta=spec.df_delta)
            t1 = time.perf_counter()
            ref.fit(d)
            nll = [float(f["best_nll"]) for f in m.fit_info]
            nll_ref = [float(f["best_nll"]) for f in ref.fit_info]
            audits.append({"model": model, "subset": subset, "seconds": float(T), "n_train": d.n_samples,
                           "nll": nll, "nll_cold": nll_ref, "gap": [a - b for a, b in zip(nll, nll_ref)],
                           "wall_s": walls[-1], "wall_cold_s": time.perf_counter() - t1})
        prev = m
    return {"model": model, "subset": subset, "nrmse": rows, "fit_wall_s": walls, "n_train": ntrain,
            "audit": audits}


def rbd_curve(state: dict[str, Any]) -> list[float]:
    """nRMSE per joint of the nominal RNEA on the (masked) test set."""
    from cascgp.metrics import nrmse

    test, mask, rbd = state["test"], state["mask"], state["rbd"]
    pred = rbd.inverse_dynamics(test.q, test.qd, test.qdd)
    return nrmse(pred[mask], test.tau[mask]).tolist()


def run_curves(spec: CurveSpec, models: list[str], *, workers: int = 2, cache_dir: str | Path | None = None,
               desc: str = "fits") -> dict[str, Any]:
    """Run every (model, subset) job; returns the per-model curves block of the results JSON:

    ``{"grid_s", "n_subsets", "n_test_rows", "models": {m: {"nrmse_mean" (G, N), "nrmse_std" (G, N),
    "nrmse_all" (S, G, N), "fit_wall_s" (S, G), "n_train" (S, G)}}, "wall_s"}``.

    Finished jobs are cached as JSON in ``cache_dir`` (keyed by the spec) so an interrupted run resumes.
    """
    t_start = time.perf_counter()
    cache = Path(cache_dir) if cache_dir else None
    key = {k: v for k, v in asdict(spec).items()}
    if cache:
        cache.mkdir(parents=True, exist_ok=True)
        spec_file = cache / "spec.json"
        if spec_file.exists() and read_json(spec_file) != read_json(write_json(cache / ".spec_new.json", key)):
            for f in cache.glob("job_*.json"):
                f.unlink()
        write_json(spec_file, key)
    gp_models = [m for m in models if m != RBD]
    jobs = [(m, s) for m in gp_models for s in range(spec.n_subsets)]
    results: dict[tuple[str, int], dict] = {}
    todo = []
    for m, s in jobs:
        f = cache / f"job_{m}_{s}.json" if cache else None
        if f is not None and f.exists():
            results[(m, s)] = read_json(f)
        else:
            todo.append((m, s))
    # big models first so the pool's tail is short
    todo.sort(key=lambda ms: (ms[0].split("-")[1] != "standard", ms[0].endswith("df")))
    bar = tqdm(total=len(jobs), initial=len(jobs) - len(todo), desc=desc, unit="job")

    def done(r: dict) -> None:
        results[(r["model"], r["subset"])] = r
        if cache:
            write_json(cache / f"job_{r['model']}_{r['subset']}.json", r)
        bar.update(1)
        bar.set_postfix_str(f"{r['model']}#{r['subset']} {sum(r['fit_wall_s']):.0f}s")

    state = None
    if workers <= 1 or not todo:
        _init_worker(spec)
        state = _STATE
        for m, s in todo:
            done(run_job(m, s))
    else:
        import multiprocessing as mp

        with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"),
                                 initializer=_init_worker, initargs=(spec,)) as pool:
            futs = [pool.submit(run_job, m, s) for m, s in todo]
            for f in as_completed(futs):
                done(f.result())
        _init_worker(spec)
        state = _STATE
    bar.close()
    out: dict[str, Any] = {"grid_s": list(spec.grid), "n_subsets": spec.n_subsets,
                           "n_test_rows": int(state["mask"].sum()),
                           "train_hz": spec.train_hz, "test_hz": spec.test_hz,
                           "n_restarts": spec.n_restarts, "warm_start": spec.warm_start,
                           "subset_seconds": [float(d.duration) for d in state["subsets"]],
                           "models": {}}
    for m in models:
        if m == RBD:
            if state["rbd"] is None:
                continue
            c = np.tile(np.asarray(rbd_curve(state))[None, None, :], (spec.n_subsets, len(spec.grid), 1))
            out["models"][m] = {"nrmse_all": c, "nrmse_mean": c.mean(0), "nrmse_std": c.std(0),
                                "nrmse_median": c[0], "nrmse_q25": c[0], "nrmse_q75": c[0]}
            continue
        allr = np.array([results[(m, s)]["nrmse"] for s in range(spec.n_subsets)])  # (S, G, N)
        out["models"][m] = {
            "nrmse_median": np.median(allr, 0), "nrmse_q25": np.percentile(allr, 25, axis=0),
            "nrmse_q75": np.percentile(allr, 75, axis=0),
            "nrmse_mean": allr.mean(0), "nrmse_std": allr.std(0), "nrmse_all": allr,
            "fit_wall_s": [results[(m, s)]["fit_wall_s"] for s in range(spec.n_subsets)],
            "n_train": [results[(m, s)]["n_train"] for s in range(spec.n_subsets)],
        }
    out["audit"] = audit_summary([a for (m, s_), r in sorted(results.items()) for a in r.get("audit", [])],
                                 spec.audit_fraction, len(gp_models) * spec.n_subsets * len(spec.grid))
    out["wall_s"] = time.perf_counter() - t_start
    out["n_cached_jobs"] = len(jobs) - len(todo)
    return out


def audit_summary(records: list[dict], fraction: float, n_fits: int, tol: float = 0.1) -> dict[str, Any]:
    """Distribution of the per-GP NLL gaps (protocol minus cold starts, nats) of the audited fits."""
    gaps = np.array([g for r in records for g in r["gap"]], float)
    out: dict[str, Any] = {"fraction_requested": fraction, "n_fits": n_fits, "n_audited_fits": len(records),
                           "n_gps": int(gaps.size), "tol_nats": tol, "records": records}
    if gaps.size:
        out.update({"within_tol": float(np.mean(gaps <= tol)), "gap_median": float(np.median(gaps)),
                    "gap_q95": float(np.percentile(gaps, 95)), "gap_max": float(gaps.max()),
                    "gap_min": float(gaps.min()), "better_than_cold": float(np.mean(gaps < -tol))})
    return out


def default_workers() -> int:
    return max(1, min(2, os.cpu_count() or 1))
