"""Calibration of the cascade's predictive variance on held-out Jaco episodes (issue 10, item 1).

For each cascade variant and training size, models are trained on the first ``seconds`` of several
training subsets (10 Hz, as the study) and predict the held-out test motions. Per joint, the fraction of
measured torques inside the 95 % predictive interval is reported for the variance *given the chained mean*
(``propagate=False``, the paper's) and the *propagated* one (``propagate=True``); both add the fitted noise
variance, since the targets are measurements. A calibrated model covers about 0.95.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from cascgp.data import DynamicsData
from cascgp.gp import GPFitConfig
from cascgp.metrics import interval_coverage
from cascgp.models import make_model
from cascgp.rbd import load_nominal
from cascgp_experiments.common import NOMINAL_URDF

__all__ = ["CASCADES", "calibration", "study_data"]

#: The cascades whose variance can be propagated (derivative-based states, as the controller uses).
CASCADES = ("np-inward", "np-outward", "sp-inward", "sp-outward")


def study_data(folder: str | Path | None, out: str | Path, *, preset: str = "quick", sensor_noise: str = "default",
               qdd_source: str = "savgol", workers: int | None = None) -> tuple[DynamicsData, DynamicsData]:
    """The study's ``jaco_train.npz``/``jaco_test.npz`` from ``folder``; without one, the collection ``preset``
    (:data:`cascgp_experiments.collect.PRESETS`) with ``sensor_noise`` and ``qdd_source`` (see
    :class:`~cascgp_experiments.collect.CollectConfig`) recorded into ``<out>/data`` on ``workers`` processes
    (``None``: every core), or reused from there when present with the same settings.

    The collection options only apply to a new collection: with ``folder``, anything but the defaults is a
    ``ValueError`` (the files are used as they were recorded)."""
    from dataclasses import replace

    from cascgp_experiments.collect import PRESETS, collect

    if folder:
        if (sensor_noise, qdd_source) != ("default", "savgol"):
            raise ValueError(f"sensor_noise={sensor_noise!r}/qdd_source={qdd_source!r} only apply to a new "
                             f"collection, not to the files in {folder!s} (leave out the data folder)")
        return tuple(DynamicsData.load(Path(folder) / f"jaco_{s}.npz") for s in ("train", "test"))
    if preset not in PRESETS:
        raise ValueError(f"preset: expected one of {tuple(PRESETS)}, got {preset!r}")
    cfg = replace(PRESETS[preset], sensor_noise=sensor_noise, qdd_source=qdd_source)
    train, test, _ = collect(Path(out) / "data", cfg, workers=workers)
    return train, test


def calibration(train: DynamicsData, test: DynamicsData, *, seconds: tuple[float, ...] = (10.0, 30.0),
                n_subsets: int = 3, models: tuple[str, ...] = CASCADES, rate_hz: float = 10.0,
                n_restarts: int = 3, level: float = 0.95, progress=None) -> dict[str, Any]:
    """Coverage per model, training size, subset and joint (see the module docstring).

    Returns a JSON-serialisable dict: ``rows`` (one per model, seconds, subset, with ``coverage_mean_input``
    and ``coverage_propagated`` lists per joint) and ``summary`` (per model and seconds: the median over
    subsets of each joint's coverage, both variances).
    """
    rbd = load_nominal(NOMINAL_URDF)
    subsets = train.split(10)[:n_subsets] if train.segments.size >= n_subsets else [train]
    test10 = test.subsample(rate_hz)
    cfg = GPFitConfig(n_restarts=n_restarts)
    rows = []
    for name in models:
        for secs in seconds:
            for k, sub in enumerate(subsets):
                t0 = time.perf_counter()
                data = sub.subsample(rate_hz).first_seconds(secs)
                m = make_model(name, train.dof, rbd if name.startswith("sp") else None, gp_config=cfg).fit(data)
                cov = {}
                for prop in (False, True):
                    mean, var = m.predict(test10.q, test10.qd, test10.qdd, propagate=prop)
                    cov[prop] = interval_coverage(mean, var + m.noise_var, test10.tau, level)
                rows.append({"model": name, "seconds": secs, "subset": k, "n_train": data.n_samples,
                             "coverage_mean_input": cov[False].tolist(), "coverage_propagated": cov[True].tolist(),
                             "noise_std": np.sqrt(m.noise_var).tolist(), "fit_s": time.perf_counter() - t0})
                if progress is not None:
                    progress(rows[-1])
    summary = {}
    for name in models:
        for secs in seconds:
            sel = [r for r in rows if r["model"] == name and r["seconds"] == secs]
            summary[f"{name}@{secs:g}s"] = {
                key: np.median(np.array([r[key] for r in sel]), axis=0).round(4).tolist()
                for key in ("coverage_mean_input", "coverage_propagated", "noise_std")}
    return {"level": level, "rate_hz": rate_hz, "n_subsets": len(subsets), "n_restarts": n_restarts,
            "n_test_rows": test10.n_samples, "collection": train.meta.get("collection"),
            "qdd_source": train.meta.get("qdd_source"), "rows": rows, "summary": summary}


def summary_table(res: dict[str, Any]) -> str:
    """Markdown: median coverage per joint, mean-input vs propagated variance (and the median fitted noise
    std in N m, when the result has it)."""
    dof = len(next(iter(res["summary"].values()))["coverage_mean_input"])
    head = "| model @ data | variance | " + " | ".join(f"J{j + 1}" for j in range(dof)) + " |"
    lines = [head, "|" + "---|" * (dof + 2)]
    for key, s in res["summary"].items():
        for label, field in (("given mean input", "coverage_mean_input"), ("propagated", "coverage_propagated"),
                             ("fitted noise std (N m)", "noise_std")):
            if field in s:
                lines.append(f"| {key} | {label} | " + " | ".join(f"{v:.3f}" for v in s[field]) + " |")
    return "\n".join(lines)


def write(res: dict[str, Any], out: str | Path) -> None:
    from cascgp.io import atomic_write_text, write_json

    out = Path(out)
    write_json(out / "calibration.json", res)
    atomic_write_text(out / "calibration.md", summary_table(res) + "\n")
