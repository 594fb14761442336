"""Multi-seed, paired evaluation of the gated feedforward (issue 10): what does the gate cost once the model
knows a task, and does it keep the first attempt on a new task near the nominal model?

The protocol was fixed (and committed) before any of its runs:

* **Settings.** The full task transfer (:class:`~cascgp_experiments.transfer.TransferConfig` defaults: tasks
  front, left, right, far; 1.2 kg unknown payload; cap 500; 3 restarts), with **4 attempts per task** so that
  the last attempt on a task runs the model retrained after three attempts there (the issue's "after three
  attempts"), and the revisit of the first task. Seeds 0-3: seed 0 is the run on which the Wiener rule was
  chosen, seeds 1-3 are new; both groups are also reported apart.
* **Jobs per seed.** ``rbd``; ``sp-inward`` (the paper's cascade, ungated) with ``sp-inward-gated``,
  ``sp-inward-gated-online`` and ``sp-inward-online`` evaluated on the *same model* after every attempt
  (``paired``: same seed, same task, nothing added to the data); and ``sp-inward-gated`` as its own learner
  (it collects its own data, so its model differs). (The two online variants were added to the protocol
  after its first launch, which was stopped after 7 attempts on the first task, before any ratio existed.)
* **Quantities**, each a ratio of tracking RMSEs per (seed, task):

  - ``gate_same_model_last``: gated / ungated on the same model, last attempt on each task (the gate's own
    cost after three attempts, free of data and fit differences);
  - ``gate_learners_last``: gated learner / ungated learner, last attempt on each task (the issue's criterion,
    target <= 1.10);
  - ``gated_first_vs_rbd``: gated learner's first attempt on each new task (left, right, far) / RBD's
    (criterion: <= 1.02); ``gate_same_model_first_vs_rbd`` and ``ungated_first_vs_rbd`` beside it;
  - ``online_first_same_model``: ``sp-inward-online`` / ``sp-inward`` on the same model, first attempt on each new
    task (the issue: online learning lowers it, ratio < 1); ``gated_online_first_same_model``: the same for
    the gated pair.

  Reported as median, interquartile range, worst and the count meeting the criterion: errors of single
  attempts are heavy-tailed (chaotic marbles), so no means.
"""

from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from cascgp.io import write_json, atomic_write_text
from cascgp_experiments.common import save_figure
from cascgp_experiments.transfer import TransferConfig, controller_job

#: The settings of the protocol (see the module docstring).
# The idealised signal these studies were measured under (before "jaco2" became the env's default).
GATE_EVAL_CONFIG = TransferConfig(controllers=("rbd", "sp-inward", "sp-inward-gated"), attempts=4,
                                  sensor_pipeline="ideal")
GATE_EVAL_SEEDS = (0, 1, 2, 3)
#: Seeds on which the gate rule was chosen (reported apart from the others).
SEEDS_SEEN_WHEN_CHOSEN = (0,)
UNGATED, GATED = "sp-inward", "sp-inward-gated"
PAIRED = (GATED, GATED + "-online", UNGATED + "-online")
CRITERIA = {"gate_learners_last": 1.10, "gated_first_vs_rbd": 1.02}


def add_protocol_args(p: Any) -> None:
    """The command-line options shared by the seed studies built on :data:`GATE_EVAL_CONFIG`
    (``studies.commands.gate_eval``, ``studies.commands.learner_divergence``): ``--out --seeds --tasks --attempts
    --restarts --cap``."""
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--seeds", type=str, default=",".join(map(str, GATE_EVAL_SEEDS)), help="comma-separated seeds")
    p.add_argument("--tasks", type=str, default=None, help="comma-separated tasks (default: the full transfer's)")
    p.add_argument("--attempts", type=int, default=GATE_EVAL_CONFIG.attempts, help="attempts per task")
    p.add_argument("--restarts", type=int, default=GATE_EVAL_CONFIG.restarts, help="GP restarts per retraining")
    p.add_argument("--cap", type=int, default=GATE_EVAL_CONFIG.cap, help="maximum training-set size")


