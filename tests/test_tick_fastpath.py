"""The control tick's single-query paths (issue 24, item 2) equal their references to round-off: the compiled
cascade mean and kernel rows (:mod:`cascgp.models.fastkernel`, when Numba is installed) against the NumPy path,
both against the batched ``predict``, with and without an online window; the controller's shortcuts (its feedback
form, the nominal torque shared with an SP model's own RBD term) change no output bit."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cascgp.controller import FeedforwardController
from cascgp.gp import GPFitConfig
from cascgp.models import MODEL_NAMES, make_model
from cascgp.models.fastkernel import JIT_WT, jit_enabled
from cascgp.models.fastpath import FastPath
from cascgp.models.queries import load_query
from tests.conftest import make_arm, sinusoid_data

needs_jit = pytest.mark.skipif(not jit_enabled(), reason="numba is not installed (or CASCGP_JIT=0)")
CFG = GPFitConfig(n_restarts=1, max_iter=30)
MODELS = [*MODEL_NAMES, "rbf:sp-inward", "matern32:sp-inward", "matern32:np-outward"]


@pytest.fixture(scope="module")
def models() -> dict:
    arm = make_arm(3, friction=0.3)
    train = sinusoid_data(arm, 4.0, 10.0, seed=1, noise=0.02)
    out = {}
    for key in MODELS:
        name = key.split(":")[-1]
        cfg = dataclasses.replace(CFG, kernel=key.split(":")[0]) if ":" in key else CFG
        out[key] = make_model(name, 3, make_arm(3) if name.startswith("sp") else None, gp_config=cfg).fit(train)
    return out


def _queries(n: int = 12) -> list[tuple[np.ndarray, ...]]:
    new = sinusoid_data(make_arm(3, friction=0.8), 2.0, 10.0, seed=7, noise=0.02)
    rows = [(new.q[i], new.qd[i], new.qdd[i], np.stack([new.q[i - 1], new.q[i - 2]]), new.tau[i])
            for i in range(2, 2 + n)]
    q, qd, qdd, h, tau = rows[0]
    rows.append((1e3 * q, 1e3 * qd, qdd, 1e3 * h, tau))  # far from the data: clipped inputs
    return rows


def _scale(f: FastPath, ref: np.ndarray) -> np.ndarray:
    """Round-off scale of a cascade mean: its terms' magnitudes (ill-conditioned fits have large weights)."""
    return np.abs(f.alpha).sum(axis=1) + np.abs(ref) + 1.0


def _both(model, q, qd, qdd, h):
    """(compiled, NumPy) mean and (compiled, NumPy) mean-and-variance of one query."""
    f, tau = load_query(model, q, qd, qdd, h)
    mean_ref = f.mean_numpy(tau)
    var_path = model.prepare_variance()
    return f, model.predict_one(q, qd, qdd, h), mean_ref, model.predict_one_var(q, qd, qdd, h), \
        var_path.mean_var_numpy(f, tau)


@needs_jit
@pytest.mark.parametrize("key", MODELS)
def test_compiled_mean_and_variance_equal_the_numpy_path_and_predict(models, key) -> None:
    model = models[key]
    assert model._fast.jit is not None
    fv = model.prepare_variance()
    assert fv.Lc is not None  # the compiled solves run; BLAS's views are of the same factors
    assert all(np.shares_memory(L, Lc) for L, Lc in zip(fv.L, fv.Lc))
    for q, qd, qdd, h, _ in _queries():
        f, m_jit, m_np, (mv_jit, v_jit), (mv_np, v_np) = _both(model, q, qd, qdd, h)
        tol = 1e-12 * _scale(f, m_np)
        assert np.all(np.abs(m_jit - m_np) <= tol), (m_jit, m_np)
        assert np.all(np.abs(mv_jit - mv_np) <= tol)
        # the propagated term carries the round-off of the chain's mean derivative: a looser bound, still round-off
        assert np.all(np.abs(v_jit - v_np) <= 1e-10 * (model.signal_var + np.abs(v_np)))
        m_b, v_b = model.predict(q, qd, qdd, h, propagate=True)  # the batched reference (torch)
        np.testing.assert_allclose(m_jit, m_b, rtol=0, atol=1e-9 * float(_scale(f, m_b).max()))
        np.testing.assert_allclose(v_jit, v_b, rtol=1e-6, atol=1e-10 * float(model.signal_var.max()))


