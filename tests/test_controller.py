"""FeedforwardController: eq. 2 of the paper, safety (finite, within limits), fallbacks."""

from __future__ import annotations

import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cascgp.controller import FeedforwardController

LIMITS = np.array([30.5, 30.5, 30.5, 6.8, 6.8, 6.8])
KP = np.array([120.0, 120, 120, 40, 40, 40])
KD = np.array([30.0, 30, 30, 9, 9, 9])


def reference(t: float):
    q_d = np.array([0.1, 2.5, 1.5, -0.2, 0.3, 0.0]) + 0.1 * np.sin(t)
    return q_d, 0.1 * np.cos(t) * np.ones(6), -0.1 * np.sin(t) * np.ones(6)


class AffineRBD:
    """A stand-in rigid-body model: tau = A q + B qd + C qdd + g (finite for finite input)."""

    dof = 6

    def __init__(self, seed: int = 0):
        rng = np.random.default_rng(seed)
        self.A, self.B, self.C = (rng.normal(size=(6, 6)) for _ in range(3))
        self.g = rng.normal(size=6)

    def inverse_dynamics(self, q, qd, qdd):
        return self.A @ q + self.B @ qd + self.C @ qdd + self.g


class NaNModel:
    """A learned model whose output is not finite."""

    dof = 6
    feature_kind = "db"
    name = "nan-model"

    def __init__(self):
        self.calls = 0

    def predict_one(self, q, qd=None, qdd=None, q_hist=None):
        self.calls += 1
        return np.full(6, np.nan)


class HistoryModel:
    """A derivative-free model stand-in that records the history it is given."""

    dof = 6
    feature_kind = "df"
    df_delta = 0.1
    name = "df-model"

    def __init__(self):
        self.q_hist = None

    def predict_one(self, q, qd=None, qdd=None, q_hist=None):
        self.q_hist = q_hist
        return np.zeros(6)


def test_pd_only_is_eq2_without_feedforward():
    ctrl = FeedforwardController(None, KP, KD, LIMITS)
    q_d, qd_d, _ = reference(0.3)
    q, qd = q_d - 0.01, qd_d + 0.02
    np.testing.assert_allclose(ctrl(0.3, q, qd, reference), KP * 0.01 - KD * 0.02)


def test_rbd_feedforward_is_evaluated_on_the_reference():
    rbd = AffineRBD()
    ctrl = FeedforwardController(rbd, KP, KD, np.full(6, 1e6))
    q_d, qd_d, qdd_d = reference(1.1)
    q, qd = q_d + 0.02, qd_d - 0.01
    expected = rbd.inverse_dynamics(q_d, qd_d, qdd_d) + KP * (q_d - q) + KD * (qd_d - qd)
    np.testing.assert_allclose(ctrl(1.1, q, qd, reference), expected, rtol=1e-12)


def test_output_is_clipped_to_the_limits():
    ctrl = FeedforwardController(None, KP, KD, LIMITS)
    q_d, qd_d, _ = reference(0.0)
    tau = ctrl(0.0, q_d - 10.0, qd_d, reference)
    np.testing.assert_array_equal(tau, LIMITS)


def test_non_finite_model_output_falls_back_to_rbd_and_is_counted():
    rbd, model = AffineRBD(), NaNModel()
    ctrl = FeedforwardController(model, KP, KD, np.full(6, 1e6), fallback=rbd)
    q_d, qd_d, qdd_d = reference(0.5)
    tau = ctrl(0.5, q_d, qd_d, reference)
    np.testing.assert_allclose(tau, rbd.inverse_dynamics(q_d, qd_d, qdd_d))
    assert ctrl.n_fallbacks == 1 and model.calls == 1
    ctrl.reset_counters()
    assert ctrl.n_fallbacks == 0
    ctrl(0.5, q_d, qd_d, reference)
    ctrl.start(None, {})  # the episode runner's start of an episode (Controller protocol) zeroes them too
    assert ctrl.n_fallbacks == 0


