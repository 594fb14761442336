"""Gymnasium environments ``JacoPour-v0`` and ``JacoPayload-v0``."""

from __future__ import annotations

import math
import shutil
import tempfile
from typing import Any

import mujoco
import numpy as np
from dm_control import mjcf
from gymnasium import spaces
from gymnasium.envs.mujoco.mujoco_env import MujocoEnv
from gymnasium.utils import EzPickle

from jaco_env import robot, scene
from jaco_env.sensors import SensorNoise
from jaco_env.kinematics import home_pose
from jaco_env.tasks import DEFAULT_TASKS, PouringTask, get_task

#: Default range (kg) of the total payload in the hand (bottle + marbles + extra rigid mass),
#: drawn uniformly per episode unless the task or ``reset(options=...)`` fixes it.
PAYLOAD_RANGE = (0.6, 1.5)
#: Largest physics step (s); the step is control_dt / ceil(control_dt / MAX_PHYSICS_STEP).
MAX_PHYSICS_STEP = 0.002
#: Reward weights: tracking penalty per second and radian, pour bonus for all marbles in the jar.
W_TRACK = 10.0
W_POUR = 10.0
#: A joint speed (rad/s) or marble speed (m/s) above these marks the simulation unstable.
MAX_JOINT_SPEED = 50.0
MAX_MARBLE_SPEED = 20.0

DEFAULT_CAMERA = {"distance": 2.0, "azimuth": 150.0, "elevation": -25.0, "lookat": np.array([0.3, 0.0, 0.25])}
_P = "jaco_arm/"


