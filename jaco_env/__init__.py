"""Simulated Kinova Jaco 2 pouring environments (Gymnasium + MuJoCo).

Importing the package registers ``JacoPour-v0`` and ``JacoPayload-v0``. Headless
rendering: when no display is available (no ``DISPLAY``/``WAYLAND_DISPLAY``) and
``MUJOCO_GL`` is unset, ``MUJOCO_GL=egl`` is set before MuJoCo is imported (use
``MUJOCO_GL=osmesa`` on machines without EGL).
"""

from __future__ import annotations

import os
import sys

if sys.platform.startswith("linux") and "MUJOCO_GL" not in os.environ and not (
    os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
):
    os.environ["MUJOCO_GL"] = "egl"
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

from gymnasium.envs.registration import register, registry  # noqa: E402

from jaco_env import robot  # noqa: E402
from jaco_env.gains import DEFAULT_KD, DEFAULT_KP  # noqa: E402
from jaco_env.sensors import SensorNoise  # noqa: E402

__all__ = ["robot", "SensorNoise", "DEFAULT_KP", "DEFAULT_KD"]

#: 60 s at the default 40 Hz control rate.
MAX_EPISODE_STEPS = 2400

if "JacoPour-v0" not in registry:
    register(id="JacoPour-v0", entry_point="jaco_env.envs:JacoPourEnv", max_episode_steps=MAX_EPISODE_STEPS)
if "JacoPayload-v0" not in registry:
    register(id="JacoPayload-v0", entry_point="jaco_env.envs:JacoPayloadEnv", max_episode_steps=MAX_EPISODE_STEPS)
