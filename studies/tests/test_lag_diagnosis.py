"""The lag diagnosis' pieces (studies.lag_diagnosis): the per-joint diagnostics of a model along a
reference (on the planar test arm), and the reading rules of both steps on synthetic records."""

from __future__ import annotations

import numpy as np
import pytest

from cascgp.gp import GPFitConfig
from cascgp.models import make_model
from studies import lag_diagnosis as lag
from studies import lag_steps as steps


def test_model_diagnostics_along_a_reference(arm3_train, arm3_rbd) -> None:
    data = arm3_train.take(np.arange(60))
    model = make_model("sp-inward", data.dof, rbd=arm3_rbd, gp_config=GPFitConfig(n_restarts=2, max_iter=100)).fit(data)
    q, qd, qdd = data.q[:20], data.qd[:20], data.qdd[:20]
    oracle = data.tau[:20]
    out = lag.model_diagnostics(model, arm3_rbd, oracle, q, qd, qdd)
    mean, _ = model.predict(q, qd, qdd)
    np.testing.assert_allclose(out["ff_err_rms"], np.sqrt(np.mean((mean - oracle) ** 2, axis=0)))
    np.testing.assert_allclose(out["rbd_err_rms"],
                               np.sqrt(np.mean((arm3_rbd.inverse_dynamics(q, qd, qdd) - oracle) ** 2, axis=0)))
    np.testing.assert_allclose(np.square(out["noise_sd"]), model.noise_var)
    assert out["n_train"] == 60 and len(out["lengthscale"]) == 3
    # the first joint of an inward cascade (the last one) sees only its own state: on training rows, distance 0
    assert out["near_dist"][2] == 0.0
    # the others are fed the *predicted* neighbour torque, not the measured one they were trained on: near, not 0
    assert all(0.0 < d < 1.0 for d in out["near_dist"][:2])
    far = lag.model_diagnostics(model, arm3_rbd, oracle, q + 3.0, qd, qdd)
    assert all(f > n for f, n in zip(far["near_dist"], out["near_dist"]))


def _step1_runs(near_gl: tuple[float, float], lag_seeds_only: bool = True, noise_gl: float = 0.1) -> dict:
    """Synthetic step-1 runs, two "left" attempts: on the lag seeds GL's J4/J6 feedforward error is 2 x UL's at
    attempt 0 and 4 x at attempt 1 (the worst), its nearest-data distance ``near_gl[k]`` x UL's at attempt k and
    its noise std ``noise_gl``; on the contrast seeds GL equals UL (or, ``lag_seeds_only=False``, is as on the lag
    seeds)."""
    runs = {}
    for s in lag.LAG_SEEDS:
        like_lag = s in lag.LAG_SEEDS_WITH_LAG or not lag_seeds_only
        gl, ul = [], []
        for k in range(2):
            factor, near, noise = (2.0 ** (k + 1), near_gl[k], noise_gl) if like_lag else (1.0, 1.0, 0.1)
            common = {"rbd_err_rms": [1.0] * 6, "lengthscale": [[1.0, 2.0, 3.0]] * 6}
            ul.append({"task": "left", "task_attempt": k, "tracking_rmse": 0.1,
                       "before": {**common, "ff_err_rms": [0.2] * 6, "near_dist": [0.05] * 6, "noise_sd": [0.1] * 6}})
            gl.append({"task": "left", "task_attempt": k, "tracking_rmse": 0.1 * factor * 0.9,
                       "before": {**common, "ff_err_rms": [0.2 * factor] * 6, "near_dist": [0.05 * near] * 6,
                                  "noise_sd": [noise] * 6}})
        runs[str(s)] = {"GL": gl, "UL": ul}
    return runs


