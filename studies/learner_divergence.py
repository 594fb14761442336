"""Why does the gated learner lag the ungated one on some tasks? A null comparison, a decomposition and a test
of the divergence hypothesis (issue 10, second criterion).

:mod:`studies.gate_eval` found that on the same model the gate costs nothing in the median after
three attempts (0.99), yet the gated *learner* was up to 1.70 x the ungated learner (10 of 16 (seed, task)
pairs within the criterion's 10 %). It proposed, untested, that a gated learner tracks worse on a new task,
collects data farther from the reference, stays less certain there, and so keeps shrinking. This experiment
tests that and asks whether the criterion can be judged per task at all. The protocol was fixed and committed
before any of its runs:

* **Settings.** Those of the gate evaluation (:data:`~studies.gate_eval.GATE_EVAL_CONFIG`: the full
  transfer, 4 attempts per task, seeds 0-3).
* **Learners per seed.**

  - ``GL``: ``sp-inward-gated`` (its own data), with ``sp-inward`` evaluated on *its* model after every
    attempt (``paired``);
  - ``UL``: ``sp-inward`` (its own data);
  - ``UL'``: ``sp-inward`` with every refit's GP seed offset by :data:`NULL_FIT_SEED_OFFSET` (only the random
    starts of its fits differ from UL's; same env seeds, same controller). The null: how far two learners
    drift apart when nothing but a random start differs.

  GL's and UL's attempts are those of the gate evaluation (same seeds; paired episodes change nothing in a
  learner's run), so they must reproduce ``docs/studies/gate_eval.json``: checked and reported.
* **Before every attempt**, along the task's reference (the first ``duration`` seconds at 10 Hz, the same
  inputs the feedforward is queried at) and with the model that attempt uses: per joint, the median of the
  propagated latent variance relative to the prior (``rel_var``), the mean Wiener weight of the gate
  (``weight``), and the RMS of the learned correction and of the latent standard deviation.
* **Quantities** per (seed, task), last attempt on the task (after three refits with its data):

  - ``null_last``: UL' / UL, tracking RMSE (the learning loop's own drift);
  - ``gate_learners_last``: GL / UL (the issue's criterion, <= 1.10);
  - ``gate_on_gl_model``: GL / (ungated on GL's model): the gate's cost on the gated learner's own model;
  - ``gl_model_vs_ul``: (ungated on GL's model) / UL: how much worse GL's model is, ungated. The last two
    multiply to ``gate_learners_last``;
  - ``rel_var_gl_vs_ul``: GL's ``rel_var`` / UL's before the last attempt, averaged over joints;
  - ``early_tracking_gl_vs_ul``: GL's / UL's mean tracking RMSE on the task's first three attempts (the data
    each collected there: a worse-tracking attempt records states farther from the reference).

* **Decision rules (fixed in advance).**

  1. If ``null_last`` is within 10 % on fewer than all 16 pairs, the per-task criterion cannot tell the gate
     from the loop's own drift at one run per (seed, task); the gate is then judged by comparing the spread
     of ``|log gate_learners_last|`` with that of ``|log null_last|`` (one-sided Mann-Whitney U: is the gated
     learner farther from UL than UL' is?), and by the median of ``gate_learners_last``.
  2. The divergence hypothesis is supported if ``early_tracking_gl_vs_ul`` and ``rel_var_gl_vs_ul`` both have
     median > 1 with a one-sided Wilcoxon p < 0.05 over the 16 pairs (12 on the three new tasks for the early
     tracking), and Spearman's rho between ``log rel_var_gl_vs_ul`` and ``log gate_learners_last`` is > 0
     with p < 0.05. Otherwise it is not supported (reported as measured).
  3. ``gate_on_gl_model`` vs ``gl_model_vs_ul``: whichever has the larger median ``|log|`` is reported as
     the larger share of the lag; no threshold.

Medians, IQRs and worst cases; no means of ratios (single attempts are heavy-tailed).
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from cascgp.controller import gate_weights
from cascgp.io import atomic_write_text, write_json
from studies.gate_eval import (GATE_EVAL_CONFIG, GATE_EVAL_SEEDS, find_attempt, ratio_figure, ratio_stats,
                                          scatter_ratios)
from cascgp_experiments.transfer import TransferConfig

__all__ = ["NULL_FIT_SEED_OFFSET", "LEARNERS", "reference_uncertainty", "divergence_job", "divergence_jobs",
           "run_divergence", "ratios", "summarise", "per_task", "tests_of_hypotheses", "joint_split",
           "joint_split_markdown", "wrist_reading"]

#: Added to UL''s GP seeds: seeds 100-119 never overlap the 0-19 that UL and GL use on seeds 0-3.
NULL_FIT_SEED_OFFSET = 100
UNGATED, GATED = "sp-inward", "sp-inward-gated"
#: label -> (controller, paired controllers, fit seed offset)
LEARNERS: dict[str, tuple[str, tuple[str, ...], int]] = {
    "GL": (GATED, (UNGATED,), 0),
    "UL": (UNGATED, (), 0),
    "UL'": (UNGATED, (), NULL_FIT_SEED_OFFSET),
}
REFERENCE_RATE_HZ = 10.0


def reference_uncertainty(model: Any, nominal: Any, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray
                          ) -> dict[str, list[float]]:
    """Per joint, along the reference points ``(q, qd, qdd)`` (T, N): ``rel_var`` (median of the propagated
    latent variance over the prior), ``weight`` (mean Wiener gate weight, :func:`cascgp.controller.gate_weights`),
    ``correction_rms`` (RMS of the learned correction, N m) and ``sd_rms`` (RMS latent standard deviation, N m)."""
    mean, var = model.predict(q, qd, qdd, propagate=True)
    d = mean - np.asarray(nominal.inverse_dynamics(q, qd, qdd), dtype=float)
    w = gate_weights(d, var, "wiener")
    return {"rel_var": np.median(var / model.signal_var, axis=0).tolist(),
            "weight": w.mean(axis=0).tolist(),
            "correction_rms": np.sqrt(np.mean(d * d, axis=0)).tolist(),
            "sd_rms": np.sqrt(np.mean(var, axis=0)).tolist()}


def divergence_job(config: dict[str, Any], label: str) -> list[dict[str, Any]]:
    """Every attempt of learner ``label`` (:data:`LEARNERS`) with the reference diagnostics in ``record["before"]``."""
    import jaco_env.tasks
    from cascgp.learning import AttemptContext, run_controller
    from cascgp.rbd import load_nominal
    from cascgp_experiments.common import NOMINAL_URDF_DM_CONTROL
    from cascgp_experiments.run_hooks import PairedEpisodes
    from cascgp_experiments.transfer import jaco_feedback
    from studies.hooks import BeforeEachAttempt, Progress

    name, paired, offset = LEARNERS[label]
    cfg = replace(TransferConfig.from_dict(config), fit_seed_offset=offset)
    rbd = load_nominal(NOMINAL_URDF_DM_CONTROL)
    env = cfg.make_env()

    def before(ctx: AttemptContext, model: Any) -> dict[str, Any] | None:
        if model is None:
            return None
        task = jaco_env.tasks.get_task(ctx.attempt[0])
        q, qd, qdd = task.reference(np.arange(0.0, task.duration, 1.0 / REFERENCE_RATE_HZ))
        return reference_uncertainty(model, rbd, q, qd, qdd)

    try:
        hooks = [BeforeEachAttempt(before), PairedEpisodes(name, paired, env, rbd, jaco_feedback()), Progress(label)]
        run = run_controller(name, env, cfg.plan(), rbd, jaco_feedback(), cfg.retrain(),
                             reset_options=cfg.reset_options(), model_factory=cfg.model_factory(), hooks=hooks)
    finally:
        env.close()
    return run.attempts


def divergence_jobs(cfg: TransferConfig, seeds: tuple[int, ...]) -> list[dict[str, Any]]:
    """One job per (seed, learner), seed-major."""
    return [{"config": replace(cfg, seed=int(s)).to_dict(), "label": label} for s in seeds for label in LEARNERS]


def run_divergence(out: Path, cfg: TransferConfig = GATE_EVAL_CONFIG, seeds: tuple[int, ...] = GATE_EVAL_SEEDS, *,
                   workers: int | None = None, ray_address: str | None = None, show_progress: bool = True,
                   reference: dict[str, Any] | None = None) -> dict[str, Any]:
    """Run every job (cached under ``out/cache``) and write ``learner_divergence.json``/``.md``/``.png`` into
    ``out``. ``reference``: the gate evaluation's results (``docs/studies/gate_eval.json``) to check GL's and UL's
    attempts against (reported as ``reproduction``)."""
    from cascgp_experiments.execution import run_jobs

    out = Path(out)
    jobs = divergence_jobs(cfg, seeds)
    t0 = time.perf_counter()
    res = run_jobs(divergence_job, jobs, workers=workers, ray_address=ray_address, cache_dir=out / "cache",
                   desc="attempts", units=[len(cfg.plan())] * len(jobs), unit="attempt",
                   priority=[-j["config"]["seed"] for j in jobs],
                   label=lambda j: f"seed {j['config']['seed']} {j['label']}", show_progress=show_progress)
    runs: dict[str, dict[str, list[dict[str, Any]]]] = {}
    for job, attempts in zip(jobs, res):
        runs.setdefault(str(job["config"]["seed"]), {})[job["label"]] = attempts
    results: dict[str, Any] = {"config": {**cfg.to_dict(), "seeds": list(seeds)},
                               "wall_seconds": time.perf_counter() - t0, "jobs": res.stats(), "runs": runs}
    if reference is not None:
        results["reproduction"] = reproduction(results, reference)
    results["ratios"] = ratios(results)
    results["summary"] = summarise(results["ratios"])
    results["tests"] = tests_of_hypotheses(results["ratios"])
    results["per_task"] = per_task(results["ratios"])
    write_json(out / "learner_divergence.json", results)
    atomic_write_text(out / "learner_divergence.md", summary_markdown(results))
    plot(results, out / "learner_divergence.png")
    return results


def reproduction(results: dict[str, Any], reference: dict[str, Any]) -> dict[str, Any]:
    """How many of GL's and UL's attempt RMSEs equal the gate evaluation's (same seeds and settings)."""
    names = {"GL": GATED, "UL": UNGATED}
    n = equal = 0
    worst = 0.0
    for seed, run in results["runs"].items():
        ref = reference["runs"].get(seed)
        if ref is None:
            continue
        for label, name in names.items():
            if len(run[label]) != len(ref[name]):
                raise ValueError(f"reference: seed {seed} {name} has {len(ref[name])} attempts, this run's {label} "
                                 f"{len(run[label])}; not the same settings")
            for a, b in zip(run[label], ref[name]):
                n += 1
                equal += a["tracking_rmse"] == b["tracking_rmse"]
                worst = max(worst, abs(a["tracking_rmse"] - b["tracking_rmse"]))
    return {"attempts_compared": n, "identical": equal, "max_abs_difference": worst}


