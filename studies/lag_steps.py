"""The lag diagnosis's steps 2-4 (:mod:`studies.lag_diagnosis` holds the protocol of all four, step 1 and the
shared setup): step 2 refits each learner's model afresh on its own data (data or fit?), step 3 crosses the two
phases' data between the learners (a factorial), step 4 measures the episodes' excitation and link-side torque."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from cascgp.metrics import rmse
from cascgp_experiments.transfer import TransferConfig
from studies.lag_diagnosis import (DIAGNOSED_TASK, FACTORIAL_SEEDS, LAG_CONFIG, LAG_LEARNERS, LAG_SEEDS,
                                   LAG_SEEDS_WITH_LAG, MIN_LAG_SEEDS, REFIT_RESTARTS, REFIT_SEEDS, UNGATED_NAME,
                                   _arm_rms, _by_seed_and_label, _label, _learner_jobs, _left_evaluator, _left_setup,
                                   _payload, _run_cached, _seed_label, _write)

__all__ = ["refit_job", "factorial_job", "run_factorial", "summarise_factorial", "factorial_markdown", "run_refit",
           "summarise_refit", "refit_markdown", "link_side_model", "episodes_job", "run_episodes",
           "summarise_episodes", "episodes_markdown"]


def _learner_episodes(cfg: TransferConfig, label: str, env: Any, rbd: Any, last: int
                      ) -> tuple[Any, list[Any], dict[str, Any]]:
    """Run learner ``label`` up to attempt ``last`` of the plan: the model that attempt used, the episodes
    recorded before it, and its record."""
    import tempfile

    from cascgp.buffer import DataBuffer
    from cascgp.learning import AttemptContext, RunHooks, run_controller
    from cascgp_experiments.transfer import jaco_feedback

    class Keep(RunHooks):
        model: Any = None

        def before_episode(self, ctx: AttemptContext, model: Any | None) -> None:
            if ctx.index == last:
                self.model = model

    keep = Keep()
    with tempfile.TemporaryDirectory() as tmp:
        run = run_controller(LAG_LEARNERS[label], env, cfg.plan()[: last + 1], rbd, jaco_feedback(), cfg.retrain(),
                             reset_options=cfg.reset_options(), model_factory=cfg.model_factory(), hooks=[keep],
                             buffer_dir=tmp)
        episodes = list(DataBuffer(tmp).episodes[:last])
    return keep.model, episodes, run.attempts[last]


def _fresh_fit(rbd: Any, episodes: list[Any], cfg: TransferConfig, seed: int) -> tuple[Any, float, int]:
    """A model fitted from scratch (:data:`REFIT_RESTARTS` starts, GP seed ``seed``) on the training set the
    loop would build from ``episodes``; the fit seconds and the training rows."""
    from cascgp.buffer import DataBuffer
    from cascgp.gp import GPFitConfig
    from cascgp.models import make_model

    buffer = DataBuffer()
    for episode in episodes:
        buffer.append(episode)
    data = buffer.training_set(cfg.rate_hz, cfg.cap)
    t0 = time.perf_counter()
    model = make_model(UNGATED_NAME, rbd.dof, rbd, gp_config=GPFitConfig(n_restarts=REFIT_RESTARTS, seed=seed))
    return model.fit(data), time.perf_counter() - t0, data.n_samples


def _last_left(cfg: TransferConfig) -> int:
    """The plan index of the last "left" attempt."""
    return max(i for i, (task, _, _) in enumerate(cfg.plan()) if task == DIAGNOSED_TASK)


def _n_front(cfg: TransferConfig, last: int) -> int:
    """How many of the episodes before attempt ``last`` are not on "left" (the "front" ones)."""
    return sum(task != DIAGNOSED_TASK for task, _, _ in cfg.plan()[:last])


def refit_job(config: dict[str, Any], label: str) -> dict[str, Any]:
    """The second step (module docstring) for one (seed, learner): the loop up to the last "left" attempt with
    its buffer kept, then the loop's model and :data:`REFIT_SEEDS` fresh fits on its training set, each run
    ungated on that attempt's episode. Returns per model the tracking RMSE, the per-joint feedforward error vs
    the oracle (``ff_err_rms``), the per-joint NLL of the fit (``best_nll``) and the fit seconds; and the loop's
    own record of the attempt."""
    cfg = TransferConfig.from_dict(config)
    rbd, oracle_ff, ref = _left_setup(cfg)
    last = _last_left(cfg)
    evaluate = _left_evaluator(cfg, rbd, oracle_ff, ref, last)
    env = cfg.make_env()
    try:
        loop_model, episodes, record = _learner_episodes(cfg, label, env, rbd, last)
        out = {"attempt": record, "loop": {**evaluate(loop_model, env), "n_train": int(loop_model.n_train)},
               "fresh": []}
        for seed in REFIT_SEEDS:
            model, secs, out["n_train"] = _fresh_fit(rbd, episodes, cfg, seed)
            out["fresh"].append({"seed": seed, "fit_seconds": secs, **evaluate(model, env)})
    finally:
        env.close()
    return out


def factorial_job(config: dict[str, Any]) -> dict[str, Any]:
    """The third step (module docstring) for one seed: both learners' episodes, the four (front, left) origin
    combinations fitted afresh with :data:`FACTORIAL_SEEDS`, each run ungated on the last "left" attempt's
    episode. Returns ``{"GL/UL": [per GP seed: {seed, fit_seconds, tracking_rmse, ff_err_rms, best_nll}]}``,
    keyed by the origin of the front and of the left episodes."""
    cfg = TransferConfig.from_dict(config)
    rbd, oracle_ff, ref = _left_setup(cfg)
    last = _last_left(cfg)
    n_front = _n_front(cfg, last)
    evaluate = _left_evaluator(cfg, rbd, oracle_ff, ref, last)
    env = cfg.make_env()
    try:
        episodes = {label: _learner_episodes(cfg, label, env, rbd, last)[1] for label in LAG_LEARNERS}
        out: dict[str, Any] = {}
        for front in LAG_LEARNERS:
            for left in LAG_LEARNERS:
                eps = episodes[front][:n_front] + episodes[left][n_front:]
                out[f"{front}/{left}"] = []
                for seed in FACTORIAL_SEEDS:
                    model, secs, _ = _fresh_fit(rbd, eps, cfg, seed)
                    out[f"{front}/{left}"].append({"seed": seed, "fit_seconds": secs, **evaluate(model, env)})
    finally:
        env.close()
    return out


def run_factorial(out: Path, cfg: TransferConfig = LAG_CONFIG, seeds: tuple[int, ...] = LAG_SEEDS, *,
                  workers: int | None = None, ray_address: str | None = None, show_progress: bool = True,
                  references: tuple[dict[str, Any], ...] = ()) -> dict[str, Any]:
    """Run every seed's :func:`factorial_job` (cached under ``out/cache``), write ``lag_factorial.json``/``.md``.
    ``references``: step 2's ``lag_refit.json``, whose fresh fits (UL, UL) and (GL, GL) must reproduce."""
    jobs = [{"config": replace(cfg, seed=int(s)).to_dict()} for s in seeds]
    res, stats, wall = _run_cached(factorial_job, jobs, out, workers=workers, ray_address=ray_address,
                                   show_progress=show_progress, desc="factorial jobs", label=_label)
    runs = {str(job["config"]["seed"]): r for job, r in zip(jobs, res)}
    results = {"config": {**cfg.to_dict(), "seeds": list(seeds), "factorial_seeds": list(FACTORIAL_SEEDS),
                          "refit_restarts": REFIT_RESTARTS},
               "wall_seconds": wall, "jobs": stats, "runs": runs, "summary": summarise_factorial(runs, references)}
    return _write(out, "lag_factorial", results, factorial_markdown)


