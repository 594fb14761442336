"""nRMSE-versus-seconds-of-data curves: the engine shared by the Jaco and SARCOS studies.

Each model is trained on the first ``T`` seconds of each subset for every ``T`` of the grid (ascending) and
evaluated on the test set after each fit. One *job* is (models, subset): a standard model with the cascades of its
kind in the run, or a model alone (:func:`job_groups`), whatever the number of workers, so that the numbers do not
depend on it.

Protocol (the paper's): every fit has ``n_restarts`` (10) starts; after the first grid point one
of them is warm-started from the previous grid point's hyperparameters (``init=``), the others are
seeded random starts around the data-driven default, optimised with the library's default
:class:`cascgp.gp.GPFitConfig` (its stall rule for the non-leading starts included).

Equivalence audit: a seeded random ``audit_fraction`` (default 5 %) of the grid fits is fitted a
second time with ``n_restarts`` *cold* starts, each run to convergence (no warm start, no
early stopping: :func:`cascgp.fit_audit.cold_config`), and the per-joint gap of the best negative log marginal
likelihood (protocol minus cold, nats; <= 0 means the protocol found an equal or better optimum) is recorded.

Same rows for every variant: the derivative-free (-df) models cannot use the first
``2 * df_delta`` of each segment (no history), so the derivative-based models drop those rows
too, in training and (``prepare``) in scoring.

Jobs run through :mod:`cascgp_experiments.execution` (local processes or a Ray cluster, each job with one
torch/BLAS thread, a resumable job cache); the numbers do not depend on the worker count or the backend.

Two scorings of a cascade (``nrmse`` and ``measured``): with its chained *predicted* neighbour torque (the
model's own prediction, the default of :meth:`cascgp.models.CascadedGPModel.predict`) and with the test data's
*measured* neighbour torque (:func:`cascgp.models.measured.predict_measured_neighbour`, ``CurveSpec.measured``).

Shared cells: a cascade's first joint in its chain direction (inward: joint N, outward: joint 1) takes every
joint's state and no torque, the inputs of the standard model's GP of that joint, so it is the same model by
construction. When the standard model of the same kind (NP/SP, derivative based/free) is in the run, the cascade
runs in the standard model's job and takes its GP of that joint at every grid point instead of fitting it again
(``share`` of :meth:`cascgp.models.CascadedGPModel.fit`: the same data, settings and random starts, so the same
fit with one GP fewer to optimise), and that joint's scores (both scorings) are the standard model's. The
cascade's ``fit_wall_s`` then leaves out that GP's fit. ``block["shared"]`` records each shared cell and the
largest difference of the cascade's own scores from the standard's there (round-off: the two models predict that
joint along different paths).

The RBD baseline is not trained: its test prediction is the nominal RNEA torque, the same for
every subset and ``T``.
"""

from __future__ import annotations

import hashlib
import importlib
import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from cascgp_experiments.common import RBD
from cascgp_experiments.execution import run_jobs
from cascgp_experiments.pooled_stats import chain_first, standard_twin


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
    # its cascades' fit takes share= (the standard model of their job); its models' predict_data takes return_var=
    factory: str = "cascgp.models:make_model"
    measured: str | None = "cascgp.models.measured:predict_measured_neighbour"  # None: predicted scoring only
    gp_overrides: dict = field(default_factory=dict)


_STATE: dict[str, Any] = {}  # the prepared data of one spec, kept per process (``"key"``: the spec's JSON)


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


def state_for(spec: CurveSpec) -> dict[str, Any]:
    """:func:`prepare` ``spec``, once per process (the last spec's state is kept)."""
    key = json.dumps(asdict(spec), sort_keys=True)
    if _STATE.get("key") != key:
        _STATE.clear()
        _STATE.update(prepare(spec))
        _STATE["key"] = key
    return _STATE


def npz_digest(path: str | Path) -> str:
    """SHA-256 of the arrays of an ``.npz`` file (names, dtypes, shapes, bytes): the data a job reads
    (the file's own bytes hold a time stamp, so the same data written twice differ there)."""
    h = hashlib.sha256()
    with np.load(path, allow_pickle=False) as z:
        for k in sorted(z.files):
            a = np.ascontiguousarray(z[k])
            h.update(f"{k}|{a.dtype.str}|{a.shape}|".encode())
            h.update(a.tobytes())
    return h.hexdigest()


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


def job_groups(models: list[str]) -> list[list[str]]:
    """The models of each job: a standard model with the cascades of its kind (NP/SP, derivative based/free) that
    are in ``models``, which take its GP of their chain's first joint instead of fitting it again (``share`` of
    :meth:`cascgp.models.CascadedGPModel.fit`: the same fits), and every other model alone."""
    groups: dict[str, list[str]] = {}
    for m in models:
        st = standard_twin(m)
        groups.setdefault(st if st in models else m, []).append(m)
    return [sorted(g, key=lambda m: m != lead) for lead, g in groups.items()]  # the standard model first


