"""Where does the gated learner's lag on "left" come from? A per-joint look inside the two learners' models
(issue 10, second criterion; follows :mod:`studies.learner_divergence`).

The divergence experiment located the lag in the gated learner's *model* (run ungated it tracks as badly), at
every attempt on "left", mostly at the wrist (J4, J6), on 6 of 8 seeds; part of it is already there when the model
fitted on "front" data alone meets "left". This diagnostic re-runs the two learners (``GL`` =
``sp-inward-gated``, ``UL`` = ``sp-inward``, seeds 0-7, the gate evaluation's settings) up to the end of "left"
and, before every attempt, records per joint what the model holds. The reading rules below were written and
committed before the run:

* **What is recorded** (``record["before"]``, along the "left" reference at 10 Hz, with the model that attempt
  uses):

  - ``ff_err_rms``: RMS of (learned feedforward - the oracle's), N m. The oracle is MuJoCo's inverse dynamics
    of the true scene (1.2 kg payload, marbles lumped at rest; :class:`jaco_env.oracle.OracleController`), the
    best feedforward any model of the arm can give; ``rbd_err_rms`` is the nominal model's on the same yardstick;
  - ``noise_sd`` and ``signal_sd`` (N m) and the lengthscales of every joint's GP (original units), and
    ``n_train``;
  - ``near_dist``: the median over reference points of the distance to the nearest training input, in the GP's
    own lengthscales (:math:`\\min_i \\lVert (x - x_i) / \\ell \\rVert`; the kernel's own notion of "near": at
    1 the kernel is 0.61, at 2 it is 0.14); the predicted neighbour torque is the input the cascade feeds.

* **Checks.** GL's and UL's attempts must reproduce the earlier runs' tracking RMSEs (``docs/studies/gate_eval.json``
  for seeds 0-3, ``docs/studies/learner_divergence_seeds4-7.json`` for 4-7; the plan is the same up to the end of
  "left"). ``ff_err_rms`` is a valid yardstick only if it explains tracking: Spearman's rho between log(GL/UL of the
  tracking RMSE) and log(GL/UL of the J1-J6 RMS of ``ff_err_rms``) over the 32 "left" attempts is reported;
  if rho < 0.5 the per-joint readings below are reported as inconclusive.

* **Candidate causes and how each is read** (J4 and J6, ratio GL / UL per seed; the "lag seeds" are the six
  where the divergence experiment found the lag: 0, 1, 2, 5, 6, 7; seeds 3, 4 are the contrast):

  1. *Coverage*: GL's training data lie farther from the "left" reference (``near_dist`` ratio > 1) and its
     learned correction there is worse. Supported if on the lag seeds the ``near_dist`` ratio is > 1 on at
     least 5 of 6 seeds at the attempt where ``ff_err_rms`` is worst, and not on both contrast seeds.
  2. *Fit*: the data are as near, but GL's GP fitted other hyperparameters (shorter lengthscales or a collapsed
     noise: ``noise_sd`` < 0.05 N m, half the torque sensor's 0.1 N m) and extrapolates worse. Supported if on at
     least 5 of 6 lag seeds the worse joint's GP of GL has a noise collapse or a median state lengthscale below
     UL's by more than a factor 1.5, with ``near_dist`` ratio within 0.9-1.1, and not on both contrast seeds.
  3. Neither pattern: reported as not identified, with the numbers.

  Reported with the numbers, whatever they show; nothing is tuned on them. A change to the library follows only
  from a supported cause, and needs its own pre-registered test on new seeds.

Second step: data or fit? (:func:`refit_job`; written and committed after the first step's results, before
this step ran.) The first step found both learners' data within 0.02-0.16 lengthscales of the "left" reference
from the first "left" refit on, yet GL's J4/J6 feedforward 1.4-3 x worse than UL's. So is GL's worse model in its
*data* (the episodes the gated learner recorded) or in its *fit* (the chain of warm-started refits with 3 starts,
which can keep a poor optimum)? For each seed 0-7 and learner, the training set of the model used at the last
"left" attempt (the buffer's first 7 episodes, 10 Hz, cap 500, exactly as the loop built it) is refitted from
scratch (no warm start) with 10 starts, 3 times (GP seeds 1000-1002). Each model, the loop's own and the 3 fresh
ones, runs the ungated controller on the last "left" attempt's episode (same env seed). Checks: the loop's model
reproduces that attempt's tracking RMSE exactly. Quantities per seed: ``loop`` = GL / UL tracking with the loop's
models; ``fresh`` = median over the 3 refits of GL's / median of UL's. Reading (the six lag seeds; the contrast
seeds reported beside):

* *Fit* is supported if ``fresh`` is within 0.9-1.1 on at least 5 of the 6 lag seeds (the data give equally good
  models once fitted afresh, so the lag came from the fit chain);
* *Data* is supported if ``fresh`` is above 1.1 on at least 5 of the 6 (GL's data give worse models however they
  are fitted);
* otherwise mixed, reported with the numbers. The same counts on the feedforward error vs the oracle (J1-J6 RMS)
  are reported as secondary. Also reported: fresh refits of UL's data against UL's loop model (does the fit chain
  cost UL too?).

Third step: which data? (:func:`factorial_job`; written and committed after step 2's verdict, "data", before
this step ran.) Per seed 0-7 both learners run up to the last "left" attempt; their 7 training episodes are
split into the "front" four and the first three "left" ones, and the four combinations (front from GL or UL) x
(left from GL or UL) are fitted afresh exactly as in step 2 (buffer order front then left, 10 Hz, cap 500; 10
starts; GP seeds 1000 and 1001) and run ungated on the last "left" attempt's episode. Checks: (UL, UL) and (GL,
GL) reproduce step 2's fresh fits with the same GP seeds (``docs/studies/lag_refit.json``). Per seed, with the median
over the two GP seeds, ``front_effect`` = (GL front, UL left) / (UL, UL), ``left_effect`` = (UL front, GL left) / (UL,
UL), ``both`` = (GL, GL) / (UL, UL). Reading (six lag seeds): a phase's data are a cause if its effect is above 1.1
on at least 5 of 6; the larger median ``|log|`` is the larger share; both or neither are reported as such.

Fourth step: what differs in the gated learner's "left" episodes? (:func:`episodes_job`; written and committed
after step 3's verdict, "left" episodes, before this step ran.) Per seed 0-7, both learners' first three "left"
episodes (those step 3 swapped), every recorded row, per joint:

* ``resid_rms``: RMS of the measured torque minus the link-side rigid-body inverse dynamics of the true scene
  (:func:`link_side_model`: the true arm, hand, bottle and 1.2 kg payload with the marbles lumped at rest; no
  rotor inertia, gear friction or damping, since the sensor reads the link side) at the *measured* q, q̇ and
  estimated q̈. What the GP must learn beyond rigid-body physics, plus what it cannot (marbles' contact forces,
  the q̈ estimate's error, sensor noise): the data's inconsistency with a function of the state;
* ``dev_rms``: RMS of the measured q minus the reference (how far the episode strays around the reference).

Per seed, GL / UL of the median over the three episodes, at J4 and J6. Reading (six lag seeds, each joint
apart): *inconsistent data* if the ``resid_rms`` ratio is above 1.1 on at least 5 of 6 and not on both contrast
seeds; *less excitation* if the ``dev_rms`` ratio is below 0.9 on at least 5 of 6 (*more excitation* above 1.1),
not on both contrast seeds; otherwise descriptive only. Nothing is changed on the strength of it.
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from cascgp.io import atomic_write_text, write_json
from cascgp.metrics import rmse
from studies.gate_eval import GATE_EVAL_CONFIG
from cascgp_experiments.transfer import TransferConfig

__all__ = ["LAG_CONFIG", "LAG_SEEDS", "LAG_LEARNERS", "DIAGNOSED_TASK", "model_diagnostics", "diagnosis_job",
           "run_diagnosis", "summarise_diagnosis", "reproduction"]

#: The gate evaluation's settings, cut after "left" (same attempts up to there; no revisit).
LAG_CONFIG = replace(GATE_EVAL_CONFIG, tasks=("front", "left"), revisit=False)
LAG_SEEDS = (0, 1, 2, 3, 4, 5, 6, 7)
#: The seeds on which learner_divergence found the lag on "left" (the others are the contrast).
LAG_SEEDS_WITH_LAG = (0, 1, 2, 5, 6, 7)
#: Every reading rule calls a pattern a cause when it holds on at least this many of the six lag seeds.
MIN_LAG_SEEDS = 5
LAG_LEARNERS = {"GL": "sp-inward-gated", "UL": "sp-inward"}
UNGATED_NAME = "sp-inward"
DIAGNOSED_TASK = "left"
REFERENCE_RATE_HZ = 10.0
REFIT_SEEDS = (1000, 1001, 1002)
REFIT_RESTARTS = 10
FACTORIAL_SEEDS = (1000, 1001)
COLLAPSED_NOISE_SD = 0.05  # N m: half the torque sensor's 0.1 N m (jaco_env.sensors.SensorNoise)


def _seed_label(seed: int) -> str:
    """A seed as the tables show it: the contrast seeds marked."""
    return f"{seed}" if seed in LAG_SEEDS_WITH_LAG else f"{seed} (contrast)"


def _arm_rms(per_joint: list[float]) -> float:
    """The J1-J6 RMS of per-joint RMS errors."""
    return float(np.sqrt(np.mean(np.square(per_joint))))


def _cascade_inputs(model: Any, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, mean: np.ndarray, j: int
                    ) -> np.ndarray:
    """Joint ``j``'s GP inputs at the reference as :meth:`cascgp.models.CascadedGPModel.predict` feeds them: its
    state columns, then the neighbour's whole predicted torque (RBD part included for SP)."""
    joints, neighbour = model.specs[j]
    cols = [np.stack([q[:, s], qd[:, s], qdd[:, s]], axis=1) for s in joints]
    if neighbour is not None:
        cols.append(mean[:, neighbour:neighbour + 1])
    return np.concatenate(cols, axis=1)