@pytest.mark.parametrize("name", ["np-inward", "sp-inward", "sp-outward", "np-standard"])
def test_online_window_compiled_and_numpy_paths_agree_as_the_window_wraps(models, name) -> None:
    model = models[name]
    new = sinusoid_data(make_arm(3, friction=0.8), 2.0, 10.0, seed=9, noise=0.02)
    query = _queries(1)[0][:4]
    model.start_online(window=5)
    try:
        for i in range(12):  # fills the window, then drops the oldest seven times
            model.add_sample(new.q[i], new.qd[i], new.qdd[i], new.tau[i])
            f, m1, m_np, (mv1, v1), (mv_np, v_np) = _both(model, *query)
            if f.jit is not None:
                np.testing.assert_array_equal(f.jit[JIT_WT], f.W.transpose(0, 2, 1))  # set_rows keeps the copy
            tol = 1e-12 * _scale(f, m_np)
            assert np.all(np.abs(m1 - m_np) <= tol)
            assert np.all(np.abs(mv1 - mv_np) <= tol)
            np.testing.assert_allclose(v1, v_np, rtol=1e-10, atol=1e-13 * float(model.signal_var.max()))
    finally:
        model.stop_online()


def test_without_the_compiled_path_the_numpy_path_runs(models, monkeypatch) -> None:
    """``CASCGP_JIT=0`` (or no numba): the fast path holds no compiled arguments and ``predict_one`` is the
    NumPy reference bit for bit."""
    monkeypatch.setenv("CASCGP_JIT", "0")
    model = make_model("sp-inward", 3, make_arm(3), gp_config=CFG)
    model.adopt_banks(models["sp-inward"].banks, models["sp-inward"].where, models["sp-inward"].n_train)
    assert model._fast.jit is None and model.prepare_variance().Lc is None
    for q, qd, qdd, _, _ in _queries(4):
        f, tau = load_query(model, q, qd, qdd, None)
        np.testing.assert_array_equal(model.predict_one(q, qd, qdd), f.mean_numpy(tau))
        ref = model.prepare_variance().mean_var_numpy(f, tau)
        for a, b in zip(model.predict_one_var(q, qd, qdd), ref):
            np.testing.assert_array_equal(a, b)


def test_rbd_torque_passed_in_equals_the_models_own_and_is_checked(models) -> None:
    model = models["sp-inward"]
    q, qd, qdd, _, _ = _queries(1)[0]
    tau = model.rbd.inverse_dynamics(q, qd, qdd)
    np.testing.assert_array_equal(model.predict_one(q, qd, qdd, rbd_torque=tau), model.predict_one(q, qd, qdd))
    for a, b in zip(model.predict_one_var(q, qd, qdd, rbd_torque=tau), model.predict_one_var(q, qd, qdd)):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError, match="rbd_torque"):
        model.predict_one(q, qd, qdd, rbd_torque=np.zeros(4))
    with pytest.raises(ValueError, match="non-finite"):
        model.predict_one(q, qd, qdd, rbd_torque=np.array([0.0, np.nan, 0.0]))


class _SameRBD:
    """The model's rigid-body model behind another object: the controller cannot share its torque."""

    def __init__(self, rbd) -> None:
        self.rbd, self.dof = rbd, rbd.dof

    def inverse_dynamics(self, q, qd, qdd):
        return self.rbd.inverse_dynamics(q, qd, qdd)


