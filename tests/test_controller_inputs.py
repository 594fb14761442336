"""FeedforwardController's inputs as one's own control loop gives them: gains, the reference, ``observe``.

A rejected call raises naming the argument and changes nothing: a twin controller that never got it gives the same
torques afterwards, bit for bit.
"""

from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest

from cascgp.controller import FeedforwardController
from tests.test_controller import KD, KP, LIMITS, reference

def planar_reference(t: float):
    return 0.3 * np.sin([t, 2 * t, 3 * t]), 0.3 * np.cos([t, 2 * t, 3 * t]), -0.3 * np.sin([t, 2 * t, 3 * t])


def test_gains_can_be_scheduled_by_assignment_and_are_validated():
    ctrl = FeedforwardController(None, KP, KD, np.full(6, 1e6))
    q_d, qd_d, _ = reference(0.3)
    q, qd = q_d - 0.01, qd_d + 0.02
    ctrl.kp, ctrl.kd = 2.0, np.arange(6.0)  # a scalar for every joint, or one gain per joint
    np.testing.assert_array_equal(ctrl.kp, np.full(6, 2.0))
    np.testing.assert_allclose(ctrl(0.3, q, qd, reference), 2.0 * 0.01 - np.arange(6.0) * 0.02, atol=1e-12)
    with pytest.raises(ValueError, match="read-only"):  # unchecked in place: a negative gain is positive feedback
        ctrl.kp[0] = -1e9
    for twin in (copy.deepcopy(ctrl), pickle.loads(pickle.dumps(ctrl))):
        with pytest.raises(ValueError, match="read-only"):
            twin.kd[0] = -1.0
    ctrl.kp = np.r_[5.0, ctrl.kp[1:]]  # one joint's gain, checked
    assert ctrl(0.3, q, qd, reference)[0] == pytest.approx(5.0 * 0.01)
    for bad, err in ((-1.0, ValueError), (np.nan, ValueError), (np.ones(5), ValueError), ("stiff", TypeError),
                     ([1.0, None, 1.0, 1.0, 1.0, 1.0], ValueError), ({}, TypeError), (1j, TypeError),
                     (np.full(6, 10 + 5j), TypeError), (True, TypeError), (np.ones(6, bool), TypeError)):
        for name in ("kp", "kd"):
            before = getattr(ctrl, name).copy()
            with pytest.raises(err, match=name):
                setattr(ctrl, name, bad)
            np.testing.assert_array_equal(getattr(ctrl, name), before)  # a rejected gain changes nothing
    with pytest.raises(ValueError, match="kd: |kd must"):
        FeedforwardController(None, KP, np.ones(3), LIMITS)


def test_a_wrong_number_of_limits_is_named_against_the_model(fitted_planar_model) -> None:
    # the limits give the controller's joints; a model of another count is named before the gains' shapes
    with pytest.raises(ValueError, match=r"model.dof \(3\) does not match torque_limits \(2 joints\)"):
        FeedforwardController(fitted_planar_model, np.ones(3), np.ones(3), np.ones(2))
    with pytest.raises(ValueError, match=r"kp must be one real number or 2 of them \(one per joint, as torque_limits"):
        FeedforwardController(None, np.ones(3), np.ones(3), np.ones(2))


@pytest.mark.parametrize("part, joint", [(0, 1), (1, 0), (2, 2)])
@pytest.mark.parametrize("value", [np.nan, np.inf])
@pytest.mark.parametrize("bad_measurement", [False, True])
def test_a_non_finite_reference_is_refused_and_changes_nothing(fitted_planar_model, arm3_rbd, part, joint, value,
                                                                bad_measurement) -> None:
    """A NaN in one joint's reference used to drop every joint's feedforward silently (the model and the fallback
    refused it): now a ValueError naming the part, also on a tick whose measurement is bad."""
    ctrl = FeedforwardController(fitted_planar_model, 10.0, 1.0, np.full(3, 50.0), fallback=arm3_rbd, gate=True)
    twin = copy.deepcopy(ctrl)
    for c in (ctrl, twin):
        c.start(None, {})
    q, qd, _ = planar_reference(0.0)
    broken = [x.copy() for x in planar_reference(0.1)]
    broken[part][joint] = value
    name = ("q_d", "qd_d", "qdd_d")[part]
    q_meas = np.r_[np.nan, q[1:]] if bad_measurement else q
    with pytest.raises(ValueError, match=rf"reference: {name} at t=0.1 must be finite; entries \[{joint}\]"):
        ctrl(0.1, q_meas, qd, lambda t: tuple(broken))
    with pytest.raises(ValueError, match=rf"reference: {name}"):
        ctrl.feedforward(0.1, lambda t: tuple(broken))
    assert (ctrl.n_fallbacks, ctrl.n_bad_measurements, ctrl.last_model_error) == (0, 0, None)
    for k in range(1, 6):
        t = 0.05 * k
        np.testing.assert_array_equal(ctrl(t, q, qd, planar_reference), twin(t, q, qd, planar_reference))


