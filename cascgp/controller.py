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
:attr:`FeedforwardController.n_bad_measurements`).

:class:`Controller` is the protocol every controller run by :func:`cascgp.episodes.run_episode`
follows (this one, and e.g. ``jaco_env.oracle``'s oracle and PD controllers).
"""

from __future__ import annotations

from typing import Any, Callable, Protocol

import numpy as np

_BIG = 1e300  # stands in for an overflowed feedback term; far beyond any actuator limit

Reference = Callable[[float], tuple[np.ndarray, np.ndarray, np.ndarray]]


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
    def dof(self) -> int: ...

    @property
    def name(self) -> str: ...

    def start(self, env: Any, info: dict[str, Any]) -> None: ...

    def __call__(self, t: float, q: np.ndarray, qd: np.ndarray, reference: Reference) -> np.ndarray: ...


class InverseDynamics(Protocol):
    """Anything with ``inverse_dynamics(q, qd, qdd) -> tau`` (e.g. :class:`cascgp.rbd.RigidBodyModel`)."""

    dof: int

    def inverse_dynamics(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray: ...


def _as_gain(value: float | np.ndarray, dof: int, name: str) -> np.ndarray:
    gain = np.broadcast_to(np.asarray(value, dtype=float), (dof,)).copy()
    if not np.all(np.isfinite(gain)) or np.any(gain < 0):
        raise ValueError(f"{name} must be finite and non-negative, got {gain}")
    return gain


#: The gate rules of :class:`FeedforwardController` (see its docstring).
GATE_RULES = ("wiener", "floor", "variance", "innovation")
#: Controller-name suffix of each rule (:attr:`FeedforwardController.name`, :func:`cascgp.learning.parse_controller`).
GATE_SUFFIXES = {"wiener": "-gated", "floor": "-fgated", "variance": "-vgated", "innovation": "-igated"}
#: Half-life (s) of the innovation gate's error sums: a model's error counts half after this time. Fixed before the
#: rule was run (docs/gate_rule.md): a task's reference crosses its part of the workspace in seconds, so errors
#: older than about a second were made at other states; at the 10 Hz of the samples the half-life is 10 samples,
#: and the discounted weights add up to about 15 samples.
INNOVATION_HALF_LIFE_S = 1.0


def innovation_weights(err_nominal: np.ndarray, err_model: np.ndarray) -> np.ndarray:
    r"""The innovation gate's weights on the learned correction: :math:`w = S_0 / (S_0 + S_m)`, with :math:`S_0`
    and :math:`S_m` the discounted sums of the squared errors of the nominal and the learned model on the
    episode's measured samples (:class:`FeedforwardController`, ``gate="innovation"``); 1/2 where both are 0 (no
    evidence yet), 0 where either is NaN; an infinite sum counts as larger than any finite one."""
    s0 = np.asarray(err_nominal, dtype=float)
    sm = np.asarray(err_model, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        w = np.where(s0 + sm > 0.0, s0 / (s0 + sm), 0.5)
        # where the sum overflows: divided by the larger sum, so that huge (even infinite) sums keep their limit
        scaled = np.where(s0 >= sm, 1.0 / (1.0 + sm / s0), (s0 / sm) / (1.0 + s0 / sm))
        w = np.where(np.isfinite(s0 + sm), w, scaled)
    return np.where(np.isfinite(w) & ~np.isnan(s0) & ~np.isnan(sm), w, 0.0)


def gate_weights(correction: np.ndarray, var: np.ndarray, rule: str = "wiener",
                 prior: np.ndarray | None = None) -> np.ndarray:
    r"""The gate's weights :math:`w \in [0, 1]` on a learned correction (:class:`FeedforwardController`, ``gate``).

    Args:
        correction: :math:`d`, the model's mean torque minus the nominal torque, any shape.
        var: :math:`v`, the model's (propagated) latent variance, the same shape.
        rule: ``"wiener"``: :math:`d^2 / (d^2 + v)` (1 where both are 0); ``"floor"``: the same with the
            correction's power floored at ``prior`` :math:`p` (the GP's signal variance),
            :math:`P / (P + v)` with :math:`P = \max(d^2, p)` (1 where both are 0); ``"variance"``:
            :math:`\operatorname{clip}(1 - v / p, 0, 1)`. ``prior`` is broadcast against ``var``.

    Returns:
        The weights; 0 (the nominal torque) where a weight, a correction or a variance is not finite.
    """
    d = np.asarray(correction, dtype=float)
    v = np.asarray(var, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        if rule == "wiener":
            d2 = d * d
            w = np.where(d2 + v > 0.0, d2 / (d2 + v), 1.0)
        elif rule in ("floor", "variance"):
            if prior is None:
                raise ValueError(f"gate_weights: rule {rule!r} needs the prior variance")
            p = np.asarray(prior, dtype=float)
            if rule == "floor":
                power = np.maximum(d * d, p)
                w = np.where(power + v > 0.0, power / (power + v), 1.0)
            else:
                w = np.clip(1.0 - v / p, 0.0, 1.0)
        else:
            raise ValueError(f"gate_weights: rule must be one of {GATE_RULES}, got {rule!r}")
    return np.where(np.isfinite(w) & np.isfinite(d) & np.isfinite(v), w, 0.0)


class FeedforwardController:
    r"""PD feedback plus a model-based feedforward torque, clipped to the actuator limits.

    Args:
        model: the feedforward model: a fitted :mod:`cascgp.models` model (uses its lean
            ``predict_one`` path), an object with ``inverse_dynamics`` (e.g. the nominal
            :class:`~cascgp.rbd.RigidBodyModel`), or ``None`` for PD only.
        kp: proportional gains (N m / rad), scalar or per joint.
        kd: derivative gains (N m s / rad), scalar or per joint.
        torque_limits: symmetric actuator limits (N m), per joint.
        fallback: rigid-body model used when ``model`` returns a non-finite torque
            (defaults to ``model`` itself if that is a rigid-body model, else an SP model's own ``rbd``,
            else zero); with ``gate``
            it is also the nominal model the feedforward falls back toward.
        gate: fall back from the learned model toward the nominal one where the model is not to be trusted
            (needs a nominal model: ``fallback``, or an SP model's own ``rbd``; and a cascgp model with
            ``predict_one_var`` for the variance rules, ``predict_one`` for the innovation rule):
            ``False``, ``True`` (the default rule: ``"innovation"`` for derivative-based models, ``"wiener"``
            for derivative-free ones), ``"innovation"``, ``"wiener"``, ``"floor"`` (semi-parametric models
            only) or ``"variance"``; see below.
        online: learn inside the episode: at :meth:`start` the model opens an online window of this many
            samples (:meth:`cascgp.models.CascadedGPModel.start_online`, hyperparameters held) and every
            ``online_every``-th measurement (:meth:`observe`) enters it. ``None``: offline only.
        online_every: ticks between online samples (4 at 40 Hz control gives the 10 Hz of the training sets).

    Gated feedforward: the learned correction :math:`d_j = \mu_j - \tau_{RBD,j}` (the model's mean torque
    minus the nominal torque) is shrunk toward zero by a weight :math:`w_j \in [0, 1]`,

    .. math::

        \tau_{ff,j} = \tau_{RBD,j} + w_j\, d_j, \qquad
        w_j^{\text{wiener}} = \frac{d_j^2}{d_j^2 + v_j}, \qquad
        w_j^{\text{floor}} = \frac{P_j}{P_j + v_j},\ P_j = \max(d_j^2, p_j), \qquad
        w_j^{\text{variance}} = \operatorname{clip}\Big(1 - \frac{v_j}{p_j},\ 0,\ 1\Big),

    with :math:`v_j` the model's latent variance propagated through the cascade
    (:meth:`cascgp.models.CascadedGPModel.predict_one_var`) and :math:`p_j` its prior (signal) variance.
    One rule for every joint, task and model, no threshold to tune:

    * ``"wiener"`` (the default before the innovation rule; still ``True``'s rule for derivative-free models): the
      Wiener gain of a correction of size :math:`d_j` estimated with noise variance
      :math:`v_j`, with :math:`d_j^2` plugged in as the correction's power: a correction well above its
      uncertainty is kept, one within its uncertainty is shrunk. Near the data (:math:`v \to 0`) it is the
      learned model.
    * ``"floor"``: the Wiener gain with the correction's power floored at the GP's own signal variance
      :math:`p_j` (its prior variance, learned by the marginal likelihood over the training data). The Wiener
      rule plugs in :math:`d_j^2` alone, so a correction smaller than its standard deviation is removed almost
      entirely (:math:`w_j d_j \approx d_j^3 / v_j`), however systematic it is. With the floor, a correction is
      never treated as weaker than what the GP learned corrections are; where :math:`v_j \le p_j` (always for a
      single GP; the propagated variance can exceed :math:`p_j` slightly) at least half of it is kept, and a
      correction well above its uncertainty is kept as by the Wiener rule (:math:`w^{\text{floor}} \ge
      w^{\text{wiener}}` everywhere). Why: on a new task the Wiener rule removed a small but systematic wrist
      correction, and the learner's later models were worse for it (docs/lag_diagnosis.md; tested as a
      replacement in docs/gate_rule.md). Semi-parametric models only: there the GP's prior is the prior of the
      correction to the RBD; an NP model's GP prior is about the torque itself.
    * ``"innovation"`` (``True``'s rule for derivative-based models): the evidence of this episode's torque
      sensors instead of the GP's variance. At every
      ``online_every``-th measurement (:meth:`observe`, the samples online learning would take: measured q and
      q̇, q̈ by central differences, the measured torque :math:`\tau`) the squared errors of the nominal and of the
      learned model enter discounted sums, and

      .. math::

          S_{0,j} \leftarrow \lambda S_{0,j} + (\tau_j - \tau_{RBD,j})^2, \quad
          S_{m,j} \leftarrow \lambda S_{m,j} + (\tau_j - \mu_j)^2, \quad
          \lambda = 2^{-\Delta t / t_{1/2}}, \qquad w_j = \frac{S_{0,j}}{S_{0,j} + S_{m,j}},

      the weight of two forecasts by their inverse mean squared errors (Bates and Granger, 1969), with the
      half-life :data:`INNOVATION_HALF_LIFE_S`. Before the first sample of an episode (0.1 s at 40 Hz control
      with ``online_every=4``) :math:`w = 1/2`. It trusts a model that has been predicting this episode's torques
      better than the nominal one, however unsure the GP is, and falls back toward the RBD when the model errs
      more, however sure it is. This weight is MSE-optimal for *uncorrelated* errors; here both errors contain
      the same measurement noise (torque sensor, q̈ by differences), so where both models are good the weight is
      pulled toward 1/2: with a nominal error :math:`b` and a shared noise variance :math:`\sigma^2`, a right model
      gets :math:`(b^2 + \sigma^2) / (b^2 + 2 \sigma^2)`. The regression form
      :math:`\sum \lambda\, e_0 d / \sum \lambda\, d^2` (clipped to [0, 1]) would cancel the shared noise; it
      has not been tested. The weight is per joint, not per state: the errors of the last seconds stand for the
      part of the workspace the reference is in.
      Any derivative-based model (SP or NP); the errors are taken before a sample enters an online window.
      Measured as a learner on new seeds (docs/gate_rule.md, pre-registered): after three attempts on a new task
      it ends at 1.05 x the ungated learner in the median (the Wiener rule 1.36 x on other new seeds), and its
      first attempts there stay at 0.15-0.39 x RBD.
    * ``"variance"``: the fraction of the prior uncertainty the data have removed at this point. It shrinks
      any correction, however large, as soon as the query leaves the training data; measured on the task
      transfer it gave up most of what the model had learned (README, "uncertainty-aware feedforward"),
      because the GP posterior mean already reverts toward its prior away from data and this gate shrinks
      it a second time. Kept for comparison.

    For an SP model the correction is the learned residual, for an NP model the difference to the RBD.
    The weights of the last tick are in :attr:`last_gate`.

    What a gate can and cannot buy. If the GP's posterior were right, :math:`\tau_j \sim \mathcal N(\mu_j, v_j)`
    and the expected squared error of the gated feedforward would be

    .. math::

        \mathbb E\big[(\tau_j - \tau_{RBD,j} - w_j d_j)^2\big] = (1 - w_j)^2 d_j^2 + v_j ,

    smallest at :math:`w_j = 1`: under the model's own beliefs any shrinkage toward the RBD costs
    :math:`(1 - w_j)^2 d_j^2`; the posterior mean has already moved away from its prior only as far as the data
    warrant. A gate is insurance against the model being wrong by more than :math:`v_j` (e.g. on a new part of
    the workspace), paid for with that cost where the model is right. Measured (docs/learner_divergence.md): on
    any one model the Wiener gate costs about nothing in the median, but a learner that uses it collects other
    data: on one task of four its model stayed about 1.35 x worse after three refits, because on that task's first
    attempt the gate shrank the wrist correction, the wrist strayed from the reference, and the models fitted on
    that episode were worse at the wrist (docs/lag_diagnosis.md; replicated on new seeds). The innovation rule
    insures against a wrong model with the torque sensors' evidence instead. It pays less on a right model than
    the variance gates, but not nothing: on "front" its learner ends at 1.07 x the ungated one in the median over
    8 seeds (a re-seeded ungated learner: 1.00), and on one model it costs 1.06-1.08 after three attempts in the
    quick transfer (the Wiener rule there: 1.01-1.03; docs/gate_rule.md).

    The controller is called every control tick with the time, the measured state and
    the task's reference ``reference(t) -> (q_d, qd_d, qdd_d)``. Derivative-free models
    additionally get the reference positions at ``t - delta`` and ``t - 2 delta``.
    """

    def __init__(
        self,
        model: Any | None,
        kp: float | np.ndarray,
        kd: float | np.ndarray,
        torque_limits: np.ndarray,
        fallback: InverseDynamics | None = None,
        gate: bool | str = False,
        online: int | None = None,
        online_every: int = 4,
    ) -> None:
        limits = np.asarray(torque_limits)
        if limits.dtype.kind not in "fiu" or limits.ndim != 1 or limits.size == 0 or \
                not np.all(np.isfinite(limits)) or not np.all(limits > 0):
            raise ValueError(f"torque_limits must be a 1-D array of finite positive values, got {torque_limits!r}")
        self.torque_limits = limits.astype(float)
        self.dof = int(self.torque_limits.shape[0])
        self.kp = _as_gain(kp, self.dof, "kp")
        self.kd = _as_gain(kd, self.dof, "kd")
        self.model: Any = model  # duck-typed (predict_one / inverse_dynamics); None: PD only
        if model is not None:
            model_dof = getattr(model, "dof", self.dof)
            if int(model_dof) != self.dof:
                raise ValueError(f"model.dof ({model_dof}) does not match torque_limits ({self.dof} joints)")
        if fallback is None and model is not None and hasattr(model, "inverse_dynamics"):
            fallback = model
        if fallback is None and model is not None and getattr(model, "rbd", None) is not None:
            fallback = model.rbd  # an SP model's own nominal model (the module docstring's promise)
        self.fallback = fallback
        if gate is True:  # the default rule (docs/gate_rule.md): innovation where the model's states allow it
            gate = "innovation" if getattr(model, "feature_kind", "db") == "db" else "wiener"
        if gate is not False and gate is not None and gate not in GATE_RULES:
            raise ValueError(f"gate: expected False, True or one of {GATE_RULES}, got {gate!r}")
        if gate == "innovation" and getattr(model, "feature_kind", "db") != "db":
            raise ValueError("gate 'innovation': needs a derivative-based model (its errors are taken at the measured "
                             f"q, qd and q̈), got {getattr(model, 'name', type(model).__name__)}")
        if gate == "floor" and getattr(model, "parametric", None) != "sp":
            raise ValueError("gate 'floor': needs a semi-parametric cascgp model (its GP's prior is the prior of "
                             f"the correction to the RBD), got {getattr(model, 'name', type(model).__name__)}; "
                             "use 'wiener' or 'variance' for other models")
        self.gate: str | None = gate or None
        self.last_gate: np.ndarray | None = None
        if self.gate:
            needs = "predict_one" if self.gate == "innovation" else "predict_one_var"
            if model is None or not hasattr(model, needs):
                raise ValueError(f"gate: needs a fitted cascgp model (with {needs}), got {type(model).__name__}")
            if fallback is None:  # an SP model's own rbd became the fallback above
                raise ValueError("gate: needs a nominal rigid-body model to fall back toward: pass fallback=... "
                                 "(an SP model's own rbd is used when there is none)")
            self._nominal: InverseDynamics = fallback
            self._prior = None if self.gate == "innovation" else np.asarray(model.signal_var, dtype=float)
        if online is not None:
            if not hasattr(model, "start_online"):
                raise ValueError(f"online: needs a fitted cascgp model, got {type(model).__name__}")
            if isinstance(online, bool) or not isinstance(online, (int, np.integer)) or online < 1:
                raise ValueError(f"online: expected None or a window of >= 1 samples, got {online!r}")
            from cascgp.models.online import check_supported

            check_supported(model)
        if isinstance(online_every, bool) or not isinstance(online_every, (int, np.integer)) or online_every < 1:
            raise ValueError(f"online_every: expected an integer >= 1, got {online_every!r}")
        self.online = None if online is None else int(online)
        self.online_every = int(online_every)
        self._recent: list[tuple[float, np.ndarray, np.ndarray, np.ndarray]] = []
        self._err_nominal = np.zeros(self.dof)
        self._err_model = np.zeros(self.dof)
        # the weights change only when a sample arrives (every online_every-th tick), not every tick
        self._innovation_w = innovation_weights(self._err_nominal, self._err_model)
        self._t_innovation: float | None = None
        self.n_innovation_samples = 0
        self._n_observed = 0
        self.n_online_samples = 0
        self.n_online_rejected = 0
        self._uses_history = getattr(model, "feature_kind", "db") == "df"
        self._delta = float(getattr(model, "df_delta", 0.0) or 0.0)
        self.n_fallbacks = 0
        self.n_bad_measurements = 0
        self.last_model_error: str | None = None

    @property
    def name(self) -> str:
        """Short description of the feedforward source."""
        if self.model is None:
            return "pd"
        name = str(getattr(self.model, "name", type(self.model).__name__))
        gate = GATE_SUFFIXES.get(self.gate, "") if self.gate else ""
        return name + gate + ("-online" if self.online else "")

    def feedforward(self, t: float, reference: Reference) -> np.ndarray:
        """The feedforward torque at time ``t`` (finite, not yet clipped)."""
        return self._feedforward(t, *self._reference(reference, t), reference)

    def _feedforward(
        self, t: float, q_d: np.ndarray, qd_d: np.ndarray, qdd_d: np.ndarray, reference: Reference
    ) -> np.ndarray:
        if self.model is None:
            return np.zeros(self.dof)
        tau = self._model_torque(t, q_d, qd_d, qdd_d, reference)
        if tau is not None and tau.shape == (self.dof,) and np.all(np.isfinite(tau)):
            return tau
        self.n_fallbacks += 1
        if self.fallback is not None and self.fallback is not self.model:
            try:
                tau = np.asarray(self.fallback.inverse_dynamics(q_d, qd_d, qdd_d), dtype=float)
            except Exception as exc:  # noqa: BLE001 - the fallback must not stop the loop either
                self.last_model_error = f"fallback: {type(exc).__name__}: {exc}"
                tau = None
            if tau is not None and tau.shape == (self.dof,) and np.all(np.isfinite(tau)):
                return tau
        return np.zeros(self.dof)

    def _model_torque(
        self, t: float, q_d: np.ndarray, qd_d: np.ndarray, qdd_d: np.ndarray, reference: Reference
    ) -> np.ndarray | None:
        model = self.model
        try:
            if hasattr(model, "predict_one"):
                q_hist = None
                if self._uses_history:
                    q_hist = np.stack([reference(t - self._delta)[0], reference(t - 2.0 * self._delta)[0]])
                if self.gate:
                    return self._gated(self.gate, q_d, qd_d, qdd_d, q_hist)
                return np.asarray(model.predict_one(q_d, qd_d, qdd_d, q_hist=q_hist), dtype=float)
            return np.asarray(model.inverse_dynamics(q_d, qd_d, qdd_d), dtype=float)
        except Exception as exc:  # noqa: BLE001
            # Whatever the model raises (a rejected input, a numerical failure, a bug in a
            # user model) is a fallback event, never a crash of the control loop; the last
            # error is kept for diagnosis. KeyboardInterrupt and SystemExit still stop it.
            self.last_model_error = f"{type(exc).__name__}: {exc}"
            return None

    def _gated(self, rule: str, q_d: np.ndarray, qd_d: np.ndarray, qdd_d: np.ndarray, q_hist: np.ndarray | None
               ) -> np.ndarray:
        """The gated feedforward with gate ``rule`` (see the class docstring)."""
        nominal = np.asarray(self._nominal.inverse_dynamics(q_d, qd_d, qdd_d), dtype=float)
        if rule == "innovation":
            d = np.asarray(self.model.predict_one(q_d, qd_d, qdd_d, q_hist=q_hist), dtype=float) - nominal
            w = self._innovation_w.copy()  # last_gate is the caller's
        else:
            mean, var = self.model.predict_one_var(q_d, qd_d, qdd_d, q_hist=q_hist)
            d = mean - nominal
            w = gate_weights(d, var, rule, self._prior)
        self.last_gate = w
        return nominal + w * d

    def __call__(self, t: float, q: np.ndarray, qd: np.ndarray, reference: Reference) -> np.ndarray:
        """Joint torques for the measured state ``(q, qd)`` at time ``t``; always finite and within limits.
        Malformed arguments (``t`` not a real number, ``q``/``qd`` not real ``(N,)`` arrays) or a reference
        that does not return three real ``(N,)`` arrays raise ``TypeError``/``ValueError`` naming them."""
        if isinstance(t, (bool, np.bool_)) or not isinstance(t, (int, float, np.integer, np.floating)):
            raise TypeError(f"t: expected a real number (s), got {type(t).__name__}")
        q, qd = self._measured("q", q), self._measured("qd", qd)
        q_d, qd_d, qdd_d = self._reference(reference, t)  # once per tick; shared with the feedforward
        bad = ~(np.isfinite(q) & np.isfinite(qd) & np.isfinite(q_d) & np.isfinite(qd_d))
        self.n_bad_measurements += bool(np.any(bad))
        with np.errstate(over="ignore", invalid="ignore"):
            # A finite but absurd error saturates with its sign (overflow to +-inf is capped
            # before the sum so that P and D terms of opposite sign cannot make inf - inf).
            terms = np.nan_to_num(np.stack([self.kp * (q_d - q), self.kd * (qd_d - qd)]), nan=0.0,
                                  posinf=_BIG, neginf=-_BIG)
        feedback = np.where(bad, 0.0, terms.sum(axis=0))
        tau = self._feedforward(t, q_d, qd_d, qdd_d, reference) + feedback
        return np.clip(tau, -self.torque_limits, self.torque_limits)

    def _measured(self, name: str, x: Any) -> np.ndarray:
        try:
            a = np.asarray(x)
        except (TypeError, ValueError) as exc:  # ragged nested sequences
            raise TypeError(f"{name}: expected a real numeric array of shape ({self.dof},) ({exc})") from None
        if a.dtype.kind not in "fiu":
            raise TypeError(f"{name}: expected a real numeric array, got dtype {a.dtype}")
        if a.shape != (self.dof,):
            raise ValueError(f"{name}: expected shape ({self.dof},), got {a.shape}")
        return a.astype(float, copy=False)

    def _reference(self, reference: Reference, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        out = reference(t)
        if not isinstance(out, (tuple, list)) or len(out) != 3:
            raise ValueError("reference: expected reference(t) to return (q_d, qd_d, qdd_d)")
        parts = []
        for nm, x in zip(("q_d", "qd_d", "qdd_d"), out):
            a = np.asarray(x)
            if a.dtype.kind not in "fiu":
                raise TypeError(f"reference: {nm} must be a real numeric array, got dtype {a.dtype}")
            if a.shape != (self.dof,):
                raise ValueError(f"reference: {nm} must have shape ({self.dof},), got {a.shape}")
            parts.append(a.astype(float, copy=False))
        return parts[0], parts[1], parts[2]

    def start(self, env: Any, info: dict[str, Any]) -> None:
        """Start of an episode (:class:`Controller` protocol): zero the counters; with ``online``, open a
        fresh online window on the model (samples of earlier episodes enter only through retraining)."""
        self.reset_counters()
        self._recent, self._n_observed = [], 0
        self.n_online_samples = self.n_online_rejected = 0
        self._err_nominal, self._err_model = np.zeros(self.dof), np.zeros(self.dof)
        self._innovation_w = innovation_weights(self._err_nominal, self._err_model)
        self._t_innovation, self.n_innovation_samples = None, 0
        self.last_gate, self.last_model_error = None, None
        if self.online:
            self.model.start_online(self.online)
        elif hasattr(self.model, "stop_online"):
            self.model.stop_online()  # an offline controller uses the fitted model, not an earlier episode's window
        if self.gate and self.gate != "innovation":
            self.model.prepare_variance()  # before the first tick, not in it

    def observe(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, t: float) -> None:
        """A new measurement (called by the runner after every step). Every ``online_every``-th call makes a
        sample of the *previous* tick: its q and qd, q̈ by central differences of the measured qd (as the
        recorded episodes), and the torque measured over the period that started at that tick (reported now).
        With the innovation gate the sample first updates the gate's error sums (``n_innovation_samples``; a
        sample with a non-finite error is skipped); with ``online`` it then enters the model. A sample the
        model refuses (e.g. non-finite) is counted in ``n_online_rejected``, never raised."""
        if not self.online and self.gate != "innovation":
            return
        self._recent = (self._recent + [(float(t), np.array(q, float), np.array(qd, float),
                                         np.array(tau, float))])[-3:]
        self._n_observed += 1
        if self._n_observed % self.online_every or len(self._recent) < 3:
            return
        (t0, _, qd0, _), (t1, q1, qd1, _), (t2, _, qd2, tau2) = self._recent
        with np.errstate(all="ignore"):  # a non-finite difference is refused by add_sample below
            qdd1 = (qd2 - qd0) / (t2 - t0)
        if self.gate == "innovation":
            self._innovate(t1, q1, qd1, qdd1, tau2)
        if not self.online:
            return
        try:
            self.model.add_sample(q1, qd1, qdd1, tau2)
            self.n_online_samples += 1
        except Exception as exc:  # noqa: BLE001 - learning must never stop the control loop
            self.n_online_rejected += 1
            self.last_model_error = f"online: {type(exc).__name__}: {exc}"

    @property
    def innovation_errors(self) -> tuple[np.ndarray, np.ndarray]:
        """The innovation gate's discounted error sums ``(S_0, S_m)`` of this episode, per joint (N m², copies)."""
        return self._err_nominal.copy(), self._err_model.copy()

    def _innovate(self, t: float, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, tau: np.ndarray) -> None:
        """The innovation gate's update with one measured sample (see the class docstring)."""
        try:
            with np.errstate(all="ignore"):
                e_model = (tau - np.asarray(self.model.predict_one(q, qd, qdd), dtype=float)) ** 2
                e_nominal = (tau - np.asarray(self._nominal.inverse_dynamics(q, qd, qdd), dtype=float)) ** 2
        except Exception as exc:  # noqa: BLE001 - the gate must never stop the control loop
            self.last_model_error = f"innovation: {type(exc).__name__}: {exc}"
            return
        if not (e_model.shape == e_nominal.shape == (self.dof,) and np.all(np.isfinite(e_model))
                and np.all(np.isfinite(e_nominal)) and np.isfinite(t)):
            return
        dt = 0.0 if self._t_innovation is None else max(t - self._t_innovation, 0.0)
        decay = 0.5 ** (dt / INNOVATION_HALF_LIFE_S)
        self._err_model = decay * self._err_model + e_model
        self._err_nominal = decay * self._err_nominal + e_nominal
        self._innovation_w = innovation_weights(self._err_nominal, self._err_model)
        self._t_innovation = t
        self.n_innovation_samples += 1

    def reset_counters(self) -> None:
        """Zero the fallback and bad-measurement counters (e.g. at the start of an episode)."""
        self.n_fallbacks = 0
        self.n_bad_measurements = 0