def ratios(results: dict[str, Any]) -> list[dict[str, Any]]:
    """One row per (seed, task, quantity): numerator, denominator, ratio (see the module docstring)."""
    cfg = results["config"]
    tasks, last = cfg["tasks"], cfg["attempts"] - 1
    rows = []

    def add(seed: str, task: str, quantity: str, num: float | None, den: float | None) -> None:
        num, den = (float("nan") if v is None else float(v) for v in (num, den))
        with np.errstate(divide="ignore", invalid="ignore"):
            rows.append({"seed": int(seed), "task": task, "quantity": quantity, "num": num, "den": den,
                         "ratio": float(np.divide(num, den))})

    for seed, run in results["runs"].items():
        gl, ul, null = run["GL"], run["UL"], run["UL'"]
        for task in tasks:
            g, u, n = find_attempt(gl, task, last), find_attempt(ul, task, last), find_attempt(null, task, last)
            g_ungated = g["paired"][UNGATED]["tracking_rmse"]
            add(seed, task, "null_last", n["tracking_rmse"], u["tracking_rmse"])
            add(seed, task, "gate_learners_last", g["tracking_rmse"], u["tracking_rmse"])
            add(seed, task, "gate_on_gl_model", g["tracking_rmse"], g_ungated)
            add(seed, task, "gl_model_vs_ul", g_ungated, u["tracking_rmse"])
            add(seed, task, "rel_var_gl_vs_ul", float(np.mean(g["before"]["rel_var"])),
                float(np.mean(u["before"]["rel_var"])))
            if task != tasks[0]:
                early = [[find_attempt(r, task, k)["tracking_rmse"] for k in range(min(3, last))] for r in (gl, ul)]
                add(seed, task, "early_tracking_gl_vs_ul", float(np.mean(early[0])), float(np.mean(early[1])))
    return rows