def test_step1_reading_rules() -> None:
    # farther data at the worst attempt (1), nearer at the other: coverage, read at the worst attempt
    s = lag.summarise_diagnosis(_step1_runs(near_gl=(0.5, 1.5)))
    assert s["causes"]["J6"]["coverage_supported"] and not s["causes"]["J6"]["fit_supported"]
    assert s["causes"]["J4"]["coverage_lag_seeds"] == 6 and s["causes"]["J4"]["coverage_contrast_seeds"] == 0
    assert s["causes"]["J4"]["per_seed"][0]["attempt"] == 1
    assert not lag.summarise_diagnosis(_step1_runs(near_gl=(1.5, 0.5)))["causes"]["J6"]["coverage_supported"]
    # as near, but GL's noise collapsed: fit
    s = lag.summarise_diagnosis(_step1_runs(near_gl=(1.0, 1.0), noise_gl=0.01))
    assert s["causes"]["J4"]["fit_supported"] and not s["causes"]["J4"]["coverage_supported"]
    # equally near data with the same hyperparameters: neither cause
    s = lag.summarise_diagnosis(_step1_runs(near_gl=(1.0, 1.0)))
    assert not any(c["coverage_supported"] or c["fit_supported"] for c in s["causes"].values())
    # the contrast seeds show the same pattern: not supported
    s = lag.summarise_diagnosis(_step1_runs(near_gl=(1.5, 1.5), lag_seeds_only=False))
    assert not s["causes"]["J6"]["coverage_supported"]
    assert s["yardstick"]["n"] == 16 and s["yardstick"]["spearman_rho"] > 0.5


def _step2_runs(fresh_gl: float) -> dict:
    """Synthetic step-2 runs: GL's loop model tracks 1.5 x UL's; fresh fits of GL's data ``fresh_gl`` x UL's."""
    runs = {}
    for s in lag.LAG_SEEDS:
        ul_fresh = [{"tracking_rmse": 0.1 * f, "ff_err_rms": [0.2 * f] * 6} for f in (0.9, 1.0, 1.1)]
        gl_fresh = [{"tracking_rmse": 0.1 * fresh_gl * f, "ff_err_rms": [0.2 * fresh_gl * f] * 6}
                    for f in (0.9, 1.0, 1.1)]
        runs[str(s)] = {
            "GL": {"attempt": {"attempt": 7, "tracking_rmse": 0.16}, "fresh": gl_fresh,
                   "loop": {"tracking_rmse": 0.15, "ff_err_rms": [0.3] * 6}},
            "UL": {"attempt": {"attempt": 7, "tracking_rmse": 0.1}, "fresh": ul_fresh,
                   "loop": {"tracking_rmse": 0.1, "ff_err_rms": [0.2] * 6}}}
    return runs


def test_step2_reading_rules_and_reproduction() -> None:
    ref = {"runs": {"0": {"GL": [{}] * 7 + [{"paired": {lag.UNGATED_NAME: {"tracking_rmse": 0.15}}}]}}}
    s = steps.summarise_refit(_step2_runs(1.0), (ref,))
    assert s["reading"]["tracking"]["verdict"] == "fit" and s["reading"]["ff"]["verdict"] == "fit"
    row0, row1 = s["rows"][0], s["rows"][1]
    assert row0["reproduced"] == {"GL": True, "UL": True} and row1["reproduced"]["GL"] is None
    np.testing.assert_allclose([row0["tracking"]["loop"], row0["tracking"]["fresh"]], [1.5, 1.0])
    np.testing.assert_allclose(row0["tracking"]["gl_fresh_vs_loop"], 0.1 / 0.15)
    assert steps.summarise_refit(_step2_runs(1.5))["reading"]["tracking"]["verdict"] == "data"
    mixed = _step2_runs(1.0)
    for seed in ("0", "1", "2"):  # half the lag seeds' data give worse models, half not
        mixed[seed]["GL"] = _step2_runs(1.5)[seed]["GL"]
    assert steps.summarise_refit(mixed)["reading"]["tracking"]["verdict"] == "mixed"
    md = steps.refit_markdown({"summary": s})
    assert "fit" in md.splitlines()[-1] and md.count("(contrast)") == 2


def _step3_runs(front: float, left: float) -> dict:
    """Synthetic step-3 runs: GL's front episodes multiply the tracking by ``front``, its left ones by ``left``."""
    runs = {}
    for s in lag.LAG_SEEDS:
        f, l_ = (front, left) if s in lag.LAG_SEEDS_WITH_LAG else (1.0, 1.0)
        runs[str(s)] = {f"{a}/{b}": [{"seed": seed, "tracking_rmse": 0.1 * (f if a == "GL" else 1.0)
                                      * (l_ if b == "GL" else 1.0) * g}
                                     for seed, g in zip(lag.FACTORIAL_SEEDS, (0.95, 1.05))]
                        for a in lag.LAG_LEARNERS for b in lag.LAG_LEARNERS}
    return runs


