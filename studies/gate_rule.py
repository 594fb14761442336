r"""Does the ``"floor"`` gate rule remove the gated learner's lag on a new task? A pre-registered test on new
seeds (issue 10, second criterion; ``docs/studies/gate_rule.md``).

Background (``docs/studies/lag_diagnosis.md``, seeds 0-11): with the Wiener rule :math:`w = d^2 / (d^2 + v)` the gated
learner ends about 1.3 x the ungated one on "left". On the first attempt there the gate shrinks the wrist (J4)
correction, J4 tracks 1.6-2.5 x worse than the same model run ungated, and the models fitted with that episode are
worse at the wrist afterwards. The Wiener rule plugs the correction's own square in as its power, so a correction
smaller than its standard deviation is removed almost entirely (:math:`w d \approx d^3 / v`). The ``"floor"`` rule
:math:`w = P / (P + v)`, :math:`P = \max(d^2, p)` with :math:`p` the GP's signal variance, floors that power at what
the GP learned corrections are: it keeps at least half a correction where :math:`v \le p` and never shrinks more
than the Wiener rule (:class:`cascgp.controller.FeedforwardController`). It was written down from that diagnosis (a
first form, :math:`p / (p + v)`, was dropped after a smoke run on seed 99, see ``docs/studies/gate_rule.md``). The
protocol below was committed before the run:

* **Settings.** Those of the wrist replication on seeds 8-11: :data:`~studies.gate_eval.GATE_EVAL_CONFIG`
  cut to the tasks front and left (4 attempts each, then the revisit of front; 1.2 kg unknown payload; cap 500;
  3 restarts). **Seeds 12-19**, never run before by any experiment.
* **Jobs per seed** (:data:`LEARNERS`): ``rbd``; ``UL`` (``sp-inward``, ungated); ``UL'`` (the same with the
  fits' random starts offset: the null, reported only); ``GLw`` (``sp-inward-gated``, the Wiener rule) and
  ``GLf`` (``sp-inward-fgated``, the floor rule), each learning from its own data, each with ``sp-inward``
  evaluated on its model after every attempt (``paired``).
* **Quantities** (:func:`ratios`), tracking-RMSE ratios per seed:

  - ``last_<task>_GLf`` / ``last_<task>_GLw`` / ``last_<task>_null``: GLf / UL, GLw / UL, UL' / UL at the last
    attempt on the task (after three refits with its data: the issue's criterion, <= 1.10);
  - ``first_left_vs_rbd_GLf`` / ``_GLw`` / ``_UL``: the learner's first attempt on "left" / RBD's (same env seed;
    the issue's criterion 1, <= 1.02);
  - ``rules_last_left``: GLf / GLw at the last "left" attempt (the paired comparison of the two rules);
  - per rule, the J4 split of :func:`studies.learner_divergence.joint_split` on "left": ``g0`` (the
    gate's effect on J4 at the first attempt) and ``m13`` (the median model effect over attempts 1-3).

* **Decision rules (fixed in advance, :func:`decide`).**

  - **A** (criterion 2 on "left"): the median over seeds of ``last_left_GLf`` is <= 1.10;
  - **B** (criterion 2 on "front" kept): the median of ``last_front_GLf`` is <= 1.10;
  - **C** (criterion 1 kept): ``first_left_vs_rbd_GLf`` <= 1.02 on every seed;
  - **D** (the rule, not the seeds): the median of ``rules_last_left`` is < 1;
  - **E** (reported, not required): one-sided Wilcoxon signed-rank of ``log rules_last_left`` < 0 (8 seeds);
    the mechanism: median ``g0`` and ``m13`` per rule.

  The floor rule **replaces the Wiener rule as the default gate** if A, B, C and D all hold. Otherwise the
  default is unchanged and the result is reported as measured.

**Second protocol: the innovation rule** (``protocol="innovation"``, :data:`INNOVATION_LEARNERS`; committed before
its run, after the floor rule's result). The floor rule shrank the lag but missed A. Any gate driven by the GP's
variance shrinks a correction the model has right whenever the model is unsure, and on a first attempt here the
model is right but unsure. The ``"innovation"`` rule weighs the learned model against the nominal one by their
errors on this episode's measured torques (Bates-Granger weights, half-life
:data:`cascgp.controller.INNOVATION_HALF_LIFE_S` = 1 s, fixed from the reasoning in its docstring; no run with it
before this protocol). **Seeds 20-27**; the same settings; jobs ``rbd``, ``UL``, ``UL'`` and ``GLi``
(``sp-inward-igated``, with ``sp-inward`` paired on its model). The rules A, B and C above, with GLi for GLf; there
is no control learner, so no D or E. The innovation rule becomes the default gate if A, B and C all hold.

Medians, IQRs and worst cases; no means of ratios (single attempts are heavy-tailed).
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from cascgp.io import atomic_write_text, write_json
from studies.gate_eval import GATE_EVAL_CONFIG, find_attempt, ratio_figure, ratio_stats, scatter_ratios
from studies.learner_divergence import NULL_FIT_SEED_OFFSET, UNGATED, joint_split
from cascgp_experiments.transfer import TransferConfig, controller_job

__all__ = ["GATE_RULE_CONFIG", "GATE_RULE_SEEDS", "LEARNERS", "INNOVATION_LEARNERS", "INNOVATION_SEEDS", "PROTOCOLS",
           "gate_rule_jobs", "run_gate_rule", "ratios",
           "wrist", "decide", "summary_markdown"]

#: The protocol's settings and seeds (see the module docstring).
GATE_RULE_CONFIG = replace(GATE_EVAL_CONFIG, tasks=("front", "left"))
GATE_RULE_SEEDS = tuple(range(12, 20))
#: label -> (controller, paired controllers, fit seed offset)
LEARNERS: dict[str, tuple[str, tuple[str, ...], int]] = {
    "rbd": ("rbd", (), 0),
    "UL": (UNGATED, (), 0),
    "UL'": (UNGATED, (), NULL_FIT_SEED_OFFSET),
    "GLw": ("sp-inward-gated", (UNGATED,), 0),
    "GLf": ("sp-inward-fgated", (UNGATED,), 0),
}
#: The second protocol (``docs/studies/gate_rule.md``, "The innovation rule"): the innovation gate as a learner,
#: seeds 20-27.
INNOVATION_LEARNERS: dict[str, tuple[str, tuple[str, ...], int]] = {
    "rbd": LEARNERS["rbd"], "UL": LEARNERS["UL"], "UL'": LEARNERS["UL'"],
    "GLi": ("sp-inward-igated", (UNGATED,), 0),
}
INNOVATION_SEEDS = tuple(range(20, 28))
#: protocol name -> (learners, candidate label, control label or None, default seeds)
PROTOCOLS: dict[str, tuple[dict[str, tuple[str, tuple[str, ...], int]], str, str | None, tuple[int, ...]]] = {
    "floor": (LEARNERS, "GLf", "GLw", GATE_RULE_SEEDS),
    "innovation": (INNOVATION_LEARNERS, "GLi", None, INNOVATION_SEEDS),
}
#: The wrist: 0-based joint index of J4.
WRIST = 3


def _gated_labels(run: dict[str, Any]) -> list[str]:
    """The gated learners of one seed's runs (labels ``GL...``), in their order."""
    return [label for label in run if label.startswith("GL")]


