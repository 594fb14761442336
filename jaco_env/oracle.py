"""Reference controllers at the control rate (NumPy + MuJoCo, no torch): the oracle and PD only.

Both follow the controller protocol of the one episode runner, :func:`cascgp.episodes.run_episode`
(``cascgp.controller.Controller``; structurally: this package never imports ``cascgp``):
attributes ``dof`` and ``name``, ``start(env, info)`` called right after ``env.reset``, and
``__call__(t, q, qd, reference) -> tau`` with ``reference(t) -> (q_d, qd_d, qdd_d)``. Both clip
their output to the Kinova torque limits.

Safety guarantees (tested, as ``cascgp.controller.FeedforwardController``'s): the output is always
finite and within the torque limits, or the call raises a clear error naming the field. Gains must
be finite and non-negative (``ValueError`` naming ``kp``/``kd``); ``t`` must be a finite real number
and ``q``, ``qd`` and each of the reference's three arrays real arrays of shape (6,)
(``TypeError``/``ValueError`` naming them). A non-finite measurement or reference entry contributes
no feedback on that joint (counted in ``n_bad_measurements``); a finite but absurd error saturates
at the limits; a non-finite feedforward (e.g. the oracle's inverse dynamics of an absurd reference)
is replaced by zero (counted in ``n_fallbacks``).

* :class:`OracleController` -- computed-torque feedforward from MuJoCo's own inverse
  dynamics (``mj_inverse``) of the full true scene: arm, welded hand, bottle and payload,
  with the true armature, joint damping and dry friction, plus PD feedback (paper eq. 2
  with the true model):

      tau = ID_true(q_d, qd_d, qdd_d) + Kp (q_d - q_meas) + Kd (qd_d - qd_meas)

  :meth:`OracleController.start` builds the rigid model (:func:`rigid_scene_model`) from the
  episode's ``info["payload_mass"]`` and ``info["n_marbles"]``. The marbles are free bodies in
  the environment; the oracle lumps them into the payload as a rigid point mass. Without an
  environment to follow, at their resting centroid in the bottle; started on a ``JacoPour-v0``
  it reads the marbles still in the bottle each control step (privileged state) and lumps
  exactly those at their current centroid, so that the pile sliding to the mouth and the
  marbles leaving the bottle are modelled quasi-statically. Everything else is exact, so the
  oracle is the best feedforward a learned model of the arm's inverse dynamics can reach.

  Tracking error during the tip (investigated): the oracle's error rises from ~0.014 rad to
  ~0.05-0.08 rad (peak) while the bottle tips. Ablations on task "front" (payload 1.2 kg):
  evaluating the feedforward over the zero-order-hold period instead of at its start changes
  nothing; removing joint friction makes it slightly worse; one marble instead of 30 removes
  most of it (peak 0.03 rad). The fixed lumped marble mass accounts for part of the error on
  joints 2 and 5 (fixed by the tracking above); the peak itself is the *dynamic* load of the
  pile avalanching down the tilting bottle and out of the mouth (contact impulses on the
  bottle), which no rigid-body feedforward can anticipate: a disturbance, not a modelling
  error.
* :class:`PDController` -- the same PD feedback without any feedforward (payload unknown, no
  gravity compensation).
"""

from __future__ import annotations

import functools
from typing import Any, Callable

import mujoco
import numpy as np

from jaco_env import robot, scene
from jaco_env.checks import is_real_number, real_array
from jaco_env.gains import DEFAULT_KD, DEFAULT_KP
from jaco_env.link_inertials import check_link_inertials

Reference = Callable[[float], tuple[np.ndarray, np.ndarray, np.ndarray]]

_N = robot.N_JOINTS
_BIG = 1e300  # stands in for an overflowed feedback term; far beyond any actuator limit


def _as_gain(value, name: str) -> np.ndarray:
    """A gain as a (6,) array of finite non-negative numbers (scalars broadcast); errors name ``name``."""
    a = np.asarray(value) if not isinstance(value, str) else value
    if isinstance(a, np.ndarray) and a.ndim == 0 and a.dtype.kind in "iuf":
        a = np.full(_N, float(a))
    gain = real_array(a, (_N,), name)
    if np.any(gain < 0):
        raise ValueError(f"{name} must be non-negative, got {gain.tolist()}")
    return gain


@functools.lru_cache(maxsize=2)
def _rigid_model_xml(link_inertials: str) -> tuple[str, dict]:
    root = scene.build_scene(kind="payload", control_mode=None, link_inertials=link_inertials)
    return root.to_xml_string(), root.get_assets()


