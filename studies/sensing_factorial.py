r"""Which part of the real arm's signal pipeline decides whether cascades win: the sensing factorial study.

Protocol and decision rules: ``docs/studies/sensing_factorial.md``, committed before any run (this module
implements them; it changes nothing in them). Seven arms (:data:`ARMS`): ``ideal``, each sensing factor alone on
top of it, and the full ``jaco2`` pipeline. Per arm, the study's data set is collected with the arm's options
(``cascgp_experiments.collect``) and the six derivative-based models (NP, SP x standard, inward, outward) are fitted
on the Table I grid points (``cascgp_experiments.curves``), the SP models with the nominal URDF of the arm's link
inertials.

Effect of arm :math:`A` for parametrisation :math:`P`, interval :math:`I` and subset :math:`s`:

.. math::

    e_{P,A,I,s} = \frac{1}{|C|}\sum_{(c, j) \in C} \frac{1}{|G_I|}\sum_{g \in G_I}
    \log\frac{\mathrm{nRMSE}_{c,j}(g, s)}{\mathrm{nRMSE}_{\mathrm{standard},j}(g, s)},

over the cascade directions :math:`c` and the joints :math:`j` where the cascade is not the standard model by
construction (``pooled_stats.identical_joints``), and the interval's grid points :math:`G_I`. Reported as
:math:`\exp(\bar e)` with the interquartile range over subsets (below 1: cascades better).

Tests (:func:`verdicts`): Wilcoxon signed-rank over subsets, Holm within two families at 1-2 s: e(A) - e(ideal) for
the six non-ideal arms and P (12 tests), e(A) against 0 for the seven arms and P (14 tests). Everything else
(4-5 s, 9-10 s, per direction, measured-neighbour scoring) is reported without verdicts.
"""

from __future__ import annotations

import os
import platform
import time
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import numpy as np

from cascgp.io import write_json
from cascgp_experiments.common import TABLE_INTERVALS, limit_threads
from cascgp_experiments.pooled_stats import holm, identical_joints, scores, wilcoxon_p
from scripts.provenance import git_commit

#: The arms: name -> options of ``cascgp_experiments.collect.CollectConfig`` on top of the study's preset.
ARMS: dict[str, dict[str, Any]] = {
    "ideal": {"sensor_pipeline": "ideal"},
    "+skew": {"sensor_pipeline": "ideal+skew"},
    "+velocity": {"sensor_pipeline": "ideal+velocity"},
    "+torque": {"sensor_pipeline": "ideal+torque"},
    "+causal": {"qdd_filter": "causal"},
    "+inertials": {"link_inertials": "kinova"},
    "jaco2": {"sensor_pipeline": "jaco2"},
}
PARAMS = ("np", "sp")
CASCADES = ("inward", "outward")
MODELS = [f"{p}-{s}" for p in PARAMS for s in ("standard", *CASCADES)]
#: The grid: Table I's intervals' points (1, 1.5, 2; 4, 4.5, 5; 9, 9.5, 10 s); ``--quick``: one per interval.
GRID = (1.0, 1.5, 2.0, 4.0, 4.5, 5.0, 9.0, 9.5, 10.0)
QUICK_GRID = (1.0, 4.0, 9.0)
#: The interval of the primary families.
PRIMARY = TABLE_INTERVALS[0]
#: The commit that fixed the protocol (docs/studies/sensing_factorial.md) before any run.
PROTOCOL_COMMIT = "ddeddef"


def effect(block: dict[str, Any], param: str, lo: float, hi: float, scoring: str = "predicted",
           cascades: tuple[str, ...] = CASCADES) -> np.ndarray:
    """(S,) per subset: the mean over (cascade, non-identical joint) pairs of the mean over the interval's grid
    points of log(nRMSE cascade / nRMSE standard) (module docstring)."""
    grid = np.asarray(block["grid_s"], float)
    g = (grid >= lo - 1e-9) & (grid <= hi + 1e-9)
    if not g.any():
        raise ValueError(f"no grid point in [{lo}, {hi}] s (grid {grid.tolist()})")
    std = scores(block, f"{param}-standard")[:, g, :]  # (S, G_I, N)
    n = std.shape[2]
    terms = []
    for c in cascades:
        m = f"{param}-{c}"
        keep = [j for j in range(n) if j not in identical_joints(m, f"{param}-standard", n)]
        lr = np.log(scores(block, m, scoring)[:, g, :] / std)[:, :, keep]  # (S, G_I, |keep|)
        terms.append(lr.mean(axis=1))  # mean over grid points: (S, |keep|)
    return np.concatenate(terms, axis=1).mean(axis=1)


def summary(e: np.ndarray) -> dict[str, Any]:
    """The effect's ratio exp(mean), its interquartile range over subsets (as ratios) and the per-subset values."""
    e = np.asarray(e, float)
    return {"ratio": float(np.exp(e.mean())), "q25": float(np.exp(np.percentile(e, 25))),
            "q75": float(np.exp(np.percentile(e, 75))), "wins": int((e < 0).sum()), "n": int(e.size),
            "e": e.tolist()}