def gate_rule_jobs(cfg: TransferConfig, seeds: tuple[int, ...],
                   learners: dict[str, tuple[str, tuple[str, ...], int]] = LEARNERS) -> list[dict[str, Any]]:
    """One :func:`~cascgp_experiments.transfer.controller_job` per (seed, learner), seed-major."""
    jobs = []
    for s in seeds:
        for label, (name, paired, offset) in learners.items():
            config = replace(cfg, seed=int(s), fit_seed_offset=offset).to_dict()
            jobs.append({"config": config, "name": name, "buffer_dir": None, "paired": list(paired) or None,
                         "_label": label})
    return jobs


def _job(config: dict[str, Any], name: str, buffer_dir: str | None, paired: list[str] | None, _label: str
         ) -> list[dict[str, Any]]:
    return controller_job(config, name, buffer_dir, paired=paired)


def run_gate_rule(out: Path, cfg: TransferConfig = GATE_RULE_CONFIG, seeds: tuple[int, ...] | None = None, *,
                  protocol: str = "floor", workers: int | None = None, ray_address: str | None = None,
                  show_progress: bool = True) -> dict[str, Any]:
    """Run every job of ``protocol`` (:data:`PROTOCOLS`; ``seeds``: its own unless given; cached under
    ``out/cache``: a stopped run resumes) and write ``gate_rule.json``, ``gate_rule.md`` and ``gate_rule.png`` into
    ``out``; returns the results (``learners``: which controller each label ran)."""
    from cascgp_experiments.execution import run_jobs

    if protocol not in PROTOCOLS:
        raise ValueError(f"protocol: expected one of {tuple(PROTOCOLS)}, got {protocol!r}")
    learners, candidate, control, protocol_seeds = PROTOCOLS[protocol]
    seeds = protocol_seeds if seeds is None else tuple(seeds)
    out = Path(out)
    jobs = gate_rule_jobs(cfg, seeds, learners)
    t0 = time.perf_counter()
    res = run_jobs(_job, jobs, workers=workers, ray_address=ray_address, cache_dir=out / "cache",
                   desc="attempts", units=[len(cfg.plan())] * len(jobs), unit="attempt",
                   priority=[-j["config"]["seed"] for j in jobs],
                   label=lambda j: f"seed {j['config']['seed']} {j['_label']}", show_progress=show_progress)
    runs: dict[str, dict[str, list[dict[str, Any]]]] = {}
    for job, attempts in zip(jobs, res):
        runs.setdefault(str(job["config"]["seed"]), {})[job["_label"]] = attempts
    results: dict[str, Any] = {"config": {**cfg.to_dict(), "seeds": list(seeds)},
                               "protocol": {"name": protocol, "candidate": candidate, "control": control},
                               "learners": {label: {"controller": name, "paired": list(paired), "fit_seed_offset": off}
                                            for label, (name, paired, off) in learners.items()},
                               "wall_seconds": time.perf_counter() - t0, "jobs": res.stats(), "runs": runs}
    results["ratios"] = ratios(results)
    results["wrist"] = wrist(results)
    results["summary"] = {q: ratio_stats([r["ratio"] for r in results["ratios"] if r["quantity"] == q],
                                         1.10 if q.startswith("last_") else 1.02 if "vs_rbd" in q else None)
                          for q in dict.fromkeys(r["quantity"] for r in results["ratios"])}
    results["decision"] = decide(results["ratios"], results["wrist"], tuple(cfg.tasks), candidate, control)
    write_json(out / "gate_rule.json", results)
    atomic_write_text(out / "gate_rule.md", summary_markdown(results))
    plot(results, out / "gate_rule.png")
    return results


