"""``JacoPayload-v0``: the Jaco 2 with a rigid payload, for data collection (:class:`JacoPayloadEnv`).

This file owns what is particular to it: the fixed or per-reset payload, the start pose option,
the privileged ``qacc`` in the info and a step without reward. The shared simulation machinery
is :class:`jaco_env.envs.base.JacoMujocoEnv`.
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np
from gymnasium import error
from gymnasium.utils import EzPickle

from jaco_env import robot, scene
from jaco_env.checks import real_array
from jaco_env.envs.base import JacoMujocoEnv, check_options
from jaco_env.excitation import JOINT_RANGES
from jaco_env.kinematics import home_pose
from jaco_env.sensors import MEASUREMENT_DIM, SensorNoise
from jaco_env.signal_pipeline import SignalPipeline


class JacoPayloadEnv(JacoMujocoEnv, EzPickle):
    r"""The Jaco 2 of ``JacoPour-v0`` with a rigid payload: no marbles, no jar, no task.

    For the paper's data collection with random sum-of-sinusoids joint motions
    (:mod:`jaco_env.excitation`), typically in velocity mode.

    ## Description
    Same robot, actuators, sensors and bottle as :class:`JacoPourEnv`; the bottle holds a
    rigid extra mass instead of marbles. Total payload in the hand (bottle + extra):
    ``payload_mass`` (constructor, default 0.8 kg) or ``reset(options={"payload_mass": m})``,
    a real number in [0.2, 1.6] kg (a string or bool raises ``TypeError``); reported in
    ``info["payload_mass"]``, never observed.

    ## Action Space
    As ``JacoPour-v0`` (torque mode: N m; velocity mode: rad/s; clipped; NaN/inf/wrong shape
    raise ``ValueError``, non-real values (str, bool, complex) ``TypeError``; the simulation is
    not touched).

    ## Observation Space
    ``Box(-inf, inf, (19,), float64)``: entries 0-18 of ``JacoPour-v0`` (measured q, qd, tau,
    time since reset), read through ``sensor_pipeline`` as in ``JacoPour-v0`` (read skew, velocity
    source, torque offset, drift, filter and noise per actuator; ``"jaco2"``, the default, or ``"ideal"``).

    ## Rewards
    Always 0 (this environment is for data collection).

    ## Starting State
    At rest at the home pose ``jaco_env.kinematics.home_pose()`` or ``options["q0"]`` (6 finite
    real angles, joints 2 and 3 within their ranges ``jaco_env.excitation.JOINT_RANGES``). A rejected option raises
    before the simulation is touched; an option given as ``None`` is as if absent.

    ## Info
    ``time, payload_mass, unstable`` and ``qacc``: the true joint accelerations at the sample
    instant (privileged, for analysis only: e.g. to measure the error of differentiated
    accelerations; never part of the observation).

    ## Episode End
    Never terminates; truncated by the time limit (``max_episode_steps=2400``, 60 s at 40 Hz;
    pass ``max_episode_steps`` to ``gym.make`` for longer runs) or on an unstable simulation
    (``info["unstable"] = True``; the last finite observation and its time are returned, ``info["qacc"]`` is NaN;
    a step after that returns the same again, with a Gymnasium warning once per episode: call ``reset``).

    ## Arguments
    ``gym.make("JacoPayload-v0", control_mode="torque", control_freq=40.0,
    sensor_noise=SensorNoise(), payload_mass=0.8, render_mode=None, width=480, height=480,
    camera_name=None, sensor_pipeline="jaco2", link_inertials=None)``; ``sensor_pipeline`` (``"ideal"``,
    ``"jaco2"`` or a :class:`jaco_env.SignalPipeline`) and ``link_inertials`` (``"dm_control"``, ``"kinova"``
    or ``None``: the pipeline's) as in ``JacoPour-v0``.

    ## Version History
    - v0: initial version.

    ## Example
        >>> import gymnasium as gym
        >>> import numpy as np
        >>> import jaco_env
        >>> env = gym.make("JacoPayload-v0", payload_mass=1.2)
        >>> obs, info = env.reset(seed=0)
        >>> q, qd, tau, t = jaco_env.split_obs(obs)
        >>> obs.shape, q.shape, t, info["payload_mass"]
        ((19,), (6,), 0.0, 1.2)
        >>> obs, reward, terminated, truncated, info = env.step(np.zeros(6, dtype=np.float32))
        >>> info["qacc"].shape, truncated                  # true accelerations: for analysis only
        ((6,), False)
    """

    _scene_kind = "payload"
    _obs_dim = MEASUREMENT_DIM

    def __init__(
        self,
        control_mode: str = "torque",
        control_freq: float = 40.0,
        sensor_noise: SensorNoise | None = SensorNoise(),
        payload_mass: float = 0.8,
        render_mode: str | None = None,
        width: int = 480,
        height: int = 480,
        camera_name: str | None = None,
        sensor_pipeline: str | SignalPipeline = "jaco2",
        link_inertials: str | None = None,
    ):
        EzPickle.__init__(self, control_mode, control_freq, sensor_noise, payload_mass, render_mode, width,
                          height, camera_name, sensor_pipeline, link_inertials)
        self._fixed_mass = scene.BOTTLE_MASS
        self.default_payload = scene.check_rigid_payload_mass(payload_mass, "payload_mass")
        JacoMujocoEnv.__init__(self, control_mode=control_mode, control_freq=control_freq,
                               sensor_noise=sensor_noise, n_marbles=0, render_mode=render_mode, width=width,
                               height=height, camera_name=camera_name,
                               sensor_pipeline=sensor_pipeline, link_inertials=link_inertials)

    def _parse_options(self, options: dict | None) -> dict:
        opts = check_options(options, ("payload_mass", "q0"))
        parsed: dict[str, Any] = {}
        if "payload_mass" in opts:
            parsed["payload_mass"] = scene.check_rigid_payload_mass(opts["payload_mass"], "options['payload_mass']")
        if "q0" in opts:
            q0 = real_array(opts["q0"], (robot.N_JOINTS,), "options['q0'] (joint angles, rad)")
            for j, limits in enumerate(JOINT_RANGES):
                if limits is not None and not limits[0] <= q0[j] <= limits[1]:
                    raise ValueError(f"options['q0'][{j}]: joint {j + 1}'s angle must be within [{limits[0]:.3f}, "
                                     f"{limits[1]:.3f}] rad, got {float(q0[j])!r}")
            parsed["q0"] = q0
        return parsed

    def reset_model(self) -> np.ndarray:
        """Payload and the arm at rest at the start pose (after ``reset``'s option check)."""
        opts = self._options
        self._set_payload(opts.get("payload_mass", self.default_payload), self._fixed_mass)
        self._reset_arm(opts["q0"] if "q0" in opts else home_pose())
        mujoco.mj_forward(self.model, self.data)
        return self._start_episode()

    def _get_reset_info(self) -> dict[str, Any]:
        return self._info()

    def _info(self) -> dict[str, Any]:
        return {"time": self.time, "payload_mass": self.payload_mass, "unstable": self._unstable,
                "qacc": self._qacc_arm.copy()}

    def step(self, action):
        """Apply ``action`` for one control period (``control_dt``, 25 ms at 40 Hz) and return ``(obs, reward,
        terminated, truncated, info)`` as the class docstring describes (``terminated`` is always ``False``;
        ``info["qacc"]`` holds the true accelerations at the observation's time, for analysis only).

        ``action`` (6,): joint torques in N m (joint velocity commands in rad/s with ``control_mode="velocity"``),
        clipped to the action space's bounds. ``TypeError`` (not real numbers) or ``ValueError`` (another shape, NaN
        or inf) naming ``action``, before anything changes; ``gymnasium.error.ResetNeeded`` before the first
        ``reset``."""
        a = self._validate_action(action)
        if self._last_obs is None:
            raise error.ResetNeeded("Cannot call `env.step()` before calling `env.reset()`")
        self._warn_if_over()
        if not self._unstable:
            if self._simulate(a):
                self._unstable = True  # the last finite observation and its time; its qacc is not known: NaN
            else:
                self._step_count += 1
                self._last_obs = self._get_obs()
        if self.render_mode == "human":
            self.render()
        info = self._info()
        if self._unstable:
            info["qacc"] = np.full(6, np.nan)
        return self._last_obs.copy(), 0.0, False, self._unstable, info