@pytest.mark.parametrize("gate", ["innovation", "wiener", "floor", "variance"])
def test_gated_ticks_sharing_the_nominal_torque_are_bit_identical(models, gate) -> None:
    model = models["sp-outward"]
    limits = np.full(3, 30.0)
    shared = FeedforwardController(model, 20.0, 2.0, limits, fallback=model.rbd, gate=gate, online_every=1)
    apart = FeedforwardController(model, 20.0, 2.0, limits, fallback=_SameRBD(model.rbd), gate=gate, online_every=1)
    assert shared.gate_rule._share and not apart.gate_rule._share
    rows = _queries()
    for c in (shared, apart):
        c.start(None, {})
    for k, (q, qd, qdd, _, tau) in enumerate(rows[:-1] * 2):
        out = [c(0.1 * k, q + 0.01, qd, lambda t, x=(q, qd, qdd): x) for c in (shared, apart)]
        np.testing.assert_array_equal(out[0], out[1])
        np.testing.assert_array_equal(shared.last_gate, apart.last_gate)
        for c in (shared, apart):
            c.observe(q, qd, tau, 0.1 * k)


def test_the_feedback_shortcut_equals_the_general_form() -> None:
    """A finite feedback (all four inputs finite, no overflow) is the general form's value bit for bit; anything
    else takes the general form (NaN measurements feed back nothing, absurd errors saturate)."""
    rng = np.random.default_rng(0)
    ctrl = FeedforwardController(None, rng.uniform(0, 50, 3), rng.uniform(0, 5, 3), np.full(3, 30.0))
    for _ in range(200):
        q, qd, q_d, qd_d = (rng.normal(scale=s, size=3) for s in (1.0, 3.0, 1.0, 3.0))
        fast = ctrl.kp * (q_d - q) + ctrl.kd * (qd_d - qd)
        np.testing.assert_array_equal(fast, ctrl._feedback_nonfinite(q, qd, q_d, qd_d))
    assert ctrl.n_bad_measurements == 0
    tau = ctrl(0.0, np.array([np.nan, 0.0, 1e308]), np.zeros(3), lambda t: (np.zeros(3),) * 3)
    assert np.all(np.isfinite(tau)) and np.all(np.abs(tau) <= 30.0) and tau[0] == 0.0
    assert ctrl.n_bad_measurements == 1


def test_the_controllers_feedback_in_python_floats_is_numpys_bit_for_bit() -> None:
    """The tick's feedback is computed in Python floats (no np.errstate): the same value as the NumPy form, bit
    for bit, from tiny to huge errors; where NumPy would overflow, the general form takes over as before."""
    rng = np.random.default_rng(3)
    kp, kd = rng.uniform(0, 1e4, 3), rng.uniform(0, 1e3, 3)
    lim = np.full(3, 1e300)
    ctrl = FeedforwardController(None, kp, kd, lim)
    ctrl.start(None, {})
    for scale in (1e-310, 1e-8, 1.0, 1e3, 1e150, 1e300):
        for _ in range(50):
            q, qd, q_d, qd_d = (rng.normal(scale=scale, size=3) for _ in range(4))
            with np.errstate(over="ignore", invalid="ignore"):
                ref = kp * (q_d - q) + kd * (qd_d - qd)
            tau = ctrl(0.0, q, qd, lambda t, a=q_d, b=qd_d: (a, b, np.zeros(3)))
            if np.all(np.isfinite(ref)):
                np.testing.assert_array_equal(tau, np.minimum(np.maximum(ref, -lim), lim))
                assert ctrl.n_bad_measurements == 0
            else:  # overflowed: saturated with its sign by the general form, no warning
                np.testing.assert_array_equal(tau, np.clip(ctrl._feedback_nonfinite(q, qd, q_d, qd_d), -lim, lim))