def test_a_huge_finite_reference_is_taken(fitted_planar_model, arm3_rbd) -> None:
    ctrl = FeedforwardController(fitted_planar_model, 10.0, 1.0, np.full(3, 50.0), fallback=arm3_rbd)
    ctrl.start(None, {})
    huge = (np.full(3, 1e308), np.full(3, -1e308), np.full(3, 1e308))  # sums overflow; every entry is finite
    tau = ctrl(0.0, np.zeros(3), np.zeros(3), lambda t: huge)
    np.testing.assert_array_equal(np.abs(tau), np.full(3, 50.0))  # clipped, as any absurd but finite reference


@pytest.mark.parametrize("bad, exc, match", [
    (("q", np.zeros(2)), ValueError, r"q: expected shape \(3,\), got \(2,\)"),
    (("qd", np.zeros((1, 3))), ValueError, r"qd: expected shape \(3,\)"),
    (("tau", np.zeros(4)), ValueError, r"tau: expected shape \(3,\), got \(4,\)"),
    (("tau", None), TypeError, "tau: expected a real numeric array"),
    (("q", ["a", "b", "c"]), TypeError, "q: expected a real numeric array"),
    (("t", None), TypeError, r"t: expected a real number \(s\), got NoneType"),
    (("t", "0.1"), TypeError, r"t: expected a real number \(s\), got str"),
])
@pytest.mark.parametrize("online", [None, 4])
def test_observe_refuses_malformed_input_and_changes_nothing(fitted_planar_model, arm3_rbd, bad, exc, match,
                                                             online) -> None:
    """observe() took anything: a wrong-sized q or tau entered the samples, or shifted the sampling phase
    unnoticed; now it is checked as a tick's arguments are. Checked at every call, the slots that make no
    sample included (online_every=4: the bad call lands on the fourth)."""
    model = copy.deepcopy(fitted_planar_model)
    ctrl = FeedforwardController(model, 10.0, 1.0, np.full(3, 50.0), fallback=arm3_rbd, gate=True, online=online,
                                 online_every=4)
    ctrl.start(None, {})
    q, qd, _ = planar_reference(0.0)
    for k in range(4):
        ctrl(0.025 * k, q, qd, planar_reference)
        ctrl.observe(q + 0.01 * k, qd, np.full(3, 0.5 + 0.1 * k), 0.025 * (k + 1))
    twin = copy.deepcopy(ctrl)
    args = {"q": q, "qd": qd, "tau": np.ones(3), "t": 0.125}
    key, value = bad
    args[key] = value
    with pytest.raises(exc, match=match):
        ctrl.observe(args["q"], args["qd"], args["tau"], args["t"])
    for k in range(4, 14):  # the same ticks and observations for both: samples, gate weights and torques equal
        t = 0.025 * k
        np.testing.assert_array_equal(ctrl(t, q, qd, planar_reference), twin(t, q, qd, planar_reference))
        for c in (ctrl, twin):
            c.observe(q + 0.01 * k, qd, np.full(3, 0.5 + 0.1 * k), 0.025 * (k + 1))
    assert ctrl.n_innovation_samples == twin.n_innovation_samples > 0
    assert ctrl.n_online_samples == twin.n_online_samples == (3 if online else 0)
    np.testing.assert_array_equal(ctrl.innovation_errors[1], twin.innovation_errors[1])


def test_observe_rides_out_a_non_finite_reading(fitted_planar_model, arm3_rbd) -> None:
    """NaN readings, a NaN time or a repeated one (an unstable simulation step reports the last finite state) are
    sensor faults, as in a tick, never raised: a reading without a usable time is not used (counted in
    n_bad_measurements), and the samples that a NaN value spoils are refused and counted."""
    model = copy.deepcopy(fitted_planar_model)
    ctrl = FeedforwardController(model, 10.0, 1.0, np.full(3, 50.0), fallback=arm3_rbd, gate=True, online=4,
                                 online_every=1)
    ctrl.start(None, {})
    q, qd, _ = planar_reference(0.0)
    for k, t in enumerate([0.0, 0.025, np.nan, 0.075, 0.1, 0.1, 0.125, 0.15]):
        ctrl.observe(q, np.r_[np.nan, qd[1:]] if k == 3 else qd, np.ones(3), np.float32(t) if k == 1 else t)
    assert ctrl.n_bad_measurements == 2  # the NaN time and the repeated 0.1
    # no sample spans the NaN time; after it, the sample with the NaN velocity is refused, the next one taken
    assert ctrl.n_online_samples == 1 and ctrl.n_online_rejected == 1