def summarise_factorial(runs: dict[str, dict[str, Any]], references: tuple[dict[str, Any], ...] = ()
                        ) -> dict[str, Any]:
    """Per seed the three effects (module docstring; tracking, median over the GP seeds), the reproduction of
    step 2's fresh fits, and the reading's counts."""
    rows = []
    for seed, run in sorted(runs.items(), key=lambda kv: int(kv[0])):
        t = {k: float(np.median([r["tracking_rmse"] for r in v])) for k, v in run.items()}
        base = t["UL/UL"]
        ref = next((r["runs"][seed] for r in references if seed in r["runs"]), None)
        reproduced = None
        if ref is not None:
            pairs = [(run[f"{lab}/{lab}"], {f["seed"]: f["tracking_rmse"] for f in ref[lab]["fresh"]})
                     for lab in LAG_LEARNERS]
            reproduced = all(r["tracking_rmse"] == by_seed.get(r["seed"]) for mine, by_seed in pairs for r in mine)
        rows.append({"seed": int(seed), "reproduced": reproduced, "tracking": t,
                     "front_effect": t["GL/UL"] / base, "left_effect": t["UL/GL"] / base, "both": t["GL/GL"] / base})
    lag = [r for r in rows if r["seed"] in LAG_SEEDS_WITH_LAG]
    reading = {}
    for key in ("front_effect", "left_effect", "both"):
        v = np.array([r[key] for r in lag])
        above = int((v > 1.1).sum())
        reading[key] = {"above_1.1": above, "n": len(lag), "median": float(np.median(v)),
                        "median_abs_log": float(np.median(np.abs(np.log(v)))), "cause": above >= MIN_LAG_SEEDS}
    return {"rows": rows, "reading": reading}


