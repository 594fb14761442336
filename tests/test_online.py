"""Learning inside an episode (issue 10, item 3): block-factor updates equal the closed-form GP on the enlarged
set with the hyperparameters held, the window drops the oldest samples, and bad samples change nothing."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from cascgp.features import states_from_arrays
from cascgp.gp import GPFitConfig
from cascgp.gp.kernels import get_kernel
from cascgp.models import make_model
from cascgp.models.fastkernel import JIT_WT
from tests.conftest import make_arm, sinusoid_data


def _closed_form(model, extra, q, qd, qdd):
    """Mean and propagated variance at one query from each joint's GP refactorised from scratch on its fitted
    set plus the online samples ``extra`` (list of (q, qd, qdd, tau)), hyperparameters held."""
    posts = model.posteriors()
    Sx = [states_from_arrays("db", e[0][None], e[1][None], e[2][None], None).reshape(-1) for e in extra]
    S = states_from_arrays("db", q[None], qd[None], qdd[None], None).reshape(-1)
    rbd = (lambda a, b, c: model.rbd.inverse_dynamics(a, b, c)) if model.parametric == "sp" else \
        (lambda a, b, c: np.zeros(model.dof))
    mean, var = np.zeros(model.dof), np.zeros(model.dof)
    for j in model.order:
        P = posts[j]
        sj, tj = model.specs[j]
        cols = np.concatenate([[3 * s, 3 * s + 1, 3 * s + 2] for s in sj])

        def norm(x, P=P):
            return np.where(np.isfinite(P.x_scale), (x - P.x_mean) / P.x_scale, 0.0)

        Zw = np.array([norm(np.append(Sx[i][cols], e[3][tj]) if tj is not None else Sx[i][cols])
                       for i, e in enumerate(extra)]).reshape(len(extra), -1)
        yw = np.array([(e[3][j] - rbd(e[0], e[1], e[2])[j] - P.y_mean) / P.y_std for e in extra])
        Z = np.vstack([P.Z, Zw])
        y0 = P.L @ (P.L.T @ P.alpha)
        y = np.concatenate([y0, yw])
        k = get_kernel(P.kernel)
        K = P.signal_var * k.value(((Z[:, None] - Z[None]) ** 2).sum(-1)) + (P.noise_var + P.jitter) * np.eye(len(Z))
        xq = np.append(S[cols], mean[tj]) if tj is not None else S[cols]
        zq = norm(xq)
        ks = P.signal_var * k.value(((zq - Z) ** 2).sum(-1))
        alpha = np.linalg.solve(K, y)
        mean[j] = P.y_mean + P.y_std * ks @ alpha + rbd(q, qd, qdd)[j]
        v = P.signal_var - ks @ np.linalg.solve(K, ks)
        if tj is not None:
            dk = k.grad_r2(((zq - Z) ** 2).sum(-1)) * 2 * (zq[-1] - Z[:, -1])
            g = P.y_std * P.signal_var * (dk @ alpha) / P.x_scale[-1]
            var[j] = v * P.y_std**2 + g * g * var[tj]
        else:
            var[j] = v * P.y_std**2
    return mean, var


@pytest.mark.parametrize("name", ["np-inward", "sp-outward", "np-standard", "matern32:sp-outward"])
def test_online_samples_equal_the_closed_form_gp_and_the_window_drops_the_oldest(name: str) -> None:
    kernel, _, name = name.rpartition(":")
    arm = make_arm(3, friction=0.3)
    train = sinusoid_data(arm, 4.0, 10.0, seed=1, noise=0.02)
    model = make_model(name, 3, make_arm(3) if name.startswith("sp") else None,
                       gp_config=GPFitConfig(kernel=kernel or "matern52", n_restarts=1, max_iter=40)).fit(train)
    new = sinusoid_data(make_arm(3, friction=0.8), 1.2, 10.0, seed=7, noise=0.02)  # another robot: new data
    samples = [(new.q[i], new.qd[i], new.qdd[i], new.tau[i]) for i in range(new.n_samples)]
    model.start_online(window=5)
    query = (new.q[3] + 0.01, new.qd[3], new.qdd[3])
    for i, s in enumerate(samples[:8]):
        model.add_sample(*s)
        kept = samples[max(0, i + 1 - 5): i + 1]
        m_ref, v_ref = _closed_form(model, kept, *query)
        m1 = model.predict_one(*query)
        m2, v2 = model.predict_one_var(*query)
        np.testing.assert_allclose(m1, m_ref, rtol=1e-7, atol=1e-7)
        np.testing.assert_allclose(m2, m_ref, rtol=1e-7, atol=1e-7)
        np.testing.assert_allclose(v2, v_ref, rtol=1e-5, atol=1e-9)
    assert model.n_online == 8


def test_many_samples_through_a_small_window_stay_equal_to_the_closed_form_gp() -> None:
    """The rank-one updates of the window's inverse (and its recomputation once per window length) keep the
    weights and variances equal to a refactorised GP after the window has turned over many times."""
    arm = make_arm(3, friction=0.3)
    model = make_model("sp-inward", 3, make_arm(3), gp_config=GPFitConfig(n_restarts=1, max_iter=40)).fit(
        sinusoid_data(arm, 4.0, 10.0, seed=1, noise=0.02))
    new = sinusoid_data(make_arm(3, friction=0.8), 4.0, 10.0, seed=11, noise=0.02)
    samples = [(new.q[i], new.qd[i], new.qdd[i], new.tau[i]) for i in range(new.n_samples)]
    model.start_online(window=4)
    query = (new.q[5] + 0.01, new.qd[5], new.qdd[5])
    for i, s in enumerate(samples[:31]):
        model.add_sample(*s)
        if i % 5 == 0 or i >= 28:
            m_ref, v_ref = _closed_form(model, samples[max(0, i - 3): i + 1], *query)
            m2, v2 = model.predict_one_var(*query)
            np.testing.assert_allclose(model.predict_one(*query), m_ref, rtol=1e-7, atol=1e-7)
            np.testing.assert_allclose(m2, m_ref, rtol=1e-7, atol=1e-7)
            np.testing.assert_allclose(v2, v_ref, rtol=1e-5, atol=1e-9)


def test_online_learning_moves_the_prediction_toward_new_data_and_refit_resets_it() -> None:
    arm = make_arm(3, friction=0.3)
    model = make_model("np-inward", 3, gp_config=GPFitConfig(n_restarts=1, max_iter=40)).fit(
        sinusoid_data(arm, 4.0, 10.0, seed=1, noise=0.02))
    other = make_arm(3, friction=2.0)
    new = sinusoid_data(other, 3.0, 10.0, seed=3)
    before = np.array([model.predict_one(new.q[i], new.qd[i], new.qdd[i]) for i in range(new.n_samples)])
    model.start_online(window=40)
    for i in range(0, new.n_samples, 2):
        model.add_sample(new.q[i], new.qd[i], new.qdd[i], new.tau[i])
    after = np.array([model.predict_one(new.q[i], new.qd[i], new.qdd[i]) for i in range(1, new.n_samples, 2)])
    err_before = np.abs(before[1::2] - new.tau[1::2]).mean()
    err_after = np.abs(after - new.tau[1::2]).mean()
    assert err_after < 0.5 * err_before
    model.fit(sinusoid_data(arm, 4.0, 10.0, seed=1, noise=0.02))
    assert model.n_online == 0
    np.testing.assert_allclose(model.predict_one(new.q[1], new.qd[1], new.qdd[1]), before[1], rtol=1e-9)


def test_bad_samples_are_refused_and_change_nothing() -> None:
    arm = make_arm(2)
    d = sinusoid_data(arm, 3.0, 10.0, seed=1)
    model = make_model("np-inward", 2, gp_config=GPFitConfig(n_restarts=1, max_iter=20)).fit(d)
    with pytest.raises(RuntimeError, match="start_online"):
        model.add_sample(d.q[0], d.qd[0], d.qdd[0], d.tau[0])
    model.start_online(window=3)
    ref = model.predict_one(d.q[1], d.qd[1], d.qdd[1])
    for bad in (np.array([np.nan, 0.0]), np.array([1e200, 0.0]), np.zeros(3), np.array([1j, 0])):
        with pytest.raises((ValueError, TypeError), match="tau"):
            model.add_sample(d.q[0], d.qd[0], d.qdd[0], bad)
    np.testing.assert_array_equal(model.predict_one(d.q[1], d.qd[1], d.qdd[1]), ref)
    assert model.n_online == 0
    with pytest.raises(ValueError, match="window"):
        model.start_online(window=0)
    model.add_sample(d.q[0], d.qd[0], d.qdd[0], d.tau[0])
    ref = model.predict_one(d.q[1], d.qd[1], d.qdd[1])
    with pytest.raises(ValueError, match=r"^window: 10000000 samples per joint would need about .* GB, more than"):
        model.start_online(window=10**7)  # NumPy's MemoryError before; the open window is kept
    assert model.n_online == 1
    np.testing.assert_array_equal(model.predict_one(d.q[1], d.qd[1], d.qdd[1]), ref)
    df = make_model("np-inward-df", 2, gp_config=GPFitConfig(n_restarts=1, max_iter=20)).fit(d)
    with pytest.raises(ValueError, match="derivative-based"):
        df.start_online()


@pytest.mark.parametrize("name", ["sp-inward", "np-standard"])
def test_stop_online_restores_the_fitted_model_exactly(name: str) -> None:
    """After stop_online, mean and propagated variance are the fitted model's again, bit for bit; a second stop
    and a stop without a window change nothing; add_sample needs a new start_online."""
    arm = make_arm(3, friction=0.3)
    model = make_model(name, 3, make_arm(3) if name.startswith("sp") else None,
                       gp_config=GPFitConfig(n_restarts=1, max_iter=30)).fit(sinusoid_data(arm, 3.0, 10.0, seed=1))
    new = sinusoid_data(make_arm(3, friction=2.0), 1.0, 10.0, seed=5)
    query = (new.q[2], new.qd[2], new.qdd[2])
    model.stop_online()  # no window: nothing to do
    mean0, (m0, v0) = model.predict_one(*query), model.predict_one_var(*query)
    model.start_online(window=6)
    for i in range(0, new.n_samples, 2):
        model.add_sample(new.q[i], new.qd[i], new.qdd[i], new.tau[i])
    assert model.n_online > 0
    assert not np.allclose(model.predict_one(*query), mean0)
    assert not np.allclose(model.predict_one_var(*query)[1], v0)
    for _ in range(2):
        model.stop_online()
        assert model.n_online == 0
        np.testing.assert_array_equal(model.predict_one(*query), mean0)
        m1, v1 = model.predict_one_var(*query)
        np.testing.assert_array_equal(m1, m0)
        np.testing.assert_allclose(v1, v0, rtol=1e-12, atol=0)
    with pytest.raises(RuntimeError, match="start_online"):
        model.add_sample(*query, new.tau[2])


@pytest.mark.parametrize("path", ["numpy", "compiled"])
def test_a_sample_refused_by_one_joint_changes_no_joint(path: str) -> None:
    """If one joint's window update fails (here forced on the second joint, with a full window, so that the
    oldest sample would have been dropped), the sample enters no joint: mean, variance and count unchanged,
    and the model goes on exactly as one that never saw it; on either path of the sample."""
    arm = make_arm(3, friction=0.3)
    model = make_model("np-inward", 3, gp_config=GPFitConfig(n_restarts=1, max_iter=30)).fit(
        sinusoid_data(arm, 3.0, 10.0, seed=1))
    new = sinusoid_data(make_arm(3, friction=2.0), 1.0, 10.0, seed=5)
    query = (new.q[1], new.qd[1], new.qdd[1])
    model.start_online(window=3)
    _use_path(model, path)
    for i in range(3):
        model.add_sample(new.q[i], new.qd[i], new.qdd[i], new.tau[i])
    twin = copy.deepcopy(model)
    mean0, var0 = model.predict_one_var(*query)
    J = model._online.joints[1]
    noise, J.noise = J.noise, -1e6  # the new sample's Schur complement on joint 1 is then negative
    with pytest.raises(np.linalg.LinAlgError, match="not positive definite"):
        model.add_sample(new.q[5], new.qd[5], new.qdd[5], new.tau[5])
    J.noise = noise
    assert model.n_online == 3
    mean1, var1 = model.predict_one_var(*query)
    np.testing.assert_array_equal(mean1, mean0)
    np.testing.assert_array_equal(var1, var0)
    for m in (model, twin):
        m.add_sample(new.q[6], new.qd[6], new.qdd[6], new.tau[6])
    np.testing.assert_array_equal(model.predict_one(*query), twin.predict_one(*query))
    np.testing.assert_array_equal(model.predict_one_var(*query)[1], twin.predict_one_var(*query)[1])


@pytest.mark.parametrize("path", ["numpy", "compiled"])
def test_an_sp_sample_whose_rigid_body_torque_is_huge_is_refused(path: str) -> None:
    """An SP model's online target is the measured torque minus the rigid-body torque: a finite but absurd
    velocity (a sensor fault) makes that torque huge, and the target is held to the fitted targets' rule
    (squares must not overflow). Such samples entered the window and turned later predictions into NaN; now
    they are refused naming ``tau`` and change nothing, and predictions stay finite."""
    arm = make_arm(2)
    d = sinusoid_data(arm, 3.0, 10.0, seed=1)
    model = make_model("sp-inward", 2, arm, gp_config=GPFitConfig(n_restarts=1, max_iter=20)).fit(d)
    model.start_online(window=5)
    _use_path(model, path)
    query = (d.q[1], d.qd[1], d.qdd[1])
    ref = model.predict_one(*query)
    qd = d.qd[0] + np.array([0.0, 1e153])  # finite, within the inputs' own rule; its Coriolis torque is ~1e305
    assert not np.abs(arm.inverse_dynamics(d.q[0], qd, d.qdd[0])).max() < 1e200
    for k in range(2):
        with pytest.raises(ValueError, match=r"^tau \(minus the rigid-body torque: the sample's target\): values too "
                                             r"large"):
            model.add_sample(d.q[0] + 0.01 * k, qd, d.qdd[0], d.tau[0])
    assert model.n_online == 0
    np.testing.assert_array_equal(model.predict_one(*query), ref)
    model.add_sample(d.q[0], d.qd[0], d.qdd[0], d.tau[0])  # a good sample still enters
    assert model.n_online == 1 and np.isfinite(model.predict_one(*query)).all()


@pytest.mark.parametrize("how", ["deepcopy", "pickle"])
def test_a_copied_window_runs_on_its_own_arrays(how: str) -> None:
    """The compiled paths gather the window's arrays once; a copy (``deepcopy``, or pickled and loaded) gathers
    its own, so that it goes on exactly as the original through samples and the periodic recomputation, and the
    two never share memory."""
    import pickle

    arm = make_arm(3, friction=0.3)
    model = make_model("sp-inward", 3, make_arm(3), gp_config=GPFitConfig(n_restarts=1, max_iter=30)).fit(
        sinusoid_data(arm, 3.0, 10.0, seed=1))
    new = sinusoid_data(make_arm(3, friction=2.0), 1.5, 10.0, seed=5)
    model.start_online(window=3)
    for i in range(2):
        model.add_sample(new.q[i], new.qd[i], new.qdd[i], new.tau[i])
    model.predict_one_var(new.q[0], new.qd[0], new.qdd[0])  # the variance's arrays are gathered too
    twin = copy.deepcopy(model) if how == "deepcopy" else pickle.loads(pickle.dumps(model))
    for i in range(2, 9):  # through two recomputations of the window's inverse (at 3 and 6 samples)
        for m in (model, twin):
            m.add_sample(new.q[i], new.qd[i], new.qdd[i], new.tau[i])
        query = (new.q[i] + 0.01, new.qd[i], new.qdd[i])
        np.testing.assert_array_equal(model.predict_one(*query), twin.predict_one(*query))
        np.testing.assert_array_equal(model.predict_one_var(*query)[1], twin.predict_one_var(*query)[1])
    for J, T in zip(model._online.joints, twin._online.joints):
        np.testing.assert_array_equal(J.Sinv, T.Sinv)
    if model._online._jit is not None:  # the gathered views are the copy's own arrays, not the original's
        for a, b in zip(model._online._arrays()["ST"], twin._online._arrays()["ST"]):
            assert not np.shares_memory(a, b)
        assert all(np.shares_memory(a, T.Sinv) for a, T in zip(twin._online._arrays()["ST"], twin._online.joints))


def _use_path(model, path: str) -> None:
    """Run the open window's samples on the NumPy path, or check that they run compiled (skip without Numba)."""
    if path == "numpy":
        model._online._jit = None
    elif model._online._jit is None:
        pytest.skip("the compiled online sample needs numba (the fast extra) and CASCGP_JIT not 0")