def summarise(rows: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per quantity: median, quartiles, range and, for the two learner ratios, the count <= 1.10."""
    return {q: ratio_stats([r["ratio"] for r in rows if r["quantity"] == q],
                      1.10 if q in ("null_last", "gate_learners_last") else None)
            for q in dict.fromkeys(r["quantity"] for r in rows)}


def per_task(rows: list[dict[str, Any]]) -> dict[str, dict[str, dict[str, float]]]:
    """Per task and quantity: the median ratio and the median ``|log ratio|`` over the seeds (finite ratios)."""
    out: dict[str, dict[str, dict[str, float]]] = {}
    for task in dict.fromkeys(r["task"] for r in rows):
        for q in dict.fromkeys(r["quantity"] for r in rows):
            v = np.array([r["ratio"] for r in rows if r["task"] == task and r["quantity"] == q], dtype=float)
            v = v[np.isfinite(v) & (v > 0)]
            if v.size:
                out.setdefault(task, {})[q] = {"n": int(v.size), "median": float(np.median(v)),
                                               "median_abs_log": float(np.median(np.abs(np.log(v))))}
    return out


def joint_split(results: dict[str, Any], task: str, joint: int) -> dict[str, list[dict[str, float]]]:
    """Per seed and attempt on ``task``, joint ``joint`` (0-based) of the tracking: ``gate`` = GL / (ungated on
    GL's model) and ``model`` = (ungated on GL's model) / UL, the per-joint form of ``gate_on_gl_model`` and
    ``gl_model_vs_ul`` (their product is GL / UL at that joint). From the records' ``joint_rmse``."""
    out: dict[str, list[dict[str, float]]] = {}
    for seed, run in results["runs"].items():
        gl = [a for a in run["GL"] if a["task"] == task]
        ul = [a for a in run["UL"] if a["task"] == task]
        if not gl or len(gl) != len(ul):
            raise ValueError(f"results: seed {seed} has no matching GL/UL attempts on task {task!r}")
        rows = []
        for g, u in zip(gl, ul):
            paired = g["paired"][UNGATED]["joint_rmse"][joint]
            rows.append({"attempt": int(g["task_attempt"]), "gate": g["joint_rmse"][joint] / paired,
                         "model": paired / u["joint_rmse"][joint]})
        out[seed] = rows
    return out


def joint_split_markdown(split: dict[str, list[dict[str, float]]]) -> str:
    """One row per seed: ``gate / model`` at every attempt."""
    n = max(len(r) for r in split.values())
    lines = ["| seed | " + " | ".join(f"attempt {k}: gate, model" for k in range(n)) + " |", "|" + "---|" * (n + 1)]
    for seed, rows in split.items():
        lines.append(f"| {seed} | " + " | ".join(f"{r['gate']:.2f}, {r['model']:.2f}" for r in rows) + " |")
    return "\n".join(lines) + "\n"


def wrist_reading(split: dict[str, list[dict[str, float]]], trigger: float = 1.5, calm: float = 1.2,
                  lag: float = 1.3) -> dict[str, Any]:
    """The pre-registered reading of the wrist hypothesis (``docs/studies/lag_diagnosis.md``, "Replication of the wrist
    pattern") on a :func:`joint_split`: per seed ``g0`` (the gate's effect at the task's first attempt), ``m0``
    (the model's there) and ``m13`` (the median model effect over the later attempts). A seed is
    *gate-triggered* if ``g0 > trigger``, *front-triggered* if not and ``m0 > lag``, else *calm* if
    ``g0 <= calm``. P1: every gate-triggered seed has ``m13 > lag``; P2: every calm seed has ``m13 <= lag``.
    ``replicated``: P1 and P2 hold and at least two seeds are gate-triggered (None: fewer than two)."""
    seeds = {}
    for seed, rows in split.items():
        g0, m0 = rows[0]["gate"], rows[0]["model"]
        m13 = float(np.median([r["model"] for r in rows[1:]]))
        kind = ("gate-triggered" if g0 > trigger else "front-triggered" if m0 > lag
                else "calm" if g0 <= calm else "between")
        seeds[seed] = {"g0": g0, "m0": m0, "m13": m13, "kind": kind}
    triggered = [v for v in seeds.values() if v["kind"] == "gate-triggered"]
    calm_ = [v for v in seeds.values() if v["kind"] == "calm"]
    p1 = all(v["m13"] > lag for v in triggered)
    p2 = all(v["m13"] <= lag for v in calm_)
    return {"seeds": seeds, "n_gate_triggered": len(triggered), "n_calm": len(calm_), "P1": p1, "P2": p2,
            "replicated": None if len(triggered) < 2 else bool(p1 and p2)}


def tests_of_hypotheses(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The decision rules of the module docstring, computed from the ratios."""
    from scipy import stats

    def col(q: str) -> np.ndarray:
        return np.array([r["ratio"] for r in rows if r["quantity"] == q], dtype=float)

    def wilcoxon_greater(q: str) -> dict[str, Any]:
        v = np.log(col(q))
        v = v[np.isfinite(v)]
        if v.size < 2 or np.all(v == 0):
            return {"n": int(v.size), "median_ratio": float(np.exp(np.median(v))) if v.size else None, "p": None}
        return {"n": int(v.size), "median_ratio": float(np.exp(np.median(v))), "n_above_1": int(np.sum(v > 0)),
                "p": float(stats.wilcoxon(v, alternative="greater").pvalue)}

    out: dict[str, Any] = {}
    g, n = np.abs(np.log(col("gate_learners_last"))), np.abs(np.log(col("null_last")))
    g, n = g[np.isfinite(g)], n[np.isfinite(n)]
    out["null_within_10pct"] = int(np.sum(n <= np.log(1.10)))
    out["null_n"] = int(n.size)
    out["spread_gate_vs_null"] = {
        "median_abs_log_gate": float(np.median(g)), "median_abs_log_null": float(np.median(n)),
        "p_mannwhitney_gate_greater": float(stats.mannwhitneyu(g, n, alternative="greater").pvalue)
        if g.size and n.size else None}
    out["early_tracking_gl_vs_ul"] = wilcoxon_greater("early_tracking_gl_vs_ul")
    out["rel_var_gl_vs_ul"] = wilcoxon_greater("rel_var_gl_vs_ul")
    x, y = np.log(col("rel_var_gl_vs_ul")), np.log(col("gate_learners_last"))
    ok = np.isfinite(x) & np.isfinite(y)
    rho = stats.spearmanr(x[ok], y[ok]) if ok.sum() > 2 else None
    out["spearman_rel_var_vs_lag"] = None if rho is None else {"rho": float(rho.statistic),
                                                                "p_two_sided": float(rho.pvalue), "n": int(ok.sum())}
    ev = out["early_tracking_gl_vs_ul"], out["rel_var_gl_vs_ul"]
    out["divergence_hypothesis_supported"] = bool(
        all(e["p"] is not None and e["median_ratio"] > 1 and e["p"] < 0.05 for e in ev)
        and rho is not None and rho.statistic > 0 and rho.pvalue < 0.05)
    share = {q: float(np.median(np.abs(np.log(col(q))))) for q in ("gate_on_gl_model", "gl_model_vs_ul")}
    out["median_abs_log_share"] = share
    return out


def summary_markdown(results: dict[str, Any]) -> str:
    """The summary, the tests and every ratio, from the JSON alone."""
    s, t, cfg = results["summary"], results["tests"], results["config"]
    lines = [f"Seeds {cfg['seeds']}, tasks {cfg['tasks']}, {cfg['attempts']} attempts each, "
             f"payload {cfg['payload_mass']} kg; wall {results['wall_seconds']:.0f} s with "
             f"{results['jobs']['n_cached']} of {results['jobs']['n_jobs']} jobs from the cache; the jobs took "
             f"{results['jobs']['job_seconds_sum']:.0f} s in all when they ran.", ""]
    if "reproduction" in results:
        r = results["reproduction"]
        lines += [f"Reproduction of docs/studies/gate_eval.json (GL, UL): {r['identical']} of "
                  f"{r['attempts_compared']} attempt RMSEs identical "
                  f"(largest difference {r['max_abs_difference']:.2e} rad).", ""]
    lines += ["| ratio | n | median | IQR | min | worst | <= 1.10 (the criterion's count) |",
              "|---|---|---|---|---|---|---|"]
    for q, st in s.items():
        if not st["n"]:
            continue
        meet = f"{st['n_meeting']} of {st['n']}" if "n_meeting" in st else "-"
        lines.append(f"| {q} | {st['n']} | {st['median']:.3f} | {st['q1']:.3f}-{st['q3']:.3f} | {st['min']:.3f} "
                     f"| {st['max']:.3f} | {meet} |")
    sp = t["spread_gate_vs_null"]
    lines += ["", f"- null within 10 % in both directions (1/1.1 <= ratio <= 1.1): {t['null_within_10pct']} of "
              f"{t['null_n']}",
              f"- median |log ratio|: gated learner {sp['median_abs_log_gate']:.3f}, null "
              f"{sp['median_abs_log_null']:.3f}; one-sided Mann-Whitney p = {sp['p_mannwhitney_gate_greater']}"]
    for q in ("early_tracking_gl_vs_ul", "rel_var_gl_vs_ul"):
        e = t[q]
        lines.append(f"- {q}: median {e['median_ratio']}, {e.get('n_above_1')} of {e['n']} above 1, one-sided Wilcoxon "
                     f"p = {e['p']}")
    sr = t["spearman_rel_var_vs_lag"]
    if sr:
        lines.append(f"- Spearman rho(log rel_var ratio, log gate_learners_last) = {sr['rho']:.3f} "
                     f"(p = {sr['p_two_sided']:.3g}, n = {sr['n']})")
    lines.append(f"- divergence hypothesis supported (rule 2): {t['divergence_hypothesis_supported']}")
    lines.append(f"- median |log| share: gate on GL's model {t['median_abs_log_share']['gate_on_gl_model']:.3f}, "
                 f"GL's model vs UL {t['median_abs_log_share']['gl_model_vs_ul']:.3f}")
    if "per_task" in results:
        qs = list(s)
        lines += ["", "Per task, median over seeds (median |log ratio| in brackets):", "",
                  "| task | " + " | ".join(qs) + " |", "|---|" + "---|" * len(qs)]
        for task, d in results["per_task"].items():
            lines.append(f"| {task} | " + " | ".join(f"{d[q]['median']:.3f} ({d[q]['median_abs_log']:.3f})"
                                                  if q in d else "-" for q in qs) + " |")
    lines += ["", "| seed | task | quantity | numerator | denominator | ratio |", "|---|---|---|---|---|---|"]
    for r in results["ratios"]:
        lines.append(f"| {r['seed']} | {r['task']} | {r['quantity']} | {r['num']:.4g} | {r['den']:.4g} "
                     f"| {r['ratio']:.3f} |")
    return "\n".join(lines) + "\n"


def plot(results: dict[str, Any], path: Path) -> None:
    """Every ratio per quantity (one dot per seed and task), medians in black, the 10 % band in red."""
    with ratio_figure(path, "Gated vs ungated learners: null (fit seed only), decomposition, uncertainty along the "
                            "reference") as ax:
        scatter_ratios(ax, results["ratios"], {q: st.get("median") for q, st in results["summary"].items()})
        for y in (1 / 1.1, 1.1):
            ax.axhline(y, color="r", ls="--", lw=0.8)
        ax.set_yscale("log")
        ax.set_ylabel("ratio")
