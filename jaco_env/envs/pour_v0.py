"""``JacoPour-v0``: the Jaco 2 pours marbles from a bottle into a jar (:class:`JacoPourEnv`).

This file owns what is particular to pouring: the payload range, the task per episode
(:mod:`jaco_env.tasks`), the marbles (placing them in the bottle, counting them in the jar, the
bottle and spilled), the reward (:meth:`JacoPourEnv._get_rew`) and the info. The shared
simulation machinery is :class:`jaco_env.envs.base.JacoMujocoEnv`.
"""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np
from gymnasium import error
from gymnasium.utils import EzPickle

from jaco_env import scene
from jaco_env.checks import is_real_number
from jaco_env.envs.base import JacoMujocoEnv, check_options
from jaco_env.sensors import POUR_OBS_DIM, SensorNoise
from jaco_env.signal_pipeline import SignalPipeline
from jaco_env.tasks import DEFAULT_TASKS, PouringTask, get_task


def _rows_times(v: np.ndarray, M: np.ndarray, start: Any = 0.0) -> np.ndarray:
    """``start + v @ M`` for (n, 3) rows ``v``, written out element-wise: a matrix product goes to the BLAS kernel
    this CPU picks (with or without FMA), whose last bits differ between CPUs, and the marbles' contacts amplify a
    last-bit difference of their start into a different episode. Element-wise products and sums round the same
    everywhere, so a seed gives the same episode on every CPU."""
    return start + v[:, 0:1] * M[0] + v[:, 1:2] * M[1] + v[:, 2:3] * M[2]

#: Default range (kg) of the total payload in the hand (bottle + marbles + extra rigid mass),
#: drawn uniformly per episode unless the task or ``reset(options=...)`` fixes it.
PAYLOAD_RANGE = (0.6, 1.5)
#: Default reward weights: tracking cost per second and radian, pour reward for all marbles in the jar.
W_TRACK = 10.0
W_POUR = 10.0