@pytest.mark.parametrize("online", [None, 4])
def test_observe_skips_readings_whose_time_does_not_increase(fitted_planar_model, arm3_rbd, online) -> None:
    """A repeated, stale or out-of-order reading gave q̈ from a time difference of zero or of the wrong sign (a
    repeated stamp: twice the true q̈; one 2 ms back: the wrong sign), and that sample entered the gate and the
    window. Now such a reading is not used: the controller goes on as a twin that never got it (samples, gate
    errors, torques), and counts it in n_bad_measurements."""
    ctrl = FeedforwardController(copy.deepcopy(fitted_planar_model), 10.0, 1.0, np.full(3, 50.0), fallback=arm3_rbd,
                                 gate=True, online=online, online_every=1)
    twin = copy.deepcopy(ctrl)
    for c in (ctrl, twin):
        c.start(None, {})

    def reading(k: int):
        t = 0.025 * k
        q, qd, _ = planar_reference(t)
        return q, qd, np.full(3, 0.5 + 0.1 * k), t

    for k in range(12):
        q, qd, tau, t = reading(k)
        np.testing.assert_array_equal(ctrl(t, q, qd, planar_reference), twin(t, q, qd, planar_reference))
        for c in (ctrl, twin):
            c.observe(q, qd, tau, t)
        if k in (3, 7):
            ctrl.observe(q, qd + 0.5, tau, t)  # the same time again (a stale driver message), other values
        if k == 9:
            ctrl.observe(*reading(k - 1)[:3], t - 0.002)  # out of order
    assert ctrl.n_bad_measurements == 3 and twin.n_bad_measurements == 0
    assert ctrl.n_innovation_samples == twin.n_innovation_samples == 10
    assert ctrl.n_online_samples == twin.n_online_samples == (10 if online else 0)
    np.testing.assert_array_equal(ctrl.innovation_errors[1], twin.innovation_errors[1])


def test_a_bogus_time_ahead_or_a_restarted_clock_costs_a_few_samples(fitted_planar_model, arm3_rbd) -> None:
    """Readings are compared with the last one received, used or not: a single time stamp far ahead, or a clock
    that starts again from 0 without ``start()``, skips one reading and starts a new run of readings, instead
    of dropping every later reading of the episode."""
    ctrl = FeedforwardController(copy.deepcopy(fitted_planar_model), 10.0, 1.0, np.full(3, 50.0), fallback=arm3_rbd,
                                 gate=True, online=50, online_every=1)
    ctrl.start(None, {})
    q, qd, _ = planar_reference(0.0)
    for k in range(40):
        ctrl.observe(q + 0.01 * k, qd, np.ones(3), 1e6 if k == 5 else 0.025 * k)
    assert ctrl.n_bad_measurements == 1  # the reading after the bogus one
    # a sample from every used reading from the third on, but for the two that start the new run after the skip:
    # 4 up to the bogus reading (whose q̈ spans its bogus time), 31 after it (the previous rule kept 4 in all)
    assert ctrl.n_online_samples + ctrl.n_online_rejected == ctrl.n_innovation_samples == 35
    before = ctrl.n_innovation_samples
    for k in range(20):  # the same controller, its clock started again at 0
        ctrl.observe(q + 0.01 * k, qd, np.ones(3), 0.025 * k)
    assert ctrl.n_bad_measurements == 2 and ctrl.n_innovation_samples - before == 17


@pytest.mark.parametrize("t", [np.nan, np.inf, -np.inf, 10**400])
def test_a_tick_at_a_non_finite_time_names_t_and_changes_nothing(fitted_planar_model, arm3_rbd, t) -> None:
    """A tick's time selects the reference: a NaN time blamed the reference ('q_d at t=nan must be finite'), and
    with a reference that ignores t it was taken. Now ``ValueError`` names t, in a tick and in feedforward()."""
    ctrl = FeedforwardController(copy.deepcopy(fitted_planar_model), 10.0, 1.0, np.full(3, 50.0), fallback=arm3_rbd,
                                 gate=True, online=4)
    ctrl.start(None, {})
    q, qd, _ = planar_reference(0.1)
    ctrl(0.1, q, qd, planar_reference)
    twin = copy.deepcopy(ctrl)
    fixed = planar_reference(0.2)
    for ref in (planar_reference, lambda _: fixed):
        with pytest.raises(ValueError, match=r"^t: expected a (finite )?time \(s\)"):
            ctrl(t, q, qd, ref)
        with pytest.raises(ValueError, match=r"^t: expected a (finite )?time \(s\)"):
            ctrl.feedforward(t, ref)
    assert (ctrl.n_fallbacks, ctrl.n_bad_measurements) == (twin.n_fallbacks, twin.n_bad_measurements)
    np.testing.assert_array_equal(ctrl(0.125, q, qd, planar_reference), twin(0.125, q, qd, planar_reference))


