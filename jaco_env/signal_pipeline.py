"""How the simulated Jaco 2 reports its joint state: the sensing pipeline and its named factors.

:class:`SignalPipeline` is a frozen set of named factors between the simulated arm and the measured
``[q, qd, tau]`` of an observation (layout in :mod:`jaco_env.sensors`). The environments take it as
``sensor_pipeline="ideal" | "jaco2" | SignalPipeline(...)``; the additive Gaussian noise stays
``sensor_noise`` (:class:`~jaco_env.sensors.SensorNoise`), which the pipeline only scales per joint.

=====================  =====================================================  ==========  ==================
field                  factor                                                 ``ideal``   ``jaco2``
=====================  =====================================================  ==========  ==================
``q_lead_s``           (a) how long before the tau read q is read             0           0.0083 s
``qd_lead_s``          (a) how long before the tau read qd is read            0           0.0028 s
``velocity_source``    (b) simulated velocity or backward difference of q     ``"true"``  "differentiated"
``velocity_window_s``  (b) the difference's window                            0.01 s      0.01 s
``tau_offset_std``     (c) torque offset drawn per episode, N m               0           0.3 / 0.07
``tau_drift_std``      (c) random-walk drift of the offset, N m/sqrt(s)       0           0.01 / 0.0025
``tau_filter_hz``      (c) first-order low-pass cut-off of the torque, Hz     0 (none)    10
``tau_noise_scale``    (c) scale of the ``SensorNoise`` torque noise          1           1 / 0.25
=====================  =====================================================  ==========  ==================

(x / y: joints 1-3 / joints 4-6.) The parameters of ``jaco2``, their public sources and the
assumptions where none exists are in ``docs/sensing-sources.md``. A single factor on top of ``ideal``
is named ``"ideal+skew"`` (a), ``"ideal+velocity"`` (b) or ``"ideal+torque"`` (c), and factors combine
(``"ideal+skew+torque"``; :data:`FACTORS`, :meth:`SignalPipeline.with_factors`).

Times are rounded to whole physics steps and kept within one control period: tau is read at its
end, q and qd at most ``frame_skip - 1`` physics steps before it, the velocity window at most what is
left of the period before the qd read. The
torque filter is the exact discretisation, at the sample rate, of a first-order filter of time
constant ``T = 1 / (2 pi f_c)`` whose input is held between samples: ``y_k = y_{k-1} + alpha (u_k -
y_{k-1})``, ``alpha = 1 - exp(-dt / T)``, started at the first sample after reset (the reset
observation's torque sample is zero, as under ``ideal``, and is not filtered). The measured torque
is ``filter(tau) + offset + drift + noise``: the noise is the read-out's, after the filter, so
``SensorNoise.tau_std`` keeps its meaning. The drift starts at 0 at reset and adds ``N(0,
tau_drift_std^2 dt)`` per sample after the noise draw. The offset is drawn at reset after the
environment's own draws (task, payload, marbles), so one seed starts the same episode under every pipeline.

``ideal`` is the identity: the environment then runs exactly its noise-only measurement (the same
random draws in the same order). A non-finite measurement truncates the episode with
``info["unstable"] = True``; no observation carries NaN or inf.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from jaco_env.checks import is_real_number
from jaco_env.robot import N_JOINTS
from jaco_env.sensors import SensorNoise

_ZERO = np.zeros(1)  # the time slot of a measurement (set by the caller)
#: Allowed ranges of the numeric fields (inclusive), for validation and its messages.
_RANGES = {
    "q_lead_s": (0.0, 0.05),
    "qd_lead_s": (0.0, 0.05),
    "velocity_window_s": (1e-4, 0.1),
    "tau_offset_std": (0.0, 10.0),  # the raw offsets before zeroing reach about +-10 N m
    "tau_drift_std": (0.0, 1.0),
    "tau_filter_hz": (0.0, 1000.0),
    "tau_noise_scale": (0.0, 10.0),
}
_PER_JOINT = ("tau_offset_std", "tau_drift_std", "tau_noise_scale")
VELOCITY_SOURCES = ("true", "differentiated")
PRESETS = ("ideal", "jaco2")
#: The environment-level factors by name, with the fields each one sets (to the ``jaco2`` values) on top of
#: ``ideal``: ``"ideal+skew+torque"`` names such a pipeline. Factor (d), the q̈ filter, belongs to data
#: collection (``cascgp_experiments.collect``), not to the environment.
FACTORS: dict[str, tuple[str, ...]] = {
    "skew": ("q_lead_s", "qd_lead_s"),                                                # (a)
    "velocity": ("velocity_source", "velocity_window_s"),                             # (b)
    "torque": ("tau_offset_std", "tau_drift_std", "tau_filter_hz", "tau_noise_scale"),  # (c)
}


def _joints(big: float, small: float) -> tuple[float, ...]:
    """Per-joint values: ``big`` on joints 1-3 (K75+ actuators), ``small`` on joints 4-6 (K58)."""
    return (big,) * 3 + (small,) * (N_JOINTS - 3)


@dataclass(frozen=True)
class SignalPipeline:
    """Named factors of the sensing pipeline (module docstring); validated at construction.

    Attributes:
        q_lead_s: how long before the torque read q is read (s, in [0, 0.05]; rounded to physics steps).
        qd_lead_s: how long before the torque read qd is read (s, in [0, 0.05]).
        velocity_source: ``"true"`` (the simulated joint velocity) or ``"differentiated"`` (a backward difference
            of q over ``velocity_window_s``).
        velocity_window_s: the difference's window (s, in [1e-4, 0.1]).
        tau_offset_std: standard deviation of the torque offset drawn at each reset (N m, per joint, in [0, 10]).
        tau_drift_std: the offset's random-walk drift (N m/sqrt(s), per joint, in [0, 1]).
        tau_filter_hz: cut-off of the first-order low-pass filter of the torque (Hz, in [0, 1000]; 0: none).
        tau_noise_scale: scale of ``SensorNoise``'s torque noise (per joint, in [0, 10]).

    Per-joint fields take one real number (all joints) or ``N_JOINTS`` of them and are stored as a tuple.
    Invalid values raise ``TypeError`` / ``ValueError`` naming the field and its allowed range.
    """

    q_lead_s: float = 0.0
    qd_lead_s: float = 0.0
    velocity_source: str = "true"
    velocity_window_s: float = 0.01
    tau_offset_std: tuple[float, ...] = (0.0,) * N_JOINTS
    tau_drift_std: tuple[float, ...] = (0.0,) * N_JOINTS
    tau_filter_hz: float = 0.0
    tau_noise_scale: tuple[float, ...] = (1.0,) * N_JOINTS

    def __post_init__(self) -> None:
        if not isinstance(self.velocity_source, str):
            raise TypeError(f"SignalPipeline.velocity_source must be one of {VELOCITY_SOURCES}, "
                            f"got {type(self.velocity_source).__name__} {self.velocity_source!r}")
        if self.velocity_source not in VELOCITY_SOURCES:
            raise ValueError(f"SignalPipeline.velocity_source must be one of {VELOCITY_SOURCES}, "
                             f"got {self.velocity_source!r}")
        for name, (lo, hi) in _RANGES.items():
            v = getattr(self, name)
            if name in _PER_JOINT:
                vals = (v,) if is_real_number(v) else v
                if not (isinstance(vals, (tuple, list, np.ndarray)) and np.ndim(vals) == 1
                        and len(vals) in (1, N_JOINTS) and all(is_real_number(x) for x in vals)):
                    raise TypeError(f"SignalPipeline.{name} must be a real number or {N_JOINTS} real numbers "
                                    f"in [{lo}, {hi}], got {v!r}")
                vals = tuple(float(x) for x in vals) * (N_JOINTS if len(vals) == 1 else 1)
            else:
                if not is_real_number(v):
                    raise TypeError(f"SignalPipeline.{name} must be a real number in [{lo}, {hi}], "
                                    f"got {type(v).__name__} {v!r}")
                vals = (float(v),)
            if not all(math.isfinite(x) and lo <= x <= hi for x in vals):
                raise ValueError(f"SignalPipeline.{name} must be in [{lo}, {hi}] (finite), got {v!r}")
            object.__setattr__(self, name, vals if name in _PER_JOINT else vals[0])

    @classmethod
    def ideal(cls) -> "SignalPipeline":
        """The identity: q, qd, tau sampled together at the end of the period, the true velocity, no offset,
        drift or filter, the same torque noise on every joint."""
        return cls()

    @classmethod
    def jaco2(cls) -> "SignalPipeline":
        """Every factor at its sourced or stated value (``docs/sensing-sources.md``)."""
        # read skew: the driver's status timer makes 9 API calls per cycle (kinova-ros kinova_arm.cpp statusTimer;
        # publishJointAngles calls getJointAngles, getAngularCommand, getJointVelocities, getJointTorques in this
        # order) and reaches about 40 Hz when asked for 100 Hz (kinova-ros issue 281): about 2.8 ms per call, so
        # q is read 3 calls and qd 1 call before tau. Velocity: a firmware estimate (kinova_comm.cpp line 623),
        # differenced over the 100 Hz main loop. Offsets and drift after zeroing (kinova-ros issues 352, 358,
        # 366), sized at about 1 % of each actuator's range. Filter: SetTorqueFilterMeasuredTorque
        # (Kinova.API.USBCommandLayerUbuntu.h), cut-off assumed. Noise scaled by the K58 / K75+ ranges 6.8 / 30.5.
        return cls(q_lead_s=0.0083, qd_lead_s=0.0028, velocity_source="differentiated", velocity_window_s=0.01,
                   tau_offset_std=_joints(0.3, 0.07), tau_drift_std=_joints(0.01, 0.0025), tau_filter_hz=10.0,
                   tau_noise_scale=_joints(1.0, 0.25))

    @classmethod
    def with_factors(cls, *factors: str) -> "SignalPipeline":
        """``ideal`` with the named factors (keys of :data:`FACTORS`) at their ``jaco2`` values."""
        bad = [f for f in factors if f not in FACTORS]
        if bad:
            raise ValueError(f"sensor_pipeline factor must be one of {tuple(FACTORS)}, got {bad[0]!r}")
        full = cls.jaco2()
        return cls(**{name: getattr(full, name) for f in factors for name in FACTORS[f]})

    @classmethod
    def resolve(cls, value: "str | SignalPipeline") -> "SignalPipeline":
        """The pipeline of the env option ``sensor_pipeline``: a preset name, ``"ideal+<factor>[+<factor>...]"``
        (factors of :data:`FACTORS`) or a ``SignalPipeline``."""
        expected = f"one of {PRESETS}, 'ideal+' and factors of {tuple(FACTORS)} joined by '+', or a SignalPipeline"
        if isinstance(value, SignalPipeline):
            return value
        if isinstance(value, str):
            if value in PRESETS:
                return cls.ideal() if value == "ideal" else cls.jaco2()
            head, *factors = value.split("+")
            if head != "ideal" or not factors or any(f not in FACTORS for f in factors):
                raise ValueError(f"sensor_pipeline must be {expected}, got {value!r}")
            return cls.with_factors(*factors)
        raise TypeError(f"sensor_pipeline must be {expected}, got {type(value).__name__} {value!r}")

    @staticmethod
    def is_name(value: object) -> bool:
        """True when ``value`` is a pipeline name that :meth:`resolve` accepts."""
        if not isinstance(value, str):
            return False
        try:
            SignalPipeline.resolve(value)
        except ValueError:
            return False
        return True

    @property
    def is_ideal(self) -> bool:
        """True when every factor is the identity (the env then skips the pipeline)."""
        return self == SignalPipeline()

    def as_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}


class PipelineState:
    """The per-environment state of a non-ideal :class:`SignalPipeline`: sample instants, offset, drift, filter.

    ``timestep`` (s) and ``frame_skip`` describe the control period of ``control_dt`` seconds. The sample
    instants are in physics steps from the start of the period: :attr:`q_step`, :attr:`qd_step` (and
    :attr:`qw_step`, the start of the velocity window); tau is sampled at ``frame_skip``.

    The samples are read by MuJoCo's delayed joint sensors (:meth:`reads`, built into the scene by
    :func:`jaco_env.robot.add_delayed_reads`), so the physics runs the period in one call; :meth:`attach` points
    :attr:`q`, :attr:`qd`, :attr:`q_at_qd`, :attr:`q_w` at their readings (a sample at the end of the period
    reads the state itself). They hold the period's samples after the evaluation at its end.
    """

    def __init__(self, pipeline: SignalPipeline, control_dt: float, timestep: float, frame_skip: int):
        p, n = pipeline, int(frame_skip)
        self.pipeline = p
        def lead(t: float) -> int:
            return min(int(round(t / timestep)), n - 1)

        self.q_step, self.qd_step = n - lead(p.q_lead_s), n - lead(p.qd_lead_s)
        self.differentiated = p.velocity_source == "differentiated"
        w = max(1, min(int(round(p.velocity_window_s / timestep)), self.qd_step))
        self.qw_step = self.qd_step - w
        self.velocity_window = w * timestep
        self.frame_skip = n
        self.q = np.zeros(N_JOINTS)   # q at q_step
        self.qd = np.zeros(N_JOINTS)  # qd at qd_step
        self.q_at_qd = np.zeros(N_JOINTS)  # q at qd_step (differentiated velocity)
        self.q_w = np.zeros(N_JOINTS)  # q at qw_step (differentiated velocity)
        self.alpha = 1.0 - math.exp(-control_dt * 2.0 * math.pi * p.tau_filter_hz) if p.tau_filter_hz > 0 else 1.0
        self.drift_step = np.asarray(p.tau_drift_std) * math.sqrt(control_dt)
        self.has_drift = bool(self.drift_step.any())
        self.scale = np.asarray(p.tau_noise_scale, dtype=np.float64)
        self.offset = np.zeros(N_JOINTS)
        self.drift = np.zeros(N_JOINTS)
        self.filtered: np.ndarray | None = None
        self._noise: SensorNoise | None = None  # the noise that _draw_scales' factors are for

    def reads(self) -> list[tuple[str, str, int]]:
        """The samples to read before the end of the period: ``(attribute, MuJoCo sensor type, lead in physics
        steps)``; a sample at the end of the period (lead 0) is not listed (it is the state)."""
        n = self.frame_skip
        out = [("q", "jointpos", n - self.q_step)]
        if self.differentiated:
            out += [("q_at_qd", "jointpos", n - self.qd_step), ("q_w", "jointpos", n - self.qw_step)]
        else:
            out.append(("qd", "jointvel", n - self.qd_step))
        return [r for r in out if r[2] > 0]

    def attach(self, delayed: dict[str, np.ndarray], q_arm: np.ndarray, qd_arm: np.ndarray) -> None:
        """Point the samples at their readings: ``delayed[attribute]``, a live view of the delayed sensors' data
        (each of :meth:`reads`), else the arm's live ``q_arm`` / ``qd_arm`` (a sample at the end of the period)."""
        self.q = delayed.get("q", q_arm)
        if self.differentiated:
            self.q_at_qd = delayed.get("q_at_qd", q_arm)
            self.q_w = delayed.get("q_w", q_arm)
        else:
            self.qd = delayed.get("qd", qd_arm)

    def reset(self, rng: np.random.Generator) -> None:
        """A new episode: the offset drawn (one draw of ``N_JOINTS`` normals), drift 0, filter unprimed."""
        std = np.asarray(self.pipeline.tau_offset_std)
        self.offset = std * rng.standard_normal(N_JOINTS) if std.any() else np.zeros(N_JOINTS)
        self.drift = np.zeros(N_JOINTS)
        self.filtered = None

    def _draw_scales(self, noise: SensorNoise) -> tuple[np.ndarray, np.ndarray]:
        """The two factors of one step's draws ``[q, qd, tau noise, drift]`` (``4 N_JOINTS`` normals): the
        ``SensorNoise`` deviations (and the drift's per-sample deviation), then the torque noise's scale (1
        elsewhere, an exact product), kept for ``noise``."""
        if noise is not self._noise:
            n = N_JOINTS
            self._first = np.concatenate((np.repeat(noise._std[:, 0], n), self.drift_step))
            self._second = np.ones(4 * n)
            self._second[2 * n:3 * n] = self.scale
            self._noise = noise
        return self._first, self._second

    def measure(self, rng: np.random.Generator, noise: SensorNoise, q: np.ndarray, qd: np.ndarray,
                tau: np.ndarray, sampled: bool) -> np.ndarray | None:
        """``[q, qd, tau, 0]`` measured (the caller sets the time), or None when not finite.

        ``sampled``: the period's samples (:attr:`q`, ...) were taken (a step); else (the reset observation)
        ``q``, ``qd`` and ``tau`` are used as they are, unfiltered.
        """
        # The arithmetic of SensorNoise.measurement and the factors in one pass over flat arrays (this runs
        # every env step): the normals of the noise (3 N) and of the drift (N) in one draw, in the order of
        # separate draws (a Generator's normals do not depend on how a request is split); the measured torque
        # is ((filter(tau) + offset) + drift) + noise, entry by entry.
        n = N_JOINTS
        first, second = self._draw_scales(noise)
        drift = sampled and self.has_drift
        k = 4 * n if drift else 3 * n
        e = rng.standard_normal(k)
        e *= first[:k]
        e *= second[:k]
        if sampled:
            if self.filtered is None or self.alpha == 1.0:  # no filter: the sample itself, exactly
                self.filtered = tau.copy()
            else:
                self.filtered += self.alpha * (tau - self.filtered)
            out = np.concatenate((self.q, self.qd if not self.differentiated else self.q_at_qd, self.filtered,
                                  _ZERO))
            if self.differentiated:
                v = out[n:2 * n]
                v -= self.q_w
                v /= self.velocity_window
            if drift:
                self.drift += e[3 * n:]
        else:
            out = np.concatenate((q, qd, tau, _ZERO))
        t = out[2 * n:3 * n]
        t += self.offset
        t += self.drift
        out[:3 * n] += e[:3 * n]
        return out if math.isfinite(out.dot(out)) else None