def test_non_finite_model_output_without_rbd_gives_pd_only():
    ctrl = FeedforwardController(NaNModel(), KP, KD, LIMITS)
    q_d, qd_d, _ = reference(0.5)
    np.testing.assert_array_equal(ctrl(0.5, q_d, qd_d, reference), np.zeros(6))
    assert ctrl.n_fallbacks == 1 and ctrl.last_model_error == "the model returned a non-finite torque"


def test_derivative_free_model_gets_reference_history():
    model = HistoryModel()
    ctrl = FeedforwardController(model, KP, KD, LIMITS)
    ctrl(2.0, *reference(2.0)[:2], reference)
    np.testing.assert_allclose(model.q_hist, np.stack([reference(1.9)[0], reference(1.8)[0]]))


def test_bad_arguments_name_the_field():
    with pytest.raises(ValueError, match="kp must be finite and non-negative, got -1.0"):
        FeedforwardController(None, -1.0, KD, LIMITS)
    with pytest.raises(ValueError, match="kp must be finite and non-negative, got None"):
        FeedforwardController(None, None, KD, LIMITS)
    with pytest.raises(ValueError, match="torque_limits"):
        FeedforwardController(None, KP, KD, np.array([1.0, -2.0]))
    with pytest.raises(ValueError, match="model.dof"):
        FeedforwardController(AffineRBD(), 1.0, 1.0, np.ones(7))
    ctrl = FeedforwardController(None, KP, KD, LIMITS)
    with pytest.raises(ValueError, match="shape"):
        ctrl(0.0, np.zeros(5), np.zeros(6), reference)
    # a model or fallback the controller cannot use is refused here, not run as PD only with a fallback every tick
    from cascgp.models import make_model

    with pytest.raises(TypeError, match="model: expected a fitted cascgp model, an object with inverse_dynamics"):
        FeedforwardController("np-inward", KP, KD, LIMITS)
    with pytest.raises(ValueError, match="model: np-inward is not fitted"):
        FeedforwardController(make_model("np-inward", 6), KP, KD, LIMITS)
    with pytest.raises(TypeError, match="fallback: expected a rigid-body model"):
        FeedforwardController(NaNModel(), KP, KD, LIMITS, fallback="rbd")
    with pytest.raises(ValueError, match=r"fallback.dof \(6\) does not match torque_limits \(3 joints\)"):
        FeedforwardController(None, KP[:3], KD[:3], LIMITS[:3], fallback=AffineRBD())


def test_new_torque_limits_are_validated_and_bound_every_later_output():
    ctrl = FeedforwardController(AffineRBD(), KP, KD, LIMITS)
    q_d, qd_d, _ = reference(0.2)
    ctrl.torque_limits = np.full(6, 1.0)
    assert np.all(np.abs(ctrl(0.2, q_d + 5.0, qd_d - 5.0, reference)) <= 1.0)
    with pytest.raises(ValueError, match="read-only"):
        ctrl.torque_limits[:] = 1e6  # in place: refused (the limits are a read-only array)
    for bad in (np.full(6, np.nan), np.zeros(6), np.ones(5), "high"):
        with pytest.raises(ValueError, match="torque_limits"):
            ctrl.torque_limits = bad
        np.testing.assert_array_equal(ctrl.torque_limits, np.ones(6))  # a rejected value changes nothing
    limits = LIMITS.copy()
    ctrl = FeedforwardController(None, KP, KD, limits)
    limits[:] = 1e6  # the caller's array is copied
    assert np.all(np.abs(ctrl(0.2, q_d + 5.0, qd_d - 5.0, reference)) <= LIMITS)
    import copy
    import pickle

    for twin in (copy.deepcopy(ctrl), pickle.loads(pickle.dumps(ctrl))):  # a copy keeps them read-only
        with pytest.raises(ValueError, match="read-only"):
            twin.torque_limits[:] = 1.0
        assert np.all(np.abs(twin(0.2, q_d + 5.0, qd_d - 5.0, reference)) <= LIMITS)