def test_the_model_is_read_only(fitted_planar_model, arm3_rbd) -> None:
    """Assigning another model to a gated controller was taken silently, but its gate stayed bound to the old
    model, which went on supplying the feedforward (the name said the new one). The model is now read-only, with
    a message that says what to do; the controller is unchanged."""
    from cascgp.models import make_model

    ctrl = FeedforwardController(fitted_planar_model, 10.0, 1.0, np.full(3, 50.0), fallback=arm3_rbd, gate=True)
    for other in (copy.deepcopy(fitted_planar_model), make_model("np-inward", 3), None):
        with pytest.raises(AttributeError, match=r"^model: read-only .* build a new FeedforwardController"):
            ctrl.model = other
    assert ctrl.model is fitted_planar_model
    for copied in (copy.deepcopy(ctrl), pickle.loads(pickle.dumps(ctrl))):
        assert copied.model is not None and copied.name == ctrl.name


class _OwnModel:
    """A duck-typed learned model of three joints: a constant torque."""

    dof = 3

    def predict_one_var(self, q, qd, qdd, q_hist=None):
        return np.ones(3), np.full(3, 0.1)


class _NoHist(_OwnModel):
    def predict_one(self, q, qd, qdd):
        return np.ones(3)


class _WithHist(_OwnModel):
    def predict_one(self, q, qd, qdd, q_hist=None):
        return np.ones(3)


def test_an_own_model_is_refused_when_the_controller_could_not_call_it(arm3_rbd) -> None:
    """A model whose predict_one takes no q_hist was accepted, then fell back to the rigid-body torque on every tick
    (the TypeError of each call counted, nothing raised); a variance gate on a model without signal_var or
    prepare_variance raised AttributeError instead of the gate's ValueError."""
    LIM3 = np.full(3, 50.0)
    with pytest.raises(TypeError, match=r"^model: the controller calls predict_one\(q, qd, qdd, q_hist=\.\.\.\), and "
                                        r"_NoHist\.predict_one\(q, qd, qdd\) cannot take that"):
        FeedforwardController(_NoHist(), 1.0, 0.1, LIM3, fallback=arm3_rbd)
    bad = _WithHist()
    bad.predict_one = 5
    with pytest.raises(TypeError, match=r"^model: predict_one must be a method, got int on _WithHist"):
        FeedforwardController(bad, 1.0, 0.1, LIM3, fallback=arm3_rbd)
    ctrl = FeedforwardController(_WithHist(), 1.0, 0.1, LIM3, fallback=arm3_rbd)
    ctrl.start(None, {})
    q = np.zeros(3)
    ctrl(0.0, q, q, lambda t: (q, q, q))
    assert ctrl.n_fallbacks == 0
    for gate in ("variance", "wiener"):
        with pytest.raises(ValueError, match=r"^gate: needs a fitted cascgp model \(with predict_one_var, signal_var, "
                                             r"prepare_variance\), got _WithHist without signal_var, prepare_variance"):
            FeedforwardController(_WithHist(), 1.0, 0.1, LIM3, fallback=arm3_rbd, gate=gate)


class _VarNoHist(_WithHist):
    signal_var = np.ones(3)

    def predict_one_var(self, q, qd, qdd):
        return np.ones(3), np.full(3, 0.1)

    def prepare_variance(self):
        return None


def test_a_variance_gate_refuses_a_predict_one_var_without_q_hist(arm3_rbd) -> None:
    """The variance gates call predict_one_var(q, qd, qdd, q_hist=...): one without q_hist raised TypeError on every
    tick, each counted as a fallback to the rigid-body torque, nothing raised."""
    LIM3 = np.full(3, 50.0)
    for gate in ("variance", "wiener"):
        with pytest.raises(TypeError, match=r"^model: the controller calls predict_one_var\(q, qd, qdd, "
                                            r"q_hist=\.\.\.\), and _VarNoHist\.predict_one_var\(q, qd, qdd\) cannot"):
            FeedforwardController(_VarNoHist(), 1.0, 0.1, LIM3, fallback=arm3_rbd, gate=gate)
    ok = _VarNoHist()
    ok.predict_one_var = lambda q, qd, qdd, q_hist=None: (np.ones(3), np.full(3, 0.1))
    FeedforwardController(ok, 1.0, 0.1, LIM3, fallback=arm3_rbd, gate="variance")