def rigid_scene_model(payload_mass: float, n_marbles: int = 0,
                      link_inertials: str = "kinova") -> mujoco.MjModel:
    """The true arm + hand + bottle with the whole payload (marbles lumped) as one rigid body.

    Args:
        payload_mass: total mass in the hand (bottle + marbles + extra, kg).
        n_marbles: number of marbles included in ``payload_mass`` (lumped at their resting centroid).
        link_inertials: the arm's link inertials, as the environment's option (:mod:`jaco_env.link_inertials`);
            the default is the default environments' arm (``sensor_pipeline="jaco2"``).
    """
    xml, assets = _rigid_model_xml(check_link_inertials(link_inertials))
    m = mujoco.MjModel.from_xml_string(xml, assets)
    b = m.body(scene.PAYLOAD_BODY).id
    extra = payload_mass - scene.BOTTLE_MASS - n_marbles * scene.MARBLE_MASS
    m_marb = n_marbles * scene.MARBLE_MASS
    if extra < -1e-9:
        raise ValueError(f"payload_mass {payload_mass} kg is lighter than the bottle and marbles")
    # Payload body origin: bottle-frame z = BOTTLE_BOTTOM - BOTTLE_WALL (where the env's extra
    # mass sits); the marbles' resting centroid lies above it along the bottle axis.
    z_marb = scene.lumped_marble_com_offset()[2] - (scene.BOTTLE_BOTTOM - scene.BOTTLE_WALL)
    total = max(extra + m_marb, 1e-9)
    com_z = m_marb * z_marb / total
    m.body_mass[b] = total
    m.body_ipos[b] = [0.0, 0.0, com_z]
    m.body_inertia[b] = scene.payload_inertia(extra, m_marb) + 1e-9
    return m


class PDController:
    """PD feedback only: ``tau = Kp (q_d - q) + Kd (qd_d - qd)``, clipped to the torque limits."""

    dof = _N
    name = "pd"

    def __init__(self, kp: np.ndarray = DEFAULT_KP, kd: np.ndarray = DEFAULT_KD):
        self.kp, self.kd = kp, kd  # the properties check them
        self.n_fallbacks = 0
        self.n_bad_measurements = 0

    @property
    def kp(self) -> np.ndarray:
        """Proportional gains (N m / rad), one per joint; assigning checks them (a scalar is broadcast)."""
        return self._kp

    @kp.setter
    def kp(self, value: np.ndarray | float) -> None:
        self._kp = _as_gain(value, "kp")

    @property
    def kd(self) -> np.ndarray:
        """Derivative gains (N m s / rad), one per joint; assigning checks them."""
        return self._kd

    @kd.setter
    def kd(self, value: np.ndarray | float) -> None:
        self._kd = _as_gain(value, "kd")

    def start(self, env: Any, info: dict[str, Any]) -> None:
        """Called by the episode runner after ``env.reset``: zero the counters. ``ValueError`` for an env in
        velocity mode (these controllers send torques)."""
        mode = getattr(getattr(env, "unwrapped", env), "control_mode", "torque")
        if mode != "torque":
            raise ValueError(f"env: {self.name} sends joint torques; the env is in control_mode={mode!r} "
                             "(make it with control_mode='torque')")
        self.n_fallbacks = 0
        self.n_bad_measurements = 0

    def feedforward(self, q_d: np.ndarray, qd_d: np.ndarray, qdd_d: np.ndarray) -> np.ndarray:
        return np.zeros(_N)

    def __call__(self, t: float, q: np.ndarray, qd: np.ndarray, reference: Reference) -> np.ndarray:
        """Joint torques for the measured ``(q, qd)`` at time ``t`` (s since reset); always finite and
        within the torque limits (module docstring: what raises, what falls back)."""
        if not is_real_number(t):
            raise TypeError(f"t must be a real number (s), got {type(t).__name__} {t!r}")
        if not np.isfinite(t):
            raise ValueError(f"t must be finite, got {t!r}")
        q = real_array(q, (_N,), "q (measured joint positions)", finite=False)
        qd = real_array(qd, (_N,), "qd (measured joint velocities)", finite=False)
        ref = reference(t)
        if not isinstance(ref, (tuple, list)) or len(ref) != 3:
            raise ValueError(f"reference(t) must return (q_d, qd_d, qdd_d), got {type(ref).__name__}")
        q_d, qd_d, qdd_d = (real_array(r, (_N,), f"reference(t)[{i}] ({n})", finite=False)
                            for i, (r, n) in enumerate(zip(ref, ("q_d", "qd_d", "qdd_d"))))
        bad = ~(np.isfinite(q) & np.isfinite(qd) & np.isfinite(q_d) & np.isfinite(qd_d))
        if np.any(bad):
            self.n_bad_measurements += 1
        with np.errstate(over="ignore", invalid="ignore"):
            p_term = np.nan_to_num(self.kp * (q_d - q), nan=0.0, posinf=_BIG, neginf=-_BIG)
            d_term = np.nan_to_num(self.kd * (qd_d - qd), nan=0.0, posinf=_BIG, neginf=-_BIG)
        ff = np.zeros(_N)
        if np.all(np.isfinite(q_d) & np.isfinite(qd_d) & np.isfinite(qdd_d)):
            with np.errstate(over="ignore", invalid="ignore"):
                ff = np.asarray(self.feedforward(q_d, qd_d, qdd_d), dtype=float)
        if not np.all(np.isfinite(ff)):
            self.n_fallbacks += 1
            ff = np.zeros(_N)
        with np.errstate(over="ignore", invalid="ignore"):
            # (ff + P) + D, as before the checks; saturated terms (1e300) cannot make inf - inf.
            tau = ff + np.where(bad, 0.0, p_term) + np.where(bad, 0.0, d_term)
        return np.clip(tau, -robot.TORQUE_LIMITS, robot.TORQUE_LIMITS)


