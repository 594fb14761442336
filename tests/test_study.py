"""Tests of the data-efficiency study (cascgp_experiments: common, curves, study, plots ...; its command line).

Fast unit tests of the table logic, the curve engine (with a fake model factory), the paper's
numbers, error paths; end-to-end ``--smoke`` (about 15 s) and ``--quick`` (about 35 s on an idle
2-core machine, up to about 2 min under load) runs of the one command, both in the default suite,
which also check that the figures and tables are regenerated from ``results.json`` alone.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cascgp.data import DynamicsData
from cascgp_experiments.common import (PAPER_TABLE, RBD, VARIANTS, category, interval_mean, label, make_table,
                                       read_json, write_json)

REPO = Path(__file__).resolve().parents[1]
PAPER = (REPO / ".." / "shared" / "paper" / "cascaded_gp_paper.tex").resolve()


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    env.setdefault("MUJOCO_GL", "egl")
    return env


# --------------------------------------------------------------------------- names and tables
def test_names_and_labels() -> None:
    assert len(VARIANTS) == 12 and len(set(VARIANTS)) == 12
    from cascgp.models import MODEL_NAMES

    assert set(VARIANTS) == set(MODEL_NAMES)
    assert label("np-inward") == "NP-Inward-Cascaded"
    assert label("sp-standard-df") == "SP-DF"
    assert label(RBD) == "RBD"
    assert category("sp-outward-df") == "df-sp" and category("np-standard") == "db-np"


def test_interval_mean_and_table_marks() -> None:
    grid = [1.0, 1.5, 2.0, 4.0, 5.0, 9.0, 10.0, 50.0]
    G, N = len(grid), 2
    base = np.linspace(1.0, 0.2, G)[:, None] * np.ones((G, N))
    curves = {m: (base * (1.0 + 0.1 * k)).tolist() for k, m in enumerate(VARIANTS)}
    # within its category (np db), np-outward is 3 % above np-inward -> "near"
    curves["np-outward"] = (base * 1.03).tolist()
    curves[RBD] = (0.01 * np.ones((G, N))).tolist()
    t = make_table(grid, curves)
    np.testing.assert_allclose(t["rows"]["np-inward"][0][0], base[:3, 0].mean())
    np.testing.assert_allclose(t["rows"]["np-inward"][1][2], base[5:7, 1].mean())
    assert interval_mean(grid, base, 20, 30).shape == (N,) and np.isnan(interval_mean(grid, base, 20, 30)).all()
    for j in range(N):
        for k in range(3):
            assert t["best"]["np-inward"][j][k] and not t["best"]["np-standard"][j][k]
            assert t["near"]["np-outward"][j][k]
            assert not t["best"][RBD][j][k]  # RBD is never marked though lowest
            # one best per category
            for cat in ("db-np", "db-sp", "df-np", "df-sp"):
                assert sum(t["best"][m][j][k] for m in VARIANTS if category(m) == cat) >= 1


@pytest.mark.skipif(not PAPER.exists(), reason="paper .tex not available")
def test_paper_table_matches_tex() -> None:
    tex = PAPER.read_text()
    for m, rows in PAPER_TABLE.items():
        name = label(m)
        line = next(ln for ln in tex.splitlines() if re.search(r"\\textbf\{" + re.escape(name) + r"\}\s*&", ln))
        vals = [float(v) for v in re.findall(r"(?<![\w{])\.\d{3}", line.split(name, 1)[1])]
        assert vals == [v for r in rows for v in r], m


def test_write_json_cleans_nan_and_numpy(tmp_path: Path) -> None:
    p = write_json(tmp_path / "a.json", {"x": np.array([1.0, np.nan]), "i": np.int64(3), "b": np.bool_(True)})
    assert read_json(p) == {"x": [1.0, None], "i": 3, "b": True}


# --------------------------------------------------------------------------- curve engine (fake model)
class _LinearModel:
    """A ridge-regression stand-in for a cascgp model (same fit / predict_data API)."""

    def __init__(self, name: str, dof: int, rbd=None, **kw) -> None:
        self.name, self.dof, self.rbd = name, dof, rbd

    def fit(self, data: DynamicsData, init=None, share=None) -> "_LinearModel":
        X = np.concatenate([data.q, data.qd, data.qdd, np.ones((data.n_samples, 1))], axis=1)
        # another ridge for a cascade, so that only taking the standard model's joint (share) makes a cascade's
        # chain-first joint equal to the standard model's
        A = X.T @ X + (1e-3 if self.name.endswith("standard") else 1.0) * np.eye(X.shape[1])
        self.W = np.linalg.solve(A, X.T @ data.tau)
        self.n_train = data.n_samples
        if share is not None:  # the standard model fitted on the same rows: take its chain-first joint
            assert share.name == "np-standard" and share.n_train == data.n_samples
            j0 = self.dof - 1 if "inward" in self.name else 0
            self.W[:, j0] = share.W[:, j0]
        self.warm = init is not None
        # An "NLL" per joint that the audit can compare: the targets' sum of squares (the same for every fit of
        # the same rows), plus a penalty on a warm start so that the audit gap is known (warm fits are 0.5 worse).
        self.fit_info = [{"best_nll": float(v) + (0.5 if self.warm else 0.0)} for v in (data.tau**2).sum(0)]
        return self

    def predict_data(self, data: DynamicsData, return_var: bool = True):
        X = np.concatenate([data.q, data.qd, data.qdd, np.ones((data.n_samples, 1))], axis=1)
        m = X @ self.W
        return m, (np.zeros_like(m) if return_var else None)


def fake_make(name, dof, rbd=None, **kw):
    return _LinearModel(name, dof, rbd, **kw)


def fake_measured(model: _LinearModel, data: DynamicsData) -> np.ndarray:
    """A stand-in for scoring with the measured neighbour torque: the prediction moved towards the data."""
    return 0.5 * (model.predict_data(data)[0] + data.tau)


def _synthetic(path: Path, n_seg: int, seconds: float, hz: float, seed: int) -> Path:
    rng = np.random.default_rng(seed)
    parts = []
    for s in range(n_seg):
        t = np.arange(int(seconds * hz)) / hz
        q = np.sin(np.outer(t, rng.uniform(0.2, 1.0, 3)) + rng.uniform(0, 6, 3))
        qd = np.gradient(q, t, axis=0)
        qdd = np.gradient(qd, t, axis=0)
        tau = 2 * q + 0.5 * qd + 0.1 * qdd + 0.01 * rng.standard_normal(q.shape)
        parts.append(DynamicsData(q=q, qd=qd, qdd=qdd, tau=tau, t=t, segment=np.full(t.size, s)))
    DynamicsData.concat(parts).save(path)
    return path


def test_run_curves_with_fake_factory_and_cache(tmp_path: Path) -> None:
    from cascgp_experiments.curves import CurveSpec, run_curves

    tr = _synthetic(tmp_path / "train.npz", 3, 12.0, 50.0, 0)
    te = _synthetic(tmp_path / "test.npz", 2, 6.0, 50.0, 1)
    spec = CurveSpec(train_path=str(tr), test_path=str(te), n_subsets=3, grid=[1.0, 2.0, 10.0],
                     factory=f"{__name__}:fake_make", urdf=None, audit_fraction=0.5,
                     measured=f"{__name__}:fake_measured")
    models = ["np-standard", "np-inward"]
    out = run_curves(spec, models, workers=1, cache_dir=tmp_path / "cache")
    # both scorings of the cascade; the standard model has one
    assert "measured" in out["models"]["np-inward"] and "measured" not in out["models"]["np-standard"]
    std, inw = (np.asarray(out["models"][m]["nrmse_all"]) for m in models)
    meas = np.asarray(out["models"]["np-inward"]["measured"]["nrmse_all"])
    assert meas.shape == inw.shape and np.all(meas[:, :, :2] < inw[:, :, :2])
    # the inward cascade's last joint is the standard model's GP: the cascade runs in the standard model's job and
    # takes it (share), so its cells there are the standard model's, bit-equal
    assert out["jobs"]["labels"] == [f"np-standard+np-inward#{s}" for s in range(3)]
    assert out["shared"][0]["model"] == "np-inward" and out["shared"][0]["joint"] == 2
    assert out["shared"][0]["max_abs_diff_own_fit"] == 0.0  # the cascade took the standard model's joint
    np.testing.assert_array_equal(inw[:, :, 2], std[:, :, 2])
    np.testing.assert_array_equal(meas[:, :, 2], std[:, :, 2])
    assert not np.array_equal(inw[:, :, 0], std[:, :, 0])
    # Audit: the seeded sample of fits, each refitted cold; gap = protocol - cold NLL (0.5 for a
    # warm-started fit of the fake model, 0 for the first grid point).
    from cascgp_experiments.curves import audited

    a = out["audit"]
    expect = sorted((m, s, gi) for m in models for s in range(3) for gi in range(3) if audited(spec, m, s, gi))
    assert 0 < len(expect) < 18 and a["n_audited_fits"] == len(expect) and a["n_fits"] == 18
    got = sorted((r["model"], r["subset"], [1.0, 2.0, 10.0].index(r["seconds"])) for r in a["records"])
    assert got == expect
    for r in a["records"]:
        want = 0.0 if r["seconds"] == 1.0 else 0.5
        np.testing.assert_allclose(r["gap"], want, atol=1e-9)
    assert out["grid_s"] == [1.0, 2.0, 10.0] and out["n_subsets"] == 3
    for m in models:
        r = out["models"][m]
        allr = np.asarray(r["nrmse_all"])
        assert allr.shape == (3, 3, 3)
        np.testing.assert_allclose(r["nrmse_mean"], allr.mean(0))
        np.testing.assert_allclose(r["nrmse_std"], allr.std(0))
        np.testing.assert_allclose(r["nrmse_median"], np.median(allr, 0))
        np.testing.assert_allclose(r["nrmse_q25"], np.percentile(allr, 25, axis=0))
        # 10 Hz: 10 rows per second, minus the first 2 * df_delta = 0.2 s (2 rows) that a -df
        # model cannot use: every variant trains on the same rows.
        assert [list(x) for x in r["n_train"]] == [[8, 18, 98]] * 3
    # the (nearly) linear truth is learned: error falls with data
    mu = np.asarray(out["models"]["np-standard"]["nrmse_mean"])
    assert np.all(mu[-1] < mu[0]) and np.all(mu[-1] < 0.2)
    # test rows: 10 Hz, minus the first 0.2 s (2 rows) of each of the 2 segments
    assert out["n_test_rows"] == 2 * (60 - 2)
    again = run_curves(spec, models, workers=1, cache_dir=tmp_path / "cache")
    assert again["n_cached_jobs"] == 3
    np.testing.assert_array_equal(again["models"]["np-inward"]["nrmse_all"], out["models"]["np-inward"]["nrmse_all"])


def test_job_groups_put_cascades_in_their_standard_models_job() -> None:
    from cascgp_experiments.curves import job_groups

    assert job_groups(["np-inward", "sp-standard-df", "np-standard", "sp-outward-df", "sp-inward", "np-outward"]) == [
        ["np-standard", "np-inward", "np-outward"], ["sp-standard-df", "sp-outward-df"], ["sp-inward"]]
    assert sorted(m for g in job_groups(list(VARIANTS)) for m in g) == sorted(VARIANTS)
    assert len(job_groups(list(VARIANTS))) == 4


def test_cascade_in_its_standard_models_job_scores_as_alone(tmp_path: Path, monkeypatch) -> None:
    """The real models: a cascade that takes the standard model's GP of its chain's first joint at every grid point
    (warm-started along the grid) scores as when it fits that GP itself in a job of its own, on every joint that
    the chain feeds (to 1e-6: see tests/test_gp_shared.py); the first joint's cells are the standard model's."""
    from cascgp.models import CascadedGPModel
    from cascgp_experiments.curves import CurveSpec, run_curves

    shares: list[tuple[str, str | None]] = []
    fit = CascadedGPModel.fit

    def spy(self, data, init=None, *, share=None):
        shares.append((self.name, None if share is None else share.name))
        return fit(self, data, init, share=share)

    monkeypatch.setattr(CascadedGPModel, "fit", spy)
    tr = _synthetic(tmp_path / "train.npz", 1, 3.0, 50.0, 0)
    te = _synthetic(tmp_path / "test.npz", 1, 3.0, 50.0, 1)
    spec = CurveSpec(train_path=str(tr), test_path=str(te), n_subsets=1, grid=[1.0, 2.0], n_restarts=3,
                     audit_fraction=0.0)
    both = run_curves(spec, ["np-standard", "np-outward", "np-inward"], workers=1, show_progress=False)
    assert shares == [("np-standard", None), ("np-outward", "np-standard"), ("np-inward", "np-standard")] * 2
    assert both["jobs"]["labels"] == ["np-standard+np-outward+np-inward#0"]
    for m, j0 in (("np-outward", 0), ("np-inward", 2)):
        alone = run_curves(spec, [m], workers=1, show_progress=False)
        assert alone["jobs"]["labels"] == [f"{m}#0"]
        b, a = both["models"][m], alone["models"][m]
        fed = [j for j in range(3) if j != j0]
        for key in ("nrmse_all", "measured"):
            got = np.asarray(b[key]["nrmse_all"] if key == "measured" else b[key])
            want = np.asarray(a[key]["nrmse_all"] if key == "measured" else a[key])
            np.testing.assert_allclose(got[:, :, fed], want[:, :, fed], rtol=1e-6)
        np.testing.assert_array_equal(np.asarray(b["nrmse_all"])[:, :, j0],
                                      np.asarray(both["models"]["np-standard"]["nrmse_all"])[:, :, j0])
        np.testing.assert_allclose(np.asarray(b["nrmse_all"])[:, :, j0], np.asarray(a["nrmse_all"])[:, :, j0],
                                   rtol=1e-6)
    assert [(sh["model"], sh["joint"], sh["with"]) for sh in both["shared"]] == \
        [("np-outward", 0, "np-standard"), ("np-inward", 2, "np-standard")]
    assert all(sh["max_abs_diff_own_fit"] <= 1e-12 for sh in both["shared"])


def test_curve_spec_errors(tmp_path: Path) -> None:
    from cascgp_experiments.curves import CurveSpec, prepare

    tr = _synthetic(tmp_path / "train.npz", 2, 3.0, 50.0, 0)
    with pytest.raises(ValueError, match="n_subsets"):
        prepare(CurveSpec(train_path=str(tr), test_path=str(tr), n_subsets=5, grid=[1.0]))
    with pytest.raises(ValueError, match="split_by"):
        prepare(CurveSpec(train_path=str(tr), test_path=str(tr), n_subsets=2, grid=[1.0], split_by="x"))


def test_collect_config_errors() -> None:
    from cascgp_experiments.collect import CollectConfig, motion_seed

    with pytest.raises(ValueError, match="n_subsets"):
        CollectConfig(n_subsets=0)
    with pytest.raises(ValueError, match="rate_hz"):
        CollectConfig(rate_hz=-1.0)
    with pytest.raises(ValueError, match="payload_mass"):
        CollectConfig(payload_mass=float("nan"))
    cfg = CollectConfig()
    seeds = {motion_seed(cfg, s, k) for s in ("train", "test") for k in range(10)}
    assert len(seeds) == 20  # every motion has its own parameters


def test_cli_rejects_unknown_model(tmp_path: Path) -> None:
    run = subprocess.run([sys.executable, "-m", "scripts.data_efficiency", "--out", str(tmp_path), "--models",
                          "np-bogus"], env=_env(), cwd=REPO, capture_output=True, text=True, timeout=120)
    assert run.returncode == 2 and "--models: unknown ['np-bogus']" in run.stderr


def test_iteration_counts_small() -> None:
    from cascgp_experiments.analyses import iteration_counts

    rng = np.random.default_rng(0)
    t = np.arange(40) / 10.0
    q = rng.standard_normal((40, 3))
    d = DynamicsData(q=q, qd=q ** 2, qdd=np.cos(q), tau=q @ rng.standard_normal((3, 3)), t=t)
    r = iteration_counts(d, n=30, n_restarts=2)
    assert set(r["models"]) == {"np-standard", "np-inward", "np-outward"}
    rec = r["models"]["np-inward"]
    assert rec["dim"] == [4, 7, 9] and len(rec["n_iter"][0]) == 2
    np.testing.assert_allclose(rec["n_iter_mean"], np.mean(rec["n_iter"], axis=1))
    with pytest.raises(ValueError, match="n"):
        iteration_counts(d, n=100)


def test_spearman_block() -> None:
    from cascgp_experiments.analyses import spearman_block

    rng = np.random.default_rng(0)
    q = rng.standard_normal((200, 2))
    d = DynamicsData(q=q, qd=q ** 3, qdd=-q, tau=np.exp(q), t=np.arange(200) / 10.0)
    c = spearman_block(d)
    M = np.asarray(c["abs_spearman"])
    assert c["labels"][:2] == ["q1", "q2"] and M.shape == (8, 8)
    # monotone transforms have rank correlation 1
    i, j = c["labels"].index("q1"), c["labels"].index("tau1")
    assert M[i, j] == pytest.approx(1.0) and c["labels"].index("qd2") == 3
    np.testing.assert_allclose(M, M.T)


# --------------------------------------------------------------------------- end to end
def _has_excitation() -> bool:
    try:
        import jaco_env.excitation  # noqa: F401
    except ImportError:
        return False
    return True


def _check_results(out: Path, res: dict) -> None:
    jaco = res["jaco"]
    assert set(jaco["models"]) == set(VARIANTS) | {RBD}
    G = len(jaco["grid_s"])
    for v in jaco["models"].values():
        mu = np.asarray(v["nrmse_mean"], float)
        assert mu.shape == (G, 6) and np.isfinite(mu).all() and (mu > 0).all()
        np.testing.assert_allclose(v["nrmse_median"], np.median(np.asarray(v["nrmse_all"], float), 0))
    # the table in the JSON is the interval mean of the median curves in the JSON
    t = make_table(jaco["grid_s"], {m: v["nrmse_median"] for m, v in jaco["models"].items()})
    assert json.loads(json.dumps(t["rows"]).replace("NaN", "null")) == jaco["table"]["rows"]
    # both scorings of every cascade; the chain-first joint shared with the standard model, bit-equal
    from cascgp_experiments.pooled_stats import chain_first, standard_twin

    assert len(jaco["shared"]) == 8 and "table_measured" in jaco and jaco["pooled"]
    for m, v in jaco["models"].items():
        j = chain_first(m, 6)
        assert ("measured" in v) == (j is not None)
        if j is not None:
            std = np.asarray(jaco["models"][standard_twin(m)]["nrmse_all"])[:, :, j]
            np.testing.assert_array_equal(np.asarray(v["nrmse_all"])[:, :, j], std)
            np.testing.assert_array_equal(np.asarray(v["measured"]["nrmse_all"])[:, :, j], std)
    a = jaco["audit"]
    assert a["n_fits"] == len(VARIANTS) * jaco["n_subsets"] * G and a["n_audited_fits"] >= 1
    assert a["n_gps"] == 6 * a["n_audited_fits"] and 0.0 <= a["within_tol"] <= 1.0
    assert "iterations" in res and "correlation" in res
    assert res["meta"]["collection"]["payload_mass"] > 0


def _regenerate_from_json_alone(out: Path, tmp_path: Path) -> None:
    """Copy only results.json to a fresh folder and rebuild every figure/table there, in a process
    that imports neither torch, the models nor jaco_env (only the light ``cascgp.io`` helpers) and,
    of the experiments, only the plotting module and what it needs (common, claims)."""
    fresh = tmp_path / "fresh"
    fresh.mkdir()
    shutil.copy(out / "results.json", fresh / "results.json")
    code = ("import sys; from cascgp_experiments import plots; plots.render(sys.argv[1], sys.argv[2]); "
            "bad = [m for m in sys.modules if m.split('.')[0] in ('jaco_env', 'torch', 'pinocchio') "
            "or (m.startswith('cascgp.') and m != 'cascgp.io') or (m.startswith('cascgp_experiments.') and m not in "
            "('cascgp_experiments.plots', 'cascgp_experiments.common', 'cascgp_experiments.claims', "
            "'cascgp_experiments.pooled_stats'))]; "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code, str(fresh / "results.json"), str(fresh)], check=True,
                   env=_env(), cwd=REPO, timeout=120)
    made = {p.name for p in out.iterdir() if p.is_file() and p.suffix in (".png", ".md", ".csv")}
    remade = {p.name for p in fresh.iterdir() if p.suffix in (".png", ".md", ".csv")}
    assert made and made == remade
    for name in ("table1.md", "claims.md", "curves_jaco.csv"):
        assert (fresh / name).read_text() == (out / name).read_text()


@pytest.mark.skipif(not _has_excitation(), reason="jaco_env.excitation not available yet")
def test_smoke_end_to_end(tmp_path: Path) -> None:
    out = tmp_path / "smoke"
    # the installed console script, from a folder outside the checkout
    subprocess.run([str(Path(sys.executable).with_name("cascgp")), "study", "--out", str(out), "--smoke"],
                   check=True, env=_env(), cwd=tmp_path, timeout=600)
    res = read_json(out / "results.json")
    _check_results(out, res)
    assert res["meta"]["settings"]["grid"] == [1.0, 2.0]
    assert res["meta"]["complete"] is True
    assert res["meta"]["reused"]["collection"] is False and res["meta"]["reused"]["jaco_jobs"][0] == 0
    # the default sensing, and the SP models' nominal URDF of the simulated arm's link inertials
    assert res["meta"]["collection"]["sensor_pipeline"] == "jaco2"
    # the settings' None resolved, as the data were collected
    assert (res["meta"]["collection"]["qdd_filter_used"], res["meta"]["collection"]["link_inertials_used"]) == \
        ("causal", "kinova")
    assert res["meta"]["nominal_urdf"] == "jaco2_nominal_kinova.urdf"
    for name in ("fig_jaco_np.png", "fig_jaco_sp.png", "fig_iterations.png", "fig_correlation.png",
                 "table1.md", "curves_jaco.csv"):
        assert (out / name).stat().st_size > 0
    if "sarcos" in res:
        import hashlib

        assert set(res["sarcos"]["models"]) == {"np-standard", "np-inward", "np-outward"}
        assert (out / "fig_sarcos.png").exists()
        # the block says which seed drew its subsets and which file it read (its digest, to check it)
        assert res["sarcos"]["seed"] == res["meta"]["settings"]["seed"]
        assert res["sarcos"]["file_sha256"] == hashlib.sha256(Path(res["sarcos"]["file"]).read_bytes()).hexdigest()
        # audited at the preset's fraction, as the Jaco curves (the smoke preset's 25 %: 2 of its 12 fits)
        assert res["sarcos"]["audit"]["fraction_requested"] == res["jaco"]["audit"]["fraction_requested"] == 0.25
        assert res["sarcos"]["audit"]["n_audited_fits"] >= 1
    _regenerate_from_json_alone(out, tmp_path)
    # the same command again: everything from the first run's files, said so; the timings are this run's
    again = subprocess.run([str(Path(sys.executable).with_name("cascgp")), "study", "--out", str(out), "--smoke"],
                           check=True, env=_env(), cwd=tmp_path, timeout=600, capture_output=True, text=True)
    res2 = read_json(out / "results.json")
    n_jobs = res["meta"]["reused"]["jaco_jobs"][1]
    assert res2["meta"]["reused"]["collection"] is True and res2["meta"]["reused"]["jaco_jobs"] == [n_jobs, n_jobs]
    assert res2["meta"]["reused"]["iterations"] is True
    assert res2["meta"]["timings"]["iterations_s"] < res2["iterations"]["wall_s"]  # the cached count kept its time
    assert "reused from an earlier run in this folder: the collection" in again.stdout
    assert res2["jaco"]["models"] == res["jaco"]["models"]


@pytest.mark.slow
@pytest.mark.skipif(not _has_excitation(), reason="jaco_env.excitation not available yet")
def test_quick_end_to_end(tmp_path: Path) -> None:
    """The --quick preset (about a minute); ``test_smoke_end_to_end`` is its fast sibling."""
    out = tmp_path / "quick"
    subprocess.run([sys.executable, "-m", "scripts.data_efficiency", "--out", str(out), "--quick"],
                   check=True, env=_env(), cwd=REPO, timeout=1200)
    res = read_json(out / "results.json")
    _check_results(out, res)
    assert res["meta"]["settings"]["grid"] == [1.0, 2.0, 5.0, 10.0]
    _regenerate_from_json_alone(out, tmp_path)


def test_sign_test_and_paired_comparison() -> None:
    from cascgp_experiments.claims import paired, paired_verdict, sign_test_p

    assert sign_test_p(10, 0) == pytest.approx(2 / 1024)
    assert sign_test_p(9, 1) == pytest.approx(2 * 11 / 1024)
    assert sign_test_p(5, 5) == 1.0 and sign_test_p(0, 0) == 1.0
    assert sign_test_p(3, 7) == sign_test_p(7, 3)
    # a beats b on every subset for joint 1, loses on every subset for joint 2, ties on joint 3
    S, G = 10, 3
    b = np.full((S, G, 3), 0.5)
    a = b.copy()
    a[:, :, 0] -= 0.1
    a[:, :, 1] += 0.1
    block = {"grid_s": [1.5, 4.5, 9.5], "models": {"x": {"nrmse_all": a.tolist()}, "y": {"nrmse_all": b.tolist()}}}
    c = paired(block, "x", "y")
    assert c["wins"][0] == [10, 10, 10] and c["losses"][1] == [10, 10, 10] and c["wins"][2] == [0, 0, 0]
    assert paired_verdict(c) == (3, 3, 3)


def test_identical_cells_shown_and_not_counted() -> None:
    """A cascade's chain-first joint against the standard model (or itself under the other scoring) is the same
    model: left out of the sign-test counts, the pooled statistic and the table's cascade-beats-standard count."""
    from cascgp_experiments.claims import cascade_vs_standard, paired, paired_markdown, paired_verdict
    from cascgp_experiments.pooled_stats import identical_joints, run_family

    assert identical_joints("np-inward", "np-standard", 6) == (5,)
    assert identical_joints("sp-standard-df", "sp-outward-df", 6) == (0,)
    assert identical_joints("np-inward", "np-inward", 6) == (5,)  # the two scorings
    assert identical_joints("np-inward", "np-outward", 6) == () == identical_joints("sp-inward", "np-standard", 6)
    assert identical_joints("np-inward-df", "np-standard", 6) == ()
    rng = np.random.default_rng(3)
    st = rng.uniform(0.1, 0.2, (10, 3, 3))
    inw = st * 0.9  # better on every joint and subset ...
    inw[:, :, 2] = st[:, :, 2]  # ... except the shared last joint, equal
    inw[:, 0, 2] *= 0.5  # (made unequal in one point: still not counted)
    meas = inw * 0.8
    meas[:, :, 2] = inw[:, :, 2]
    block = {"grid_s": [1.5, 4.5, 9.5], "n_subsets": 10, "models": {
        "np-standard": {"nrmse_all": st}, "np-inward": {"nrmse_all": inw, "measured": {"nrmse_all": meas}}}}
    c = paired(block, "np-inward", "np-standard")
    assert c["identical"] == [2] and c["wins"][2] == [0, 0, 0] and c["losses"][2] == [0, 0, 0]
    assert paired_verdict(c) == (6, 0, 0)  # 2 joints x 3 intervals; the shared joint not counted
    c = paired(block, "np-inward", "np-inward", a_scoring="measured")
    assert c["identical"] == [2] and paired_verdict(c) == (6, 0, 0)
    text = "\n".join(paired_markdown(block, "t"))
    assert "J3 =" in text and "better in 6, worse in 0, no significant difference in 0 of 6 cells" in text
    fam = run_family(block, ())
    assert fam == []
    from cascgp_experiments.pooled_stats import JACO_FAMILIES

    rows = run_family(block, JACO_FAMILIES["cascade vs standard (predicted neighbour torque)"])
    assert len(rows) == 3 and all(r["excluded_joints"] == [2] for r in rows)
    np.testing.assert_allclose([r["ratio"] for r in rows], 0.9)  # joint 3 left out: exactly 0.9
    assert all(r["wins"] == 10 for r in rows)
    rows_t = {m: np.asarray(v["nrmse_all"]).mean(0).T.tolist() for m, v in block["models"].items()}
    rows_t["np-outward"] = rows_t["np-standard"]
    assert list(cascade_vs_standard(rows_t, "np")) == [2, 2, 2]


def test_study_sensor_pipeline_option() -> None:
    """``--sensor-pipeline`` reaches the settings; a bad name is refused naming the field, before any work."""
    from cascgp_experiments.study import Settings

    assert Settings().sensor_pipeline == "jaco2" and Settings(sensor_pipeline="ideal").sensor_pipeline == "ideal"
    with pytest.raises(ValueError, match="sensor_pipeline: expected"):
        Settings(sensor_pipeline="real")
    r = subprocess.run([str(Path(sys.executable).with_name("cascgp")), "study", "--out", "unused", "--smoke",
                        "--sensor-pipeline", "real"], env=_env(), cwd=REPO, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 2 and "--sensor-pipeline: expected" in r.stderr