def protocol_from_args(p: Any, a: Any, *, min_attempts: int, two_tasks_why: str
                       ) -> tuple[TransferConfig, tuple[int, ...]]:
    """The settings and seeds of :func:`add_protocol_args`' options (``p.error`` for bad ones: seeds not integers,
    fewer than ``min_attempts`` attempts, fewer than two tasks, explained by ``two_tasks_why``; an ``--out`` that
    cannot be written)."""
    from cascgp_experiments.cli.options import check_output

    check_output(p, a.out, "--out", "folder")
    try:
        seeds = tuple(int(s) for s in a.seeds.split(","))
    except ValueError:
        p.error(f"--seeds: expected comma-separated integers, got {a.seeds!r}")
    if a.attempts < min_attempts:
        p.error(f"--attempts must be at least {min_attempts}")
    try:
        cfg = replace(GATE_EVAL_CONFIG, attempts=a.attempts, restarts=a.restarts, cap=a.cap,
                      **({"tasks": tuple(a.tasks.split(","))} if a.tasks else {}))
    except ValueError as exc:  # TransferConfig's checks (unknown or repeated tasks, cap, restarts)
        p.error(str(exc))
    if len(cfg.tasks) < 2:
        p.error(f"--tasks: at least two tasks ({two_tasks_why})")
    return cfg, seeds


