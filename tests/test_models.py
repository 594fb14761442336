"""The twelve model variants on an analytic planar arm: learning, the cascade, the fast path,
save/load and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from cascgp.data import DynamicsData
from cascgp.features import input_dim, state_features
from cascgp.gp import GPFitConfig
from cascgp.metrics import nrmse
from cascgp.models import MODEL_NAMES, CascadedGPModel, load_model, make_model
from tests.conftest import make_arm, sinusoid_data, two_link_closed_form

FAST = GPFitConfig(n_restarts=1, max_iter=200)


def _rbd_for(name, rbd):
    return rbd if name.startswith("sp") else None


# ------------------------------------------------------------------ the test arm itself
def test_planar_newton_euler_matches_closed_form():
    arm = make_arm(2, friction=0.2)
    rng = np.random.default_rng(0)
    q, qd, qdd = (rng.normal(size=(50, 2)) for _ in range(3))
    np.testing.assert_allclose(arm.inverse_dynamics(q, qd, qdd), two_link_closed_form(arm, q, qd, qdd),
                               rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(arm.inverse_dynamics(q[3], qd[3], qdd[3]), two_link_closed_form(arm, q, qd, qdd)[3])


# ------------------------------------------------------------------ shared fitted models
@pytest.fixture(scope="module")
def interleaved(arm3):
    """20 Hz trajectory: even rows (10 Hz, 100 samples) train, odd rows test."""
    full = sinusoid_data(arm3, 10.0, 20.0, seed=1, noise=0.01)
    return full.take(np.arange(0, full.n_samples, 2)), full.take(np.arange(1, full.n_samples, 2))


@pytest.fixture(scope="module")
def fitted(interleaved, arm3_rbd):
    tr, _ = interleaved
    return {name: make_model(name, 3, _rbd_for(name, arm3_rbd), gp_config=FAST).fit(tr) for name in MODEL_NAMES}


def test_names():
    assert len(MODEL_NAMES) == 12 and len(set(MODEL_NAMES)) == 12
    assert {"np-standard", "sp-inward", "np-outward-df", "sp-outward-df"} <= set(MODEL_NAMES)


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_every_variant_learns(name, fitted, interleaved):
    tr, te = interleaved
    m = fitted[name]
    mean, var = m.predict_data(te)
    assert mean.shape == var.shape == te.tau.shape
    assert np.isfinite(mean).all() and np.isfinite(var).all() and (var >= 0).all()
    mean_only, none = m.predict_data(te, return_var=False)  # the study's scoring: the same mean, no variance
    assert none is None and np.array_equal(mean_only, mean)
    valid = state_features(te, m.feature_kind, m.df_delta)[1]
    err = nrmse(mean[valid], te.tau[valid])
    trivial = nrmse(np.broadcast_to(tr.tau.mean(0), te.tau.shape)[valid], te.tau[valid])
    assert (err < 0.25 * trivial).all(), (name, err, trivial)


def test_sp_with_true_rbd_beats_np_at_small_n(arm3, arm3_rbd):
    # 20 samples (1 Hz) of one trajectory, tested on another trajectory
    tr = sinusoid_data(arm3, 20.0, 1.0, seed=3, noise=0.01)
    te = sinusoid_data(arm3, 20.0, 10.0, seed=4)
    for structure in ("standard", "inward", "outward"):
        e = {}
        for p in ("np", "sp"):
            name = f"{p}-{structure}"
            m = make_model(name, 3, _rbd_for(name, arm3_rbd), gp_config=FAST).fit(tr)
            e[p] = nrmse(m.predict_data(te)[0], te.tau)
        assert (e["sp"] < e["np"]).all() and e["sp"].mean() < 0.5 * e["np"].mean(), (structure, e)


# ------------------------------------------------------------------ dimensions for N = 6, 7
@pytest.mark.parametrize("N", [6, 7])
@pytest.mark.parametrize("structure", ["standard", "inward", "outward"])
def test_gp_input_dimensions(N, structure):
    arm = make_arm(N)
    d = sinusoid_data(arm, 3.0, 10.0, seed=0, noise=0.01)
    m = make_model(f"np-{structure}", N, gp_config=GPFitConfig(n_restarts=1, max_iter=5)).fit(d)
    assert len(m.banks) == 1  # all joints in ONE bank (one batched fit)
    assert m.banks[0].dims == tuple(input_dim(structure, j, N) for j in range(N))
    if structure == "inward":
        assert m.banks[0].dims == tuple([3 * i + 1 for i in range(1, N)] + [3 * N])
    if structure == "outward":
        assert m.banks[0].dims == tuple([3 * N] + [3 * (N - i + 1) + 1 for i in range(2, N + 1)])


# ------------------------------------------------------------------ the cascade
@pytest.mark.parametrize("name", ["np-inward", "np-outward", "sp-inward", "sp-outward-df"])
def test_cascade_chains_predicted_torques(name, fitted, interleaved):
    tr, te = interleaved
    m = fitted[name]
    mean, _ = m.predict_data(te)
    # measured torques play no part in prediction: corrupting them changes nothing
    bad = DynamicsData(q=te.q, qd=te.qd, qdd=te.qdd, tau=te.tau * 0 + 1e3, t=te.t, segment=te.segment)
    np.testing.assert_array_equal(m.predict_data(bad)[0], mean)
    # explicit chain: joint j's GP input is the PREDICTED neighbour torque
    S, _ = state_features(te, m.feature_kind, m.df_delta)
    tau_rbd = m.rbd.inverse_dynamics(te.q, te.qd, te.qdd) if m.parametric == "sp" else np.zeros_like(te.tau)
    n_chained = 0
    for j in range(3):
        sj, tj = m.specs[j]
        if tj is None:
            continue
        n_chained += 1
        xs = S[:, list(sj)].reshape(len(te), -1)
        P = m._post[j]
        with_pred = P.predict(np.c_[xs, mean[:, tj]], return_var=False)[0] + tau_rbd[:, j]
        with_meas = P.predict(np.c_[xs, te.tau[:, tj]], return_var=False)[0] + tau_rbd[:, j]
        np.testing.assert_allclose(mean[:, j], with_pred, rtol=1e-12, atol=1e-10)
        if m.parametric == "np":  # (an SP residual GP may ignore its torque input: friction only)
            assert np.abs(mean[:, j] - with_meas).max() > 1e-6
    assert n_chained == 2
    # order: inward N -> 1, outward 1 -> N
    assert m.order == ((2, 1, 0) if m.structure == "inward" else (0, 1, 2))


def test_train_on_predicted(interleaved):
    tr, te = interleaved
    m = make_model("np-inward", 3, gp_config=FAST, train_on_predicted=True).fit(tr)
    assert len(m.banks) == 3  # fitted one joint at a time, in cascade order
    # the torque input each joint was trained on == the in-sample chained prediction of its neighbour
    pred_tr, _ = m.predict_data(tr)
    for j in range(2):
        k, b = m.where[j]
        X_train = m.banks[k].state_dict()["X"][b]
        np.testing.assert_allclose(X_train[:, -1], pred_tr[:, j + 1], rtol=1e-10, atol=1e-10)
    err = nrmse(m.predict_data(te)[0], te.tau)
    assert (err < 0.1).all()
    # standard models have no torque input: the option changes nothing
    s = make_model("np-standard", 3, gp_config=FAST, train_on_predicted=True).fit(tr)
    assert len(s.banks) == 1


def test_warm_start(fitted, interleaved):
    tr, te = interleaved
    m0 = fitted["np-inward"]
    m1 = make_model("np-inward", 3, gp_config=FAST).fit(tr, init=m0)
    assert all(fi["warm_start"] for fi in m1.fit_info)
    np.testing.assert_allclose(m1.predict_data(te)[0], m0.predict_data(te)[0], rtol=1e-4, atol=1e-4)
    with pytest.raises(ValueError, match="init"):
        make_model("np-outward", 3, gp_config=FAST).fit(tr, init=m0)


# ------------------------------------------------------------------ fast path
def _roundoff_scale(m) -> np.ndarray:
    """Per joint sum_i |a_i| with a = y_std * s_f^2 * alpha: the mean is sum_i a_i k_i, so two
    correct evaluations that differ only in round-off agree to about eps * this."""
    return np.array([np.abs(P.y_std * P.signal_var * P.alpha).sum() for P in m._post])


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_predict_one_equals_predict(name, fitted, interleaved):
    _, te = interleaved
    m = fitted[name]
    S, _ = state_features(te, "df", m.df_delta)
    q_hist = S[:, :, 1:].transpose(0, 2, 1)  # (T, 2, N)
    mean, _ = m.predict(te.q, te.qd, te.qdd, q_hist if m.feature_kind == "df" else None)
    # ~1e-10 for a well-conditioned GP (see the 6-DOF test below); an ill-conditioned optimum
    # (noise at its floor, huge signal variance, as the 1-restart fits here sometimes reach)
    # amplifies round-off by sum|a| (see _roundoff_scale), and a cascade passes a joint's
    # round-off on to the next joint: hence the tolerance uses the largest scale of all joints.
    tol = 1e-10 * (1 + np.abs(mean).max(0)) + 1e-13 * _roundoff_scale(m).max()
    for r in range(0, len(te), 7):
        one = m.predict_one(te.q[r], te.qd[r], te.qdd[r], q_hist[r] if m.feature_kind == "df" else None)
        assert (np.abs(one - mean[r]) <= tol).all(), (one - mean[r], tol)
    # single-row predict returns (N,)
    m1, v1 = m.predict(te.q[0], te.qd[0], te.qdd[0], q_hist[0] if m.feature_kind == "df" else None)
    assert m1.shape == v1.shape == (3,)


def test_predict_one_equals_predict_6dof_inward():
    """The controller's case: a 6-joint inward cascade; agreement to 1e-10 (relative) plus the round-off of the
    weighted sum (a few eps * sum|a|, about 1e-9 here: the two paths add the same terms in different orders, and
    which order a CPU's kernels take differs; one CPU measured 9e-10 on torques of about 70 and 2e-10 on one of 0.3).
    The asserted conditioning bounds that term at 16 eps * 1e7 = 3.6e-8, still far below any real disagreement."""
    arm = make_arm(6, friction=0.3)
    tr = sinusoid_data(arm, 20.0, 10.0, seed=1, noise=0.05)
    te = sinusoid_data(arm, 5.0, 10.0, seed=2)
    m = make_model("np-inward", 6, gp_config=GPFitConfig(n_restarts=1, max_iter=60)).fit(tr)
    scale = _roundoff_scale(m).max()
    assert scale < 1e7  # well conditioned
    mean, _ = m.predict(te.q, te.qd, te.qdd)
    one = np.array([m.predict_one(te.q[r], te.qd[r], te.qdd[r]) for r in range(len(te))])
    np.testing.assert_allclose(one, mean, rtol=1e-10, atol=16 * np.finfo(float).eps * scale)


@pytest.mark.parametrize("name", ["np-inward", "sp-outward", "np-standard-df"])
def test_never_nan_for_extreme_finite_inputs(name, fitted):
    m = fitted[name]
    for scale in (1e3, 1e12, 1e200):
        x = np.array([scale, -scale, 0.5 * scale])
        h = np.stack([x, -x])
        if m.parametric == "sp":
            continue  # the RBD itself is not defined for such inputs
        mean, var = m.predict(x, x, x, h)
        one = m.predict_one(x, x, x, h)
        assert np.isfinite(mean).all() and np.isfinite(var).all() and np.isfinite(one).all()
        np.testing.assert_allclose(one, mean, rtol=1e-9, atol=1e-9)
    x = np.array([5.0, -7.0, 9.0])
    assert np.isfinite(m.predict_one(x, x, x, np.stack([x, x]))).all()


# ------------------------------------------------------------------ save / load
@pytest.mark.parametrize("name", MODEL_NAMES)
def test_save_load_identical(name, fitted, interleaved, arm3_rbd, tmp_path):
    _, te = interleaved
    m = fitted[name]
    p = m.save(tmp_path / "m.npz")
    m2 = load_model(p, rbd=_rbd_for(name, arm3_rbd))
    assert (m2.name, m2.dof, m2.df_delta, m2.n_train) == (m.name, m.dof, m.df_delta, m.n_train)
    a, b = m.predict_data(te), m2.predict_data(te)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    x = te.q[3], te.qd[3], te.qdd[3], np.stack([te.q[2], te.q[1]])
    np.testing.assert_array_equal(m.predict_one(*x), m2.predict_one(*x))


def test_load_errors(fitted, arm3_rbd, tmp_path):
    m = fitted["np-inward"]
    p = m.save(tmp_path / "m.npz")
    raw = p.read_bytes()
    (tmp_path / "trunc.npz").write_bytes(raw[: len(raw) // 3])
    with pytest.raises(ValueError, match="trunc.npz.*corrupt or truncated"):
        load_model(tmp_path / "trunc.npz")
    bad = bytearray(raw)
    i = raw.index(b"bank0/theta.npy") + 150
    bad[i] ^= 0x55
    (tmp_path / "flip.npz").write_bytes(bytes(bad))
    with pytest.raises(ValueError, match="flip.npz"):
        load_model(tmp_path / "flip.npz")
    with pytest.raises(FileNotFoundError):
        load_model(tmp_path / "missing.npz")
    z = dict(np.load(p))
    z["format_version"] = np.array(7)
    np.savez(tmp_path / "v7.npz", **z)
    with pytest.raises(ValueError, match="format_version"):
        load_model(tmp_path / "v7.npz")
    # consistent-looking but altered content (hyperparameter changed): check predictions catch it
    z = dict(np.load(p))
    z["bank0/theta"] = z["bank0/theta"] + 0.01
    np.savez(tmp_path / "alt.npz", **z)
    with pytest.raises(ValueError, match="check predictions"):
        load_model(tmp_path / "alt.npz")
    # the file records the version that wrote it; a file without it (written before it was recorded) loads
    import json

    import cascgp
    from cascgp.models.io import saved_config

    assert saved_config(p)["cascgp_version"] == cascgp.__version__ and saved_config(p)["name"] == "np-inward"
    z = dict(np.load(p))
    z["config_json"] = np.array(json.dumps({k: v for k, v in json.loads(str(z["config_json"])).items()
                                            if k != "cascgp_version"}))
    np.savez(tmp_path / "older.npz", **z)
    assert load_model(tmp_path / "older.npz").name == "np-inward" and "cascgp_version" not in saved_config(
        tmp_path / "older.npz")
    # provenance given at save time is stored as given and read back; one JSON cannot write is refused, no file written
    told = {"data": {"file": "train.csv", "sha256": "ab" * 32, "n_rows": 600}, "command": ["fit", "--seed", "0"]}
    fitted["np-inward"].save(tmp_path / "told.npz", provenance=told)
    assert saved_config(tmp_path / "told.npz")["provenance"] == told and "provenance" not in saved_config(p)
    assert load_model(tmp_path / "told.npz").name == "np-inward"
    for bad, match in (([1, 2], "provenance: expected a mapping"), ({"x": float("nan")}, "provenance: .*finite"),
                       ({1: "a"}, "provenance: .*strings, got 1"), ({"x": object()}, "provenance: .*object")):
        with pytest.raises(TypeError, match=match):
            fitted["np-inward"].save(tmp_path / "bad.npz", provenance=bad)
        assert not (tmp_path / "bad.npz").exists()
    # another machine's BLAS kernels round differently: a relative 1e-7 in the stored check means (several hundred
    # times the round-off measured across thread counts and MKL's code paths) still loads; 1e-4 does not
    for rel, loads in ((1e-7, True), (1e-4, False)):
        z = dict(np.load(p))
        z["check/mean"] = z["check/mean"] * (1 + rel) + rel
        np.savez(tmp_path / "roundoff.npz", **z)
        if loads:
            load_model(tmp_path / "roundoff.npz")
        else:
            with pytest.raises(ValueError, match="check predictions"):
                load_model(tmp_path / "roundoff.npz")
    z = dict(np.load(p))
    del z["bank0/X"]
    np.savez(tmp_path / "nox.npz", **z)
    with pytest.raises(ValueError, match="X"):
        load_model(tmp_path / "nox.npz")
    # n_banks / n_train fields that are wrong in kind: a ValueError naming the file, not an IndexError/TypeError
    import json

    for field, value, match in (("n_banks", 0, "n_banks"), ("n_train", None, "nbank.npz")):
        z = dict(np.load(p))
        cfg = json.loads(str(z["config_json"]))
        cfg[field] = value
        z["config_json"] = np.array(json.dumps(cfg))
        np.savez(tmp_path / "nbank.npz", **z)
        with pytest.raises(ValueError, match=match):
            load_model(tmp_path / "nbank.npz")
    DynamicsData(q=np.zeros((2, 1)), qd=np.zeros((2, 1)), qdd=np.zeros((2, 1)), tau=np.zeros((2, 1)),
                 t=[0, 1]).save(tmp_path / "data.npz")
    with pytest.raises(ValueError, match="format_kind"):
        load_model(tmp_path / "data.npz")
    with pytest.raises(ValueError, match="data.npz.*format_kind"):
        saved_config(tmp_path / "data.npz")
    # SP: the RBD is needed, and a different one is detected
    sp = fitted["sp-inward"]
    ps = sp.save(tmp_path / "sp.npz")
    with pytest.raises(ValueError, match="rbd"):
        load_model(ps)
    other = make_arm(3, friction=0.0)
    other.m = other.m * 1.1
    with pytest.raises(ValueError, match="rigid-body model"):
        load_model(ps, rbd=other)
    with pytest.raises(ValueError, match="DOF mismatch"):
        load_model(ps, rbd=make_arm(2))


def test_sp_with_urdf_rbd_reloads_from_source(tmp_path):
    from pathlib import Path

    from cascgp.rbd import load_nominal

    urdf = Path(__file__).resolve().parents[1] / "jaco_env" / "assets" / "jaco2_nominal.urdf"
    if not urdf.exists():
        pytest.skip("jaco_env/assets/jaco2_nominal.urdf not generated")
    rbd = load_nominal(urdf)
    rng = np.random.default_rng(0)
    T = 30
    q, qd, qdd = rng.normal(size=(T, 6)), rng.normal(size=(T, 6)), rng.normal(size=(T, 6))
    tau = rbd.inverse_dynamics(q, qd, qdd) + 0.1 * np.sin(q)
    d = DynamicsData(q=q, qd=qd, qdd=qdd, tau=tau, t=np.arange(T) * 0.1)
    m = make_model("sp-inward", 6, rbd, gp_config=GPFitConfig(n_restarts=1, max_iter=30)).fit(d)
    p = m.save(tmp_path / "sp.npz")
    m2 = load_model(p)  # RBD rebuilt from the recorded URDF + sidecar
    np.testing.assert_array_equal(m2.predict(q, qd, qdd)[0], m.predict(q, qd, qdd)[0])
    with pytest.raises(ValueError, match="DOF mismatch"):
        make_model("sp-inward", 7, rbd)


# ------------------------------------------------------------------ bad input
def test_construction_errors(arm3_rbd):
    with pytest.raises(ValueError, match="name"):
        make_model("np-sideways", 3)
    with pytest.raises(ValueError, match="rbd"):
        make_model("sp-inward", 3)
    with pytest.raises(ValueError, match="DOF mismatch"):
        make_model("sp-standard", 4, arm3_rbd)
    with pytest.raises(TypeError, match="rbd"):
        make_model("sp-standard", 3, object())
    with pytest.raises(ValueError, match="dof"):
        make_model("np-standard", 0)
    with pytest.raises(TypeError, match="gp_config"):
        make_model("np-standard", 3, gp_config={"n_restarts": 1})
    with pytest.raises(ValueError, match="df_delta"):
        make_model("np-standard-df", 3, df_delta=0.0)
    with pytest.raises(RuntimeError, match="not fitted"):
        make_model("np-standard", 3).predict(np.zeros(3), np.zeros(3), np.zeros(3))
    for one in ("predict_one", "predict_one_var"):  # predict_one raised AttributeError on None before
        with pytest.raises(RuntimeError, match="not fitted"):
            getattr(make_model("np-standard", 3), one)(np.zeros(3), np.zeros(3), np.zeros(3))
    assert isinstance(make_model("np-standard", 3, arm3_rbd), CascadedGPModel)  # rbd ignored for NP


def test_fit_errors(interleaved):
    tr, _ = interleaved
    m = make_model("np-inward", 3, gp_config=FAST)
    with pytest.raises(ValueError, match="DOF mismatch"):
        m.fit(sinusoid_data(make_arm(2), 5.0, 10.0, seed=0))
    with pytest.raises(TypeError, match="data"):
        m.fit(tr.q)
    with pytest.raises(ValueError, match="at least 2"):
        m.fit(tr.take([0]))  # a single sample
    with pytest.raises(ValueError, match="at least 2"):
        make_model("np-inward-df", 3, gp_config=FAST).fit(tr.take(np.arange(2)))  # no row has history
    # (empty data sets cannot even be built: DynamicsData refuses T = 0, see test_data.py)


def test_query_errors(fitted):
    m = fitted["np-inward"]
    q = np.zeros(3)
    bad = np.array([0.0, np.nan, 0.0])
    with pytest.raises(ValueError, match="qd.*row 0"):
        m.predict(q, bad, q)
    with pytest.raises(ValueError, match="non-finite"):
        m.predict_one(q, q, np.array([np.inf, 0, 0]))
    with pytest.raises(ValueError, match="q: expected shape"):
        m.predict(np.zeros((5, 4)), np.zeros((5, 4)), np.zeros((5, 4)))
    with pytest.raises(ValueError, match="q: expected shape"):
        m.predict_one(np.zeros(4), np.zeros(4), np.zeros(4))
    with pytest.raises(ValueError, match="qdd: expected 5 rows"):
        m.predict(np.zeros((5, 3)), np.zeros((5, 3)), np.zeros((4, 3)))
    with pytest.raises(ValueError, match=r"^q: expected at least one row, got shape \(0, 3\)$"):  # said "(T, 3)"
        m.predict(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)))
    with pytest.raises(ValueError, match="qd/qdd"):
        m.predict(q)
    df = fitted["np-inward-df"]
    with pytest.raises(ValueError, match="q_hist"):
        df.predict(q)
    with pytest.raises(ValueError, match="q_hist"):
        df.predict_one(q, q_hist=np.zeros((3, 3)))
    assert df.predict(q, q_hist=np.zeros((2, 3)))[0].shape == (3,)  # NP-df needs no qd/qdd
    with pytest.raises(ValueError, match="DOF mismatch"):
        m.predict_data(sinusoid_data(make_arm(2), 5.0, 10.0, seed=0))


def test_duplicated_samples_and_constant_targets(interleaved):
    tr, te = interleaved
    # every sample twice (a second segment): fits, finite, still accurate
    dup = DynamicsData.concat([tr, tr])
    m = make_model("np-inward", 3, gp_config=FAST).fit(dup)
    assert m.n_train == 2 * tr.n_samples
    mean = m.predict_data(te)[0]
    assert np.isfinite(mean).all() and (nrmse(mean, te.tau) < 0.1).all()
    # a joint with constant torque: predicted as that constant, other joints unaffected
    tau = tr.tau.copy()
    tau[:, 2] = 1.5
    const = DynamicsData(q=tr.q, qd=tr.qd, qdd=tr.qdd, tau=tau, t=tr.t, segment=tr.segment)
    mc = make_model("np-inward", 3, gp_config=FAST).fit(const)
    pc = mc.predict_data(te)[0]
    np.testing.assert_allclose(pc[:, 2], 1.5, atol=1e-9)
    assert np.isfinite(pc).all()
    assert mc.fit_info[2]["constant_target"]


def test_df_warns_when_data_is_coarser_than_delta(arm3):
    d = sinusoid_data(arm3, 10.0, 5.0, seed=0, noise=0.01)  # dt = 0.2 s > df_delta = 0.1 s
    with pytest.warns(UserWarning, match="df_delta"):
        make_model("np-standard-df", 3, gp_config=GPFitConfig(n_restarts=1, max_iter=5)).fit(d)


def test_package_exports():
    import cascgp

    assert cascgp.make_model is make_model and cascgp.MODEL_NAMES == MODEL_NAMES
    assert cascgp.DynamicsData is DynamicsData and callable(cascgp.nrmse) and callable(cascgp.load_ias)
    with pytest.raises(AttributeError):
        cascgp.nope  # noqa: B018


def test_adopt_banks_refuses_banks_of_different_sizes_and_changes_nothing(arm3_train):
    """Banks whose GPs hold different numbers of rows (a crafted file) are refused before anything changes."""
    from cascgp.gp import GPFitConfig

    cfg = GPFitConfig(n_restarts=1, max_iter=10)
    a = make_model("np-inward", 3, gp_config=cfg).fit(arm3_train.take(np.arange(40)))
    b = make_model("np-inward", 3, gp_config=cfg).fit(arm3_train.take(np.arange(50)))
    query = (arm3_train.q[3], arm3_train.qd[3], arm3_train.qdd[3])
    before, banks, where = a.predict_one(*query), list(a.banks), list(a.where)
    with pytest.raises(ValueError, match="different numbers of training rows"):
        a.adopt_banks([a.banks[0], b.banks[0]], [(0, 0), (1, 1), (0, 2)], 40)
    assert a.banks == banks and a.where == where and a.n_train == 40
    np.testing.assert_array_equal(a.predict_one(*query), before)


def test_adopt_banks_refuses_a_row_count_other_than_the_banks(arm3_train):
    """``n_train`` must be the banks' number of rows (a file's ``config_json.n_train`` of -5 was accepted)."""
    from cascgp.gp import GPFitConfig

    a = make_model("np-inward", 3, gp_config=GPFitConfig(n_restarts=1, max_iter=10)).fit(arm3_train.take(np.arange(40)))
    banks, where = list(a.banks), list(a.where)
    for bad in (-5, 39, 40.0, True, "40"):
        with pytest.raises(ValueError, match=r"^n_train: expected the banks' number of training rows \(40\), got "):
            a.adopt_banks(banks, where, bad)
    assert a.n_train == 40
    a.adopt_banks(banks, where, np.int64(40))
    assert a.n_train == 40 and type(a.n_train) is int