def curve_job(spec: dict[str, Any], models: list[str], subset: int, data_sha256: dict[str, str] | None = None
              ) -> dict[str, Any]:
    """One job: train each of ``models`` (one of :func:`job_groups`) on growing prefixes of subset ``subset``;
    nRMSE per joint after each fit. Returns ``{"models": [one result per model]}``.

    ``spec``: the :class:`CurveSpec` as a dict; ``data_sha256``: digests of its data files
    (:func:`npz_digest`), unused here but part of the job's inputs, so that the job cache is keyed
    by the data as well as by the settings."""
    spec_ = CurveSpec(**spec)
    st = state_for(spec_)
    tracks = [_Track(spec_, st, m, subset) for m in models]
    for gi, T in enumerate(spec_.grid):
        std = tracks[0].step(gi, T)
        for tr in tracks[1:]:  # cascades of the standard model tracks[0]
            tr.step(gi, T, share=std)
    return {"models": [tr.result() for tr in tracks]}


class _Track:
    """One model's curve within a job: its fits along the grid (each warm-started from the last), scores, audits."""

    def __init__(self, spec: CurveSpec, state: dict[str, Any], model: str, subset: int) -> None:
        self.spec, self.state, self.model, self.subset = spec, state, model, subset
        self.data = state["subsets"][subset]
        self.make = _resolve(spec.factory)
        self.measured = (_resolve(spec.measured) if spec.measured and model.split("-")[1] != "standard"
                         else None)
        self.rbd = state["rbd"] if model.startswith("sp") else None
        self.rows: list[list[float]] = []
        self.rows_meas: list[list[float]] = []
        self.walls: list[float] = []
        self.ntrain: list[int] = []
        self.audits: list[dict[str, Any]] = []
        self.prev: Any = None

    def step(self, gi: int, T: float, share: Any = None) -> Any:
        """Fit on the first ``T`` seconds (taking ``share``'s GP of the chain's first joint, if given), score and
        maybe audit the fit; returns the fitted model."""
        from cascgp.features import history_from_data
        from cascgp.metrics import nrmse

        from cascgp_experiments.execution import report_progress

        spec, model, subset = self.spec, self.model, self.subset
        test, mask = self.state["test"], self.state["mask"]
        d = self.data.first_seconds(T)
        if not model.endswith("-df"):
            # The rows a -df model cannot use (no history yet): dropped for every variant alike.
            d = d.take(history_from_data(d, spec.df_delta)[1])
        m = self.make(model, self.data.dof, rbd=self.rbd, gp_config=_gp_config(spec, subset), df_delta=spec.df_delta)
        t0 = time.perf_counter()
        m.fit(d, init=self.prev if spec.warm_start else None, **({"share": share} if share is not None else {}))
        self.walls.append(time.perf_counter() - t0)
        mean, _ = m.predict_data(test, return_var=False)  # the score needs the mean alone
        self.rows.append(nrmse(np.asarray(mean)[mask], test.tau[mask]).tolist())
        if self.measured is not None:
            self.rows_meas.append(nrmse(np.asarray(self.measured(m, test))[mask], test.tau[mask]).tolist())
        self.ntrain.append(d.n_samples)
        if audited(spec, model, subset, gi):
            ref = self.make(model, self.data.dof, rbd=self.rbd, gp_config=_cold_config(spec, subset),
                            df_delta=spec.df_delta)
            t1 = time.perf_counter()
            ref.fit(d)
            nll = [float(f["best_nll"]) for f in m.fit_info]
            nll_ref = [float(f["best_nll"]) for f in ref.fit_info]
            self.audits.append({"model": model, "subset": subset, "seconds": float(T), "n_train": d.n_samples,
                                "nll": nll, "nll_cold": nll_ref, "gap": [a - b for a, b in zip(nll, nll_ref)],
                                "wall_s": self.walls[-1], "wall_cold_s": time.perf_counter() - t1})
        self.prev = m
        report_progress(1, f"{model}#{subset} T={T:g} s")
        return m

    def result(self) -> dict[str, Any]:
        out = {"model": self.model, "subset": self.subset, "nrmse": self.rows, "fit_wall_s": self.walls,
               "n_train": self.ntrain, "audit": self.audits}
        if self.measured is not None:
            out["nrmse_measured"] = self.rows_meas
        return out