@contextmanager
def ratio_figure(path: Path, title: str, figsize: tuple[float, float] = (9.0, 4.5)) -> Iterator[Any]:
    """The axes of a ratio plot (headless); when the block ends it gets ``title`` and is saved to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=figsize)
    try:
        yield ax
        ax.set_title(title, fontsize=9)
        fig.tight_layout()
        save_figure(fig, path, dpi=120)
    finally:
        plt.close(fig)


def scatter_ratios(ax: Any, rows: list[dict[str, Any]], medians: dict[str, float | None], colors: Any = None,
                   limits: dict[str, float | None] | None = None) -> list[str]:
    """Every ratio of ``rows`` for each quantity of ``medians`` (one dot per seed and task, ``colors(row)`` or blue),
    the quantity's median as a black bar (none when None), its criterion in ``limits`` as a red dashed bar, the
    quantities as x labels; returns them."""
    quantities = list(medians)
    for i, quantity in enumerate(quantities):
        sel = [r for r in rows if r["quantity"] == quantity]
        x = i + np.linspace(-0.2, 0.2, len(sel)) if len(sel) > 1 else np.array([i])
        ax.scatter(x, [r["ratio"] for r in sel], c=[colors(r) if colors else "C0" for r in sel], s=18)
        if medians[quantity] is not None:
            ax.hlines(medians[quantity], i - 0.3, i + 0.3, color="k")
        if limits and limits.get(quantity) is not None:
            ax.hlines(limits[quantity], i - 0.35, i + 0.35, color="r", linestyles="dashed")
    ax.axhline(1.0, color="0.7", lw=1, zorder=0)
    ax.set_xticks(range(len(quantities)), [q.replace("_", "\n") for q in quantities], fontsize=7)
    return quantities


def gate_jobs(cfg: TransferConfig, seeds: tuple[int, ...]) -> list[dict[str, Any]]:
    """One job per (seed, controller), seed-major (a stopped run keeps whole seeds)."""
    jobs = []
    for seed in seeds:
        config = replace(cfg, seed=int(seed)).to_dict()
        for name in (GATED, UNGATED, "rbd"):
            job: dict[str, Any] = {"config": config, "name": name, "buffer_dir": None}
            if name == UNGATED:
                job["paired"] = list(PAIRED)
            jobs.append(job)
    return jobs


def run_gate_eval(out: Path, cfg: TransferConfig = GATE_EVAL_CONFIG, seeds: tuple[int, ...] = GATE_EVAL_SEEDS, *,
                  workers: int | None = None, ray_address: str | None = None,
                  show_progress: bool = True) -> dict[str, Any]:
    """Run every job (cached under ``out/cache``: a stopped run resumes) and write ``gate_eval.json``,
    ``gate_eval.md`` and ``gate_eval.png`` into ``out``; returns the results."""
    from cascgp_experiments.execution import run_jobs

    out = Path(out)
    jobs = gate_jobs(cfg, seeds)
    t0 = time.perf_counter()
    res = run_jobs(controller_job, jobs, workers=workers, ray_address=ray_address, cache_dir=out / "cache",
                   desc="attempts", units=[len(cfg.plan())] * len(jobs), unit="attempt",
                   priority=[-j["config"]["seed"] for j in jobs],
                   label=lambda j: f"seed {j['config']['seed']} {j['name']}", show_progress=show_progress)
    runs: dict[int, dict[str, list[dict[str, Any]]]] = {}
    for job, attempts in zip(jobs, res):
        runs.setdefault(job["config"]["seed"], {})[job["name"]] = attempts
    results = {"config": {**cfg.to_dict(), "seeds": list(seeds)}, "wall_seconds": time.perf_counter() - t0,
               "jobs": res.stats(), "runs": {str(s): r for s, r in runs.items()}}
    results["ratios"] = ratios(results)
    results["summary"] = summarise(results["ratios"])
    write_json(out / "gate_eval.json", results)
    atomic_write_text(out / "gate_eval.md", summary_markdown(results))
    plot(results, out / "gate_eval.png")
    return results


def find_attempt(attempts: list[dict[str, Any]], task: str, k: int | None = None,
                 phase: str = "train") -> dict[str, Any]:
    """The one record of ``phase`` on ``task`` (attempt ``k`` there, or any); ``ValueError`` unless exactly one."""
    sel = [a for a in attempts if a["task"] == task and a["phase"] == phase and (k is None or a["task_attempt"] == k)]
    if len(sel) != 1:
        raise ValueError(f"expected one {phase} attempt {k} on task {task!r}, found {len(sel)}")
    return sel[0]


def ratios(results: dict[str, Any]) -> list[dict[str, Any]]:
    """One row per (seed, task, quantity) with the two RMSEs and their ratio (see the module docstring)."""
    cfg = results["config"]
    tasks, last = cfg["tasks"], cfg["attempts"] - 1
    rows = []
    for seed, run in results["runs"].items():
        ung, gat, rbd = run[UNGATED], run[GATED], run["rbd"]

        def add(quantity: str, task: str, num: float | None, den: float | None, seed: str = seed) -> None:
            # a non-finite RMSE went through JSON as None: its ratio is NaN (and shows as such in the tables)
            num, den = (float("nan") if v is None else float(v) for v in (num, den))
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = float(np.divide(num, den))
            rows.append({"seed": int(seed), "task": task, "quantity": quantity, "num": num, "den": den,
                         "ratio": ratio})

        for task in tasks:
            u = find_attempt(ung, task, last)
            add("gate_same_model_last", task, u["paired"][GATED]["tracking_rmse"], u["tracking_rmse"])
            add("gate_learners_last", task, find_attempt(gat, task, last)["tracking_rmse"], u["tracking_rmse"])
        for task in tasks[1:]:
            r = find_attempt(rbd, task, 0)["tracking_rmse"]
            u = find_attempt(ung, task, 0)
            add("gated_first_vs_rbd", task, find_attempt(gat, task, 0)["tracking_rmse"], r)
            add("gate_same_model_first_vs_rbd", task, u["paired"][GATED]["tracking_rmse"], r)
            add("ungated_first_vs_rbd", task, u["tracking_rmse"], r)
            p = u["paired"]
            add("online_first_same_model", task, p[UNGATED + "-online"]["tracking_rmse"], u["tracking_rmse"])
            add("gated_online_first_same_model", task, p[GATED + "-online"]["tracking_rmse"], p[GATED]["tracking_rmse"])
        u, g = find_attempt(ung, tasks[0], phase="revisit"), find_attempt(gat, tasks[0], phase="revisit")
        add("gate_same_model_revisit", tasks[0], u["paired"][GATED]["tracking_rmse"], u["tracking_rmse"])
        add("gate_learners_revisit", tasks[0], g["tracking_rmse"], u["tracking_rmse"])
    return rows


def ratio_stats(values: list[float], limit: float | None) -> dict[str, Any]:
    """Median, quartiles and range of the finite ratios; ``n_nonfinite`` counts the others (none in a sound run)."""
    a = np.asarray(values, dtype=float)
    v = a[np.isfinite(a)]
    if v.size == 0:
        return {"n": 0, "n_nonfinite": int(a.size)}
    q1, med, q3 = np.percentile(v, [25, 50, 75])
    out = {"n": int(v.size), "n_nonfinite": int(a.size - v.size), "median": float(med), "q1": float(q1),
           "q3": float(q3), "min": float(v.min()), "max": float(v.max())}
    if limit is not None:
        out["limit"] = limit
        out["n_meeting"] = int(np.sum(v <= limit))
    return out


def summarise(rows: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per quantity: all seeds, the seeds seen when the rule was chosen, and the new seeds."""
    out: dict[str, dict[str, Any]] = {}
    for quantity in dict.fromkeys(r["quantity"] for r in rows):
        sel = [r for r in rows if r["quantity"] == quantity]
        limit = CRITERIA.get(quantity)
        groups = {"all": sel, "seen": [r for r in sel if r["seed"] in SEEDS_SEEN_WHEN_CHOSEN],
                  "new": [r for r in sel if r["seed"] not in SEEDS_SEEN_WHEN_CHOSEN]}
        out[quantity] = {g: ratio_stats([r["ratio"] for r in rs], limit) for g, rs in groups.items() if rs}
    return out