def factorial_markdown(results: dict[str, Any]) -> str:
    """The per-seed table and the reading."""
    s = results["summary"]
    lines = ["| seed | reproduced | UL/UL tracking (rad) | front effect (GL front) | left effect (GL left) | both |",
             "|---|---|---|---|---|---|"]
    for r in s["rows"]:
        lines.append(f"| {_seed_label(r['seed'])} | {r['reproduced']} | "
                     f"{r['tracking']['UL/UL']:.4f} | {r['front_effect']:.2f} | {r['left_effect']:.2f} | "
                     f"{r['both']:.2f} |")
    lines += [""] + [f"{k}: above 1.1 on {v['above_1.1']} of {v['n']} lag seeds, median {v['median']:.2f}, median "
                     f"|log| {v['median_abs_log']:.3f}; a cause by the rule: {v['cause']}"
                     for k, v in s["reading"].items()]
    return "\n".join(lines) + "\n"


def run_refit(out: Path, cfg: TransferConfig = LAG_CONFIG, seeds: tuple[int, ...] = LAG_SEEDS, *,
              workers: int | None = None, ray_address: str | None = None, show_progress: bool = True,
              references: tuple[dict[str, Any], ...] = ()) -> dict[str, Any]:
    """Run every (seed, learner) :func:`refit_job` (cached under ``out/cache``), write ``lag_refit.json``/``.md``.
    ``references``: the divergence experiment's JSONs, whose paired episodes (the ungated controller on GL's
    model) GL's loop model must reproduce."""
    jobs = _learner_jobs(cfg, seeds)
    res, stats, wall = _run_cached(refit_job, jobs, out, workers=workers, ray_address=ray_address,
                                   show_progress=show_progress, desc="refit jobs", label=_label)
    runs = _by_seed_and_label(jobs, res)
    results = {"config": {**cfg.to_dict(), "seeds": list(seeds), "refit_seeds": list(REFIT_SEEDS),
                          "refit_restarts": REFIT_RESTARTS},
               "wall_seconds": wall, "jobs": stats, "runs": runs, "summary": summarise_refit(runs, references)}
    return _write(out, "lag_refit", results, refit_markdown)


def summarise_refit(runs: dict[str, dict[str, Any]], references: tuple[dict[str, Any], ...] = ()
                    ) -> dict[str, Any]:
    """Per seed: the loop's and the fresh fits' GL / UL ratios (tracking, and J1-J6 RMS feedforward error vs the
    oracle), the fresh / loop ratio of each learner, and the reading's counts (module docstring). ``reproduced``:
    UL's loop model run again equals UL's attempt; GL's (run ungated) equals the reference's paired episode
    (None without a reference for the seed)."""
    def arm(r: dict[str, Any]) -> float:
        return _arm_rms(r["ff_err_rms"])

    rows = []
    for seed, run in sorted(runs.items(), key=lambda kv: int(kv[0])):
        g, u = run["GL"], run["UL"]
        i = g["attempt"]["attempt"]
        paired = next((r["runs"][seed]["GL"][i]["paired"][UNGATED_NAME]["tracking_rmse"] for r in references
                       if seed in r["runs"]), None)
        row = {"seed": int(seed),
               "reproduced": {"GL": None if paired is None else g["loop"]["tracking_rmse"] == paired,
                              "UL": u["loop"]["tracking_rmse"] == u["attempt"]["tracking_rmse"]}}
        for key, f in (("tracking", lambda r: r["tracking_rmse"]), ("ff", arm)):
            fg, fu = np.median([f(r) for r in g["fresh"]]), np.median([f(r) for r in u["fresh"]])
            row[key] = {"loop": f(g["loop"]) / f(u["loop"]), "fresh": float(fg / fu),
                        "gl_fresh_vs_loop": float(fg / f(g["loop"])), "ul_fresh_vs_loop": float(fu / f(u["loop"]))}
        rows.append(row)
    lag = [r for r in rows if r["seed"] in LAG_SEEDS_WITH_LAG]
    reading = {}
    for key in ("tracking", "ff"):
        fit = sum(0.9 <= r[key]["fresh"] <= 1.1 for r in lag)
        data = sum(r[key]["fresh"] > 1.1 for r in lag)
        reading[key] = {"fit_lag_seeds": fit, "data_lag_seeds": data, "n_lag_seeds": len(lag),
                        "verdict": "fit" if fit >= MIN_LAG_SEEDS else "data" if data >= MIN_LAG_SEEDS else "mixed"}
    return {"rows": rows, "reading": reading}


