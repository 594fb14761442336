"""Simulated Kinova Jaco 2 pouring environments (Gymnasium + MuJoCo; never imports torch).

Importing the package registers ``JacoPour-v0`` and ``JacoPayload-v0`` (:mod:`jaco_env.envs`).

==================  ==========================================================================
module              owns
==================  ==========================================================================
``robot``           the arm: joint names, limits, actuator figures, the bare-arm MJCF, quaternions
``scene``           the composed scene (bottle, payload, marbles, jar, actuators), model names,
                    the payload inertia
``sensors``         sensor noise and the observation layout (:func:`split_obs`)
``signal_pipeline`` how the real arm's signals are read (skew, differenced velocity, torque offset,
                    drift, filter): :class:`SignalPipeline`
``kinematics``      forward kinematics, IK, the home pose
``trajectory``      joint-space paths and quintic time scaling
``tasks``           pouring tasks, their reference trajectories, the default task catalogue
``envs``            the environments (``base``, ``pour_v0``, ``payload_v0``)
``gains``           recommended PD gains
``oracle``          reference controllers (oracle, PD) for the episode runner
``excitation``      sum-of-sinusoids motions for data collection
``checks``          input checks shared by the envs and controllers (real numbers, real arrays)
``link_inertials``  the arm's link inertials: dm_control's or Kinova's URDF values
==================  ==========================================================================

Headless
rendering: when no display is available (no ``DISPLAY``/``WAYLAND_DISPLAY``) and
``MUJOCO_GL`` is unset, ``MUJOCO_GL=egl`` is set before MuJoCo is imported (use
``MUJOCO_GL=osmesa`` on machines without EGL).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

#: Version of the ``cascgp-jaco`` distribution (the same as ``cascgp.__version__``).
__version__ = "0.2.0"

_ASSETS = Path(__file__).resolve().parent / "assets"

#: The nominal rigid-body model of the environments' default arm (Kinova's URDF link inertials, those of the
#: default ``sensor_pipeline="jaco2"``): a URDF with a calibration error and no payload or friction, and its JSON
#: sidecar (armature, limits) beside it; ``cascgp.load_nominal(jaco_env.NOMINAL_URDF)`` reads both. The same as
#: ``nominal_urdf("kinova")``; an env made with dm_control's inertials needs ``nominal_urdf("dm_control")``.
#: Written by ``python -m scripts.generate_urdf`` (:mod:`cascgp_experiments.nominal_urdf`).
NOMINAL_URDF = _ASSETS / "jaco2_nominal_kinova.urdf"


def nominal_urdf(link_inertials: str = "kinova") -> Path:
    """The shipped nominal URDF of the arm with the given link inertials (the env option ``link_inertials``,
    resolved as ``env.unwrapped.link_inertials``): ``"kinova"``, Kinova's URDF values, :data:`NOMINAL_URDF` (the
    default arm's), or ``"dm_control"``, the dm_control assets' (:mod:`jaco_env.link_inertials`).

    Example:
        >>> import jaco_env
        >>> jaco_env.nominal_urdf("kinova").name
        'jaco2_nominal_kinova.urdf'
    """
    from jaco_env.link_inertials import check_link_inertials

    suffix = "" if check_link_inertials(link_inertials) == "dm_control" else f"_{link_inertials}"
    return _ASSETS / f"jaco2_nominal{suffix}.urdf"


if sys.platform.startswith("linux") and "MUJOCO_GL" not in os.environ and not (
    os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
):
    os.environ["MUJOCO_GL"] = "egl"
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

from gymnasium.envs.registration import register, registry  # noqa: E402

from jaco_env import robot  # noqa: E402
from jaco_env.gains import DEFAULT_KD, DEFAULT_KP  # noqa: E402
from jaco_env.sensors import (  # noqa: E402
    MEASUREMENT_DIM,
    OBS_JAR,
    OBS_Q,
    OBS_QD,
    OBS_TAU,
    OBS_TIME,
    POUR_OBS_DIM,
    SensorNoise,
    split_obs,
)
from jaco_env.signal_pipeline import SignalPipeline  # noqa: E402

__all__ = ["__version__", "NOMINAL_URDF", "nominal_urdf", "robot", "SensorNoise", "SignalPipeline", "DEFAULT_KP",
           "DEFAULT_KD", "split_obs", "OBS_Q", "OBS_QD", "OBS_TAU", "OBS_TIME", "OBS_JAR", "MEASUREMENT_DIM",
           "POUR_OBS_DIM"]

#: The registered envs' time limit (Gymnasium's ``max_episode_steps``) in control steps, whatever ``control_freq``:
#: 60 s at the default 40 Hz.
MAX_EPISODE_STEPS = 2400

for _id, _entry in (("JacoPour-v0", "jaco_env.envs.pour_v0:JacoPourEnv"),
                    ("JacoPayload-v0", "jaco_env.envs.payload_v0:JacoPayloadEnv")):
    if _id not in registry:
        register(id=_id, entry_point=_entry, max_episode_steps=MAX_EPISODE_STEPS)