class JacoPourEnv(JacoMujocoEnv, EzPickle):
    r"""A torque-controlled Kinova Jaco 2 pours marbles from a bottle into a jar.

    ## Description
    The arm and three-finger hand are the Kinova assets shipped with ``dm_control``, composed
    at run time with ``dm_control.mjcf`` (see :mod:`jaco_env.scene`); MuJoCo simulates them.
    The fingers are welded closed and the **bottle is rigidly attached to the hand** (a
    perfect grasp, no slip). ``n_marbles`` free marbles (default 30, 20-40 recommended) are
    placed inside the bottle at reset. A jar (inner radius 27 mm, 12 cm tall; marbles 15 mm)
    stands on the table at the task's position. The
    actuators emulate the Jaco 2's firmware torque loop, closed on link-side joint torque
    sensors: the link torque follows the command up to the residual rotor inertia and gear
    friction the loop does not remove and a 5 ms lag (:mod:`jaco_env.robot` gives the figures
    and their derivation). The hand carries an **unknown payload** = bottle + marbles + an
    extra rigid mass in the bottle's bottom; its total (``info["payload_mass"]``) is drawn
    uniformly from ``PAYLOAD_RANGE`` = (0.6, 1.5) kg per episode unless the task or
    ``reset(options={"payload_mass": m})`` fixes it (at most 1.6 kg, the Jaco 2 datasheet
    payload). It is never part of the observation.

    A task (:class:`jaco_env.tasks.PouringTask`) gives the reference trajectory
    ``q_d(t), qd_d(t), qdd_d(t)`` (approach, tip, hold, untip, return, settle); the episode
    starts at rest at ``q_d(0)`` with the marbles in the bottle.

    ## Action Space
    ``Box(-limit, limit, (6,), float32)``. Out-of-range actions are **clipped** to the bounds;
    NaN/inf or a wrong shape raise ``ValueError``, values that are not real numbers (strings,
    bools, complex numbers, None) ``TypeError`` (the simulation is not touched).

    | Num | torque mode (default): joint torque (N m) | velocity mode: joint velocity command (rad/s) |
    |-----|-------------------------------------------|-----------------------------------------------|
    | 0-2 | joints 1-3, limit 30.5                     | joints 1-3, limit 0.628 (36 deg/s)            |
    | 3-5 | joints 4-6, limit 6.8                      | joints 4-6, limit 0.838 (48 deg/s)            |

    Torque mode: the commanded torque is held for one control period and reaches the links
    through the firmware torque loop (residual rotor inertia 0.067 / 0.0096 kg m^2 and dry
    friction 0.3 / 0.068 N m on joints 1-3 / 4-6, 5 ms lag). Velocity mode emulates the Kinova
    firmware's joint velocity loop at the physics rate (PI loop ``tau = KV (v - qd) + KI
    (q_ref - q)``, ``q_ref`` the integral of ``v``; gains ``scene.FIRMWARE_KV/KI``) on the same
    torque loop, its torque clipped to the torque limits. The paper collected its training data
    this way.

    ## Observation Space
    ``Box(-inf, inf, (22,), float64)``; measurements carry Gaussian noise
    (:class:`jaco_env.sensors.SensorNoise`, default q 5e-4 rad, qd 5e-3 rad/s, tau 0.1 N m).
    Joint accelerations are not observed. All measurements are **instantaneous samples at the
    same instant** (the end of the control period) under ``sensor_pipeline="ideal"``; the default
    ``"jaco2"`` reads them as the real arm does (table below). The
    measured joint torque is the **link-side** torque of the strain-gauge joint torque sensors,
    read from MuJoCo ``torque`` sensors on the child links and projected on the joint axes: the
    torque passed to the links, without rotor inertia or gear friction. Hence ``(q, qd, tau)`` of
    one observation (noise off) satisfy the rigid-body inverse dynamics of the links and the
    payload at that instant, with the acceleration at that instant (which a data set estimates by
    differentiating ``qd``); contact forces of the marbles on the bottle are part of it. The
    layout is defined once in :mod:`jaco_env.sensors` (``jaco_env.split_obs``).

    ``sensor_pipeline`` chooses how the joint state is read (:mod:`jaco_env.signal_pipeline`; values and
    their sources in ``docs/sensing-sources.md``); the physics is the same under every pipeline:

    | Factor (joints 1-3 / 4-6)            | ``SignalPipeline`` field | ``"ideal"`` | ``"jaco2"``          |
    |--------------------------------------|--------------------------|-------------|----------------------|
    | q read before tau (read skew)        | ``q_lead_s``             | 0           | 8.3 ms               |
    | qd read before tau (read skew)       | ``qd_lead_s``            | 0           | 2.8 ms               |
    | velocity (``velocity_window_s``)     | ``velocity_source``      | ``"true"``  | differenced, 10 ms   |
    | torque offset per episode (std)      | ``tau_offset_std``       | 0           | 0.3 / 0.07 N m       |
    | torque random-walk drift             | ``tau_drift_std``        | 0           | 0.01 / 0.0025 N m/√s |
    | torque first-order low-pass cut-off  | ``tau_filter_hz``        | 0 (none)    | 10 Hz                |
    | torque noise per actuator size       | ``tau_noise_scale``      | 1           | 1 / 0.25             |

    ``"ideal"`` is the behaviour described above, draw for draw. A non-finite measurement truncates the
    episode with ``info["unstable"] = True``.

    | Num   | Observation                                                         | Unit  |
    |-------|---------------------------------------------------------------------|-------|
    | 0-5   | measured joint positions q (dm_control convention, see robot.py)   | rad   |
    | 6-11  | measured joint velocities qd                                        | rad/s |
    | 12-17 | measured joint torque at the sample instant + noise (see below)     | N m   |
    | 18    | time since reset                                                    | s     |
    | 19-21 | jar position (bottom centre, world frame)                          | m     |

    ## Rewards
    ``reward = reward_tracking + reward_pour`` (:meth:`_get_rew`) with
    ``reward_tracking = -tracking_cost_weight * control_dt * ||q_d(t) - q(t)||`` (true q, rad;
    default weight ``W_TRACK`` = 10) and ``reward_pour = pour_reward_weight * (change of the marbles
    in the jar) / n_marbles`` (default weight ``W_POUR`` = 10): positive as marbles land, negative if one
    leaves the jar, so a full pour earns 10.

    ## Starting State
    The arm at rest at ``q_d(0)`` (the common home pose), marbles stacked in the bottle with a
    sub-millimetre random jitter, payload drawn as above.

    ## Episode End
    - Termination: when ``time >= task.duration`` (the pour, return and settling are over).
      Calling ``step`` after ``terminated = True`` logs a Gymnasium warning (once per episode)
      and keeps simulating (the final pose is held by the reference); call ``reset``.
    - Truncation: the registered time limit (``max_episode_steps=2400``, 60 s at 40 Hz), or an
      unstable simulation (NaN, joint speed > 50 rad/s, marble speed > 20 m/s or a MuJoCo
      warning): then ``info["unstable"] = True`` and the last finite observation is returned, with its
      time, tracking error and marble counts in ``info``, and its tracking cost as the step's reward.
      In torque mode, random torques spin the light wrist joints past 50 rad/s within a few seconds
      (nothing limits a joint's speed in the simulation). A step after that returns the same again, with a
      Gymnasium warning (once per episode); call ``reset``.

    ## Info
    ``time, payload_mass, marbles_in_jar, marbles_spilled, marbles_in_bottle, n_marbles,
    tracking_error`` (``||q_d - q||``, true q, rad), ``reward_tracking, reward_pour, unstable,
    task`` (name).

    ## Arguments
    ``gym.make("JacoPour-v0", control_mode="torque", control_freq=40.0,
    sensor_noise=SensorNoise(), n_marbles=30, task=None, payload_range=PAYLOAD_RANGE,
    render_mode=None, width=480, height=480, camera_name=None, tracking_cost_weight=W_TRACK,
    pour_reward_weight=W_POUR, sensor_pipeline="jaco2", link_inertials=None)``. ``sensor_pipeline``: ``"ideal"``,
    ``"jaco2"`` or a :class:`jaco_env.SignalPipeline` (see Observation Space). ``link_inertials``: the arm's
    link inertials, ``"dm_control"`` or ``"kinova"`` (Kinova's URDF values, :mod:`jaco_env.link_inertials`);
    ``None`` follows the pipeline (``"kinova"`` under ``"jaco2"``). ``task``: default task name or
    ``PouringTask``; ``None`` draws one of ``DEFAULT_TASKS`` per reset (``env.unwrapped.task`` is the episode's
    task from ``reset`` on; before the first one it is only a placeholder). ``reset(options=
    {"task": name_or_task, "payload_mass": kg})`` overrides both for one episode (an option given as ``None``
    is as if absent). Every option is
    checked before the simulation is touched (a rejected ``reset`` changes no state): unknown keys
    and out-of-range or unreachable values raise ``ValueError``, wrong types (e.g. a mass given as
    a string or bool) ``TypeError``; a task's reference is built (IK) at that check.
    Physics step: ``control_dt / ceil(control_dt / 2 ms)`` (1.92 ms at 40 Hz).
    Rendering: ``rgb_array`` works headless with ``MUJOCO_GL=egl`` (set by ``import jaco_env``
    when no display is found) or ``osmesa``; ``human`` needs a display. ``render()`` before the
    first ``reset()`` raises ``gymnasium.error.ResetNeeded``; an env left unclosed is closed at exit.

    ## Version History
    - v0: initial version. (Pre-release revisions: jar inner radius 27 mm, pour 5 cm above it, shorter tasks, CG
      solver, the measured torque is an instantaneous sample instead of the period mean; then link-side torque
      sensors, the firmware torque loop with datasheet-derived rotor inertia and friction instead of dm_control's
      4 / 2 kg m^2 armature, and gains derived for the new inertia.)

    ## Example
        >>> import gymnasium as gym
        >>> import jaco_env
        >>> env = gym.make("JacoPour-v0")
        >>> obs, info = env.reset(seed=0, options={"task": "left"})
        >>> obs.shape, info["task"], info["n_marbles"] > 0
        ((22,), 'left', True)
        >>> q, qd, tau, t = jaco_env.split_obs(obs)      # measured joint state; obs[19:22] is the jar position
        >>> obs, reward, terminated, truncated, info = env.step(env.action_space.low * 0)
        >>> round(float(obs[jaco_env.OBS_TIME]), 3), info["unstable"]
        (0.025, False)
    """

    _scene_kind = "pour"
    _obs_dim = POUR_OBS_DIM

    def __init__(
        self,
        control_mode: str = "torque",
        control_freq: float = 40.0,
        sensor_noise: SensorNoise | None = SensorNoise(),
        n_marbles: int = 30,
        task: str | PouringTask | None = None,
        payload_range: tuple[float, float] = PAYLOAD_RANGE,
        render_mode: str | None = None,
        width: int = 480,
        height: int = 480,
        camera_name: str | None = None,
        tracking_cost_weight: float = W_TRACK,
        pour_reward_weight: float = W_POUR,
        sensor_pipeline: str | SignalPipeline = "jaco2",
        link_inertials: str | None = None,
    ):
        EzPickle.__init__(self, control_mode, control_freq, sensor_noise, n_marbles, task, payload_range,
                          render_mode, width, height, camera_name, tracking_cost_weight, pour_reward_weight,
                          sensor_pipeline, link_inertials)
        if not isinstance(n_marbles, (int, np.integer)) or isinstance(n_marbles, (bool, np.bool_)):
            raise TypeError(f"n_marbles must be an integer, got {type(n_marbles).__name__} {n_marbles!r}")
        if not 1 <= n_marbles <= scene.MAX_MARBLES:
            raise ValueError(f"n_marbles must be an integer in [1, {scene.MAX_MARBLES}], got {n_marbles!r}")
        for name, w in (("tracking_cost_weight", tracking_cost_weight), ("pour_reward_weight", pour_reward_weight)):
            if not is_real_number(w):
                raise TypeError(f"{name} must be a real number, got {type(w).__name__} {w!r}")
            if not np.isfinite(w) or w < 0:
                raise ValueError(f"{name} must be a finite number >= 0, got {w!r}")
        self._tracking_cost_weight = float(tracking_cost_weight)
        self._pour_reward_weight = float(pour_reward_weight)
        self._fixed_mass = scene.bottle_mass(n_marbles)
        if not (isinstance(payload_range, (tuple, list, np.ndarray)) and np.ndim(payload_range) == 1
                and len(payload_range) == 2 and all(is_real_number(x) for x in payload_range)):
            raise TypeError(f"payload_range must be two real numbers (low, high) in kg, got {payload_range!r}")
        lo, hi = (float(x) for x in payload_range)
        if not (self._fixed_mass < lo <= hi <= scene.MAX_PAYLOAD):
            raise ValueError(
                f"payload_range must satisfy {self._fixed_mass:.3f} < low <= high <= {scene.MAX_PAYLOAD} kg "
                f"(bottle + marbles weigh {self._fixed_mass:.3f} kg), got {payload_range!r}")
        self.payload_range = (lo, hi)
        self.default_task = None if task is None else self._check_task(get_task(task), "task")
        for t in DEFAULT_TASKS.values() if task is None else ():
            if t.payload_mass is not None:  # drawn per reset: check now, not halfway through one
                scene.check_payload_mass(t.payload_mass, self._fixed_mass, f"task {t.name!r} payload_mass")
        JacoMujocoEnv.__init__(self, control_mode=control_mode, control_freq=control_freq,
                               sensor_noise=sensor_noise, n_marbles=n_marbles, render_mode=render_mode,
                               width=width, height=height, camera_name=camera_name,
                               sensor_pipeline=sensor_pipeline, link_inertials=link_inertials)
        m = self.model
        self._jar_body = m.body("jar").id
        self.marble_qpos_adr = np.array([m.jnt_qposadr[m.joint(f"marble{k}").id] for k in range(n_marbles)])
        self.marble_dof_adr = np.array([m.jnt_dofadr[m.joint(f"marble{k}").id] for k in range(n_marbles)])
        self._marble_pos = self.marble_qpos_adr[:, None] + np.arange(3)
        self._period.watch_marbles(self.marble_dof_adr)
        self.task: PouringTask = self.default_task or DEFAULT_TASKS["front"]
        self._in_jar = 0

    # ------------------------------------------------------------------ marbles
    def marble_positions(self) -> np.ndarray:
        """(n_marbles, 3) world positions of the marbles."""
        return self._qpos[self._marble_pos]  # a gather: a copy

    def marbles_in_bottle_frame(self) -> tuple[np.ndarray, np.ndarray]:
        """Marble positions in the bottle frame (n_marbles, 3) and which are inside the bottle (bool)."""
        p = self.marble_positions()
        xb = self.data.xpos[self._bottle_body]
        Rb = self.data.xmat[self._bottle_body].reshape(3, 3)
        loc = _rows_times(p - xb, Rb)
        in_bottle = (np.linalg.norm(loc[:, :2], axis=1) < scene.BOTTLE_INNER_RADIUS + 0.003) & (
            loc[:, 2] > scene.BOTTLE_BOTTOM - 0.003) & (loc[:, 2] < scene.BOTTLE_TOP)
        return loc, in_bottle

    def marble_counts(self) -> tuple[int, int, int]:
        """(in jar, in bottle, spilled). Spilled: outside both and below the jar rim height."""
        p = self.marble_positions()
        jar = self.task.jar_pos
        r = np.linalg.norm(p[:, :2] - jar[:2], axis=1)
        z = p[:, 2] - jar[2]
        in_jar = (r < scene.JAR_INNER_RADIUS) & (z > -0.01) & (z < scene.JAR_HEIGHT)
        _, in_bottle = self.marbles_in_bottle_frame()
        spilled = ~in_jar & ~in_bottle & (z < scene.JAR_HEIGHT)
        return int(in_jar.sum()), int(in_bottle.sum()), int(spilled.sum())

    def _place_marbles(self) -> None:
        d = self.data
        mujoco.mj_kinematics(self.model, d)
        xb = d.xpos[self._bottle_body].copy()
        Rb = d.xmat[self._bottle_body].reshape(3, 3).copy()
        r = scene.MARBLE_RADIUS
        ring = scene.BOTTLE_INNER_RADIUS - r - 0.0015
        spots: list[list[float]] = []
        layer = 0
        while len(spots) < self.n_marbles:
            z = scene.BOTTLE_BOTTOM + r + 0.001 + layer * (2 * r + 0.001)
            rot = layer * np.pi / 8
            spots.append([0.0, 0.0, z])
            for k in range(8):
                a = rot + 2 * np.pi * k / 8
                spots.append([ring * np.cos(a), ring * np.sin(a), z])
            layer += 1
        local = np.array(spots[: self.n_marbles])
        local[:, :2] += self.np_random.uniform(-3e-4, 3e-4, size=(self.n_marbles, 2))
        world = _rows_times(local, Rb.T, xb)  # xb + local @ Rb.T, the same on every CPU
        for k in range(self.n_marbles):
            a = self.marble_qpos_adr[k]
            d.qpos[a:a + 3] = world[k]
            d.qpos[a + 3:a + 7] = [1.0, 0.0, 0.0, 0.0]

    # ------------------------------------------------------------------ gym API
    def _check_task(self, task: PouringTask, what: str) -> PouringTask:
        """``task`` if this env can run it: its reference is built (an unreachable jar raises
        ``ValueError`` here, not halfway through a reset) and its payload fits the marbles."""
        task.reference(0.0)
        if task.payload_mass is not None:
            scene.check_payload_mass(task.payload_mass, self._fixed_mass,
                                     f"{what} {task.name!r} payload_mass (total in the hand)")
        return task

    def _parse_options(self, options: dict | None) -> dict:
        opts = check_options(options, ("task", "payload_mass"))
        parsed: dict[str, Any] = {}
        if "task" in opts:
            parsed["task"] = self._check_task(get_task(opts["task"]), "options['task']")
        if "payload_mass" in opts:
            parsed["payload_mass"] = scene.check_payload_mass(opts["payload_mass"], self._fixed_mass,
                                                              "options['payload_mass'] (total in the hand)")
        return parsed

    def reset_model(self) -> np.ndarray:
        """Task, payload, arm at rest at ``q_d(0)``, marbles in the bottle (after ``reset``'s option check)."""
        opts = self._options
        task = opts.get("task", self.default_task)
        if task is None:
            names = sorted(DEFAULT_TASKS)
            task = DEFAULT_TASKS[names[int(self.np_random.integers(len(names)))]]
        if "payload_mass" in opts:
            mass = opts["payload_mass"]
        elif task.payload_mass is not None:
            mass = task.payload_mass  # checked by _check_task or in __init__
        else:
            mass = float(self.np_random.uniform(*self.payload_range))
        self.task = task
        self._set_payload(mass, self._fixed_mass)
        self.model.body_pos[self._jar_body] = task.jar_pos
        q0, _, _ = task.reference(0.0)
        self._reset_arm(q0)
        self._place_marbles()
        mujoco.mj_forward(self.model, self.data)
        self._in_jar = 0
        return self._start_episode()

    def _get_reset_info(self) -> dict[str, Any]:
        self._last_err, self._last_counts = 0.0, self.marble_counts()  # what an unstable first step reports
        return self._info({"reward_tracking": 0.0, "reward_pour": 0.0}, 0.0, self._last_counts)

    def _get_obs(self) -> np.ndarray:
        return np.concatenate([self._measure(), self.task.jar_pos])

    def _get_rew(self, tracking_error: float, in_jar: int) -> tuple[float, dict[str, float]]:
        """Reward of a step and its terms, from the true tracking error (rad) and the marbles now in the jar."""
        r_track = -self._tracking_cost_weight * self.control_dt * tracking_error
        r_pour = self._pour_reward_weight * (in_jar - self._in_jar) / self.n_marbles
        return r_track + r_pour, {"reward_tracking": r_track, "reward_pour": r_pour}

    def _info(self, reward_info: dict[str, float], tracking_error: float,
              counts: tuple[int, int, int] | None = None) -> dict[str, Any]:
        in_jar, in_bottle, spilled = self.marble_counts() if counts is None else counts
        return {
            "time": self.time,
            "task": self.task.name,
            "payload_mass": self.payload_mass,
            "marbles_in_jar": in_jar,
            "marbles_in_bottle": in_bottle,
            "marbles_spilled": spilled,
            "n_marbles": self.n_marbles,
            "tracking_error": float(tracking_error),
            "reward_tracking": float(reward_info["reward_tracking"]),
            "reward_pour": float(reward_info["reward_pour"]),
            "unstable": self._unstable,
        }

    def step(self, action):
        """Apply ``action`` for one control period (``control_dt``, 25 ms at 40 Hz) and return ``(obs, reward,
        terminated, truncated, info)`` as the class docstring describes (Action Space, Observation Space, Rewards,
        Episode End, Info).

        ``action`` (6,): joint torques in N m (joint velocity commands in rad/s with ``control_mode="velocity"``),
        clipped to the action space's bounds. ``TypeError`` (not real numbers) or ``ValueError`` (another shape, NaN
        or inf) naming ``action``, before anything changes; ``gymnasium.error.ResetNeeded`` before the first
        ``reset``."""
        a = self._validate_action(action)
        if self._last_obs is None:
            raise error.ResetNeeded("Cannot call `env.step()` before calling `env.reset()`")
        self._warn_if_over()
        if self._unstable or self._simulate(a):
            # The last finite observation, its time and marble counts, charged its tracking cost (a step of the
            # episode like the others: a reward of 0 here paid a learner to make the simulation unstable)
            self._unstable = True
            reward, reward_info = self._get_rew(self._last_err, self._last_counts[0])  # no marble moved: no pour term
            return (self._last_obs.copy(), reward, False, True,
                    self._info(reward_info, self._last_err, self._last_counts))
        self._step_count += 1
        e = self.task.reference_position(self.time) - self._q_arm
        err = math.hypot(*e)  # not e.dot(e): BLAS rounds differently from one CPU to another (see _place_marbles)
        counts = self.marble_counts()
        reward, reward_info = self._get_rew(err, counts[0])
        self._in_jar = counts[0]
        self._last_err, self._last_counts = err, counts
        obs = self._get_obs()
        self._last_obs = obs
        terminated = self.time >= self.task.duration - 1e-9
        self._terminated = self._terminated or terminated
        if self.render_mode == "human":
            self.render()
        # a copy: the caller may change it, and an unstable step returns _last_obs again
        return obs.copy(), reward, terminated, False, self._info(reward_info, err, counts)
