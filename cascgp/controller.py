r"""Feedforward torque controller (paper eq. 2).

.. math::

    \tau = f(q_d, \dot q_d, \ddot q_d) + K_p (q_d - q) + K_d (\dot q_d - \dot q)

where :math:`f` is a learned inverse-dynamics model (any of the twelve variants of
:mod:`cascgp.models`), the nominal rigid-body model alone, or zero (PD only). The
feedforward term is evaluated on the *reference*, as in the paper, so it depends
only on the task and never on the noisy measurements; the feedback term uses the
measured joint positions and velocities.

Safety guarantees (tested): the output is always finite and within
``[-torque_limits, torque_limits]``. If the model's output is not finite, or the model
raises any exception (kept in :attr:`FeedforwardController.last_model_error`), the
controller falls back to the rigid-body feedforward (or to zero when no RBD model
is given) and counts the event in :attr:`FeedforwardController.n_fallbacks`. A
non-finite measurement contributes no feedback on that joint (counted in
:attr:`FeedforwardController.n_bad_measurements`, as are the readings :meth:`FeedforwardController.observe` cannot
use).

Threads: a controller and its model belong to one thread. The model's single-query paths write into buffers of
the model, so two threads must not query one model at once (two controllers, or a monitor calling
``predict_one``): give each its own (``cascgp.load_model`` again, or ``copy.deepcopy``). To retrain while the robot
runs, fit a *new* model in the background and build a new controller with it (:attr:`FeedforwardController.model`
is read-only); refitting the controller's own model while it runs is a data race.

A gate (``FeedforwardController(gate=...)``) shrinks the learned correction toward the nominal model by one of the
rules of :mod:`cascgp.gates`.

:class:`Controller` is the protocol every controller run by :func:`cascgp.episodes.run_episode`
follows (this one, and e.g. ``jaco_env.oracle``'s oracle and PD controllers).
"""

from __future__ import annotations

import math
from typing import Any, Protocol

import numpy as np

from cascgp.checks import check_count
from cascgp.controller_args import (Reference, as_gain, check_finite_reference, check_predict_one, check_time,
                                    measured, reference_at)
from cascgp.data import all_finite
from cascgp.gates import (GATE_RULES, GATE_SUFFIXES, INNOVATION_HALF_LIFE_S, GateRule, InnovationGate, gate_weights,
                          innovation_weights, make_gate)

__all__ = ["Controller", "InverseDynamics", "FeedforwardController", "GateRule", "GATE_RULES", "GATE_SUFFIXES",
           "INNOVATION_HALF_LIFE_S", "gate_weights", "innovation_weights"]

_BIG = 1e300  # stands in for an overflowed feedback term; far beyond any actuator limit


class Controller(Protocol):
    """What the episode runner (:func:`cascgp.episodes.run_episode`) needs of a controller.

    ``start(env, info)`` is called right after ``env.reset`` with the unwrapped environment and
    the reset's ``info`` (reset per-episode state, read e.g. the payload); then every control
    tick ``__call__(t, q, qd, reference)`` returns the joint command for the measured state at
    time ``t``, with ``reference(t) -> (q_d, qd_d, qdd_d)``. A controller may count the ticks on
    which it fell back in ``n_fallbacks`` (the runner reads ``getattr(controller, "n_fallbacks", 0)``).
    A controller that learns from the measurements may define ``observe(q, qd, tau, t)``: the runner
    calls it after every step with the new measured joint state, torque and time.
    """

    @property
    def dof(self) -> int:
        """Number of joints N."""

    @property
    def name(self) -> str:
        """A label for tables and plots."""

    def start(self, env: Any, info: dict[str, Any]) -> None: ...

    def __call__(self, t: float, q: np.ndarray, qd: np.ndarray, reference: Reference) -> np.ndarray: ...