def refit_markdown(results: dict[str, Any]) -> str:
    """The per-seed table and the reading."""
    s = results["summary"]
    lines = ["| seed | reproduced GL, UL | tracking GL/UL loop | fresh | GL fresh/loop | UL fresh/loop | "
             "ff GL/UL loop | fresh |", "|" + "---|" * 8]
    for r in s["rows"]:
        t, f = r["tracking"], r["ff"]
        lines.append(f"| {_seed_label(r['seed'])} | "
                     f"{r['reproduced']['GL']}, {r['reproduced']['UL']} | {t['loop']:.2f} | {t['fresh']:.2f} | "
                     f"{t['gl_fresh_vs_loop']:.2f} | {t['ul_fresh_vs_loop']:.2f} | {f['loop']:.2f} | "
                     f"{f['fresh']:.2f} |")
    lines += [""] + [f"{k}: fresh within 0.9-1.1 on {v['fit_lag_seeds']} of {v['n_lag_seeds']} lag seeds, above 1.1 on "
                     f"{v['data_lag_seeds']}: {v['verdict']}" for k, v in s["reading"].items()]
    return "\n".join(lines) + "\n"


def link_side_model(payload_mass: float, n_marbles: int) -> Any:
    """The true scene with the whole payload as one rigid body (:func:`jaco_env.oracle.rigid_scene_model`), its
    arm joints' armature, damping and dry friction set to 0: ``mj_inverse`` then gives the link-side torque the
    joint torque sensors read (``jaco_env.robot``), for the marbles at rest."""
    from jaco_env.oracle import rigid_scene_model

    m = rigid_scene_model(payload_mass, n_marbles, "dm_control")  # the ideal env's arm
    m.dof_armature[:6] = 0.0
    m.dof_damping[:6] = 0.0
    m.dof_frictionloss[:6] = 0.0
    return m