def test_a_float64_query_and_the_general_form_give_the_same_answer_and_errors(models) -> None:
    """``predict_one`` on three float64 ``(N,)`` arrays (the controller's tick) skips the general form's
    conversions: same output bit for bit as lists or float32 input, same errors."""
    for key in ("sp-inward", "np-outward"):
        model = models[key]
        for q, qd, qdd, _, _ in _queries(4):
            fast = model.predict_one(q, qd, qdd)
            np.testing.assert_array_equal(fast, model.predict_one(q.tolist(), qd.tolist(), qdd.tolist()))
            if model.parametric == "sp":
                tau = model.rbd.inverse_dynamics(q, qd, qdd)
                np.testing.assert_array_equal(model.predict_one(q, qd, qdd, rbd_torque=tau), fast)
                np.testing.assert_array_equal(model.predict_one(q, qd, qdd, rbd_torque=tau.tolist()), fast)
        bad = q.copy()
        bad[1] = np.nan
        for args in ((bad, qd, qdd), (bad.tolist(), qd.tolist(), qdd.tolist()), (q, qd, np.full(3, np.inf))):
            with pytest.raises(ValueError, match="non-finite"):
                model.predict_one(*args)
        with pytest.raises(ValueError, match="shape"):
            model.predict_one(q, qd, np.zeros(4))


@needs_jit
@pytest.mark.parametrize("key", ["sp-inward", "np-outward", "np-standard", "rbf:sp-inward",
                                 "online:sp-inward", "online:np-outward"])
def test_compiled_variance_solves_are_blas_solves(models, key) -> None:
    """Given the same kernel rows, the compiled loop's variances equal the per-joint BLAS path's to round-off (the
    solves are the same BLAS calls; with an online window, its product with the inverse is too, and its product
    with L_w0 is SciPy's dgemv where the per-joint path uses NumPy's)."""
    from cascgp.models.fastkernel import jit_mean, jit_var

    online = key.startswith("online:")
    model = models[key.removeprefix("online:")]
    window, queries = None, _queries(6)
    if online:  # a window that has turned over (samples dropped, its inverse recomputed once)
        new = sinusoid_data(make_arm(3, friction=0.8), 2.0, 10.0, seed=9, noise=0.02)
        model.start_online(window=5)
        for i in range(7):
            model.add_sample(new.q[i], new.qd[i], new.qdd[i], new.tau[i])
        window = model._online.compiled_var_terms()
        assert window[0] == 5
        queries.append((new.q[6], new.qd[6], new.qdd[6], None, None))  # at the last sample: its term shows
    try:
        fv = model.prepare_variance()
        assert (fv.window is not None) == online and fv.Lc is not None
        for q, qd, qdd, h, _ in queries:
            f, tau = load_query(model, q, qd, qdd, h)
            N = len(f.order)
            K, G, mean = np.empty(f.alpha.shape), np.zeros(N), np.empty(N)
            assert jit_mean(f.jit, f.buf, tau, mean, (K, G))
            var = np.full(N, np.nan)
            assert jit_var(f.jit, fv.Lc, fv.scale, fv.prior, K, G, var, window)
            ref = np.empty(N)
            for j in f.order:  # FastVariance.mean_var's loop without the compiled solves
                tj = f.torque_from[j]
                ref[j] = fv._var(j, K[j], G[j] * G[j] * ref[tj] if tj is not None else None)
            assert np.all(np.abs(var - ref) <= 1e-13 * (fv.prior + np.abs(ref))), (var, ref)
        if online:  # the window's term was there: without it the last query's variances are larger
            off = np.full(N, np.nan)
            assert jit_var(f.jit, fv.Lc, fv.scale, fv.prior, K, G, off)
            assert np.all(off >= var) and np.any(off > var * (1 + 1e-3)), (off, var)
    finally:
        model.stop_online()