class _JacoBase(MujocoEnv):
    """Common machinery of both environments (not registered)."""

    metadata = {"render_modes": ["human", "rgb_array", "depth_array"], "render_fps": 40}
    _kind = "payload"

    def __init__(
        self,
        *,
        control_mode: str = "torque",
        control_freq: float = 40.0,
        sensor_noise: SensorNoise | None = SensorNoise(),
        n_marbles: int = 0,
        render_mode: str | None = None,
        width: int = 480,
        height: int = 480,
        camera_name: str | None = None,
    ):
        if control_mode not in ("torque", "velocity"):
            raise ValueError(f"control_mode must be 'torque' or 'velocity', got {control_mode!r}")
        if not isinstance(control_freq, (int, float)) or not math.isfinite(control_freq) or not (
            1.0 <= control_freq <= 1000.0
        ):
            raise ValueError(f"control_freq must be a number in [1, 1000] Hz, got {control_freq!r}")
        if sensor_noise is not None and not isinstance(sensor_noise, SensorNoise):
            raise TypeError(f"sensor_noise must be a SensorNoise or None, got {type(sensor_noise).__name__}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        self.control_mode = control_mode
        self.sensor_noise = sensor_noise if sensor_noise is not None else SensorNoise.none()
        self.control_dt = 1.0 / float(control_freq)
        n_sub = int(math.ceil(self.control_dt / MAX_PHYSICS_STEP - 1e-9))
        timestep = self.control_dt / n_sub
        self.n_marbles = int(n_marbles)
        self.torque_limits = robot.TORQUE_LIMITS.copy()
        self.metadata = {**type(self).metadata, "render_fps": int(round(control_freq))}

        root = scene.build_scene(kind=self._kind, n_marbles=self.n_marbles, control_mode=control_mode,
                                 timestep=timestep)
        # MujocoEnv loads from a file: write the composed MJCF with its mesh assets to a temp
        # dir, load it in _initialize_simulation and delete the dir right away.
        self._tmpdir = tempfile.mkdtemp(prefix="jaco_env_")
        mjcf.export_with_assets(root, self._tmpdir, "scene.xml")
        obs_dim = 19 if self._kind == "payload" else 22
        obs_space = spaces.Box(-np.inf, np.inf, shape=(obs_dim,), dtype=np.float64)
        MujocoEnv.__init__(
            self, f"{self._tmpdir}/scene.xml", n_sub, observation_space=obs_space, render_mode=render_mode,
            width=width, height=height, camera_name=camera_name,
            default_camera_config=None if camera_name else DEFAULT_CAMERA,
        )
        m = self.model
        self._arm_qpos = np.array([m.jnt_qposadr[m.joint(_P + n).id] for n in robot.JOINT_NAMES])
        self._arm_dof = np.array([m.jnt_dofadr[m.joint(_P + n).id] for n in robot.JOINT_NAMES])
        self._payload_body = m.body(_P + "jaco_hand/payload").id
        self._bottle_body = m.body(_P + "jaco_hand/bottle").id
        self._tau_sensor = np.array([m.sensor_adr[m.sensor(_P + n).id] + 2 for n in robot.TORQUE_SENSOR_NAMES])
        self._int_act = np.array([m.actuator_actadr[m.actuator(f"int_{i + 1}").id] for i in range(6)]) if (
            control_mode == "velocity") else np.zeros(0, int)
        self._warn_counts = np.zeros(len(self.data.warning), dtype=np.int64)
        self._step_count = 0
        self._unstable = False
        self._tau_meas_true = np.zeros(6)
        self._last_obs: np.ndarray | None = None
        self._marble_dof = np.zeros(0, dtype=int)
        self.payload_mass = 0.0

    # ------------------------------------------------------------------ plumbing
    def _initialize_simulation(self):
        model = mujoco.MjModel.from_xml_path(self.fullpath)
        shutil.rmtree(self._tmpdir, ignore_errors=True)
        model.vis.global_.offwidth = self.width
        model.vis.global_.offheight = self.height
        return model, mujoco.MjData(model)

    def _set_action_space(self):
        lim = robot.TORQUE_LIMITS if self.control_mode == "torque" else robot.VELOCITY_LIMITS
        self.action_space = spaces.Box(-lim.astype(np.float32), lim.astype(np.float32), dtype=np.float32)
        return self.action_space

    @property
    def time(self) -> float:
        """Time since reset (s)."""
        return self._step_count * self.control_dt

    def _set_payload(self, total: float, fixed_mass: float) -> None:
        extra = total - fixed_mass
        self.model.body_mass[self._payload_body] = extra
        self.model.body_inertia[self._payload_body] = scene.payload_inertia(extra)
        self.payload_mass = float(total)

    def _validate_action(self, action) -> np.ndarray:
        try:
            a = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"action must be an array of 6 numbers, got {type(action).__name__}") from exc
        if a.shape != (6,):
            raise ValueError(f"action must have shape (6,), got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            bad = np.flatnonzero(~np.isfinite(a)).tolist()
            raise ValueError(f"action must be finite; entries {bad} are NaN or inf: {a.tolist()}")
        return np.clip(a, self.action_space.low, self.action_space.high)

    def _simulate(self, a: np.ndarray) -> bool:
        """Advance one control period; return True when the simulation went unstable."""
        m, d = self.model, self.data
        d.ctrl[:6] = a
        if self.control_mode == "velocity":
            d.ctrl[6:12] = a
        mujoco.mj_step(m, d, nstep=self.frame_skip)
        # The joint torque sensors sample at the same instant as q and qd (the end of the period),
        # with the command of the period just ended still in effect: mj_step left the sensors of
        # the *start* of its last physics step, so evaluate the model at the current state.
        mujoco.mj_forward(m, d)
        self._tau_meas_true = d.sensordata[self._tau_sensor].copy()
        warn = np.array([w.number for w in d.warning], dtype=np.int64)
        new_warning = bool(np.any(warn > self._warn_counts))
        self._warn_counts = warn
        unstable = new_warning or not (np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel)))
        if not unstable:
            unstable = bool(np.max(np.abs(d.qvel[self._arm_dof])) > MAX_JOINT_SPEED)
        if not unstable and self.n_marbles:
            lin = d.qvel[self._marble_dof[:, None] + np.arange(3)]
            unstable = bool(np.max(np.linalg.norm(lin, axis=1)) > MAX_MARBLE_SPEED)
        return unstable

    def _measure(self) -> np.ndarray:
        d = self.data
        q = d.qpos[self._arm_qpos].copy()
        qd = d.qvel[self._arm_dof].copy()
        qm, qdm, taum = self.sensor_noise.apply(self.np_random, q, qd, self._tau_meas_true)
        return np.concatenate([qm, qdm, taum, [self.time]])

    def _reset_arm(self, q0: np.ndarray) -> None:
        d = self.data
        d.qpos[self._arm_qpos] = q0
        d.qvel[:] = 0.0
        if self.control_mode == "velocity":
            d.act[self._int_act] = q0
        self._step_count = 0
        self._unstable = False
        self._tau_meas_true = np.zeros(6)
        self._warn_counts = np.zeros(len(d.warning), dtype=np.int64)

    @staticmethod
    def _check_options(options: dict | None, allowed: tuple[str, ...]) -> dict:
        if options is None:
            return {}
        if not isinstance(options, dict):
            raise TypeError(f"reset options must be a dict, got {type(options).__name__}")
        unknown = sorted(set(options) - set(allowed))
        if unknown:
            raise ValueError(f"unknown reset option(s) {unknown}; allowed: {list(allowed)}")
        return options

    @staticmethod
    def _check_mass(value, lo: float, hi: float, what: str) -> float:
        try:
            v = float(value)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"{what} must be a number (kg), got {value!r}") from exc
        if not math.isfinite(v) or not (lo <= v <= hi):
            raise ValueError(f"{what} must be in [{lo:.3f}, {hi:.3f}] kg, got {v!r}")
        return v