class OracleController(PDController):
    """Computed-torque oracle: true inverse dynamics of the full scene at the reference + PD.

    Args:
        payload_mass: total mass in the hand (kg) for a model usable before :meth:`start`
            (``None``: no model until :meth:`start`).
        n_marbles: marbles included in the payload when ``info`` does not say (``JacoPayload-v0``
            has none).
        kp, kd: PD gains.
        link_inertials: the arm's link inertials of the model built from ``payload_mass`` before :meth:`start`
            (``"kinova"``: the default environments' arm; :meth:`start` uses the env's own).
        follow_marbles: on a ``JacoPour-v0``, lump only the marbles still in the bottle, at their
            current centroid (privileged state), instead of all of them at rest.
    """

    name = "oracle"

    def __init__(self, payload_mass: float | None = None, n_marbles: int = 0, kp: np.ndarray = DEFAULT_KP,
                 kd: np.ndarray = DEFAULT_KD, *, follow_marbles: bool = True, link_inertials: str = "kinova"):
        super().__init__(kp, kd)
        if not isinstance(n_marbles, (int, np.integer)) or isinstance(n_marbles, (bool, np.bool_)) or n_marbles < 0:
            raise ValueError(f"n_marbles must be a non-negative integer, got {n_marbles!r}")
        if payload_mass is not None:
            lo = scene.BOTTLE_MASS + n_marbles * scene.MARBLE_MASS
            if not is_real_number(payload_mass):
                raise TypeError(f"payload_mass must be a real number (kg) or None, got {payload_mass!r}")
            if not lo <= payload_mass <= scene.MAX_PAYLOAD:
                raise ValueError(f"payload_mass must be in [{lo:.3f}, {scene.MAX_PAYLOAD}] kg, got {payload_mass!r}")
        self.n_marbles = int(n_marbles)
        self.follow_marbles = follow_marbles
        self.model: mujoco.MjModel | None = None
        self.data: mujoco.MjData | None = None
        self._env: Any = None  # the pouring env whose marbles are followed, or None
        self._extra = 0.0
        self._payload_b = -1
        # Payload body origin in the bottle frame (same orientation as the bottle).
        self._payload_origin = np.array([0.0, 0.0, scene.BOTTLE_BOTTOM - scene.BOTTLE_WALL])
        if payload_mass is not None:
            self._build(float(payload_mass), self.n_marbles, check_link_inertials(link_inertials))

    def _build(self, payload_mass: float, n_marbles: int, link_inertials: str) -> None:
        self.model = rigid_scene_model(payload_mass, n_marbles, link_inertials)
        self.data = mujoco.MjData(self.model)
        self._payload_b = self.model.body(scene.PAYLOAD_BODY).id
        self._extra = payload_mass - scene.BOTTLE_MASS - n_marbles * scene.MARBLE_MASS

    def start(self, env: Any, info: dict[str, Any]) -> None:
        """Build the rigid model for this episode's payload and the env's link inertials and, on a pouring
        env, follow its marbles."""
        super().start(env, info)
        n_marbles = int(info.get("n_marbles", self.n_marbles))
        if "payload_mass" not in info:
            raise ValueError("info: expected the reset's info with 'payload_mass' (kg), as the jaco_env envs give it")
        mass = scene.check_rigid_payload_mass(info["payload_mass"], "info['payload_mass']")
        unwrapped = getattr(env, "unwrapped", env)  # a Gymnasium wrapper forwards no attributes
        self._build(mass, n_marbles, getattr(unwrapped, "link_inertials", "dm_control"))
        follow = self.follow_marbles and n_marbles > 0 and hasattr(unwrapped, "marbles_in_bottle_frame")
        self._env = unwrapped if follow else None

    def _update_marbles(self, model: mujoco.MjModel) -> None:
        loc, in_bottle = self._env.marbles_in_bottle_frame()
        m_in = scene.MARBLE_MASS * int(in_bottle.sum())
        c = loc[in_bottle].mean(axis=0) - self._payload_origin if m_in > 0 else np.zeros(3)
        total = max(self._extra + m_in, 1e-9)
        model.body_mass[self._payload_b] = total
        model.body_ipos[self._payload_b] = m_in * c / total

    def feedforward(self, q_d: np.ndarray, qd_d: np.ndarray, qdd_d: np.ndarray) -> np.ndarray:
        model, d = self.model, self.data
        if model is None or d is None:  # _build sets both
            raise RuntimeError("OracleController has no model: pass payload_mass or call start(env, info)")
        if self._env is not None:
            self._update_marbles(model)
        d.qpos[:_N] = q_d
        d.qvel[:_N] = qd_d
        d.qacc[:_N] = qdd_d
        mujoco.mj_inverse(model, d)
        return d.qfrc_inverse[:_N].copy()