class InverseDynamics(Protocol):
    """Anything with ``inverse_dynamics(q, qd, qdd) -> tau`` (e.g. :class:`cascgp.rbd.RigidBodyModel`)."""

    dof: int

    def inverse_dynamics(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray: ...


class FeedforwardController:
    r"""PD feedback plus a model-based feedforward torque, clipped to the actuator limits.

    Args:
        model: the feedforward model: a fitted :mod:`cascgp.models` model (uses its lean
            ``predict_one`` path; another object with ``predict_one(q, qd, qdd, q_hist=None)`` returning the (N,)
            torques works too), an object with ``inverse_dynamics`` (e.g. the nominal
            :class:`~cascgp.rbd.RigidBodyModel`), or ``None`` for PD only.
        kp: proportional gains (N m / rad; N / m for a prismatic joint), scalar or per joint.
        kd: derivative gains (N m s / rad; N s / m for a prismatic joint), scalar or per joint.
        torque_limits: symmetric actuator limits (N m; N for a prismatic joint), per joint; their number is the
            controller's number of joints.
        fallback: rigid-body model used when ``model`` returns a non-finite torque
            (defaults to ``model`` itself if that is a rigid-body model, else an SP model's own ``rbd``,
            else zero); with ``gate`` it is also the nominal model the feedforward falls back toward.
        gate: fall back from the learned model toward the nominal one where the model is not to be trusted
            (needs a nominal model: ``fallback``, or an SP model's own ``rbd``): ``False`` (no gate), the name of a
            rule below, ``True`` (:func:`~cascgp.gates.default_rule`: ``"innovation"`` for derivative-based models,
            ``"wiener"`` for derivative-free ones) or a :class:`~cascgp.gates.GateRule` object (one per controller).
        online: learn inside the episode: at :meth:`start` the model opens an online window of this many
            samples (:meth:`cascgp.models.CascadedGPModel.start_online`, hyperparameters held) and every
            ``online_every``-th measurement (:meth:`observe`) enters it. ``None``: offline only.
        online_every: ticks between online samples (4 at 40 Hz control gives the 10 Hz of the training sets).

    The controller is called every control tick with the time, the measured state and
    the task's reference ``reference(t) -> (q_d, qd_d, qdd_d)``. Derivative-free models
    additionally get the reference positions at ``t - delta`` and ``t - 2 delta``.

    Gated feedforward (:mod:`cascgp.gates`): the learned correction :math:`d_j = \mu_j - \tau_{RBD,j}` (the model's
    mean torque minus the nominal torque) is shrunk toward zero by a weight :math:`w_j \in [0, 1]`,

    .. math::

        \tau_{ff,j} = \tau_{RBD,j} + w_j\, d_j ,

    with the weight of the rule ``gate`` (:math:`v_j`: the model's latent variance propagated through the cascade,
    :math:`p_j`: its prior variance):

    * ``"innovation"`` (:class:`~cascgp.gates.InnovationGate`): :math:`w_j = S_{0,j} / (S_{0,j} + S_{m,j})`, the
      discounted sums of the squared errors of the nominal and of the learned model on this episode's measured
      torques (every ``online_every``-th measurement, :meth:`observe`; half-life
      :data:`~cascgp.gates.INNOVATION_HALF_LIFE_S`), 1/2 before the first;
    * ``"wiener"`` (:class:`~cascgp.gates.WienerGate`): :math:`w_j = d_j^2 / (d_j^2 + v_j)`;
    * ``"floor"`` (:class:`~cascgp.gates.FloorGate`, semi-parametric models only): :math:`w_j = P_j / (P_j + v_j)`
      with :math:`P_j = \max(d_j^2, p_j)`;
    * ``"variance"`` (:class:`~cascgp.gates.VarianceGate`): :math:`w_j = \operatorname{clip}(1 - v_j / p_j, 0, 1)`.

    The weights of the last tick are in :attr:`last_gate`. What the gates cost and buy, measured:
    docs/studies/index.md.

    Example:
        >>> import numpy as np
        >>> reference = lambda t: (np.array([0.3, 0.0]), np.zeros(2), np.zeros(2))  # q_d, qd_d, qdd_d at t
        >>> pd = FeedforwardController(None, kp=10.0, kd=1.0, torque_limits=np.array([5.0, 5.0]))
        >>> pd.start(None, {})
        >>> pd(0.0, np.zeros(2), np.array([0.0, 1.0]), reference)  # Kp e + Kd e_dot, no feedforward
        array([ 3., -1.])
        >>> pd(0.0, np.array([-1.0, 0.0]), np.zeros(2), reference)  # clipped to the actuator limits
        array([5., 0.])

        With a fitted model (:mod:`cascgp.models`) the feedforward is ``model.predict_one(q_d, qd_d, qdd_d)``:
        ``FeedforwardController(model, kp, kd, limits, fallback=nominal_rbd, gate=True)``.
    """

    def __init__(
        self,
        model: Any | None,
        kp: float | np.ndarray,
        kd: float | np.ndarray,
        torque_limits: np.ndarray,
        fallback: InverseDynamics | None = None,
        gate: bool | str | GateRule = False,
        online: int | None = None,
        online_every: int = 4,
    ) -> None:
        self.dof = 0  # set from the limits: their setter checks them
        self.torque_limits = torque_limits
        self.dof = int(self._torque_limits.shape[0])
        self._model: Any = model  # duck-typed (predict_one / inverse_dynamics); None: PD only
        if model is not None:
            if not (hasattr(model, "predict_one") or hasattr(model, "inverse_dynamics")):
                raise TypeError("model: expected a fitted cascgp model, an object with inverse_dynamics(q, qd, qdd) "
                                f"or None (PD only), got {type(model).__name__}")
            check_predict_one(model)
            if getattr(model, "fitted", True) is False:
                raise ValueError(f"model: {getattr(model, 'name', type(model).__name__)} is not fitted (fit it "
                                 "first: model.fit(data))")
            model_dof = getattr(model, "dof", self.dof)
            if int(model_dof) != self.dof:
                raise ValueError(f"model.dof ({model_dof}) does not match torque_limits ({self.dof} joints)")
        self.kp, self.kd = kp, kd  # the properties' setters check them (one per joint of the limits)
        if fallback is not None:
            if not hasattr(fallback, "inverse_dynamics"):
                raise TypeError("fallback: expected a rigid-body model (an object with inverse_dynamics(q, qd, qdd)) "
                                f"or None, got {type(fallback).__name__}")
            fallback_dof = getattr(fallback, "dof", self.dof)
            if int(fallback_dof) != self.dof:
                raise ValueError(f"fallback.dof ({fallback_dof}) does not match torque_limits ({self.dof} joints)")
        if fallback is None and model is not None and hasattr(model, "inverse_dynamics"):
            fallback = model
        if fallback is None and model is not None and getattr(model, "rbd", None) is not None:
            fallback = model.rbd  # an SP model's own nominal model (the module docstring's promise)
        self.fallback = fallback
        rule = make_gate(gate, model)
        if rule is not None:
            rule.bind(model, fallback, self.dof)
            assert fallback is not None  # bind refuses a missing nominal model
            self._nominal: InverseDynamics = fallback
        self.gate_rule: GateRule | None = rule
        self.gate: str | None = rule.name if rule is not None else None
        self.last_gate: np.ndarray | None = None
        if online is not None:
            if not hasattr(model, "start_online"):
                raise ValueError(f"online: needs a fitted cascgp model, got {type(model).__name__}")
            if isinstance(online, bool) or not isinstance(online, (int, np.integer)) or online < 1:
                raise ValueError(f"online: expected None or a window of >= 1 samples, got {online!r}")
            from cascgp.models.online import check_supported

            check_supported(model, int(online), "online")  # also its memory: refused here, not at start()
        online_every = check_count(online_every, "online_every")
        self.online = None if online is None else int(online)
        self.online_every = online_every
        self._recent: list[tuple[float, np.ndarray, np.ndarray, np.ndarray]] = []
        self._t_received = -math.inf  # the time of the last reading observe() got (used or not)
        self._n_observed = 0
        self.n_online_samples = 0
        self.n_online_rejected = 0
        self._uses_history = getattr(model, "feature_kind", "db") == "df"
        self._delta = float(getattr(model, "df_delta", 0.0) or 0.0)
        self.n_fallbacks = 0
        self.n_bad_measurements = 0
        self.last_model_error: str | None = None

    def __setstate__(self, state: dict[str, Any]) -> None:
        """A copy or an unpickled controller keeps its limits and gains read-only (copying makes arrays writable)."""
        self.__dict__.update(state)
        for name in ("_torque_limits", "_neg_limits", "_kp", "_kd"):
            getattr(self, name).setflags(write=False)

    @property
    def model(self) -> Any:
        """The feedforward model given at construction (read-only: its gate and online window are bound to it). To
        use a retrained model, build a new controller with it, as :mod:`cascgp.learning` does between attempts."""
        return self._model

    @model.setter
    def model(self, value: Any) -> None:
        raise AttributeError("model: read-only (the controller's gate and online window are bound to its model); "
                             "build a new FeedforwardController for another model")

    @property
    def torque_limits(self) -> np.ndarray:
        """Symmetric actuator limits (N m), one per joint, as a read-only array. Assigning new limits (as many
        joints) validates them as the constructor does (``ValueError`` for a non-finite or non-positive limit or
        another shape, nothing changed); every later output lies within them."""
        return self._torque_limits

    @torque_limits.setter
    def torque_limits(self, value: Any) -> None:
        limits = np.asarray(value)
        if limits.dtype.kind not in "fiu" or limits.ndim != 1 or limits.size == 0 or \
                not np.all(np.isfinite(limits)) or not np.all(limits > 0):
            raise ValueError(f"torque_limits must be a 1-D array of finite positive values, got {value!r}")
        if self.dof and limits.shape != (self.dof,):
            raise ValueError(f"torque_limits: expected {self.dof} limits (one per joint), got shape {limits.shape}")
        limits = limits.astype(float)  # a copy: the caller's array cannot change the limits later
        limits.setflags(write=False)
        neg = -limits
        neg.setflags(write=False)
        self._torque_limits, self._neg_limits = limits, neg

    @property
    def kp(self) -> np.ndarray:
        """Proportional gains (N m / rad; N / m for a prismatic joint), one per joint, as a read-only array.
        Assigning a scalar or per-joint values (gain scheduling) validates them as the constructor does
        (``ValueError`` for a negative or non-finite gain, nothing changed)."""
        return self._kp

    @kp.setter
    def kp(self, value: float | np.ndarray) -> None:
        self._kp = as_gain(value, self.dof, "kp")

    @property
    def kd(self) -> np.ndarray:
        """Derivative gains (N m s / rad; N s / m for a prismatic joint), one per joint, read-only; assignment as
        for :attr:`kp`."""
        return self._kd

    @kd.setter
    def kd(self, value: float | np.ndarray) -> None:
        self._kd = as_gain(value, self.dof, "kd")

    @property
    def name(self) -> str:
        """Short description of the feedforward source."""
        if self._model is None:
            return "pd"
        name = str(getattr(self._model, "name", type(self._model).__name__))
        gate = self.gate_rule.suffix if self.gate_rule is not None else ""
        return name + gate + ("-online" if self.online else "")

    def feedforward(self, t: float, reference: Reference) -> np.ndarray:
        """The feedforward torque at time ``t`` (finite, not yet clipped); a reference as :meth:`__call__` takes."""
        check_time(t)
        q_d, qd_d, qdd_d = reference_at(reference, t, self.dof)
        check_finite_reference(q_d, qd_d, qdd_d, t)
        return self._feedforward(t, q_d, qd_d, qdd_d, reference)

    def _feedforward(
        self, t: float, q_d: np.ndarray, qd_d: np.ndarray, qdd_d: np.ndarray, reference: Reference
    ) -> np.ndarray:
        if self._model is None:
            return np.zeros(self.dof)
        tau = self._model_torque(t, q_d, qd_d, qdd_d, reference)
        if tau is not None and tau.shape == (self.dof,) and all_finite(tau):
            return tau
        if tau is not None:  # an output, but not one torque per joint, finite
            self.last_model_error = (f"the model returned shape {tau.shape}, expected ({self.dof},)"
                                     if tau.shape != (self.dof,) else "the model returned a non-finite torque")
        self.n_fallbacks += 1
        if self.fallback is not None and self.fallback is not self._model:
            try:
                tau = np.asarray(self.fallback.inverse_dynamics(q_d, qd_d, qdd_d), dtype=float)
            except Exception as exc:  # noqa: BLE001 - the fallback must not stop the loop either
                self.last_model_error = f"fallback: {type(exc).__name__}: {exc}"
                tau = None
            if tau is not None and tau.shape == (self.dof,) and all_finite(tau):
                return tau
        return np.zeros(self.dof)

    def _model_torque(
        self, t: float, q_d: np.ndarray, qd_d: np.ndarray, qdd_d: np.ndarray, reference: Reference
    ) -> np.ndarray | None:
        model = self._model
        try:
            if hasattr(model, "predict_one"):
                q_hist = None
                if self._uses_history:
                    q_hist = np.stack([reference(t - self._delta)[0], reference(t - 2.0 * self._delta)[0]])
                if self.gate_rule is not None:
                    return self._gated(self.gate_rule, q_d, qd_d, qdd_d, q_hist)
                return np.asarray(model.predict_one(q_d, qd_d, qdd_d, q_hist=q_hist), dtype=float)
            return np.asarray(model.inverse_dynamics(q_d, qd_d, qdd_d), dtype=float)
        except Exception as exc:  # noqa: BLE001
            # Whatever the model raises (a rejected input, a numerical failure, a bug in a
            # user model) is a fallback event, never a crash of the control loop; the last
            # error is kept for diagnosis. KeyboardInterrupt and SystemExit still stop it.
            self.last_model_error = f"{type(exc).__name__}: {exc}"
            return None

    def _gated(self, rule: GateRule, q_d: np.ndarray, qd_d: np.ndarray, qdd_d: np.ndarray, q_hist: np.ndarray | None
               ) -> np.ndarray:
        """The gated feedforward of ``rule`` (:mod:`cascgp.gates`)."""
        nominal = np.asarray(self._nominal.inverse_dynamics(q_d, qd_d, qdd_d), dtype=float)
        d, w = rule.correction(q_d, qd_d, qdd_d, q_hist, nominal)
        self.last_gate = w
        return nominal + w * d

    def __call__(self, t: float, q: np.ndarray, qd: np.ndarray, reference: Reference) -> np.ndarray:
        """Joint torques for the measured state ``(q, qd)`` at time ``t``; always finite and within limits.
        Malformed arguments (``t`` not a finite real number, ``q``/``qd`` not real ``(N,)`` arrays) or a reference
        that does not return three finite real ``(N,)`` arrays raise ``TypeError``/``ValueError`` naming them, and
        change nothing. A non-finite *measurement* is a sensor fault, not an error: no feedback on that joint
        (:attr:`n_bad_measurements`)."""
        check_time(t)
        q, qd = measured("q", q, self.dof), measured("qd", qd, self.dof)
        q_d, qd_d, qdd_d = reference_at(reference, t, self.dof)  # once per tick; shared with the feedforward
        if not all_finite(qdd_d):  # q_d and qd_d: by the feedback's finiteness below
            check_finite_reference(q_d, qd_d, qdd_d, t)
        # Kp (q_d - q) + Kd (qd_d - qd) in Python floats: the same IEEE double operations in the same order as
        # NumPy's, bit for bit, but an overflow or inf - inf gives inf or NaN without a floating-point warning,
        # so the usual tick needs neither np.errstate (a third of this form's cost) nor array temporaries.
        fb = [p * (a - b) + d * (c - e) for p, a, b, d, c, e in
              zip(self._kp.tolist(), q_d.tolist(), q.tolist(), self._kd.tolist(), qd_d.tolist(), qd.tolist())]
        if all(map(math.isfinite, fb)):
            feedback = np.array(fb)  # so q_d and qd_d are finite too (0 * inf is NaN)
        else:
            # A finite feedback needs all four inputs finite and no overflow: then it equals the general form
            # below, which this tick needs only for a non-finite measurement or an absurd error.
            check_finite_reference(q_d, qd_d, qdd_d, t)
            feedback = self._feedback_nonfinite(q, qd, q_d, qd_d)
        tau = self._feedforward(t, q_d, qd_d, qdd_d, reference) + feedback
        return np.minimum(np.maximum(tau, self._neg_limits), self._torque_limits)  # np.clip, without its wrapper

    def _feedback_nonfinite(self, q: np.ndarray, qd: np.ndarray, q_d: np.ndarray, qd_d: np.ndarray) -> np.ndarray:
        """The feedback torque when a measurement is not finite or an error overflows."""
        bad = ~(np.isfinite(q) & np.isfinite(qd))  # the reference is finite (checked)
        self.n_bad_measurements += bool(np.any(bad))
        with np.errstate(over="ignore", invalid="ignore"):
            # A finite but absurd error saturates with its sign (overflow to +-inf is capped
            # before the sum so that P and D terms of opposite sign cannot make inf - inf).
            terms = np.nan_to_num(np.stack([self.kp * (q_d - q), self.kd * (qd_d - qd)]), nan=0.0,
                                  posinf=_BIG, neginf=-_BIG)
        return np.where(bad, 0.0, terms.sum(axis=0))

    def start(self, env: Any, info: dict[str, Any]) -> None:
        """Start of an episode (:class:`Controller` protocol; ``env`` and ``info``, the environment and its reset
        info, are not used): zero the counters; with ``online``, open a fresh online window on the model (samples
        of earlier episodes enter only through retraining)."""
        self.reset_counters()
        self._recent, self._n_observed, self._t_received = [], 0, -math.inf
        self.n_online_samples = self.n_online_rejected = 0
        self.last_gate, self.last_model_error = None, None
        if self.online:
            self._model.start_online(self.online)
        elif hasattr(self._model, "stop_online"):
            self._model.stop_online()  # an offline controller uses the fitted model, not an earlier episode's window
        if self.gate_rule is not None:
            self.gate_rule.start()  # after the window: a variance rule prepares the variance path of this episode

    def observe(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, t: float) -> None:
        """A new measurement, after every tick (the episode runner calls it after every step): the measured
        ``q``, ``qd`` at the end of the control period, the joint torque ``tau`` measured over it (a torque
        sensor's reading; without one, the best estimate of the torque applied), and the time ``t`` (s) of
        that reading. A controller with the innovation gate (``gate=True`` with a derivative-based model) or
        ``online`` needs these calls: without them the gate's weights stay 1/2 and nothing is learned.

        Every ``online_every``-th call makes a sample of the *previous* tick: its q and qd, q̈ by central
        differences of the measured qd (as the recorded episodes), and the torque measured over the period that
        started at that tick (reported now). A gate rule that observes (the innovation rule) gets the sample
        first (an error it raises is kept in ``last_model_error``); with ``online`` it then enters the model. A
        sample the model refuses (non-finite values, a sensor fault or an unstable step's) is counted in
        ``n_online_rejected``, never raised. A reading whose time is not after the previous reading's (a stale,
        repeated or out-of-order reading, which would give a wrong q̈) or not finite is not used and is counted in
        ``n_bad_measurements``; no sample spans a non-finite time, and one used after a jump back in time starts
        a new run of readings (a bogus time far ahead costs a few samples, not the episode). Malformed arguments
        (``q``/``qd``/``tau`` not real ``(N,)`` arrays, ``t`` not a real number) raise ``TypeError``/``ValueError``
        naming them and change nothing."""
        t = check_time(t, finite=False)  # a reading's NaN time is a sensor fault, as its NaN values
        q, qd, tau = measured("q", q, self.dof), measured("qd", qd, self.dof), measured("tau", tau, self.dof)
        rule = self.gate_rule if self.gate_rule is not None and self.gate_rule.observes else None
        if not self.online and rule is None:
            return
        if not self._t_received < t < math.inf:  # not finite, or not after the last reading (stale, out of order)
            self.n_bad_measurements += 1
            if math.isfinite(t):
                self._t_received = t
            else:
                self._recent = []  # a gap: no sample spans it (as the episode runner starts a new segment)
            return
        self._t_received = t
        if self._recent and not t > self._recent[-1][0]:
            self._recent = []  # after a time jump (back, or a bogus one ahead): a new run of readings
        self._recent = (self._recent + [(t, q.copy(), qd.copy(), tau.copy())])[-3:]
        self._n_observed += 1
        if self._n_observed % self.online_every or len(self._recent) < 3:
            return
        (t0, _, qd0, _), (t1, q1, qd1, _), (t2, _, qd2, tau2) = self._recent
        with np.errstate(all="ignore"):  # a non-finite difference is refused by add_sample below
            qdd1 = (qd2 - qd0) / (t2 - t0)
        if rule is not None:
            try:
                rule.observe(t1, q1, qd1, qdd1, tau2)
            except Exception as exc:  # noqa: BLE001 - the gate must never stop the control loop
                self.last_model_error = f"{rule.name}: {type(exc).__name__}: {exc}"
        if not self.online:
            return
        try:
            self._model.add_sample(q1, qd1, qdd1, tau2)
            self.n_online_samples += 1
        except Exception as exc:  # noqa: BLE001 - learning must never stop the control loop
            self.n_online_rejected += 1
            self.last_model_error = f"online: {type(exc).__name__}: {exc}"

    @property
    def innovation_errors(self) -> tuple[np.ndarray, np.ndarray]:
        """The innovation gate's discounted error sums ``(S_0, S_m)`` of this episode, per joint (N² m², copies;
        zeros without that gate)."""
        if isinstance(self.gate_rule, InnovationGate):
            return self.gate_rule.errors
        return np.zeros(self.dof), np.zeros(self.dof)

    @property
    def n_innovation_samples(self) -> int:
        """Samples the innovation gate has taken this episode (0 without that gate)."""
        return self.gate_rule.n_samples if isinstance(self.gate_rule, InnovationGate) else 0

    def reset_counters(self) -> None:
        """Zero the fallback and bad-measurement counters (e.g. at the start of an episode)."""
        self.n_fallbacks = 0
        self.n_bad_measurements = 0