class JacoPourEnv(_JacoBase, EzPickle):
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
    NaN/inf or a wrong shape raise ``ValueError`` (the simulation is not touched).

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
    same instant** (the end of the control period), as the Jaco 2's sampled joint sensors. The
    measured joint torque is the **link-side** torque of the strain-gauge joint torque sensors,
    read from MuJoCo ``torque`` sensors on the child links and projected on the joint axes: the
    torque passed to the links, without rotor inertia or gear friction. Hence ``(q, qd, tau)`` of
    one observation (noise off) satisfy the rigid-body inverse dynamics of the links and the
    payload at that instant, with the acceleration at that instant (which a data set estimates by
    differentiating ``qd``); contact forces of the marbles on the bottle are part of it.

    | Num   | Observation                                                         | Unit  |
    |-------|---------------------------------------------------------------------|-------|
    | 0-5   | measured joint positions q (dm_control convention, see robot.py)   | rad   |
    | 6-11  | measured joint velocities qd                                        | rad/s |
    | 12-17 | measured joint torque at the sample instant + noise (see below)     | N m   |
    | 18    | time since reset                                                    | s     |
    | 19-21 | jar position (bottom centre, world frame)                          | m     |

    ## Rewards
    ``reward = reward_tracking + reward_pour`` with
    ``reward_tracking = -W_TRACK * control_dt * ||q_d(t) - q(t)||`` (true q, rad; W_TRACK = 10)
    and ``reward_pour = W_POUR * (newly landed marbles in the jar) / n_marbles`` (W_POUR = 10,
    so a full pour earns 10).

    ## Starting State
    The arm at rest at ``q_d(0)`` (the common home pose), marbles stacked in the bottle with a
    sub-millimetre random jitter, payload drawn as above.

    ## Episode End
    - Termination: when ``time >= task.duration`` (the pour, return and settling are over).
    - Truncation: the registered time limit (``max_episode_steps=2400``, 60 s at 40 Hz), or an
      unstable simulation (NaN, joint speed > 50 rad/s, marble speed > 20 m/s or a MuJoCo
      warning): then ``info["unstable"] = True`` and the last finite observation is returned.

    ## Info
    ``time, payload_mass, marbles_in_jar, marbles_spilled, marbles_in_bottle, n_marbles,
    tracking_error`` (``||q_d - q||``, true q, rad), ``reward_tracking, reward_pour, unstable,
    task`` (name).

    ## Arguments
    ``gym.make("JacoPour-v0", control_mode="torque", control_freq=40.0,
    sensor_noise=SensorNoise(), n_marbles=30, task=None, payload_range=PAYLOAD_RANGE,
    render_mode=None, width=480, height=480)``. ``task``: default task name or
    ``PouringTask``; ``None`` draws one of ``DEFAULT_TASKS`` per reset. ``reset(options=
    {"task": name_or_task, "payload_mass": kg})`` overrides both for one episode.
    Physics step: ``control_dt / ceil(control_dt / 2 ms)`` (1.92 ms at 40 Hz).
    Rendering: ``rgb_array`` works headless with ``MUJOCO_GL=egl`` (set by ``import jaco_env``
    when no display is found) or ``osmesa``; ``human`` needs a display.

    ## Version History
    - v0: initial version. (Pre-release revisions: jar inner radius 27 mm, pour 5 cm above it, shorter tasks, CG
      solver, the measured torque is an instantaneous sample instead of the period mean; then link-side torque
      sensors, the firmware torque loop with datasheet-derived rotor inertia and friction instead of dm_control's
      4 / 2 kg m^2 armature, and gains derived for the new inertia.)
    """

    _kind = "pour"

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
    ):
        EzPickle.__init__(self, control_mode, control_freq, sensor_noise, n_marbles, task, payload_range,
                          render_mode, width, height, camera_name)
        if not isinstance(n_marbles, (int, np.integer)) or not 1 <= n_marbles <= 60:
            raise ValueError(f"n_marbles must be an integer in [1, 60], got {n_marbles!r}")
        self._fixed_mass = scene.BOTTLE_MASS + n_marbles * scene.MARBLE_MASS
        lo, hi = (float(x) for x in payload_range)
        if not (self._fixed_mass < lo <= hi <= scene.MAX_PAYLOAD):
            raise ValueError(
                f"payload_range must satisfy {self._fixed_mass:.3f} < low <= high <= {scene.MAX_PAYLOAD} kg "
                f"(bottle + marbles weigh {self._fixed_mass:.3f} kg), got {payload_range!r}")
        self.payload_range = (lo, hi)
        self.default_task = None if task is None else get_task(task)
        _JacoBase.__init__(self, control_mode=control_mode, control_freq=control_freq, sensor_noise=sensor_noise,
                           n_marbles=n_marbles, render_mode=render_mode, width=width, height=height,
                           camera_name=camera_name)
        m = self.model
        self._jar_body = m.body("jar").id
        self._marble_qpos = np.array([m.jnt_qposadr[m.joint(f"marble{k}").id] for k in range(n_marbles)])
        self._marble_dof = np.array([m.jnt_dofadr[m.joint(f"marble{k}").id] for k in range(n_marbles)])
        self.task: PouringTask = self.default_task or DEFAULT_TASKS["front"]
        self._in_jar = 0

    # ------------------------------------------------------------------ marbles
    def marble_positions(self) -> np.ndarray:
        """(n_marbles, 3) world positions of the marbles."""
        idx = self._marble_qpos[:, None] + np.arange(3)
        return self.data.qpos[idx].copy()

    def marbles_in_bottle_frame(self) -> tuple[np.ndarray, np.ndarray]:
        """Marble positions in the bottle frame (n_marbles, 3) and which are inside the bottle (bool)."""
        p = self.marble_positions()
        xb = self.data.xpos[self._bottle_body]
        Rb = self.data.xmat[self._bottle_body].reshape(3, 3)
        loc = (p - xb) @ Rb
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
        local = []
        layer = 0
        while len(local) < self.n_marbles:
            z = scene.BOTTLE_BOTTOM + r + 0.001 + layer * (2 * r + 0.001)
            rot = layer * np.pi / 8
            local.append([0.0, 0.0, z])
            for k in range(8):
                a = rot + 2 * np.pi * k / 8
                local.append([ring * np.cos(a), ring * np.sin(a), z])
            layer += 1
        local = np.array(local[: self.n_marbles])
        local[:, :2] += self.np_random.uniform(-3e-4, 3e-4, size=(self.n_marbles, 2))
        world = xb + local @ Rb.T
        for k in range(self.n_marbles):
            a = self._marble_qpos[k]
            d.qpos[a:a + 3] = world[k]
            d.qpos[a + 3:a + 7] = [1.0, 0.0, 0.0, 0.0]

    # ------------------------------------------------------------------ gym API
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        opts = self._check_options(options, ("task", "payload_mass"))
        # Resolve everything before touching the simulation.
        if "task" in opts:
            task = get_task(opts["task"])
        elif self.default_task is not None:
            task = self.default_task
        else:
            task = None
        MujocoEnv.reset(self, seed=seed, options=None)  # seeds np_random, resets data, calls reset_model
        if task is None:
            names = sorted(DEFAULT_TASKS)
            task = DEFAULT_TASKS[names[int(self.np_random.integers(len(names)))]]
        if "payload_mass" in opts:
            mass = self._check_mass(opts["payload_mass"], self._fixed_mass + 1e-3, scene.MAX_PAYLOAD,
                                    "options['payload_mass'] (total in the hand)")
        elif task.payload_mass is not None:
            mass = self._check_mass(task.payload_mass, self._fixed_mass + 1e-3, scene.MAX_PAYLOAD,
                                    f"task {task.name!r} payload_mass")
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
        obs = self._get_obs()
        self._last_obs = obs
        if self.render_mode == "human":
            self.render()
        return obs, self._info(0.0, 0.0, tracking_error=0.0)

    def reset_model(self):  # called by MujocoEnv.reset; the real work is in reset()
        return np.zeros(self.observation_space.shape)

    def _get_obs(self) -> np.ndarray:
        return np.concatenate([self._measure(), self.task.jar_pos])

    def _info(self, r_track: float, r_pour: float, tracking_error: float) -> dict[str, Any]:
        in_jar, in_bottle, spilled = self.marble_counts()
        return {
            "time": self.time,
            "task": self.task.name,
            "payload_mass": self.payload_mass,
            "marbles_in_jar": in_jar,
            "marbles_in_bottle": in_bottle,
            "marbles_spilled": spilled,
            "n_marbles": self.n_marbles,
            "tracking_error": float(tracking_error),
            "reward_tracking": float(r_track),
            "reward_pour": float(r_pour),
            "unstable": self._unstable,
        }

    def step(self, action):
        a = self._validate_action(action)
        if self._last_obs is None:
            raise RuntimeError("call reset() before step()")
        if self._unstable:
            info = self._info(0.0, 0.0, float("nan"))
            info["tracking_error"] = 0.0
            return self._last_obs.copy(), 0.0, False, True, info
        unstable = self._simulate(a)
        self._step_count += 1
        if unstable:
            self._unstable = True
            info = self._info(0.0, 0.0, 0.0)
            return self._last_obs.copy(), 0.0, False, True, info
        q_d, _, _ = self.task.reference(self.time)
        err = float(np.linalg.norm(q_d - self.data.qpos[self._arm_qpos]))
        in_jar, _, _ = self.marble_counts()
        r_track = -W_TRACK * self.control_dt * err
        r_pour = W_POUR * (in_jar - self._in_jar) / self.n_marbles
        self._in_jar = in_jar
        obs = self._get_obs()
        self._last_obs = obs
        terminated = self.time >= self.task.duration - 1e-9
        if self.render_mode == "human":
            self.render()
        return obs, r_track + r_pour, terminated, False, self._info(r_track, r_pour, err)


class JacoPayloadEnv(_JacoBase, EzPickle):
    r"""The Jaco 2 of ``JacoPour-v0`` with a rigid payload: no marbles, no jar, no task.

    For the paper's data collection with random sum-of-sinusoids joint motions
    (:mod:`jaco_env.excitation`), typically in velocity mode.

    ## Description
    Same robot, actuators, sensors and bottle as :class:`JacoPourEnv`; the bottle holds a
    rigid extra mass instead of marbles. Total payload in the hand (bottle + extra):
    ``payload_mass`` (constructor, default 0.8 kg) or ``reset(options={"payload_mass": m})``,
    in [0.2, 1.6] kg; reported in ``info["payload_mass"]``, never observed.

    ## Action Space
    As ``JacoPour-v0`` (torque mode: N m; velocity mode: rad/s; clipped; NaN/inf/wrong shape
    raise ``ValueError``).

    ## Observation Space
    ``Box(-inf, inf, (19,), float64)``: entries 0-18 of ``JacoPour-v0`` (measured q, qd, tau,
    time since reset).

    ## Rewards
    Always 0 (this environment is for data collection).

    ## Starting State
    At rest at the home pose ``jaco_env.tasks.home_pose()`` or ``options["q0"]`` (6 angles).

    ## Info
    ``time, payload_mass, unstable`` and ``qacc``: the true joint accelerations at the sample
    instant (privileged, for analysis only: e.g. to measure the error of differentiated
    accelerations; never part of the observation).

    ## Episode End
    Never terminates; truncated by the time limit (``max_episode_steps=2400``, 60 s at 40 Hz;
    pass ``max_episode_steps`` to ``gym.make`` for longer runs) or on an unstable simulation
    (``info["unstable"] = True``).

    ## Arguments
    ``gym.make("JacoPayload-v0", control_mode="torque", control_freq=40.0,
    sensor_noise=SensorNoise(), payload_mass=0.8, render_mode=None, width=480, height=480)``.

    ## Version History
    - v0: initial version.
    """

    _kind = "payload"

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
    ):
        EzPickle.__init__(self, control_mode, control_freq, sensor_noise, payload_mass, render_mode, width,
                          height, camera_name)
        self._fixed_mass = scene.BOTTLE_MASS
        self.default_payload = self._check_mass(payload_mass, scene.BOTTLE_MASS, scene.MAX_PAYLOAD, "payload_mass")
        _JacoBase.__init__(self, control_mode=control_mode, control_freq=control_freq, sensor_noise=sensor_noise,
                           n_marbles=0, render_mode=render_mode, width=width, height=height,
                           camera_name=camera_name)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        opts = self._check_options(options, ("payload_mass", "q0"))
        mass = self.default_payload
        if "payload_mass" in opts:
            mass = self._check_mass(opts["payload_mass"], scene.BOTTLE_MASS, scene.MAX_PAYLOAD,
                                    "options['payload_mass']")
        q0 = home_pose()
        if "q0" in opts:
            q0 = np.asarray(opts["q0"], dtype=float)
            if q0.shape != (6,) or not np.all(np.isfinite(q0)):
                raise ValueError(f"options['q0'] must be 6 finite joint angles, got {opts['q0']!r}")
        MujocoEnv.reset(self, seed=seed, options=None)
        self._set_payload(mass, self._fixed_mass)
        self._reset_arm(q0)
        mujoco.mj_forward(self.model, self.data)
        obs = self._measure()
        self._last_obs = obs
        if self.render_mode == "human":
            self.render()
        return obs, self._info()

    def reset_model(self):
        return np.zeros(self.observation_space.shape)

    def _info(self) -> dict[str, Any]:
        return {"time": self.time, "payload_mass": self.payload_mass, "unstable": self._unstable,
                "qacc": self.data.qacc[self._arm_dof].copy()}

    def step(self, action):
        a = self._validate_action(action)
        if self._last_obs is None:
            raise RuntimeError("call reset() before step()")
        if not self._unstable:
            self._step_count += 1
            if self._simulate(a):
                self._unstable = True
            else:
                self._last_obs = self._measure()
        if self.render_mode == "human":
            self.render()
        return self._last_obs.copy(), 0.0, False, self._unstable, self._info()