def ratios(results: dict[str, Any]) -> list[dict[str, Any]]:
    """One row per (seed, quantity): numerator, denominator, ratio (see the module docstring)."""
    cfg = results["config"]
    tasks, last = cfg["tasks"], cfg["attempts"] - 1
    new_task = tasks[1]
    proto = results.get("protocol", {"candidate": "GLf", "control": "GLw"})  # files of the first protocol lack it
    rows = []

    def add(seed: str, quantity: str, num: float | None, den: float | None) -> None:
        num, den = (float("nan") if v is None else float(v) for v in (num, den))
        with np.errstate(divide="ignore", invalid="ignore"):
            rows.append({"seed": int(seed), "quantity": quantity, "num": num, "den": den,
                         "ratio": float(np.divide(num, den))})

    for seed, run in results["runs"].items():
        def rmse(label: str, task: str, k: int, run: dict = run) -> float:
            return find_attempt(run[label], task, k)["tracking_rmse"]

        gated = _gated_labels(run)
        for task in tasks:
            u = rmse("UL", task, last)
            for label in gated:
                add(seed, f"last_{task}_{label}", rmse(label, task, last), u)
            add(seed, f"last_{task}_null", rmse("UL'", task, last), u)
        r = rmse("rbd", new_task, 0)
        for label in (*gated, "UL"):
            add(seed, f"first_{new_task}_vs_rbd_{label}", rmse(label, new_task, 0), r)
        if proto["control"] is not None:
            add(seed, f"rules_last_{new_task}", rmse(proto["candidate"], new_task, last),
                rmse(proto["control"], new_task, last))
    return rows