@needs_jit
def test_a_compiled_variance_loop_that_fails_to_build_leaves_the_blas_solves(models, monkeypatch) -> None:
    """A compiled variance loop that fails in its trial run warns; the per-joint BLAS solves run, with the same
    variances to round-off (the references are computed before the failure is staged)."""
    import cascgp.models.fastkernel as fk

    def broken(*a):
        raise RuntimeError("no cache location")

    reference = [models["sp-inward"].predict_one_var(q, qd, qdd) for q, qd, qdd, _, _ in _queries(3)]
    monkeypatch.setattr(fk, "_compiled", {"mean": fk._kernel(), "var": broken, "dtrsv": fk.blas_routine("dtrsv")})
    model = make_model("sp-inward", 3, make_arm(3), gp_config=CFG)
    model.adopt_banks(models["sp-inward"].banks, models["sp-inward"].where, models["sp-inward"].n_train)
    with pytest.warns(RuntimeWarning, match="compiled variance loop is not used"):
        fv = model.prepare_variance()
    assert fv.Lc is None and model._fast.jit is not None  # the compiled mean still runs
    for (q, qd, qdd, _, _), (m_ref, v_ref) in zip(_queries(3), reference):
        m, v = model.predict_one_var(q, qd, qdd)
        np.testing.assert_array_equal(m, m_ref)
        np.testing.assert_allclose(v, v_ref, rtol=1e-10, atol=1e-13 * float(model.signal_var.max()))


@needs_jit
def test_the_window_variance_is_compiled_when_the_window_opens_and_falls_back_if_it_fails(models,
                                                                                        monkeypatch) -> None:
    """The variance loop's form with an online window's term is compiled (or loaded) when the window's variance
    path is prepared, not in the first gated tick; if that fails, a warning, and the per-joint path gives the same
    variances to round-off."""
    import cascgp.models.fastkernel as fk
    import cascgp.models.online as online

    model = models["sp-inward"]
    new = sinusoid_data(make_arm(3, friction=0.8), 2.0, 10.0, seed=9, noise=0.02)
    queries = [(new.q[i] + 0.01, new.qd[i], new.qdd[i]) for i in (3, 6)]
    model.start_online(window=5)
    calls = []
    monkeypatch.setattr(online, "jit_var", lambda *a: calls.append(a[-1]) or fk.jit_var(*a))
    try:
        fv = model.prepare_variance()
        assert fv.Lc is not None
        # run once when it opened, with the window's arrays and as with samples held (its BLAS calls included)
        assert len(calls) == 1 and calls[0][0] == 1 and calls[0][1] is model._online.compiled_var_terms()[1]
        monkeypatch.undo()
        for i in range(7):
            model.add_sample(new.q[i], new.qd[i], new.qdd[i], new.tau[i])
        reference = [model.predict_one_var(*q) for q in queries]
        real = fk._compiled["var"]

        def refuses_the_window(*a):
            if a[-1] is not None:
                raise RuntimeError("cannot compile")
            return real(*a)

        monkeypatch.setitem(fk._compiled, "var", refuses_the_window)
        model.start_online(window=5)
        with pytest.warns(RuntimeWarning, match="compiled variance of the online window is not used"):
            fv = model.prepare_variance()
        assert fv.Lc is None and fv.window is not None
        for i in range(7):
            model.add_sample(new.q[i], new.qd[i], new.qdd[i], new.tau[i])
        for q, (m_ref, v_ref) in zip(queries, reference):
            m, v = model.predict_one_var(*q)
            np.testing.assert_array_equal(m, m_ref)
            np.testing.assert_allclose(v, v_ref, rtol=1e-10, atol=1e-13 * float(model.signal_var.max()))
    finally:
        model.stop_online()


def test_a_compiled_loop_that_fails_to_build_leaves_the_numpy_path(models, monkeypatch) -> None:
    import cascgp.models.fastkernel as fk

    def broken(*a):
        raise RuntimeError("no cache location")

    monkeypatch.setattr(fk, "_compiled", {"mean": broken})
    monkeypatch.delenv("CASCGP_JIT", raising=False)
    model = make_model("np-inward", 3, gp_config=CFG)
    with pytest.warns(RuntimeWarning, match="NumPy path runs"):
        model.adopt_banks(models["np-inward"].banks, models["np-inward"].where, models["np-inward"].n_train)
    assert model._fast.jit is None and not fk.jit_enabled()
    q, qd, qdd, _, _ = _queries(1)[0]
    np.testing.assert_allclose(model.predict_one(q, qd, qdd), models["np-inward"].predict_one(q, qd, qdd),
                               rtol=1e-12, atol=1e-12)