def model_diagnostics(model: Any, nominal: Any, oracle_ff: np.ndarray, q: np.ndarray, qd: np.ndarray,
                      qdd: np.ndarray) -> dict[str, Any]:
    """Per joint, along the reference ``(q, qd, qdd)`` (T, N) with the oracle's feedforward ``oracle_ff`` (T, N):
    ``ff_err_rms``, ``rbd_err_rms``, ``noise_sd``, ``signal_sd``, ``lengthscale`` and ``near_dist`` (module
    docstring), and ``n_train``."""
    mean, _ = model.predict(q, qd, qdd)
    rbd = np.asarray(nominal.inverse_dynamics(q, qd, qdd), dtype=float)
    out: dict[str, Any] = {
        "ff_err_rms": rmse(mean, oracle_ff).tolist(), "rbd_err_rms": rmse(rbd, oracle_ff).tolist(),
        "noise_sd": np.sqrt(model.noise_var).tolist(), "signal_sd": np.sqrt(model.signal_var).tolist(),
        "n_train": int(model.n_train), "lengthscale": [], "near_dist": []}
    for j, (k, b) in enumerate(model.where):
        bank = model.banks[k]
        ls = np.asarray(bank.hyperparameters(b)["lengthscale"], dtype=float)
        X = bank.training_data()[0][b]
        x = _cascade_inputs(model, q, qd, qdd, mean, j)
        if x.shape[1] != X.shape[1]:
            raise ValueError(f"joint {j}: reference inputs have {x.shape[1]} columns, the GP {X.shape[1]}")
        inv = np.where(np.isfinite(ls), 1.0 / ls, 0.0)
        d2 = (((x[:, None, :] - X[None, :, :]) * inv) ** 2).sum(-1)
        out["lengthscale"].append(np.where(np.isfinite(ls), ls, -1.0).tolist())  # -1: an ignored column
        out["near_dist"].append(float(np.median(np.sqrt(d2.min(axis=1)))))
    return out