def _link_side_torque(model: Any, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
    """``mj_inverse`` of ``model`` at every row (T, 6) of the arm's state (the rest of the scene at rest)."""
    import mujoco

    d = mujoco.MjData(model)
    out = np.empty_like(q)
    for i in range(q.shape[0]):
        d.qpos[:6], d.qvel[:6], d.qacc[:6] = q[i], qd[i], qdd[i]
        mujoco.mj_inverse(model, d)
        out[i] = d.qfrc_inverse[:6]
    return out


def episodes_job(config: dict[str, Any]) -> dict[str, Any]:
    """The fourth step (module docstring) for one seed: per learner, per "left" training episode, its rows ``n``
    and ``resid_rms`` and ``dev_rms`` per joint."""
    import jaco_env.tasks

    from cascgp.rbd import load_nominal
    from cascgp_experiments.common import NOMINAL_URDF_DM_CONTROL

    cfg = TransferConfig.from_dict(config)
    rbd = load_nominal(NOMINAL_URDF_DM_CONTROL)
    link = link_side_model(*_payload(cfg))
    task = jaco_env.tasks.get_task(DIAGNOSED_TASK)
    last = _last_left(cfg)
    n_front = _n_front(cfg, last)
    env = cfg.make_env()
    out: dict[str, Any] = {}
    try:
        for label in LAG_LEARNERS:
            _, episodes, _ = _learner_episodes(cfg, label, env, rbd, last)
            out[label] = []
            for ep in episodes[n_front:]:
                q_ref = task.reference(ep.t)[0]  # t: the observation's time since reset, as the controller's
                link_tau = _link_side_torque(link, ep.q, ep.qd, ep.qdd)
                out[label].append({"n": int(ep.n_samples), "resid_rms": rmse(ep.tau, link_tau).tolist(),
                                   "dev_rms": rmse(ep.q, q_ref).tolist()})
    finally:
        env.close()
    return out


def run_episodes(out: Path, cfg: TransferConfig = LAG_CONFIG, seeds: tuple[int, ...] = LAG_SEEDS, *,
                 workers: int | None = None, ray_address: str | None = None, show_progress: bool = True
                 ) -> dict[str, Any]:
    """Run every seed's :func:`episodes_job` (cached under ``out/cache``), write ``lag_episodes.json``/``.md``."""
    jobs = [{"config": replace(cfg, seed=int(s)).to_dict()} for s in seeds]
    res, stats, wall = _run_cached(episodes_job, jobs, out, workers=workers, ray_address=ray_address,
                                   show_progress=show_progress, desc="episode jobs", label=_label)
    runs = {str(job["config"]["seed"]): r for job, r in zip(jobs, res)}
    results = {"config": {**cfg.to_dict(), "seeds": list(seeds)}, "wall_seconds": wall, "jobs": stats,
               "runs": runs, "summary": summarise_episodes(runs)}
    return _write(out, "lag_episodes", results, episodes_markdown)


def summarise_episodes(runs: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Per seed GL / UL of the median over the "left" episodes of ``resid_rms`` and ``dev_rms`` per joint, and the
    reading's counts at J4 and J6 (module docstring)."""
    rows = []
    for seed, run in sorted(runs.items(), key=lambda kv: int(kv[0])):
        row: dict[str, Any] = {"seed": int(seed)}
        for key in ("resid_rms", "dev_rms"):
            med = {lab: np.median([e[key] for e in run[lab]], axis=0) for lab in LAG_LEARNERS}
            row[key] = (med["GL"] / med["UL"]).tolist()
            row[f"{key}_ul"] = med["UL"].tolist()
        rows.append(row)
    reading: dict[str, Any] = {}
    for j in (3, 5):
        lag = [r for r in rows if r["seed"] in LAG_SEEDS_WITH_LAG]
        con = [r for r in rows if r["seed"] not in LAG_SEEDS_WITH_LAG]
        for name, key, test in (("inconsistent data", "resid_rms", lambda v: v > 1.1),
                                ("less excitation", "dev_rms", lambda v: v < 0.9),
                                ("more excitation", "dev_rms", lambda v: v > 1.1)):
            n_lag = sum(test(r[key][j]) for r in lag)
            n_con = sum(test(r[key][j]) for r in con)
            reading[f"J{j + 1} {name}"] = {
                "lag_seeds": n_lag, "contrast_seeds": n_con,
                "median_ratio": float(np.median([r[key][j] for r in lag])),
                "supported": bool(n_lag >= MIN_LAG_SEEDS and not (con and n_con == len(con)))}
    return {"rows": rows, "reading": reading}


def episodes_markdown(results: dict[str, Any]) -> str:
    """The per-seed table (J4, J6) and the reading."""
    s = results["summary"]
    lines = ["| seed | resid J4 GL/UL | resid J6 GL/UL | UL resid J4, J6 (N m) | dev J4 GL/UL | dev J6 GL/UL |",
             "|---|---|---|---|---|---|"]
    for r in s["rows"]:
        lines.append(f"| {_seed_label(r['seed'])} | "
                     f"{r['resid_rms'][3]:.2f} | {r['resid_rms'][5]:.2f} | {r['resid_rms_ul'][3]:.3f}, "
                     f"{r['resid_rms_ul'][5]:.3f} | {r['dev_rms'][3]:.2f} | {r['dev_rms'][5]:.2f} |")
    lines += [""] + [f"{k}: lag seeds {v['lag_seeds']} of 6, contrast {v['contrast_seeds']} of 2, median ratio "
                     f"{v['median_ratio']:.2f}; supported: {v['supported']}" for k, v in s["reading"].items()]
    return "\n".join(lines) + "\n"