_any_float = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(min_value=-1e6, max_value=1e6),
)


@settings(max_examples=300, deadline=None)
@given(
    q=st.lists(_any_float, min_size=6, max_size=6),
    qd=st.lists(_any_float, min_size=6, max_size=6),
    t=st.floats(min_value=-1e3, max_value=1e3),
    which=st.sampled_from(["pd", "rbd", "nan", "df"]),
)
def test_output_is_always_finite_and_within_limits(q, qd, t, which):
    """Property: random and far out-of-range (even non-finite) measurements never give NaN or excess torque."""
    model = {"pd": None, "rbd": AffineRBD(), "nan": NaNModel(), "df": HistoryModel()}[which]
    ctrl = FeedforwardController(model, KP, KD, LIMITS, fallback=AffineRBD(1))
    tau = ctrl(t, np.array(q), np.array(qd), reference)
    assert tau.shape == (6,)
    assert np.all(np.isfinite(tau))
    assert np.all(np.abs(tau) <= LIMITS)


@settings(max_examples=60, deadline=None)
@given(scale=st.floats(min_value=1.0, max_value=1e8),
       gate=st.sampled_from([False, "wiener", "floor", "variance", "innovation"]),
       bad=st.sampled_from([None, np.nan, np.inf, -np.inf]), online=st.booleans())
def test_far_out_of_range_states_with_a_fitted_gp_model(scale, gate, bad, online, fitted_planar_model,
                                                        fitted_planar_sp_model, arm3_rbd):
    """A real fitted cascade (gated or not, learning online or not) queried far outside its training data, or
    with non-finite measurements, stays finite and clipped; absurd online samples are refused, never raised.
    The 'floor' rule runs on an SP cascade (it refuses NP models), the others on an NP one; the innovation gate
    also sees the absurd samples."""
    import copy

    fitted = fitted_planar_sp_model if gate == "floor" else fitted_planar_model
    model = copy.deepcopy(fitted) if online else fitted
    limits = np.full(model.dof, 5.0)
    ctrl = FeedforwardController(model, 10.0, 1.0, limits, fallback=arm3_rbd, gate=gate,
                                 online=4 if online else None, online_every=1)
    if online or gate == "innovation":
        ctrl.start(None, {})
        value = scale if bad is None else bad
        for k in range(6):
            ctrl.observe(np.full(model.dof, value * (k % 2)), np.full(model.dof, -value), np.full(model.dof, value),
                         0.1 * k)
        if online:
            assert ctrl.n_online_samples + ctrl.n_online_rejected == 4
        if gate == "innovation":  # four samples; those with non-finite errors are skipped, never kept
            assert ctrl.n_innovation_samples == (4 if bad is None else 0)
            s0, sm = ctrl.innovation_errors
            assert not np.any(np.isnan(s0)) and not np.any(np.isnan(sm))
    if bad is not None:
        tau = ctrl(0.0, np.full(model.dof, bad), np.full(model.dof, bad), lambda t: (np.zeros(3),) * 3)
        assert np.all(np.isfinite(tau)) and np.all(np.abs(tau) <= limits)

    def far_reference(t):
        return np.full(model.dof, scale), np.full(model.dof, -scale), np.full(model.dof, scale)

    tau = ctrl(0.0, np.full(model.dof, -scale), np.full(model.dof, scale), far_reference)
    assert np.all(np.isfinite(tau)) and np.all(np.abs(tau) <= limits)


@pytest.fixture(scope="module")
def fitted_planar_sp_model(arm3_train, arm3_rbd):
    from cascgp.gp import GPFitConfig
    from cascgp.models import make_model

    data = arm3_train.take(np.arange(min(80, arm3_train.n_samples)))
    return make_model("sp-inward", data.dof, rbd=arm3_rbd,
                      gp_config=GPFitConfig(n_restarts=2, max_iter=200)).fit(data)