def rbd_curve(state: dict[str, Any]) -> list[float]:
    """nRMSE per joint of the nominal RNEA on the (masked) test set."""
    from cascgp.metrics import nrmse

    test, mask, rbd = state["test"], state["mask"], state["rbd"]
    pred = rbd.inverse_dynamics(test.q, test.qd, test.qdd)
    return nrmse(pred[mask], test.tau[mask]).tolist()


def run_curves(spec: CurveSpec, models: list[str], *, workers: int | None = None, ray_address: str | None = None,
               cache_dir: str | Path | None = None, desc: str = "fits", show_progress: bool = True
               ) -> dict[str, Any]:
    """Run every (models, subset) job (:func:`job_groups`, :func:`curve_job`) with
    :func:`cascgp_experiments.execution.run_jobs` (``workers`` local processes, default every core, or the Ray
    cluster at ``ray_address``); returns the per-model curves block of the results JSON:

    ``{"grid_s", "n_subsets", "n_test_rows", "models": {m: {"nrmse_mean" (G, N), "nrmse_std" (G, N),
    "nrmse_median", "nrmse_q25", "nrmse_q75" (G, N), "nrmse_all" (S, G, N), "fit_wall_s" (S, G), "n_train" (S, G),
    "measured": {the same nrmse_* summaries, cascades scored with the measured neighbour torque}}},
    "shared": [{"model", "joint", "with", "max_abs_diff_own_fit"}], "wall_s", "jobs"}``.

    Finished jobs are cached as JSON in ``cache_dir`` (keyed by the spec, the model, the subset and the
    data files' contents) so an interrupted run resumes; the numbers do not depend on ``workers`` or
    the backend.
    """
    t_start = time.perf_counter()
    gp_models = [m for m in models if m != RBD]
    digests = {"train": npz_digest(spec.train_path), "test": npz_digest(spec.test_path)}
    spec_d = asdict(spec)
    pairs = [(g, s) for g in job_groups(gp_models) for s in range(spec.n_subsets)]
    jobs = [{"spec": spec_d, "models": g, "subset": s, "data_sha256": digests} for g, s in pairs]
    # big jobs first so the pool's tail is short (a standard model's fit is the largest)
    prio = [2 * sum(1 + 2 * (m == standard_twin(m)) for m in g) + (not g[0].endswith("df")) for g, _ in pairs]
    res = run_jobs(curve_job, jobs, workers=workers, ray_address=ray_address, cache_dir=cache_dir, desc=desc,
                   units=[len(spec.grid) * len(g) for g, _ in pairs], unit="fit", priority=prio,
                   label=lambda j: f"{'+'.join(j['models'])}#{j['subset']}", show_progress=show_progress)
    results = {(r["model"], s): r for (_, s), job in zip(pairs, res) for r in job["models"]}
    state = state_for(spec)
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
        meas = [results[(m, s)].get("nrmse_measured") for s in range(spec.n_subsets)]
        allm = np.array(meas) if all(x is not None for x in meas) else None
        st = standard_twin(m)
        j0 = chain_first(m, allr.shape[2])
        if j0 is not None and st in gp_models:
            std = np.array([results[(st, s)]["nrmse"] for s in range(spec.n_subsets)])
            out.setdefault("shared", []).append({"model": m, "joint": j0, "with": st, "max_abs_diff_own_fit": float(
                np.abs(allr[:, :, j0] - std[:, :, j0]).max())})
            for a in (allr, allm):
                if a is not None:
                    a[:, :, j0] = std[:, :, j0]
        out["models"][m] = {**_summary(allr),
                            "fit_wall_s": [results[(m, s)]["fit_wall_s"] for s in range(spec.n_subsets)],
                            "n_train": [results[(m, s)]["n_train"] for s in range(spec.n_subsets)]}
        if allm is not None:
            out["models"][m]["measured"] = _summary(allm)
    out["audit"] = audit_summary([a for (m, s_), r in sorted(results.items()) for a in r.get("audit", [])],
                                 spec.audit_fraction, len(gp_models) * spec.n_subsets * len(spec.grid))
    out["wall_s"] = time.perf_counter() - t_start
    out["n_cached_jobs"] = res.n_cached
    out["jobs"] = {**res.stats(), "labels": [f"{'+'.join(g)}#{s}" for g, s in pairs]}
    return out


def _summary(allr: np.ndarray) -> dict[str, Any]:
    """Summaries over subsets of (S, G, N) scores, with the scores themselves (``nrmse_all``)."""
    return {"nrmse_median": np.median(allr, 0), "nrmse_q25": np.percentile(allr, 25, axis=0),
            "nrmse_q75": np.percentile(allr, 75, axis=0), "nrmse_mean": allr.mean(0), "nrmse_std": allr.std(0),
            "nrmse_all": allr}


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