def _payload(cfg: TransferConfig) -> tuple[float, int]:
    """The "left" episodes' payload mass (kg) and number of marbles, read from a reset of a second env (its own
    RNG; the learners' envs are not touched)."""
    probe = cfg.make_env()
    try:
        _, info = probe.reset(seed=0, options={"task": DIAGNOSED_TASK, **cfg.reset_options()})
    finally:
        probe.close()
    return float(info["payload_mass"]), int(info["n_marbles"])


def _left_setup(cfg: TransferConfig) -> tuple[Any, np.ndarray, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The nominal RBD model, the oracle's feedforward along the "left" reference and that reference (10 Hz)."""
    import jaco_env.tasks
    from cascgp.rbd import load_nominal
    from cascgp_experiments.common import NOMINAL_URDF_DM_CONTROL
    from jaco_env.oracle import OracleController

    rbd = load_nominal(NOMINAL_URDF_DM_CONTROL)
    oracle = OracleController(*_payload(cfg), link_inertials="dm_control")  # the ideal env's arm
    task = jaco_env.tasks.get_task(DIAGNOSED_TASK)
    q, qd, qdd = task.reference(np.arange(0.0, task.duration, 1.0 / REFERENCE_RATE_HZ))
    return rbd, np.array([oracle.feedforward(*r) for r in zip(q, qd, qdd)]), (q, qd, qdd)


def diagnosis_job(config: dict[str, Any], label: str) -> list[dict[str, Any]]:
    """Every attempt of learner ``label`` (:data:`LAG_LEARNERS`), with :func:`model_diagnostics` along the
    "left" reference in ``record["before"]``."""
    from cascgp.learning import run_controller
    from cascgp_experiments.transfer import jaco_feedback
    from studies.hooks import BeforeEachAttempt, Progress

    cfg = TransferConfig.from_dict(config)
    rbd, oracle_ff, (q, qd, qdd) = _left_setup(cfg)
    env = cfg.make_env()

    def before(_ctx: Any, model: Any) -> dict[str, Any] | None:
        return None if model is None else model_diagnostics(model, rbd, oracle_ff, q, qd, qdd)

    try:
        run = run_controller(LAG_LEARNERS[label], env, cfg.plan(), rbd, jaco_feedback(), cfg.retrain(),
                             reset_options=cfg.reset_options(), model_factory=cfg.model_factory(),
                             hooks=[BeforeEachAttempt(before), Progress(label)])
    finally:
        env.close()
    return run.attempts


def _left_evaluator(cfg: TransferConfig, rbd: Any, oracle_ff: np.ndarray,
                    ref: tuple[np.ndarray, np.ndarray, np.ndarray], last: int) -> Any:
    """``evaluate(model, env)``: the ungated controller on ``model`` for attempt ``last``'s episode (its env
    seed): tracking RMSE, per-joint feedforward error vs the oracle along the reference, per-joint fit NLL."""
    from cascgp.episodes import run_episode
    from cascgp.learning import make_controller
    from cascgp_experiments.transfer import jaco_feedback

    def evaluate(model: Any, env: Any) -> dict[str, Any]:
        controller = make_controller(UNGATED_NAME, rbd, model, jaco_feedback())
        res = run_episode(env, controller, seed=cfg.seed * 1000 + last,
                          options={"task": DIAGNOSED_TASK, **cfg.reset_options()})
        mean, _ = model.predict(*ref)
        return {"tracking_rmse": res.summary()["tracking_rmse"],
                "ff_err_rms": rmse(mean, oracle_ff).tolist(),
                # per joint, the fit's negative log marginal likelihood (normalised units; every model here is
                # fitted on the same training set, so the values compare: lower is the better optimum)
                "best_nll": [float(f["best_nll"]) for f in model.fit_info]}

    return evaluate


def _run_cached(fn: Any, jobs: list[dict[str, Any]], out: Path, *, workers: int | None, ray_address: str | None,
                show_progress: bool, desc: str, label: Any, **kw: Any) -> tuple[list[Any], dict[str, Any], float]:
    """Every job of ``fn`` through :func:`cascgp_experiments.execution.run_jobs` (cached under ``out/cache``):
    the results in job order, the run's statistics and its wall seconds."""
    from cascgp_experiments.execution import run_jobs

    t0 = time.perf_counter()
    res = run_jobs(fn, jobs, workers=workers, ray_address=ray_address, cache_dir=Path(out) / "cache", desc=desc,
                   label=label, show_progress=show_progress, **kw)
    return list(res), res.stats(), time.perf_counter() - t0


def _write(out: Path, name: str, results: dict[str, Any], markdown: Any) -> dict[str, Any]:
    """``results`` as ``out/<name>.json`` and ``markdown(results)`` as ``out/<name>.md``; returns ``results``."""
    write_json(Path(out) / f"{name}.json", results)
    atomic_write_text(Path(out) / f"{name}.md", markdown(results))
    return results


def _learner_jobs(cfg: TransferConfig, seeds: tuple[int, ...]) -> list[dict[str, Any]]:
    return [{"config": replace(cfg, seed=int(s)).to_dict(), "label": label} for s in seeds for label in LAG_LEARNERS]


def _by_seed_and_label(jobs: list[dict[str, Any]], res: list[Any]) -> dict[str, dict[str, Any]]:
    runs: dict[str, dict[str, Any]] = {}
    for job, r in zip(jobs, res):
        runs.setdefault(str(job["config"]["seed"]), {})[job["label"]] = r
    return runs


def _label(job: dict[str, Any]) -> str:
    return f"seed {job['config']['seed']}" + (f" {job['label']}" if "label" in job else "")


def run_diagnosis(out: Path, cfg: TransferConfig = LAG_CONFIG, seeds: tuple[int, ...] = LAG_SEEDS, *,
                  workers: int | None = None, ray_address: str | None = None, show_progress: bool = True,
                  references: tuple[dict[str, Any], ...] = ()) -> dict[str, Any]:
    """Run every (seed, learner) job (cached under ``out/cache``), write ``lag_diagnosis.json``/``.md`` into
    ``out``. ``references``: earlier results with ``runs[seed][controller]`` attempt lists (the gate evaluation)
    or ``runs[seed][label]`` (the divergence experiment) to check the attempts against."""
    jobs = _learner_jobs(cfg, seeds)
    res, stats, wall = _run_cached(diagnosis_job, jobs, out, workers=workers, ray_address=ray_address,
                                   show_progress=show_progress, desc="attempts", label=_label,
                                   units=[len(cfg.plan())] * len(jobs), unit="attempt")
    runs = _by_seed_and_label(jobs, res)
    results = {"config": {**cfg.to_dict(), "seeds": list(seeds)}, "wall_seconds": wall, "jobs": stats, "runs": runs,
               "reproduction": reproduction(runs, references), "summary": summarise_diagnosis(runs)}
    return _write(out, "lag_diagnosis", results, summary_markdown)


def reproduction(runs: dict[str, dict[str, list[dict[str, Any]]]], references: tuple[dict[str, Any], ...]
                 ) -> dict[str, Any]:
    """How many attempts equal an earlier run's tracking RMSE (same seed, learner, task and attempt on it)."""
    n = equal = 0
    for seed, run in runs.items():
        for label, name in LAG_LEARNERS.items():
            ref = next((r["runs"][seed].get(name, r["runs"][seed].get(label)) for r in references
                        if seed in r["runs"]), None)
            if ref is None:
                continue
            by_key = {(b["task"], b["task_attempt"]): b["tracking_rmse"] for b in ref if b.get("phase") == "train"}
            for a in run[label]:
                if (a["task"], a["task_attempt"]) in by_key:
                    n += 1
                    equal += a["tracking_rmse"] == by_key[(a["task"], a["task_attempt"])]
    return {"attempts_compared": n, "identical": equal}


def _spearman(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    from scipy.stats import spearmanr
    r = spearmanr(a, b)
    return float(r.statistic), float(r.pvalue)


def summarise_diagnosis(runs: dict[str, dict[str, list[dict[str, Any]]]]) -> dict[str, Any]:
    """Per seed and "left" attempt, GL / UL of tracking and of every diagnostic; the yardstick check and the
    two candidate causes' counts (module docstring). As coded: a joint's "worst" attempt per seed is the one with
    the largest GL / UL ``ff_err_rms`` ratio, and a "noise collapse" counts when GL's GP is collapsed and UL's is
    not (``docs/studies/lag_diagnosis.md`` reports how the other readings of the rule come out)."""
    rows = []
    for seed, run in sorted(runs.items(), key=lambda kv: int(kv[0])):
        gl = [a for a in run["GL"] if a["task"] == DIAGNOSED_TASK]
        ul = [a for a in run["UL"] if a["task"] == DIAGNOSED_TASK]
        for a, b in zip(gl, ul):
            ga, ub = a["before"], b["before"]
            rows.append({
                "seed": int(seed), "attempt": int(a["task_attempt"]),
                "tracking": a["tracking_rmse"] / b["tracking_rmse"],
                "ff_all": _arm_rms(ga["ff_err_rms"]) / _arm_rms(ub["ff_err_rms"]),
                "ff": (np.array(ga["ff_err_rms"]) / np.array(ub["ff_err_rms"])).tolist(),
                "ff_gl_vs_rbd": (np.array(ga["ff_err_rms"]) / np.array(ga["rbd_err_rms"])).tolist(),
                "ff_ul_vs_rbd": (np.array(ub["ff_err_rms"]) / np.array(ub["rbd_err_rms"])).tolist(),
                "near": (np.array(ga["near_dist"]) / np.array(ub["near_dist"])).tolist(),
                "near_gl": ga["near_dist"], "near_ul": ub["near_dist"],
                "noise_gl": ga["noise_sd"], "noise_ul": ub["noise_sd"],
                "ls_state": [float(_median_state_ls(g) / _median_state_ls(u))
                             for g, u in zip(ga["lengthscale"], ub["lengthscale"])],
            })
    rho, p = _spearman(np.log([r["tracking"] for r in rows]), np.log([r["ff_all"] for r in rows]))
    causes = {}
    for j in (3, 5):  # J4, J6 (0-based)
        per_seed = {}
        for seed in sorted({r["seed"] for r in rows}):
            rs = [r for r in rows if r["seed"] == seed]
            worst = max(rs, key=lambda r: r["ff"][j])
            per_seed[seed] = {
                "attempt": worst["attempt"], "ff": worst["ff"][j], "near": worst["near"][j],
                "noise_gl": worst["noise_gl"][j], "noise_ul": worst["noise_ul"][j], "ls_state": worst["ls_state"][j],
                "coverage": worst["near"][j] > 1.0,
                "fit": (0.9 <= worst["near"][j] <= 1.1
                        and (worst["noise_gl"][j] < COLLAPSED_NOISE_SD <= worst["noise_ul"][j]
                             or worst["ls_state"][j] < 1 / 1.5)),
            }
        lag = [per_seed[s] for s in LAG_SEEDS_WITH_LAG if s in per_seed]
        contrast = [per_seed[s] for s in per_seed if s not in LAG_SEEDS_WITH_LAG]
        causes[f"J{j + 1}"] = {
            "per_seed": per_seed,
            **{f"{c}_lag_seeds": sum(x[c] for x in lag) for c in ("coverage", "fit")},
            **{f"{c}_contrast_seeds": sum(x[c] for x in contrast) for c in ("coverage", "fit")},
            **{f"{c}_supported": (sum(x[c] for x in lag) >= MIN_LAG_SEEDS and len(lag) == len(LAG_SEEDS_WITH_LAG)
                                  and not (contrast and all(x[c] for x in contrast)))
               for c in ("coverage", "fit")},
        }
    return {"rows": rows, "yardstick": {"spearman_rho": rho, "p": p, "n": len(rows), "valid": rho >= 0.5},
            "causes": causes}


def _median_state_ls(ls: list[float]) -> float:
    """Median lengthscale of a GP's state columns (not the neighbour torque, the last column when there are
    3k + 1 columns); ignored columns (-1) left out."""
    a = np.asarray(ls, dtype=float)
    if a.size % 3 == 1:
        a = a[:-1]
    a = a[a > 0]
    return float(np.median(a)) if a.size else float("nan")


def summary_markdown(results: dict[str, Any]) -> str:
    """The per-seed table (J4, J6 and the whole arm, each attempt on "left") and the causes' counts."""
    s = results["summary"]
    y = s["yardstick"]
    lines = [f"Reproduction: {results['reproduction']['identical']} of {results['reproduction']['attempts_compared']}"
             " attempts identical to the earlier runs.", "",
             f"Yardstick: Spearman rho(log tracking GL/UL, log feedforward error GL/UL) = {y['spearman_rho']:.2f} "
             f"(p = {y['p']:.3g}, n = {y['n']}); valid (rho >= 0.5): {y['valid']}", "",
             "| seed | attempt | tracking GL/UL | ff err GL/UL (arm) | J4 ff | J4 near | J4 noise GL, UL | J4 ls | "
             "J6 ff | J6 near | J6 noise GL, UL | J6 ls |", "|" + "---|" * 12]
    for r in s["rows"]:
        cells = [str(r["seed"]), str(r["attempt"]), f"{r['tracking']:.2f}", f"{r['ff_all']:.2f}"]
        for j in (3, 5):
            cells += [f"{r['ff'][j]:.2f}", f"{r['near'][j]:.2f}", f"{r['noise_gl'][j]:.3f}, {r['noise_ul'][j]:.3f}",
                      f"{r['ls_state'][j]:.2f}"]
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", "| joint | coverage: lag seeds (of 6), contrast (of 2) | fit: lag seeds, contrast | "
              "supported |", "|---|---|---|---|"]
    for name, c in s["causes"].items():
        sup = [k for k in ("coverage", "fit") if c[f"{k}_supported"]] or ["neither"]
        lines.append(f"| {name} | {c['coverage_lag_seeds']}, {c['coverage_contrast_seeds']} | "
                     f"{c['fit_lag_seeds']}, {c['fit_contrast_seeds']} | {', '.join(sup)} |")
    return "\n".join(lines) + "\n"
