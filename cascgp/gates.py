r"""Gate rules: how far :class:`cascgp.controller.FeedforwardController` trusts a learned correction.

A gate shrinks the learned correction :math:`d_j = \mu_j - \tau_{RBD,j}` (the model's mean torque minus the nominal
torque of joint :math:`j`) toward zero by a weight :math:`w_j \in [0, 1]`,

.. math::

    \tau_{ff,j} = \tau_{RBD,j} + w_j\, d_j .

For a semi-parametric model :math:`d_j` is the learned residual, for a non-parametric one the difference to the
nominal model. Every rule is a :class:`GateRule`. Four are given, one class each: :class:`InnovationGate` weighs
the model and the nominal one by their errors on this episode's measured torques; :class:`WienerGate`,
:class:`FloorGate` and :class:`VarianceGate` weigh by the model's latent variance :math:`v_j` propagated through
the cascade (:meth:`cascgp.models.CascadedGPModel.predict_one_var`) and its prior (signal) variance :math:`p_j`.
Each is one rule for every joint, task and model, with no threshold to tune. A weight, correction or variance that
is not finite gives :math:`w_j = 0` (the nominal torque).

What a gate can and cannot buy. If the GP's posterior were right, :math:`\tau_j \sim \mathcal N(\mu_j, v_j)` and
the expected squared error of the gated feedforward would be

.. math::

    \mathbb E\big[(\tau_j - \tau_{RBD,j} - w_j d_j)^2\big] = (1 - w_j)^2 d_j^2 + v_j ,

smallest at :math:`w_j = 1`: under the model's own beliefs any shrinkage toward the nominal model costs
:math:`(1 - w_j)^2 d_j^2`, since the posterior mean has already moved away from its prior only as far as the data
warrant. A gate is insurance against the model being wrong by more than :math:`v_j` (e.g. on a new part of the
workspace), paid for with that cost where the model is right. The measurements: docs/studies/index.md.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

from cascgp.controller_args import check_predict_one
from cascgp.data import all_finite

__all__ = ["GateRule", "InnovationGate", "WienerGate", "FloorGate", "VarianceGate", "GATE_RULES", "GATE_SUFFIXES",
           "INNOVATION_HALF_LIFE_S", "default_rule", "make_gate", "gate_weights", "innovation_weights"]

#: Half-life (s) of the innovation gate's error sums: a model's error counts half after this time. A task's
#: reference crosses its part of the workspace in seconds, so errors older than about a second were made at other
#: states; at 10 Hz samples the half-life is 10 samples, and the discounted weights add up to about 15 samples.
INNOVATION_HALF_LIFE_S = 1.0


@runtime_checkable
class GateRule(Protocol):
    """What :class:`~cascgp.controller.FeedforwardController` needs of a gate rule.

    The controller calls :meth:`bind` once when it is built, :meth:`start` at the start of every episode (after
    opening or closing an online window), :meth:`correction` every control tick, and, when :attr:`observes` is
    true, :meth:`observe` with every measured sample (every ``online_every``-th tick, before the sample enters an
    online window). A rule object holds one controller's state: give each controller its own.
    """

    #: The rule's name (:attr:`FeedforwardController.gate <cascgp.controller.FeedforwardController>`).
    name: str
    #: Controller-name suffix (:attr:`FeedforwardController.name <cascgp.controller.FeedforwardController>`).
    suffix: str
    #: Whether the rule learns from measured samples (:meth:`observe`).
    observes: bool

    def bind(self, model: Any, nominal: Any, dof: int) -> None:
        """Check that the rule can gate ``model`` toward ``nominal`` (an object with ``inverse_dynamics``, or
        None) and keep what it needs of both; ``ValueError`` naming the gate otherwise."""
        ...

    def start(self) -> None:
        """Start of an episode: forget the last episode's state, prepare what the first tick needs."""
        ...

    def correction(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, q_hist: np.ndarray | None,
                   nominal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The learned correction :math:`d` and its weights :math:`w`, each (N,), at the reference state (``q_hist``:
        derivative-free models' history) with nominal torque ``nominal``."""
        ...

    def observe(self, t: float, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, tau: np.ndarray) -> None:
        """One measured sample: state, measured torque ``tau`` and time ``t`` (s). May raise; the controller
        records the error and goes on."""
        ...


def _check_bound(model: Any, nominal: Any, *needs: str) -> None:
    missing = [n for n in needs if not hasattr(model, n)]
    if model is None or missing:
        raise ValueError(f"gate: needs a fitted cascgp model (with {', '.join(needs)}), got {type(model).__name__}"
                         + (f" without {', '.join(missing)}" if model is not None else ""))
    if nominal is None:
        raise ValueError("gate: needs a nominal rigid-body model to fall back toward: pass fallback=... "
                         "(an SP model's own rbd is used when there is none)")


def _shares_rbd(model: Any, nominal: Any) -> bool:
    """Whether ``model`` is a cascgp SP model whose own rigid-body model is ``nominal``: then the nominal torque
    the controller computed is the model's RBD torque, passed as ``rbd_torque`` instead of computed again."""
    from cascgp.models import CascadedGPModel

    return isinstance(model, CascadedGPModel) and model.parametric == "sp" and model.rbd is nominal


def _with_nominal(predict: Any, share: bool, nominal: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                  q_hist: np.ndarray | None = None) -> Any:
    """``predict(q, qd, qdd, q_hist=q_hist)`` (a model's ``predict_one`` or ``predict_one_var``), given the
    controller's ``nominal`` torque as ``rbd_torque`` when the model shares it (:func:`_shares_rbd`); a model that
    does not is called without the keyword, which it need not accept. Two calls rather than a keyword dict: this
    runs every control tick."""
    if share:
        return predict(q, qd, qdd, q_hist=q_hist, rbd_torque=nominal)
    return predict(q, qd, qdd, q_hist=q_hist)


def innovation_weights(err_nominal: np.ndarray, err_model: np.ndarray) -> np.ndarray:
    r"""The innovation gate's weights on the learned correction: :math:`w = S_0 / (S_0 + S_m)`, with :math:`S_0`
    and :math:`S_m` the discounted sums of the squared errors of the nominal and the learned model
    (:class:`InnovationGate`); 1/2 where both are 0 (no evidence yet), 0 where either is NaN; an infinite sum
    counts as larger than any finite one."""
    s0 = np.asarray(err_nominal, dtype=float)
    sm = np.asarray(err_model, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        w = np.where(s0 + sm > 0.0, s0 / (s0 + sm), 0.5)
        # where the sum overflows: divided by the larger sum, so that huge (even infinite) sums keep their limit
        scaled = np.where(s0 >= sm, 1.0 / (1.0 + sm / s0), (s0 / sm) / (1.0 + s0 / sm))
        w = np.where(np.isfinite(s0 + sm), w, scaled)
    return np.where(np.isfinite(w) & ~np.isnan(s0) & ~np.isnan(sm), w, 0.0)


class InnovationGate:
    r"""Trust the learned model as far as it has predicted this episode's measured torques better than the nominal.

    At every measured sample (:meth:`observe`: measured :math:`q`, :math:`\dot q`, :math:`\ddot q` by central
    differences, the measured torque :math:`\tau`, at time :math:`t`) the squared errors of the nominal and of the
    learned model enter discounted sums, and the weight is that of two forecasts by their inverse mean squared
    errors (Bates and Granger, 1969):

    .. math::

        S_{0,j} \leftarrow \lambda S_{0,j} + (\tau_j - \tau_{RBD,j})^2, \quad
        S_{m,j} \leftarrow \lambda S_{m,j} + (\tau_j - \mu_j)^2, \quad
        \lambda = 2^{-\Delta t / t_{1/2}}, \qquad w_j = \frac{S_{0,j}}{S_{0,j} + S_{m,j}}

    (:func:`innovation_weights`), with :math:`\Delta t` the time since the last sample and the half-life
    :math:`t_{1/2}` = :data:`INNOVATION_HALF_LIFE_S`. Before the first sample of an episode :math:`w = 1/2`; a
    sample with a non-finite error is skipped. The weight trusts a model that has been predicting better than the
    nominal one however unsure the GP is, and falls back toward the nominal one when the model errs more however
    sure it is. It is per joint, not per state: the errors of the last seconds stand for the part of the workspace
    the reference is in.

    The weight is MSE-optimal for *uncorrelated* errors. Both errors contain the same measurement noise (torque
    sensor, :math:`\ddot q` by differences), so where both models are good it is pulled toward 1/2: with a nominal
    error :math:`b` and a shared noise variance :math:`\sigma^2`, a right model gets
    :math:`(b^2 + \sigma^2) / (b^2 + 2 \sigma^2)`.

    Needs a derivative-based model with ``predict_one`` (its errors are taken at the measured states) and uses its
    mean only, no variance.
    """

    name = "innovation"
    suffix = "-igated"
    observes = True

    def __init__(self) -> None:
        self.model: Any = None
        self.nominal: Any = None
        self.dof = 0
        self._share = False
        self._reset()

    def _reset(self) -> None:
        self._err_nominal = np.zeros(self.dof)
        self._err_model = np.zeros(self.dof)
        # the weights change only when a sample arrives, not every tick
        self._w = innovation_weights(self._err_nominal, self._err_model)
        self._t: float | None = None
        self.n_samples = 0

    def bind(self, model: Any, nominal: Any, dof: int) -> None:
        if getattr(model, "feature_kind", "db") != "db":
            raise ValueError("gate 'innovation': needs a derivative-based model (its errors are taken at the measured "
                             f"q, qd and q̈), got {getattr(model, 'name', type(model).__name__)}")
        _check_bound(model, nominal, "predict_one")
        self.model, self.nominal, self.dof = model, nominal, int(dof)
        self._share = _shares_rbd(model, nominal)
        self._reset()

    def start(self) -> None:
        self._reset()

    def correction(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, q_hist: np.ndarray | None,
                   nominal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        mean = _with_nominal(self.model.predict_one, self._share, nominal, q, qd, qdd, q_hist)
        d = np.asarray(mean, dtype=float) - nominal
        return d, self._w.copy()  # the copy is the caller's

    @property
    def errors(self) -> tuple[np.ndarray, np.ndarray]:
        """The discounted error sums ``(S_0, S_m)`` of this episode, per joint (N² m², copies)."""
        return self._err_nominal.copy(), self._err_model.copy()

    def observe(self, t: float, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, tau: np.ndarray) -> None:
        with np.errstate(all="ignore"):
            nominal = np.asarray(self.nominal.inverse_dynamics(q, qd, qdd), dtype=float)
            e_model = (tau - np.asarray(_with_nominal(self.model.predict_one, self._share, nominal, q, qd, qdd),
                                        dtype=float)) ** 2
            e_nominal = (tau - nominal) ** 2
        if not (e_model.shape == e_nominal.shape == (self.dof,) and all_finite(e_model)
                and all_finite(e_nominal) and np.isfinite(t)):
            return
        dt = 0.0 if self._t is None else max(t - self._t, 0.0)
        decay = 0.5 ** (dt / INNOVATION_HALF_LIFE_S)
        self._err_model = decay * self._err_model + e_model
        self._err_nominal = decay * self._err_nominal + e_nominal
        self._w = innovation_weights(self._err_nominal, self._err_model)
        self._t = t
        self.n_samples += 1


class _VarianceRule:
    """The rules driven by the model's propagated latent variance :math:`v` and prior variance :math:`p`."""

    name = ""
    suffix = ""
    observes = False

    def __init__(self) -> None:
        self.model: Any = None
        self.nominal: Any = None
        self._share = False
        self.prior: np.ndarray | None = None

    def _check(self, model: Any) -> None:
        """``ValueError`` if the rule does not apply to ``model`` (besides what every variance rule needs)."""

    def bind(self, model: Any, nominal: Any, dof: int) -> None:
        self._check(model)
        _check_bound(model, nominal, "predict_one_var", "signal_var", "prepare_variance")
        check_predict_one(model, "predict_one_var")
        self.model, self.nominal = model, nominal
        self._share = _shares_rbd(model, nominal)
        self.prior = np.asarray(model.signal_var, dtype=float)

    def start(self) -> None:
        self.model.prepare_variance()  # before the first tick, not in it

    def correction(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, q_hist: np.ndarray | None,
                   nominal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        mean, var = _with_nominal(self.model.predict_one_var, self._share, nominal, q, qd, qdd, q_hist)
        d = mean - nominal
        return d, self.weights(d, var, self.prior)

    def observe(self, t: float, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, tau: np.ndarray) -> None:
        """Nothing: the rule does not learn from the measurements."""

    def weights(self, correction: Any, var: Any, prior: Any = None) -> np.ndarray:
        """The weights for corrections :math:`d` and variances :math:`v` (any shape; ``prior`` :math:`p` broadcast
        against ``var``); 0 where a weight, a correction or a variance is not finite."""
        d = np.asarray(correction, dtype=float)
        v_raw = np.asarray(var, dtype=float)
        v = np.maximum(v_raw, 0.0)  # a negative finite variance (round-off, a user model) is 0
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            w = self._weights(d, v, prior)
        return np.where(np.isfinite(w) & np.isfinite(d) & np.isfinite(v_raw), w, 0.0)

    def _weights(self, d: np.ndarray, v: np.ndarray, prior: Any) -> np.ndarray:
        raise NotImplementedError

    def _prior(self, prior: Any) -> np.ndarray:
        if prior is None:
            raise ValueError(f"gate_weights: rule {self.name!r} needs the prior variance")
        return np.asarray(prior, dtype=float)


class WienerGate(_VarianceRule):
    r"""The Wiener gain of a correction of size :math:`d_j` estimated with noise variance :math:`v_j`, with
    :math:`d_j^2` plugged in as the correction's power:

    .. math::

        w_j = \frac{d_j^2}{d_j^2 + v_j} \qquad (1 \text{ where both are } 0).

    A correction well above its uncertainty is kept, one within its uncertainty is shrunk; near the data
    (:math:`v \to 0`) it is the learned model. A correction smaller than its standard deviation is removed almost
    entirely (:math:`w_j d_j \approx d_j^3 / v_j`), however systematic it is. Any model with ``predict_one_var``,
    ``signal_var`` (the GPs' prior variances, (N,)) and ``prepare_variance()``, as the cascgp models have.
    """

    name = "wiener"
    suffix = "-gated"

    def _weights(self, d: np.ndarray, v: np.ndarray, prior: Any) -> np.ndarray:
        d2 = d * d
        return np.where(d2 + v > 0.0, d2 / (d2 + v), 1.0)


class FloorGate(_VarianceRule):
    r"""The Wiener gain with the correction's power floored at the GP's prior (signal) variance :math:`p_j`:

    .. math::

        w_j = \frac{P_j}{P_j + v_j}, \qquad P_j = \max(d_j^2, p_j) \qquad (1 \text{ where both are } 0).

    A correction is never treated as weaker than what the GP's prior says corrections are: where
    :math:`v_j \le p_j` (always for a single GP; the propagated variance can exceed :math:`p_j` slightly) at least
    half of it is kept, and a correction well above its uncertainty is kept as by :class:`WienerGate`
    (:math:`w^{\text{floor}} \ge w^{\text{wiener}}` everywhere). Semi-parametric models only: there the GP's prior
    is the prior of the correction to the nominal model; a non-parametric model's GP prior is about the torque
    itself.
    """

    name = "floor"
    suffix = "-fgated"

    def _check(self, model: Any) -> None:
        if getattr(model, "parametric", None) != "sp":
            raise ValueError("gate 'floor': needs a semi-parametric cascgp model (its GP's prior is the prior of "
                             f"the correction to the RBD), got {getattr(model, 'name', type(model).__name__)}; "
                             "use 'wiener' or 'variance' for other models")

    def _weights(self, d: np.ndarray, v: np.ndarray, prior: Any) -> np.ndarray:
        p = self._prior(prior)
        power = np.maximum(d * d, p)
        return np.where(power + v > 0.0, power / (power + v), 1.0)


class VarianceGate(_VarianceRule):
    r"""The fraction of the prior uncertainty the data have removed at the query:

    .. math::

        w_j = \operatorname{clip}\Big(1 - \frac{v_j}{p_j},\ 0,\ 1\Big).

    It shrinks any correction, however large, as soon as the query leaves the training data, although the GP
    posterior mean already reverts toward its prior there: away from the data the correction is shrunk twice.
    Any model with ``predict_one_var``, ``signal_var`` and ``prepare_variance()`` (:class:`WienerGate`).
    """

    name = "variance"
    suffix = "-vgated"

    def _weights(self, d: np.ndarray, v: np.ndarray, prior: Any) -> np.ndarray:
        return np.clip(1.0 - v / self._prior(prior), 0.0, 1.0)


_RULES: dict[str, type[_VarianceRule] | type[InnovationGate]] = {
    "wiener": WienerGate, "floor": FloorGate, "variance": VarianceGate, "innovation": InnovationGate}
#: The names of the given gate rules (``FeedforwardController(gate=name)``).
GATE_RULES = ("wiener", "floor", "variance", "innovation")
#: Controller-name suffix of each rule (:attr:`FeedforwardController.name
#: <cascgp.controller.FeedforwardController>`, :func:`cascgp.learning.parse_controller`).
GATE_SUFFIXES = {name: _RULES[name].suffix for name in GATE_RULES}


def default_rule(model: Any) -> str:
    """The rule of ``gate=True``: ``"innovation"`` for a derivative-based model, ``"wiener"`` for a
    derivative-free one (the innovation rule's errors need the measured states)."""
    return "innovation" if getattr(model, "feature_kind", "db") == "db" else "wiener"


def make_gate(gate: Any, model: Any) -> GateRule | None:
    """The rule object of ``FeedforwardController(gate=...)``: None for ``False``/``None``, :func:`default_rule`'s
    for ``True``, a new object of the named rule for a name in :data:`GATE_RULES`, ``gate`` itself for a
    :class:`GateRule`; ``ValueError`` otherwise. Not yet bound to ``model``."""
    if gate is False or gate is None:
        return None
    if gate is True:
        gate = default_rule(model)
    if isinstance(gate, str) and gate in GATE_RULES:
        return _RULES[gate]()
    if not isinstance(gate, str) and isinstance(gate, GateRule):
        return gate
    raise ValueError(f"gate: expected False, True, one of {GATE_RULES} or a GateRule, got {gate!r}")


def gate_weights(correction: np.ndarray, var: np.ndarray, rule: str = "wiener",
                 prior: np.ndarray | None = None) -> np.ndarray:
    r"""The weights :math:`w \in [0, 1]` of the variance rule ``rule`` (``"wiener"``: :class:`WienerGate`,
    ``"floor"``: :class:`FloorGate`, ``"variance"``: :class:`VarianceGate`) on corrections :math:`d` with
    variances :math:`v` (any shape; ``prior`` :math:`p` broadcast against ``var``, needed by the last two); 0 (the
    nominal torque) where a weight, a correction or a variance is not finite."""
    cls = _RULES.get(rule) if isinstance(rule, str) else None
    if cls is None or not issubclass(cls, _VarianceRule):
        raise ValueError(f"gate_weights: rule must be one of {GATE_RULES[:3]}, got {rule!r}")
    return cls().weights(correction, var, prior)