def wrist(results: dict[str, Any]) -> dict[str, dict[str, dict[str, float]]]:
    """Per rule and seed, on the new task at J4: ``g0`` (gate / ungated on the same model, first attempt),
    ``m0`` and ``m13`` (that model / UL's, first attempt and median over the later ones)."""
    task = results["config"]["tasks"][1]
    out: dict[str, dict[str, dict[str, float]]] = {}
    for label in _gated_labels(next(iter(results["runs"].values()))):
        view = {"runs": {s: {"GL": run[label], "UL": run["UL"]} for s, run in results["runs"].items()}}
        split = joint_split(view, task, WRIST)
        out[label] = {s: {"g0": rows[0]["gate"], "m0": rows[0]["model"],
                          "m13": float(np.median([r["model"] for r in rows[1:]]))} for s, rows in split.items()}
    return out


def decide(rows: list[dict[str, Any]], wrist_: dict[str, dict[str, dict[str, float]]],
           tasks: tuple[str, ...] = GATE_RULE_CONFIG.tasks, candidate: str = "GLf", control: str | None = "GLw"
           ) -> dict[str, Any]:
    """The decision rules A-E of the module docstring (``tasks``: the first and the new task, front and left in
    the protocol) for the ``candidate`` learner; D and E compare it with the ``control`` learner and are left out
    without one (the innovation protocol: A, B and C decide)."""
    from scipy import stats

    def col(q: str) -> np.ndarray:
        return np.array([r["ratio"] for r in rows if r["quantity"] == q], dtype=float)

    def median(q: str) -> float:
        v = col(q)
        return float(np.median(v)) if v.size and np.all(np.isfinite(v)) else float("nan")

    first_task, new = tasks[0], tasks[1]
    a = median(f"last_{new}_{candidate}")
    b = median(f"last_{first_task}_{candidate}")
    first = col(f"first_{new}_vs_rbd_{candidate}")
    out: dict[str, Any] = {
        "candidate": candidate, "control": control,
        "A_last_new_median": a, "A": bool(a <= 1.10),
        "B_last_first_task_median": b, "B": bool(b <= 1.10),
        "C_first_new_vs_rbd_worst": float(np.max(first)) if first.size else float("nan"),
        "C": bool(first.size > 0 and np.all(np.isfinite(first)) and np.all(first <= 1.02)),
        "mechanism": {label: {k: float(np.median([v[k] for v in seeds.values()])) for k in ("g0", "m0", "m13")}
                      for label, seeds in wrist_.items()},
    }
    if control is not None:
        d = median(f"rules_last_{new}")
        logs = np.log(col(f"rules_last_{new}"))
        p = (float(stats.wilcoxon(logs, alternative="less").pvalue)
             if logs.size >= 2 and np.all(np.isfinite(logs)) and np.any(logs != 0) else None)
        out.update({"D_rules_last_new_median": d, "D": bool(d < 1.0), "E_wilcoxon_p_less": p,
                    "E_n_candidate_better": int(np.sum(logs < 0)), "E_n": int(logs.size)})
    out["adopt"] = bool(out["A"] and out["B"] and out["C"] and out.get("D", True))
    return out


