"""The Gymnasium environments, one per file (as Gymnasium's MuJoCo v5 envs).

==================  =================================================  =============================
id                  class                                              file
==================  =================================================  =============================
``JacoPour-v0``     :class:`~jaco_env.envs.pour_v0.JacoPourEnv`        :mod:`jaco_env.envs.pour_v0`
``JacoPayload-v0``  :class:`~jaco_env.envs.payload_v0.JacoPayloadEnv`  :mod:`jaco_env.envs.payload_v0`
(shared base)       :class:`~jaco_env.envs.base.JacoMujocoEnv`         :mod:`jaco_env.envs.base`
==================  =================================================  =============================

``import jaco_env`` registers both ids.
"""

from __future__ import annotations

from jaco_env.envs.base import JacoMujocoEnv
from jaco_env.envs.payload_v0 import JacoPayloadEnv
from jaco_env.envs.pour_v0 import JacoPourEnv

__all__ = ["JacoMujocoEnv", "JacoPourEnv", "JacoPayloadEnv"]
