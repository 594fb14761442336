"""Reference controllers at the control rate (NumPy + MuJoCo, no torch): the oracle and PD only.

Both follow the controller protocol of the one episode runner, :func:`cascgp.episodes.run_episode`
(``cascgp.controller.Controller``; structurally: this package never imports ``cascgp``):
attributes ``dof`` and ``name``, ``start(env, info)`` called right after ``env.reset``, and
``__call__(t, q, qd, reference) -> tau`` with ``reference(t) -> (q_d, qd_d, qdd_d)``. Both clip
their output to the Kinova torque limits.

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
from jaco_env.gains import DEFAULT_KD, DEFAULT_KP

Reference = Callable[[float], tuple[np.ndarray, np.ndarray, np.ndarray]]

_N = robot.N_JOINTS


@functools.lru_cache(maxsize=1)
def _rigid_model_xml() -> tuple[str, dict]:
    root = scene.build_scene(kind="payload", control_mode=None)
    return root.to_xml_string(), root.get_assets()


def rigid_scene_model(payload_mass: float, n_marbles: int = 0) -> mujoco.MjModel:
    """The true arm + hand + bottle with the whole payload (marbles lumped) as one rigid body.

    Args:
        payload_mass: total mass in the hand (bottle + marbles + extra, kg).
        n_marbles: number of marbles included in ``payload_mass`` (lumped at their resting centroid).
    """
    xml, assets = _rigid_model_xml()
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
    n_fallbacks = 0

    def __init__(self, kp: np.ndarray = DEFAULT_KP, kd: np.ndarray = DEFAULT_KD):
        self.kp = np.asarray(kp, float)
        self.kd = np.asarray(kd, float)

    def start(self, env: Any, info: dict[str, Any]) -> None:
        """Called by the episode runner after ``env.reset``; PD keeps no episode state."""

    def feedforward(self, q_d: np.ndarray, qd_d: np.ndarray, qdd_d: np.ndarray) -> np.ndarray:
        return np.zeros(_N)

    def __call__(self, t: float, q: np.ndarray, qd: np.ndarray, reference: Reference) -> np.ndarray:
        """Joint torques for the measured ``(q, qd)`` at time ``t`` (s since reset)."""
        q_d, qd_d, qdd_d = reference(t)
        tau = self.feedforward(q_d, qd_d, qdd_d) + self.kp * (q_d - q) + self.kd * (qd_d - qd)
        return np.clip(tau, -robot.TORQUE_LIMITS, robot.TORQUE_LIMITS)


class OracleController(PDController):
    """Computed-torque oracle: true inverse dynamics of the full scene at the reference + PD.

    Args:
        payload_mass: total mass in the hand (kg) for a model usable before :meth:`start`
            (``None``: no model until :meth:`start`).
        n_marbles: marbles included in the payload when ``info`` does not say (``JacoPayload-v0``
            has none).
        kp, kd: PD gains.
        follow_marbles: on a ``JacoPour-v0``, lump only the marbles still in the bottle, at their
            current centroid (privileged state), instead of all of them at rest.
    """

    name = "oracle"

    def __init__(self, payload_mass: float | None = None, n_marbles: int = 0, kp: np.ndarray = DEFAULT_KP,
                 kd: np.ndarray = DEFAULT_KD, *, follow_marbles: bool = True):
        super().__init__(kp, kd)
        self.n_marbles = int(n_marbles)
        self.follow_marbles = follow_marbles
        self.model: mujoco.MjModel | None = None
        self.data: mujoco.MjData | None = None
        self._env = None
        self._extra = 0.0
        self._payload_b = -1
        # Payload body origin in the bottle frame (same orientation as the bottle).
        self._payload_origin = np.array([0.0, 0.0, scene.BOTTLE_BOTTOM - scene.BOTTLE_WALL])
        if payload_mass is not None:
            self._build(float(payload_mass), self.n_marbles)

    def _build(self, payload_mass: float, n_marbles: int) -> None:
        self.model = rigid_scene_model(payload_mass, n_marbles)
        self.data = mujoco.MjData(self.model)
        self._payload_b = self.model.body(scene.PAYLOAD_BODY).id
        self._extra = payload_mass - scene.BOTTLE_MASS - n_marbles * scene.MARBLE_MASS

    def start(self, env: Any, info: dict[str, Any]) -> None:
        """Build the rigid model for this episode's payload and, on a pouring env, follow its marbles."""
        n_marbles = int(info.get("n_marbles", self.n_marbles))
        self._build(float(info["payload_mass"]), n_marbles)
        follow = self.follow_marbles and n_marbles > 0 and hasattr(env, "marbles_in_bottle_frame")
        self._env = env if follow else None

    def _update_marbles(self) -> None:
        loc, in_bottle = self._env.marbles_in_bottle_frame()
        m_in = scene.MARBLE_MASS * int(in_bottle.sum())
        c = loc[in_bottle].mean(axis=0) - self._payload_origin if m_in > 0 else np.zeros(3)
        total = max(self._extra + m_in, 1e-9)
        self.model.body_mass[self._payload_b] = total
        self.model.body_ipos[self._payload_b] = m_in * c / total

    def feedforward(self, q_d: np.ndarray, qd_d: np.ndarray, qdd_d: np.ndarray) -> np.ndarray:
        if self.model is None:
            raise RuntimeError("OracleController has no model: pass payload_mass or call start(env, info)")
        if self._env is not None:
            self._update_marbles()
        d = self.data
        d.qpos[:_N] = q_d
        d.qvel[:_N] = qd_d
        d.qacc[:_N] = qdd_d
        mujoco.mj_inverse(self.model, d)
        return d.qfrc_inverse[:_N].copy()