def test_step3_effects_reading_and_reproduction() -> None:
    runs = _step3_runs(front=1.0, left=1.5)
    ref = {"runs": {"0": {lab: {"fresh": [{"seed": r["seed"], "tracking_rmse": r["tracking_rmse"]}
                                          for r in runs["0"][f"{lab}/{lab}"]]} for lab in lag.LAG_LEARNERS}}}
    s = steps.summarise_factorial(runs, (ref,))
    np.testing.assert_allclose([s["rows"][0][k] for k in ("front_effect", "left_effect", "both")], [1.0, 1.5, 1.5])
    assert s["rows"][0]["reproduced"] is True and s["rows"][1]["reproduced"] is None
    assert s["reading"]["left_effect"]["cause"] and not s["reading"]["front_effect"]["cause"]
    ref["runs"]["0"]["GL"]["fresh"][0]["tracking_rmse"] += 1e-9  # one fit that does not reproduce
    assert steps.summarise_factorial(runs, (ref,))["rows"][0]["reproduced"] is False
    s = steps.summarise_factorial(_step3_runs(front=1.3, left=1.0))
    assert s["reading"]["front_effect"]["cause"] and not s["reading"]["left_effect"]["cause"]
    md = steps.factorial_markdown({"summary": s})
    assert md.count("(contrast)") == 2 and "front_effect: above 1.1 on 6 of 6" in md


def test_cli_errors(tmp_path, capsys) -> None:
    """Argument errors exit with status 2 and a message naming the option (in-process: no work starts)."""
    from studies.commands.lag_diagnosis import main

    for args, msg in ((["--refit", "--factorial"], "one step at a time"),
                      (["--episodes", "--refit"], "one step at a time"), (["--seeds", "a,b"], "--seeds"),
                      (["--episodes", "--reference", __file__], "nothing to check against"),
                      (["--reference", str(tmp_path / "none.json")], "--reference")):
        with pytest.raises(SystemExit) as exc:
            main(["--out", str(tmp_path), *args])
        assert exc.value.code == 2
        err = capsys.readouterr().err
        assert msg in err, err


def test_link_side_model_is_the_true_scene_without_the_drive() -> None:
    """The link-side torque the sensors read: the full model's inverse dynamics minus the residual rotor inertia
    and gear damping of jaco_env.robot (dry friction removed from both for the comparison)."""
    from jaco_env import robot
    from jaco_env.oracle import rigid_scene_model

    rng = np.random.default_rng(0)
    q, qd, qdd = rng.uniform(-1, 1, (5, 6)), rng.uniform(-0.5, 0.5, (5, 6)), rng.uniform(-1, 1, (5, 6))
    link = steps.link_side_model(1.2, 30)
    full = rigid_scene_model(1.2, 30, "dm_control")
    assert not link.dof_armature[:6].any() and not link.dof_frictionloss[:6].any() and full.dof_armature[:6].all()
    full.dof_frictionloss[:6] = 0.0
    diff = steps._link_side_torque(full, q, qd, qdd) - steps._link_side_torque(link, q, qd, qdd)
    np.testing.assert_allclose(diff, robot.ARMATURE * qdd + robot.DAMPING * qd, atol=1e-8)


def test_step4_ratios_and_reading() -> None:
    def episodes(resid: float, dev: float) -> list[dict]:
        return [{"n": 100, "resid_rms": [0.1 * resid * f] * 6, "dev_rms": [0.01 * dev * f] * 6} for f in (0.9, 1, 2)]

    runs = {str(s): {"GL": episodes(1.5, 0.8) if s in lag.LAG_SEEDS_WITH_LAG else episodes(1.0, 1.0),
                     "UL": episodes(1.0, 1.0)} for s in lag.LAG_SEEDS}
    s = steps.summarise_episodes(runs)
    np.testing.assert_allclose(s["rows"][0]["resid_rms"], 1.5)
    np.testing.assert_allclose(s["rows"][0]["resid_rms_ul"], 0.1)
    r = s["reading"]
    assert r["J4 inconsistent data"]["supported"] and r["J6 less excitation"]["supported"]
    assert not r["J6 more excitation"]["supported"] and r["J4 inconsistent data"]["contrast_seeds"] == 0
    runs["3"]["GL"] = runs["4"]["GL"] = episodes(1.5, 0.8)  # the contrast seeds show it too: not supported
    assert not steps.summarise_episodes(runs)["reading"]["J4 inconsistent data"]["supported"]
    assert "lag seeds 6 of 6" in steps.episodes_markdown({"summary": s})
