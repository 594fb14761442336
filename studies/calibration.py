"""Calibration of the cascade's predictive variance on held-out Jaco episodes (issue 10, item 1).

For each cascade variant and training size, models are trained on the first ``seconds`` of several
training subsets (10 Hz, as the study) and predict the held-out test motions. Per joint, the fraction of
measured torques inside the 95 % predictive interval is reported for the variance *given the chained mean*
(``propagate=False``, the paper's) and the *propagated* one (``propagate=True``); both add the fitted noise
variance, since the targets are measurements. A calibrated model covers about 0.95.

With ``input_var`` (:func:`sensor_input_var`) the propagated variance plus the test-time input-noise term
(``predict(..., input_var=...)``) is scored too. Diagnostics per fit: the fitted noise std, the factor on the
predictive std that 95 % coverage of the test torques would need, and the coverage on the rest of the training
subset's own motion. :func:`compare_arms` and :func:`combined_table` compare runs (the noisy / noiseless /
true-q̈ arms of ``docs/studies/calibration.md``, collected with :attr:`CollectConfig.sensor_noise
<cascgp_experiments.collect.CollectConfig.sensor_noise>` and ``qdd_source``).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from cascgp.data import DynamicsData, SavGol
from cascgp.gp import GPFitConfig
from cascgp.metrics import interval_coverage, std_scale_for_level
from cascgp.models import make_model
from cascgp.rbd import load_nominal
from cascgp_experiments.collect import nominal_urdf_for

__all__ = ["CASCADES", "BAND", "calibration", "combined_table", "compare_arms", "floor_effect",
           "recalibration_effect", "sensor_input_var", "sensor_torque_var"]

#: The issue's target band for the coverage of a 95 % interval.
BAND = (0.90, 0.98)

#: The cascades whose variance can be propagated (derivative-based states, as the controller uses).
CASCADES = ("np-inward", "np-outward", "sp-inward", "sp-outward")


def _sensor_model(collection: dict, sensor_std: dict | None) -> Any:
    """The :class:`jaco_env.SensorNoise` a collection was recorded with: the standard deviations stored with the
    data (``meta["sensor_std"]``), else, for files collected before they were stored, the one its
    ``sensor_noise`` setting gives today (:func:`cascgp_experiments.collect.sensor_model`; the env's defaults have
    not changed since the env was written)."""
    from jaco_env import SensorNoise

    from cascgp_experiments.collect import sensor_model

    if sensor_std is None:
        return sensor_model(collection.get("sensor_noise", "default"))
    if not isinstance(sensor_std, dict) or set(sensor_std) != {"q_std", "qd_std", "tau_std"}:
        raise ValueError(f"sensor_std: expected the meta['sensor_std'] of a collected Jaco file (q_std, qd_std, "
                         f"tau_std), got {sensor_std!r}")
    return SensorNoise(**sensor_std)


def sensor_input_var(collection: dict, dof: int, sensor_std: dict | None = None) -> np.ndarray:
    """Variances of the noise of the GP's measured inputs, (dof, 3) = ``(q, qd, qdd)`` per joint, from physics:
    the sensor model the data were recorded with (:func:`_sensor_model`: ``sensor_std``, a data file's
    ``meta["sensor_std"]``, or the env's ``SensorNoise()`` for files without it, or none for
    ``sensor_noise="none"``) for q and qd, and for the filtered qdd the velocity noise times the Savitzky-Golay
    filter's gain at the recording rate (:meth:`cascgp.data.SavGol.noise_gain`; 0 for ``qdd_source="true"``).
    ``collection``: a data file's ``meta["collection"]`` (:class:`cascgp_experiments.collect.CollectConfig` as a
    dict)."""
    if not isinstance(collection, dict) or not {"rate_hz", "savgol_window", "savgol_polyorder"} <= set(collection):
        raise ValueError("collection: expected the meta['collection'] of a collected Jaco file (rate_hz, savgol_window,"
                         f" savgol_polyorder), got {collection!r}")
    sn = _sensor_model(collection, sensor_std)
    gain = SavGol(int(collection["savgol_window"]), int(collection["savgol_polyorder"])).noise_gain(
        1.0 / float(collection["rate_hz"]))
    qdd_var = 0.0 if collection.get("qdd_source", "savgol") == "true" else sn.qd_std**2 * gain
    return np.tile([sn.q_std**2, sn.qd_std**2, qdd_var], (int(dof), 1))


def sensor_torque_var(collection: dict, sensor_std: dict | None = None) -> float:
    """The torque sensor's noise variance (N² m²) of a collection (``meta["collection"]``, and ``meta["sensor_std"]``
    where the file has it; :func:`sensor_input_var`): ``tau_std²``, 0.01 for the env's default sensors.
    ``ValueError`` for a noiseless collection (``sensor_noise="none"``), whose torques carry no sensor noise to
    bound the fit by."""
    if not isinstance(collection, dict):
        raise ValueError(f"collection: expected the meta['collection'] of a collected Jaco file, got {collection!r}")
    if collection.get("sensor_noise", "default") == "none":
        raise ValueError("collection: noiseless sensors (sensor_noise='none'): there is no torque-sensor noise to "
                         "take a noise floor from")
    return float(_sensor_model(collection, sensor_std).tau_std) ** 2


def calibration(train: DynamicsData, test: DynamicsData, *, seconds: tuple[float, ...] = (10.0, 30.0),
                n_subsets: int = 3, models: tuple[str, ...] = CASCADES, rate_hz: float = 10.0,
                n_restarts: int = 3, level: float = 0.95, input_var: np.ndarray | None = None,
                noise_var_floor: float | None = None, recalibrate: bool = False, progress=None) -> dict[str, Any]:
    """Coverage per model, training size, subset and joint (see the module docstring).

    ``input_var`` (dof, 3): variances of the input noise (:func:`sensor_input_var`); with it a third
    variance, the propagated one plus the test-time input-noise term (``predict(..., input_var=...)``), is
    scored as ``coverage_input_noise``. ``noise_var_floor``: lower bound of every joint GP's noise variance in
    N² m² (``make_model(..., noise_var_floor=...)``; :func:`sensor_torque_var` gives the torque sensor's);
    ``None``: none, the default fit. Every row also has the held-out RMSE of the mean per joint (``rmse``, N m).
    ``recalibrate``: the model trained on subset k also predicts training motion ``n_subsets + k`` (a motion it
    has not seen, never a test motion), the per-joint factor on its propagated predictive std that covers
    ``level`` there is fitted (:func:`cascgp.metrics.std_scale_for_level`, ``recal_scale``), and the test
    coverage with the std so scaled is scored (``coverage_recalibrated``).

    Returns a JSON-serialisable dict: ``rows`` (one per model, seconds, subset, with ``coverage_mean_input``
    and ``coverage_propagated`` lists per joint) and ``summary`` (per model and seconds: the median over
    subsets of each joint's coverage, both variances).
    """
    rbd = load_nominal(nominal_urdf_for(train.meta))  # the nominal model of the arm that recorded the data
    motions = train.split(10)
    subsets = motions[:n_subsets] if train.segments.size >= n_subsets else [train]
    if recalibrate:  # the motion a factor is fitted on must share no segment (motion) with any training subset
        seen = set(np.concatenate([sub.segment for sub in subsets]).tolist())
        if (len(subsets) + n_subsets > len(motions)
                or any(seen & set(motions[n_subsets + k].segment.tolist()) for k in range(len(subsets)))):
            raise ValueError(f"recalibrate: needs a training motion (segment) unseen by each of the "
                             f"{n_subsets} subsets, i.e. at least {2 * n_subsets} motions split evenly; the training "
                             f"data have {train.segments.size} segment(s)")
    test10 = test.subsample(rate_hz)
    cfg = GPFitConfig(n_restarts=n_restarts)
    rows = []
    for name in models:
        for secs in seconds:
            for k, sub in enumerate(subsets):
                t0 = time.perf_counter()
                data = sub.subsample(rate_hz).first_seconds(secs)
                m = make_model(name, train.dof, rbd if name.startswith("sp") else None, gp_config=cfg,
                               noise_var_floor=noise_var_floor).fit(data)
                cov = {}
                for prop in (False, True):
                    mean, var = m.predict(test10.q, test10.qd, test10.qdd, propagate=prop)
                    cov[prop] = interval_coverage(mean, var + m.noise_var, test10.tau, level)
                # (mean, var): the propagated prediction from here on
                # diagnostics: the factor on the predictive std that would make the 95 % interval cover 95 % of
                # the test torques, and the coverage on the rest of the training subset's own motion (rows after
                # the first `secs`, same excitation, states near the training ones)
                scale = std_scale_for_level(mean, var + m.noise_var, test10.tau, level)
                sub10 = sub.subsample(rate_hz)
                n_rest = sub10.n_samples - data.n_samples
                rows.append({"model": name, "seconds": secs, "subset": k, "n_train": data.n_samples,
                             "coverage_mean_input": cov[False].tolist(), "coverage_propagated": cov[True].tolist(),
                             "noise_std": np.sqrt(m.noise_var).tolist(), "std_scale_for_level": scale.tolist(),
                             "rmse": np.sqrt(np.mean((test10.tau - mean) ** 2, axis=0)).tolist(),
                             "n_same_motion_rest": n_rest})
                if n_rest > 0:
                    rest = sub10.take(np.arange(data.n_samples, sub10.n_samples))
                    mr, vr = m.predict(rest.q, rest.qd, rest.qdd, propagate=True)
                    rows[-1]["coverage_same_motion_rest"] = interval_coverage(mr, vr + m.noise_var, rest.tau,
                                                                              level).tolist()
                if recalibrate:
                    cal = motions[n_subsets + k].subsample(rate_hz)
                    mc, vc = m.predict(cal.q, cal.qd, cal.qdd, propagate=True)
                    c = std_scale_for_level(mc, vc + m.noise_var, cal.tau, level)
                    rows[-1]["recal_scale"] = c.tolist()
                    rows[-1]["coverage_recalibrated"] = interval_coverage(mean, c**2 * (var + m.noise_var),
                                                                          test10.tau, level).tolist()
                if input_var is not None:
                    _, var_in = m.predict(test10.q, test10.qd, test10.qdd, propagate=True, input_var=input_var)
                    rows[-1]["coverage_input_noise"] = interval_coverage(mean, var_in + m.noise_var, test10.tau,
                                                                         level).tolist()
                    # the input-noise term's size: median over the test rows of its std, per joint (N m)
                    rows[-1]["input_noise_std"] = np.median(np.sqrt(np.maximum(var_in - var, 0.0)), 0).tolist()
                rows[-1]["fit_s"] = time.perf_counter() - t0
                if progress is not None:
                    progress(rows[-1])
    summary = {}
    for name in models:
        for secs in seconds:
            sel = [r for r in rows if r["model"] == name and r["seconds"] == secs]
            summary[f"{name}@{secs:g}s"] = {
                key: np.median(np.array([r[key] for r in sel]), axis=0).round(4).tolist()
                for key in ("coverage_mean_input", "coverage_propagated", "coverage_input_noise", "noise_std",
                            "input_noise_std", "std_scale_for_level", "coverage_same_motion_rest", "rmse",
                            "recal_scale", "coverage_recalibrated")
                if all(key in r for r in sel)}
    return {"level": level, "rate_hz": rate_hz, "n_subsets": len(subsets), "n_restarts": n_restarts,
            "n_test_rows": test10.n_samples, "collection": train.meta.get("collection"),
            "input_var": None if input_var is None else np.asarray(input_var).tolist(),
            "noise_var_floor": noise_var_floor,
            "qdd_source": train.meta.get("qdd_source"), "rows": rows, "summary": summary}


def summary_table(res: dict[str, Any]) -> str:
    """Markdown: median coverage per joint, mean-input vs propagated variance (and the median fitted noise
    std in N m, when the result has it)."""
    dof = len(next(iter(res["summary"].values()))["coverage_mean_input"])
    head = "| model @ data | variance | " + " | ".join(f"J{j + 1}" for j in range(dof)) + " |"
    lines = [head, "|" + "---|" * (dof + 2)]
    for key, s in res["summary"].items():
        for label, field in (("given mean input", "coverage_mean_input"), ("propagated", "coverage_propagated"),
                             ("propagated + input noise", "coverage_input_noise"),
                             ("propagated, rest of the training motion", "coverage_same_motion_rest"),
                             ("std factor for 95 % (propagated)", "std_scale_for_level"),
                             ("recalibrated on an unseen training motion", "coverage_recalibrated"),
                             ("its std factor (fitted on that motion)", "recal_scale"),
                             ("fitted noise std (N m)", "noise_std"), ("input-noise std (N m)", "input_noise_std")):
            if field in s:
                lines.append(f"| {key} | {label} | " + " | ".join(f"{v:.3f}" for v in s[field]) + " |")
    return "\n".join(lines)


def write(res: dict[str, Any], out: str | Path) -> None:
    from cascgp.io import atomic_write_text, write_json

    out = Path(out)
    write_json(out / "calibration.json", res)
    atomic_write_text(out / "calibration.md", summary_table(res) + "\n")


def _cells(res: dict[str, Any], field: str) -> np.ndarray:
    """``field`` of every model @ seconds (sorted) and joint: (cells, dof), each the median over subsets."""
    return np.array([s[field] for _, s in sorted(res["summary"].items())], float)


def _n_in_band(c: np.ndarray) -> int:
    """How many of the coverages ``c`` lie in :data:`BAND`."""
    return int(((c >= BAND[0]) & (c <= BAND[1])).sum())


def compare_arms(arms: dict[str, dict[str, Any]], field: str = "coverage_propagated", base: str | None = None) -> str:
    """Markdown: the decision statistics of ``docs/studies/calibration.md`` for each arm (a :func:`calibration` result):
    over all cells (model @ seconds x joint, each the median over subsets) of ``field``, the median cell, the
    range, the number of cells in :data:`BAND`, and against the arm ``base`` (default: the first) the median of
    the paired change per cell."""
    names = list(arms)
    base = base or names[0]
    ref = _cells(arms[base], field).ravel()
    lines = [f"| arm | cells | median | min - max | in {BAND[0]:.2f}-{BAND[1]:.2f} | median change vs {base} |",
             "|---|---|---|---|---|---|"]
    for name in names:
        c = _cells(arms[name], field).ravel()
        if c.shape != ref.shape:
            raise ValueError(f"arm {name!r}: {c.size} cells, the base arm {base!r} has {ref.size}")
        lines.append(f"| {name} | {c.size} | {np.median(c):.3f} | {c.min():.3f} - {c.max():.3f} | {_n_in_band(c)} | "
                     f"{np.median(c - ref):+.3f} |")
    return "\n".join(lines)


def combined_table(arms: dict[str, dict[str, Any]], field: str = "coverage_propagated") -> str:
    """Markdown: ``field`` (medians over subsets, per joint) of several arms side by side, one row per model @
    seconds and arm."""
    first = next(iter(arms.values()))
    dof = len(next(iter(first["summary"].values()))[field])
    lines = ["| model @ data | arm | " + " | ".join(f"J{j + 1}" for j in range(dof)) + " |", "|" + "---|" * (dof + 2)]
    for key in first["summary"]:
        for name, res in arms.items():
            vals = res["summary"][key].get(field)
            cells = " | ".join(f"{v:.3f}" for v in vals) if vals is not None else " | ".join("-" * dof)
            lines.append(f"| {key} | {name} | {cells} |")
    return "\n".join(lines)


def recalibration_effect(res: dict[str, Any]) -> str:
    """Markdown: the pre-registered statistics of the recalibration test in ``docs/studies/calibration.md`` for one
    :func:`calibration` result run with ``recalibrate=True``: over all cells (model @ seconds x joint, each the
    median over subsets), the propagated and the recalibrated coverage side by side: median cell, cells in
    :data:`BAND`, below and above it, and the median paired change with how many cells rose or fell."""
    if any("coverage_recalibrated" not in s for s in res["summary"].values()):
        raise ValueError("res: no recalibrated coverage (run calibration(..., recalibrate=True))")
    a, b = _cells(res, "coverage_propagated").ravel(), _cells(res, "coverage_recalibrated").ravel()
    d = b - a
    lines = [f"| variance | cells | median | min - max | in {BAND[0]:.2f}-{BAND[1]:.2f} | below | above | "
             "median change | up / down / same |", "|---|---|---|---|---|---|---|---|---|"]
    for label, c in (("propagated", a), ("recalibrated", b)):
        ch = f"{np.median(d):+.3f} | {(d > 0).sum()} / {(d < 0).sum()} / {(d == 0).sum()}" if c is b else "- | -"
        lines.append(f"| {label} | {c.size} | {np.median(c):.3f} | {c.min():.3f} - {c.max():.3f} | {_n_in_band(c)} | "
                     f"{int((c < BAND[0]).sum())} | {int((c > BAND[1]).sum())} | {ch} |")
    return "\n".join(lines)


def floor_effect(base: dict[str, Any], floored: dict[str, Any], field: str = "coverage_propagated",
                 low_std: float = 0.05) -> str:
    """Markdown: the pre-registered statistics of the noise-floor test in ``docs/studies/calibration.md`` for two
    :func:`calibration` results on the same subsets, ``base`` (no floor) and ``floored``. Cells are model @ seconds
    x joint, each the median over subsets. A cell is *collapsed* when in ``base`` at least one of its subsets'
    fits has a noise std below ``low_std`` (N m). Reports, for all / collapsed / other cells: the count, the
    median cell of both runs, the cells in :data:`BAND`, the median paired change and how many cells rose or fell,
    and the median paired ratio of the held-out RMSE of the mean (floored / base) with its range."""
    keys = sorted(base["summary"])
    if sorted(floored["summary"]) != keys:
        raise ValueError("floored: not the same models and training sizes as base")
    if len(base["rows"]) != len(floored["rows"]):
        raise ValueError(f"floored: {len(floored['rows'])} rows, base has {len(base['rows'])}; not the same runs")
    for rb, rf in zip(base["rows"], floored["rows"]):
        if (rb["model"], rb["seconds"], rb["subset"], rb["n_train"]) != (rf["model"], rf["seconds"], rf["subset"],
                                                                           rf["n_train"]):
            raise ValueError("floored: rows are not paired with base's (model, seconds, subset, n_train)")
    c0, c1 = _cells(base, field), _cells(floored, field)
    collapsed = np.zeros_like(c0, dtype=bool)
    for i, k in enumerate(keys):
        name, secs = k.rsplit("@", 1)
        sel = [r for r in base["rows"] if r["model"] == name and f"{r['seconds']:g}s" == secs]
        collapsed[i] = (np.array([r["noise_std"] for r in sel]) < low_std).any(axis=0)
    have_rmse = all("rmse" in base["summary"][k] and "rmse" in floored["summary"][k] for k in keys)
    if have_rmse:
        ratio = np.array([floored["summary"][k]["rmse"] for k in keys]) / np.array([base["summary"][k]["rmse"]
                                                                                     for k in keys])
    lines = [f"| cells | n | median base | median floored | in {BAND[0]:.2f}-{BAND[1]:.2f} base -> floored | "
             "median change | up / down / same | median RMSE ratio (range) |", "|---|---|---|---|---|---|---|---|"]
    for label, sel in (("all", np.ones_like(collapsed)), (f"collapsed (a fit < {low_std:g} N m)", collapsed),
                       ("other", ~collapsed)):
        if not sel.any():
            lines.append(f"| {label} | 0 | - | - | - | - | - | - |")
            continue
        a, b = c0[sel], c1[sel]
        inb = [_n_in_band(x) for x in (a, b)]
        d = b - a
        rr = (f"{np.median(ratio[sel]):.3f} ({ratio[sel].min():.3f} - {ratio[sel].max():.3f})" if have_rmse
              else "-")
        lines.append(f"| {label} | {sel.sum()} | {np.median(a):.3f} | {np.median(b):.3f} | {inb[0]} -> {inb[1]} | "
                     f"{np.median(d):+.3f} | {(d > 0).sum()} / {(d < 0).sum()} / {(d == 0).sum()} | {rr} |")
    return "\n".join(lines)