def summary_markdown(results: dict[str, Any]) -> str:
    """The summary table and the per-(seed, task) ratios, from the JSON alone."""
    s, cfg = results["summary"], results["config"]
    lines = [f"Seeds {cfg['seeds']} (chosen-on: {list(SEEDS_SEEN_WHEN_CHOSEN)}), tasks {cfg['tasks']}, "
             f"{cfg['attempts']} attempts each, payload {cfg['payload_mass']} kg.", "",
             "| ratio of tracking RMSEs | group | n | median | IQR | worst | meeting the criterion |",
             "|---|---|---|---|---|---|---|"]
    for quantity, groups in s.items():
        for g, st in groups.items():
            if st["n"] == 0:
                lines.append(f"| {quantity} | {g} | 0 | - | - | - | - ({st['n_nonfinite']} not finite) |")
                continue
            meet = f"{st['n_meeting']} of {st['n']} (<= {st['limit']})" if "limit" in st else "-"
            if st.get("n_nonfinite"):
                meet += f"; {st['n_nonfinite']} not finite"
            lines.append(f"| {quantity} | {g} | {st['n']} | {st['median']:.3f} | {st['q1']:.3f}-{st['q3']:.3f} "
                         f"| {st['max']:.3f} | {meet} |")
    lines += ["", "| seed | task | quantity | numerator RMSE | denominator RMSE | ratio |", "|---|---|---|---|---|---|"]
    for r in results["ratios"]:
        lines.append(f"| {r['seed']} | {r['task']} | {r['quantity']} | {r['num']:.4f} | {r['den']:.4f} "
                     f"| {r['ratio']:.3f} |")
    return "\n".join(lines) + "\n"


def plot(results: dict[str, Any], path: Path) -> None:
    """Every ratio per quantity (one dot per seed and task), with the criteria as lines."""
    with ratio_figure(path, "Gated feedforward, paired across seeds (orange: seed the rule was chosen on; "
                            "black: median; red: criterion)") as ax:
        medians = {q: g["all"].get("median") for q, g in results["summary"].items()}
        scatter_ratios(ax, results["ratios"], medians, lambda r: "C1" if r["seed"] in SEEDS_SEEN_WHEN_CHOSEN else "C0",
                       limits=CRITERIA)
        ax.set_ylabel("ratio of tracking RMSEs")