def summary_markdown(results: dict[str, Any]) -> str:
    """The decision, the summary and every ratio, from the JSON alone."""
    cfg, s, dec, jobs = results["config"], results["summary"], results["decision"], results["jobs"]
    lines = [f"Seeds {cfg['seeds']}, tasks {cfg['tasks']}, {cfg['attempts']} attempts each, payload "
             f"{cfg['payload_mass']} kg; wall {results['wall_seconds']:.0f} s with {jobs['n_cached']} of "
             f"{jobs['n_jobs']} jobs from the cache; the jobs took {jobs['job_seconds_sum']:.0f} s in all.", "",
             "| ratio | n | median | IQR | min | worst | meeting the criterion |", "|---|---|---|---|---|---|---|"]
    for q, st in s.items():
        if not st["n"]:
            lines.append(f"| {q} | 0 | - | - | - | - | - |")
            continue
        meet = f"{st['n_meeting']} of {st['n']} (<= {st['limit']})" if "limit" in st else "-"
        lines.append(f"| {q} | {st['n']} | {st['median']:.3f} | {st['q1']:.3f}-{st['q3']:.3f} | {st['min']:.3f} "
                     f"| {st['max']:.3f} | {meet} |")
    c, first_task, new = dec["candidate"], cfg["tasks"][0], cfg["tasks"][1]
    lines += ["", "Decision (rules fixed before the run):", "",
              f"- A, median {c} / UL at the last '{new}' attempt <= 1.10: {dec['A_last_new_median']:.3f} -> {dec['A']}",
              f"- B, the same on '{first_task}': {dec['B_last_first_task_median']:.3f} -> {dec['B']}",
              f"- C, {c}'s first '{new}' attempt <= 1.02 x RBD on every seed (worst "
              f"{dec['C_first_new_vs_rbd_worst']:.3f}) -> {dec['C']}"]
    if dec["control"] is not None:
        lines += [f"- D, median {c} / {dec['control']} at the last '{new}' attempt < 1: "
                  f"{dec['D_rules_last_new_median']:.3f} -> {dec['D']}",
                  f"- E (reported): {c} better on {dec['E_n_candidate_better']} of {dec['E_n']} seeds; one-sided "
                  f"Wilcoxon p = {dec['E_wilcoxon_p_less']}"]
    lines += [f"- **{c}'s rule adopted as the default gate: {dec['adopt']}**", "",
              "J4 on 'left' (medians over seeds): " + "; ".join(
                  f"{label}: g0 {m['g0']:.2f}, m0 {m['m0']:.2f}, m13 {m['m13']:.2f}"
                  for label, m in dec["mechanism"].items()), "",
              "| seed | " + " | ".join(f"{label} g0, m0, m13" for label in results["wrist"]) + " |",
              "|---|" + "---|" * len(results["wrist"])]
    for seed in results["runs"]:
        lines.append(f"| {seed} | " + " | ".join(
            "{g0:.2f}, {m0:.2f}, {m13:.2f}".format(**results["wrist"][label][seed]) for label in results["wrist"])
            + " |")
    lines += ["", "| seed | quantity | numerator | denominator | ratio |", "|---|---|---|---|---|"]
    for r in results["ratios"]:
        lines.append(f"| {r['seed']} | {r['quantity']} | {r['num']:.4g} | {r['den']:.4g} | {r['ratio']:.3f} |")
    return "\n".join(lines) + "\n"


def plot(results: dict[str, Any], path: Path) -> None:
    """Every ratio per quantity (one dot per seed), medians in black, the criteria in red."""
    names = {"GLf": "floor rule", "GLw": "Wiener rule", "GLi": "innovation rule"}
    gated = [f"{label} ({names.get(label, label)})" for label in results["wrist"]]
    title = (f"Gate rules as learners on seeds {results['config']['seeds']}: " + ", ".join(gated)
             + ", UL' (null); all / UL unless named")
    summary = results["summary"]
    with ratio_figure(path, title, figsize=(10, 4.5)) as ax:
        scatter_ratios(ax, results["ratios"], {q: st.get("median") for q, st in summary.items()},
                       limits={q: st.get("limit") for q, st in summary.items()})
        ax.set_yscale("log")
        ax.set_ylabel("ratio of tracking RMSEs")