@pytest.mark.parametrize("rule", ["wiener", "floor", "variance"])
def test_gated_feedforward_follows_its_rule(rule, request, arm3_rbd, arm3_train):
    """tau = tau_RBD + w d with d = mu - tau_RBD: w ~ 1 at a training point (the model), and for the variance
    rule w ~ 0 far away (the nominal torque), the floor rule keeps at least half; the weights equal the
    documented formulas."""
    model = request.getfixturevalue("fitted_planar_sp_model" if rule == "floor" else "fitted_planar_model")
    ctrl = FeedforwardController(model, 0.0, 0.0, np.full(3, 1e6), fallback=arm3_rbd, gate=rule)
    assert ctrl.name.endswith({"wiener": "-gated", "floor": "-fgated", "variance": "-vgated"}[rule])
    r = 10
    state = (arm3_train.q[r], arm3_train.qd[r], arm3_train.qdd[r])
    for query in (state, tuple(x + 50.0 for x in state)):
        tau = ctrl(0.0, query[0], query[1], lambda t, query=query: query)
        mean, var = model.predict(*query, propagate=True)
        nominal = arm3_rbd.inverse_dynamics(*query)
        d = mean - nominal
        p = model.signal_var
        w = {"wiener": d**2 / (d**2 + var), "floor": np.maximum(d**2, p) / (np.maximum(d**2, p) + var),
             "variance": np.clip(1 - var / p, 0, 1)}[rule]
        np.testing.assert_allclose(ctrl.last_gate, w, rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(tau, nominal + w * d, rtol=1e-9, atol=1e-6)
        if query is state:
            assert np.all(ctrl.last_gate > 0.9)
        elif rule == "variance":
            assert np.all(ctrl.last_gate < 0.05)
        if rule == "floor":  # at least half wherever v <= p, however small the correction; never below Wiener
            assert np.all(ctrl.last_gate[var <= p] >= 0.5) and np.all(ctrl.last_gate <= 1.0)
            assert np.all(ctrl.last_gate >= d**2 / (d**2 + var) - 1e-12)


def _feed(ctrl, states, torque, dt=0.1):
    """Measurements at constant velocity (so the controller's central-difference q̈ is 0), each sample's measured
    torque ``torque(q, qd)``; ``online_every=1``: a sample per call from the third on."""
    qdd0 = np.zeros(ctrl.dof)
    for k, (q, qd) in enumerate(states):
        # the torque measured at call k belongs to the previous tick's state (see observe)
        prev = states[k - 1] if k else states[0]
        ctrl.observe(q, qd, torque(prev[0], prev[1], qdd0), dt * k)


def test_innovation_gate_trusts_the_predictor_with_the_smaller_errors(fitted_planar_sp_model, arm3_rbd, arm3_train):
    """w = S_0 / (S_0 + S_m): 1/2 before any sample; 0 when the measured torques are the nominal model's (the
    learned model errs, the nominal does not); 1 when they are the learned model's; the sums discount with the
    documented half-life."""
    from cascgp.controller import INNOVATION_HALF_LIFE_S, innovation_weights

    model = fitted_planar_sp_model
    ctrl = FeedforwardController(model, 0.0, 0.0, np.full(3, 1e6), fallback=arm3_rbd, gate="innovation",
                                 online_every=1)
    assert ctrl.name.endswith("-igated")
    ctrl.start(None, {})
    state = (arm3_train.q[10], arm3_train.qd[10], arm3_train.qdd[10])
    tau = ctrl(0.0, state[0], state[1], lambda t: state)
    nominal, mean = arm3_rbd.inverse_dynamics(*state), model.predict_one(*state)
    np.testing.assert_allclose(ctrl.last_gate, 0.5)
    np.testing.assert_allclose(tau, nominal + 0.5 * (mean - nominal), rtol=1e-9, atol=1e-9)

    states = [(arm3_train.q[k], np.full(3, 0.2)) for k in range(20, 30)]
    _feed(ctrl, states, arm3_rbd.inverse_dynamics)
    assert ctrl.n_innovation_samples == 8
    s0, sm = ctrl.innovation_errors
    assert np.all(s0 == 0) and np.all(sm > 0)
    ctrl(0.0, state[0], state[1], lambda t: state)
    np.testing.assert_array_equal(ctrl.last_gate, 0.0)

    ctrl.start(None, {})  # a new episode forgets
    assert ctrl.n_innovation_samples == 0 and not np.any(ctrl.innovation_errors[0])
    _feed(ctrl, states, model.predict_one)
    s0, sm = ctrl.innovation_errors
    np.testing.assert_allclose(sm, 0.0, atol=1e-20)
    ctrl(0.0, state[0], state[1], lambda t: state)
    np.testing.assert_allclose(ctrl.last_gate, 1.0)

    # Discounting: two samples 0.5 s apart; the first counts 2^(-0.5 / half-life).
    ctrl.start(None, {})
    _feed(ctrl, states[:4], lambda q, qd, qdd: arm3_rbd.inverse_dynamics(q, qd, qdd) + 1.0, dt=0.5)
    s0, _ = ctrl.innovation_errors
    np.testing.assert_allclose(s0, 1.0 + 2.0 ** (-0.5 / INNOVATION_HALF_LIFE_S), rtol=1e-12)
    np.testing.assert_allclose(innovation_weights([0.0, 1.0, np.nan], [0.0, 3.0, 1.0]), [0.5, 0.25, 0.0])
    # Huge sums keep their limit: an infinite nominal error trusts the model fully; equal huge sums give 1/2.
    np.testing.assert_allclose(innovation_weights([np.inf, 1e308, np.inf, 1.0], [1.0, 1e308, np.inf, np.inf]),
                               [1.0, 0.5, 0.0, 0.0])


def test_innovation_gate_needs_only_a_mean_prediction(arm3_rbd):
    """The innovation gate uses the model's mean and the nominal torque, no variance: a derivative-based model
    with predict_one alone is enough."""

    class MeanOnly:
        dof, feature_kind, name = 3, "db", "mean-only"

        def predict_one(self, q, qd=None, qdd=None, q_hist=None):
            return arm3_rbd.inverse_dynamics(q, qd, qdd) + 1.0

    ctrl = FeedforwardController(MeanOnly(), 0.0, 0.0, np.full(3, 1e6), fallback=arm3_rbd, gate=True)
    assert ctrl.gate == "innovation"
    ctrl.start(None, {})
    state = (np.full(3, 0.1), np.zeros(3), np.zeros(3))
    np.testing.assert_allclose(ctrl(0.0, state[0], state[1], lambda t: state),
                               arm3_rbd.inverse_dynamics(*state) + 0.5)  # w = 1/2 before any sample


def test_innovation_errors_are_taken_before_the_sample_enters_the_online_window(fitted_planar_sp_model, arm3_rbd,
                                                                                arm3_train):
    import copy

    model = copy.deepcopy(fitted_planar_sp_model)
    ctrl = FeedforwardController(model, 0.0, 0.0, np.full(3, 1e6), fallback=arm3_rbd, gate="innovation",
                                 online=10, online_every=1)
    ctrl.start(None, {})
    states = [(arm3_train.q[k], np.full(3, 0.2)) for k in range(40, 43)]
    before = model.predict_one(states[1][0], states[1][1], np.zeros(3))
    _feed(ctrl, states, lambda q, qd, qdd: arm3_rbd.inverse_dynamics(q, qd, qdd) + 2.0)
    assert ctrl.n_innovation_samples == ctrl.n_online_samples == 1
    measured = arm3_rbd.inverse_dynamics(states[1][0], states[1][1], np.zeros(3)) + 2.0
    np.testing.assert_allclose(ctrl.innovation_errors[1], (measured - before) ** 2, rtol=1e-9)
    assert not np.allclose(model.predict_one(states[1][0], states[1][1], np.zeros(3)), before)  # it did learn


def test_gate_rules_are_objects_behind_one_protocol(fitted_planar_sp_model, arm3_rbd, arm3_train):
    """Each named rule is a GateRule object; passing the object gives the same controller as passing its name; a
    rule of one's own (here a constant weight) plugs in the same way."""
    from cascgp.gates import GATE_RULES, GATE_SUFFIXES, FloorGate, GateRule, InnovationGate, VarianceGate, WienerGate

    model = fitted_planar_sp_model
    state = (arm3_train.q[10], arm3_train.qd[10], arm3_train.qdd[10])
    classes = {"innovation": InnovationGate, "wiener": WienerGate, "floor": FloorGate, "variance": VarianceGate}
    assert set(classes) == set(GATE_RULES)
    for name, cls in classes.items():
        rule = cls()
        assert isinstance(rule, GateRule) and rule.name == name and rule.suffix == GATE_SUFFIXES[name]
        by_name, by_rule = (FeedforwardController(model, 0.0, 0.0, np.full(3, 1e6), fallback=arm3_rbd, gate=g)
                            for g in (name, rule))
        assert by_rule.gate == name and by_rule.gate_rule is rule and by_rule.name == by_name.name
        for ctrl in (by_name, by_rule):
            ctrl.start(None, {})
        np.testing.assert_array_equal(by_rule(0.0, state[0], state[1], lambda t: state),
                                      by_name(0.0, state[0], state[1], lambda t: state))
        np.testing.assert_array_equal(by_rule.last_gate, by_name.last_gate)

    class Half:
        name, suffix, observes = "half", "-hgated", False

        def bind(self, model, nominal, dof):
            self.model = model

        def start(self):
            pass

        def correction(self, q, qd, qdd, q_hist, nominal):
            return self.model.predict_one(q, qd, qdd) - nominal, np.full(3, 0.5)

        def observe(self, t, q, qd, qdd, tau):
            raise AssertionError("not called: observes is False")

    ctrl = FeedforwardController(model, 0.0, 0.0, np.full(3, 1e6), fallback=arm3_rbd, gate=Half())
    assert ctrl.gate == "half" and ctrl.name == "sp-inward-hgated"
    ctrl.start(None, {})
    nominal, mean = arm3_rbd.inverse_dynamics(*state), model.predict_one(*state)
    np.testing.assert_allclose(ctrl(0.0, state[0], state[1], lambda t: state), nominal + 0.5 * (mean - nominal))
    ctrl.observe(state[0], state[1], nominal, 0.1)


def test_gate_needs_a_cascade_model_and_a_nominal_model(fitted_planar_model, arm3_rbd):
    with pytest.raises(ValueError, match="gate: needs a nominal"):
        FeedforwardController(fitted_planar_model, KP[:3], KD[:3], LIMITS[:3], gate=True)
    with pytest.raises(ValueError, match="gate: needs a fitted cascgp model"):
        FeedforwardController(AffineRBD(), KP, KD, LIMITS, gate=True)
    with pytest.raises(ValueError, match="gate: expected"):
        FeedforwardController(AffineRBD(), KP, KD, LIMITS, gate="sometimes")
    from cascgp.gp import GPFitConfig
    from cascgp.models import make_model
    from tests.conftest import make_arm, sinusoid_data

    df = make_model("np-inward-df", 3, gp_config=GPFitConfig(n_restarts=1, max_iter=10)).fit(
        sinusoid_data(make_arm(3), 6.0, 10.0, seed=4))
    with pytest.raises(ValueError, match="gate 'innovation': needs a derivative-based"):
        FeedforwardController(df, KP[:3], KD[:3], LIMITS[:3], fallback=arm3_rbd, gate="innovation")
    # gate=True is the default rule: innovation for a derivative-based model, Wiener for a derivative-free one.
    arm = make_arm(3)
    assert FeedforwardController(fitted_planar_model, KP[:3], KD[:3], LIMITS[:3], fallback=arm, gate=True).gate == \
        "innovation"
    assert FeedforwardController(df, KP[:3], KD[:3], LIMITS[:3], fallback=arm, gate=True).gate == "wiener"
    with pytest.raises(ValueError, match="gate 'floor': needs a semi-parametric"):
        FeedforwardController(fitted_planar_model, KP[:3], KD[:3], LIMITS[:3], fallback=arm, gate="floor")


def test_an_offline_controller_uses_the_fitted_model_even_after_an_online_episode(fitted_planar_model, arm3_train):
    """A window left open by an online episode on a shared model must not reach the next, offline one."""
    import copy

    model = copy.deepcopy(fitted_planar_model)
    ref_state = (arm3_train.q[7], arm3_train.qd[7], arm3_train.qdd[7])
    fitted = model.predict_one(*ref_state)
    model.start_online(5)
    for i in range(20, 25):
        model.add_sample(arm3_train.q[i] + 0.3, arm3_train.qd[i], arm3_train.qdd[i], arm3_train.tau[i] + 2.0)
    assert not np.allclose(model.predict_one(*ref_state), fitted)
    ctrl = FeedforwardController(model, 0.0, 0.0, np.full(3, 1e6))
    ctrl.start(None, {})
    np.testing.assert_array_equal(ctrl.feedforward(0.0, lambda t: ref_state), fitted)


def test_an_sp_model_that_fails_falls_back_to_its_own_rbd(arm3_rbd, arm3_train, monkeypatch):
    """Without a fallback argument, an SP model's own nominal model is the fallback (not zero)."""
    from cascgp.gp import GPFitConfig
    from cascgp.models import make_model

    data = arm3_train.take(np.arange(40))
    model = make_model("sp-inward", 3, rbd=arm3_rbd, gp_config=GPFitConfig(n_restarts=1, max_iter=30)).fit(data)
    ctrl = FeedforwardController(model, 0.0, 0.0, np.full(3, 1e6))

    def broken(*args, **kwargs):
        raise RuntimeError("model broke")

    monkeypatch.setattr(model, "predict_one", broken)
    state = (data.q[3], data.qd[3], data.qdd[3])
    np.testing.assert_allclose(ctrl.feedforward(0.0, lambda t: state), arm3_rbd.inverse_dynamics(*state))
    assert ctrl.n_fallbacks == 1 and "model broke" in ctrl.last_model_error


def test_online_learning_is_refused_for_a_cascade_trained_on_predicted_torques(arm3_train):
    from cascgp.gp import GPFitConfig
    from cascgp.models import make_model

    model = make_model("np-inward", 3, gp_config=GPFitConfig(n_restarts=1, max_iter=20),
                       train_on_predicted=True).fit(arm3_train.take(np.arange(40)))
    with pytest.raises(ValueError, match="predicted neighbour torques"):
        FeedforwardController(model, 1.0, 0.1, np.full(3, 10.0), online=5)
    with pytest.raises(ValueError, match="predicted neighbour torques"):
        model.start_online(5)


@pytest.mark.skipif(not hasattr(os, "sysconf") or "SC_PHYS_PAGES" not in getattr(os, "sysconf_names", {}),
                    reason="the physical memory is known on POSIX only")
def test_an_online_window_too_large_for_memory_is_refused_at_construction(arm3_train):
    from cascgp.gp import GPFitConfig
    from cascgp.models import make_model

    model = make_model("np-inward", 3, gp_config=GPFitConfig(n_restarts=1, max_iter=20)).fit(
        arm3_train.take(np.arange(40)))
    with pytest.raises(ValueError, match=r"^online: 1000000000000 samples per joint would need about .* GB"):
        FeedforwardController(model, 1.0, 0.1, np.full(3, 10.0), online=10**12)  # refused only at start() before
    assert FeedforwardController(model, 1.0, 0.1, np.full(3, 10.0), online=5).online == 5

    class NoPosteriors:  # a user's wrapper without posteriors(): its window is checked when it opens, as before
        def __getattr__(self, name):
            if name == "posteriors":
                raise AttributeError(name)
            return getattr(model, name)

    assert FeedforwardController(NoPosteriors(), 1.0, 0.1, np.full(3, 10.0), online=10**12).online == 10**12