@pytest.mark.parametrize("name", ["np-inward", "sp-outward", "np-standard", "sp-inward", "matern32:sp-outward",
                                  "rbf:np-inward"])
def test_compiled_and_numpy_samples_agree_as_the_window_turns_over(name: str) -> None:
    """The compiled sample (:mod:`cascgp.models.online_kernel`) and the NumPy path keep the same window (its
    inverse, weights, rows, the fast path's rows) to round-off through fills, drops and the periodic
    recomputation, and give the same predictions."""
    kernel, _, name = name.rpartition(":")
    arm = make_arm(3, friction=0.3)
    model = make_model(name, 3, make_arm(3) if name.startswith("sp") else None,
                       gp_config=GPFitConfig(kernel=kernel or "matern52", n_restarts=1, max_iter=30)).fit(
        sinusoid_data(arm, 3.0, 10.0, seed=1))
    new = sinusoid_data(make_arm(3, friction=0.8), 3.0, 10.0, seed=13, noise=0.02)
    model.start_online(window=4)
    _use_path(model, "compiled")
    ref = copy.deepcopy(model)
    _use_path(ref, "numpy")
    query = (new.q[2] + 0.01, new.qd[2], new.qdd[2])
    # The two paths' kernel rows differ in the last bits (exp, dot products); the solves with the fitted factor
    # carry that as round-off times the condition number of K00 (about 2e7 for these fits).
    rel = [64 * np.finfo(float).eps * np.linalg.cond(P.L @ P.L.T) for P in model.posteriors()]

    def close(a, b, rel, what):
        np.testing.assert_allclose(a, b, rtol=rel, atol=rel * float(np.abs(b).max()), err_msg=what)

    far = (1e9 * new.q[11], 1e9 * new.qd[11], new.qdd[11], new.tau[11])  # normalised inputs beyond the clip
    names = ("Zw", "B", "Lw0", "S", "Sinv", "r", "alphaw", "alpha0")
    held = [[getattr(J, nm) for nm in names] for m in (model, ref) for J in m._online.joints]
    for i in range(12):  # fills the window, drops the oldest, recomputes its inverse twice (at 4 and 8)
        sample = far if i == 11 else (new.q[i], new.qd[i], new.qdd[i], new.tau[i])
        for m in (model, ref):
            m.add_sample(*sample)
        # both paths write into the window's arrays, never replace them (the compiled paths hold them)
        assert all(a is getattr(J, nm) for m, arrays in zip((model, ref), (held[:3], held[3:]))
                   for J, row in zip(m._online.joints, arrays) for nm, a in zip(names, row))
        f, g = model._online.fast, ref._online.fast
        for j, (J, R) in enumerate(zip(model._online.joints, ref._online.joints)):
            assert (J.m, J.n_in) == (R.m, R.n_in)
            np.testing.assert_array_equal(J.Zw, R.Zw)  # the same normalisation and clipping, bit for bit
            for nm in ("B", "Lw0", "S", "r", "alphaw", "alpha0"):
                close(getattr(J, nm), getattr(R, nm), rel[j], nm)
            close(np.tril(J.Sinv), np.tril(R.Sinv), rel[j], "Sinv")
            scale = J.P.y_std * J.P.signal_var  # the fast path's weights are the window's, also after a recompute
            np.testing.assert_array_equal(f.alpha[j], np.concatenate([J.alpha0, J.alphaw]) * scale)
        for nm in ("W", "Zt"):
            np.testing.assert_array_equal(getattr(f, nm), getattr(g, nm), err_msg=nm)
        close(f.W2, g.W2, max(rel), "W2")
        np.testing.assert_array_equal(f.jit[JIT_WT], f.W.transpose(0, 2, 1))  # the compiled mean's copy kept equal
        if i == 11:
            break
        m1, v1 = model.predict_one_var(*query)
        m2, v2 = ref.predict_one_var(*query)
        np.testing.assert_allclose(m1, m2, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(v1, v2, rtol=1e-8, atol=1e-12)
        np.testing.assert_allclose(model.predict_one(*query), m2, rtol=1e-9, atol=1e-9)
    zlim = model._online.fast.zclip / model._online.c
    assert any(np.abs(J.Zw).max() == zlim for J in model._online.joints)  # the far sample was clipped
    assert model.n_online == ref.n_online == 12


def _small_np_inward():
    """A quickly fitted 3-joint NP inward cascade (the fallback tests' model)."""
    return make_model("np-inward", 3, gp_config=GPFitConfig(n_restarts=1, max_iter=20)).fit(
        sinusoid_data(make_arm(3), 2.0, 10.0, seed=1))


def _opens_on_the_numpy_path_with_a_warning(model):
    """Open a window that warns and runs the NumPy path; one sample enters it. Returns the samples' motion."""
    with pytest.warns(RuntimeWarning, match="compiled online sample is not used"):
        model.start_online(window=3)
    assert model._online._jit is None
    new = sinusoid_data(make_arm(3, friction=0.8), 1.0, 10.0, seed=3)  # another arm
    model.add_sample(new.q[0], new.qd[0], new.qdd[0], new.tau[0])
    assert model.n_online == 1
    return new


def test_a_compiled_sample_that_fails_to_build_leaves_the_numpy_path(monkeypatch) -> None:
    """A compiled sample that fails in its trial run (here: any error) warns and leaves the NumPy path, which
    works; ``CASCGP_JIT=0`` chooses the NumPy path without a warning."""
    pytest.importorskip("numba")
    import cascgp.models.online_kernel as ok

    def broken(*a):
        raise RuntimeError("no cache location")

    monkeypatch.setattr(ok, "propose", broken)
    monkeypatch.delenv("CASCGP_JIT", raising=False)
    model = _small_np_inward()
    _opens_on_the_numpy_path_with_a_warning(model)
    monkeypatch.undo()
    monkeypatch.setenv("CASCGP_JIT", "0")
    model.start_online(window=3)
    assert model._online._jit is None


def test_add_refuses_inputs_of_the_wrong_shape_and_changes_nothing() -> None:
    model = _small_np_inward()
    model.start_online(window=3)
    win = model._online
    xs = [np.zeros(J.Zw.shape[1]) for J in win.joints]
    for bad_x, bad_y, match in ((xs[:2], np.zeros(3), "3 joint inputs"), (xs, np.zeros(2), "3 joint inputs"),
                                ([xs[0], xs[1], np.zeros(1)], np.zeros(3), r"x_per_joint\[2\]")):
        with pytest.raises(ValueError, match=match):
            win.add(bad_x, bad_y)
    assert model.n_online == 0 and all(J.m == 0 for J in win.joints)


def test_the_variance_path_is_built_once_per_fit_and_shared_by_online_windows() -> None:
    """prepare_variance builds the fitted sets' variance path once; opening and closing windows reuses them
    (no rebuild at the first gated tick of each episode), and the values equal a fresh build's."""
    arm = make_arm(3, friction=0.3)
    model = make_model("sp-inward", 3, make_arm(3), gp_config=GPFitConfig(n_restarts=1, max_iter=30)).fit(
        sinusoid_data(arm, 3.0, 10.0, seed=1))
    new = sinusoid_data(make_arm(3, friction=2.0), 1.0, 10.0, seed=5)
    query = (new.q[2], new.qd[2], new.qdd[2])
    base = model.prepare_variance()
    assert model.prepare_variance() is base
    v_off = model.predict_one_var(*query)[1]
    model.start_online(4)
    assert model.prepare_variance().L is base.L
    model.add_sample(new.q[0], new.qd[0], new.qdd[0], new.tau[0])
    v_on = model.predict_one_var(*query)[1]
    fresh = copy.deepcopy(model)
    fresh._fast_var = fresh._fast_var_offline = None  # what a rebuild from scratch gives
    np.testing.assert_allclose(fresh.predict_one_var(*query)[1], v_on, rtol=1e-12)
    model.stop_online()
    assert model.prepare_variance() is base
    np.testing.assert_array_equal(model.predict_one_var(*query)[1], v_off)


def test_a_numba_that_cannot_cache_leaves_the_numpy_paths(monkeypatch) -> None:
    """Numba refuses ``cache=True`` when it decorates a function and finds no writable cache location: the compiled
    online sample (decorated when its module is imported) and the control tick's loops (decorated on first use)
    then warn and leave their NumPy paths."""
    numba = pytest.importorskip("numba")
    import sys

    import cascgp.models
    import cascgp.models.fastkernel as fk

    monkeypatch.delenv("CASCGP_JIT", raising=False)
    fitted = _small_np_inward()
    if fitted._fast.jit is None:
        pytest.skip("the compiled tick is not in use here")

    def no_cache(*args, **kwargs):
        raise RuntimeError("cannot cache function: no locator available")

    monkeypatch.setattr(numba, "njit", no_cache)
    monkeypatch.delitem(sys.modules, "cascgp.models.online_kernel", raising=False)
    monkeypatch.delattr(cascgp.models, "online_kernel", raising=False)
    new = _opens_on_the_numpy_path_with_a_warning(fitted)

    monkeypatch.setattr(fk, "_compiled", {})  # nothing decorated yet in this process
    model = make_model("np-inward", 3, gp_config=GPFitConfig(n_restarts=1, max_iter=20))
    with pytest.warns(RuntimeWarning, match="compiled single-query loop is not used"):
        model.adopt_banks(fitted.banks, fitted.where, fitted.n_train)
    assert model._fast.jit is None and model.prepare_variance().Lc is None
    q = (new.q[1], new.qd[1], new.qdd[1])
    fitted.stop_online()
    np.testing.assert_allclose(model.predict_one(*q), fitted.predict_one(*q), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("value, on", [("0", False), ("false", False), ("No", False), (" OFF ", False), ("1", True),
                                       ("yes", True)])
def test_cascgp_jit_turns_the_compiled_loops_off_with_any_usual_word(monkeypatch, value: str, on: bool) -> None:
    """Only "0" turned them off; "false", "no" and "off" left them on without a word."""
    from cascgp.models import fastkernel

    monkeypatch.setattr(fastkernel, "_kernel", lambda: object())  # as if Numba were installed
    monkeypatch.setenv("CASCGP_JIT", value)
    assert fastkernel.jit_enabled() is on