def effects(blocks: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Every arm's effect per P, interval and scoring, with the per-direction effects (secondary)."""
    out: dict[str, Any] = {}
    for arm, block in blocks.items():
        for p in PARAMS:
            for lo, hi in TABLE_INTERVALS:
                key = f"{arm}|{p}|{lo:g}-{hi:g}"
                rec = {"arm": arm, "param": p, "interval": [lo, hi]}
                for scoring in ("predicted", "measured"):
                    rec[scoring] = summary(effect(block, p, lo, hi, scoring))
                rec["per_direction"] = {c: summary(effect(block, p, lo, hi, "predicted", (c,))) for c in CASCADES}
                out[key] = rec
    return out


def _family(tests: list[dict[str, Any]]) -> list[dict[str, Any]]:
    adj = holm([t["p"] for t in tests]) if tests else []
    for t, a in zip(tests, adj):
        t["p_holm"] = float(a)
        t["reject"] = bool(a < 0.05)
    return tests


def _wins(e: dict[tuple[str, str], np.ndarray], blocks: dict[str, Any]) -> list[dict[str, Any]]:
    return [{"arm": a, "param": p, "ratio": summary(e[(a, p)])["ratio"], "p": wilcoxon_p(e[(a, p)]),
             "e": e[(a, p)].tolist()} for a in blocks for p in PARAMS]


def verdicts(blocks: dict[str, dict[str, Any]], interval: tuple[float, float] = PRIMARY, *,
             adjust: bool = True) -> dict[str, Any]:
    """The two primary families at ``interval`` (protocol, "Tests and decision rules"): Holm-adjusted p-values
    and verdicts; ``adjust=False`` (the secondary intervals): the unadjusted p-values only, no verdicts."""
    lo, hi = interval
    e = {(a, p): effect(b, p, lo, hi) for a, b in blocks.items() for p in PARAMS}
    changes = []
    for a in blocks:
        if a == "ideal" or "ideal" not in blocks:
            continue
        for p in PARAMS:
            d = e[(a, p)] - e[("ideal", p)]
            changes.append({"arm": a, "param": p, "median_diff": float(np.median(d)),
                            "ratio_of_ratios": float(np.exp(d.mean())), "p": wilcoxon_p(d), "d": d.tolist()})
    if not adjust:
        return {"interval": [lo, hi], "factor_changes_effect": changes, "cascades_beat_standard": _wins(e, blocks)}
    _family(changes)
    for t in changes:
        t["verdict"] = ("matters: cascades helped" if t["median_diff"] < 0 else "matters: cascades hurt") if (
            t["reject"]) else "no detected change"
    wins = _wins(e, blocks)
    _family(wins)
    for t in wins:
        t["verdict"] = "cascades win" if t["reject"] and t["ratio"] < 1 else (
            "cascades lose" if t["reject"] else "no detected difference")
    return {"interval": [lo, hi], "factor_changes_effect": changes, "cascades_beat_standard": wins}


def run(out: str | Path, *, quick: bool = False, workers: int | None = None, ray_address: str | None = None,
        arms: list[str] | None = None, command: str = "") -> dict[str, Any]:
    """Collect, fit and score every arm, then the effects and (not ``quick``) the verdicts; writes
    ``factorial.json``, ``factorial.md`` and ``factorial.png`` to ``out`` (jobs cached under ``out/<arm>/cache``)."""
    from cascgp_experiments import collect as col
    from cascgp_experiments.curves import CurveSpec, run_curves
    from jaco_env import nominal_urdf

    limit_threads(1)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    arms = list(arms or ARMS)
    unknown = [a for a in arms if a not in ARMS]
    if unknown:
        raise ValueError(f"arms: expected names of {tuple(ARMS)}, got {unknown}")
    grid = QUICK_GRID if quick else GRID
    n_subsets, n_restarts = (2, 2) if quick else (10, 10)
    t0 = time.perf_counter()
    res: dict[str, Any] = {"meta": {
        "command": command, "protocol": "docs/studies/sensing_factorial.md", "protocol_commit": PROTOCOL_COMMIT,
        "code_commit": git_commit(), "quick": quick, "arms": {a: ARMS[a] for a in arms}, "grid_s": list(grid),
        "n_subsets": n_subsets, "n_restarts": n_restarts, "models": MODELS, "workers": workers,
        "started": time.strftime("%Y-%m-%d %H:%M:%S"), "loadavg_start": list(os.getloadavg()),
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform()}}, "arms": {}}
    blocks: dict[str, dict[str, Any]] = {}
    for arm in arms:
        cfg = replace(col.PRESETS["quick" if quick else "full"], **ARMS[arm])
        train, test, info = col.collect(out / arm / "data", cfg, workers=workers, ray_address=ray_address)
        urdf = nominal_urdf(cfg.nominal_link_inertials)
        spec = CurveSpec(train_path=str(out / arm / "data" / "jaco_train.npz"),
                         test_path=str(out / arm / "data" / "jaco_test.npz"), n_subsets=n_subsets, grid=list(grid),
                         urdf=str(urdf), n_restarts=n_restarts, warm_start=True, seed=0, audit_fraction=0.0)
        block = run_curves(spec, MODELS, workers=workers, ray_address=ray_address, cache_dir=out / arm / "cache",
                           desc=f"{arm} fits")
        blocks[arm] = block
        res["arms"][arm] = {"collection": asdict(cfg), "nominal_urdf": urdf.name, "collect_wall_s": info["wall_s"],
                            "curves": block}
        print(f"{arm}: collected in {info['wall_s']:.0f} s, fitted in {block['wall_s']:.0f} s", flush=True)
    res["effects"] = effects(blocks)
    if not quick:
        res["verdicts"] = verdicts(blocks)
        res["secondary"] = {f"{lo:g}-{hi:g}": verdicts(blocks, (lo, hi), adjust=False)
                            for lo, hi in TABLE_INTERVALS[1:]}
    res["meta"]["wall_s"] = time.perf_counter() - t0
    res["meta"]["loadavg_end"] = list(os.getloadavg())
    res["meta"]["finished"] = time.strftime("%Y-%m-%d %H:%M:%S")
    write_json(out / "factorial.json", res)
    from studies.sensing_factorial_report import figure, markdown

    (out / "factorial.md").write_text(markdown(res), encoding="utf-8")
    figure(res, out / "factorial.png")
    return res
