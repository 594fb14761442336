"""The machinery both Jaco 2 environments share (not registered): :class:`JacoMujocoEnv`.

It owns the simulation plumbing on top of Gymnasium's :class:`MujocoEnv`: composing the scene
(:func:`jaco_env.scene.build_scene`) and loading it, the action space and its checks, one
control period of physics (:meth:`JacoMujocoEnv._simulate`: command, torque sensing, instability
checks), the measured part of the observation (:meth:`JacoMujocoEnv._measure`, layout in
:mod:`jaco_env.sensors`), setting the payload, placing the arm at rest, and the reset flow.

Reset flow (as Gymnasium's MuJoCo v5 envs, plus options): :meth:`JacoMujocoEnv.reset` checks the
options with the subclass's :meth:`~JacoMujocoEnv._parse_options` *before* touching the
simulation, keeps them, and calls :meth:`MujocoEnv.reset` (seeds ``np_random``, resets the data,
calls :meth:`reset_model` and :meth:`_get_reset_info`). The override is needed because
``MujocoEnv.reset`` drops ``options``, so ``reset_model`` could not see them otherwise. Each
environment (:mod:`jaco_env.envs.pour_v0`, :mod:`jaco_env.envs.payload_v0`) implements
``reset_model``, ``_get_obs``, ``_get_reset_info`` and ``step``. Every check that can reject a
call (options, action) runs before the simulation is touched: a rejected call changes no state.

Scene files: ``MujocoEnv`` loads its model from a file, and MuJoCo caches the compiled meshes
by file path. The composed scene is therefore written once per process into one folder
(:func:`export_scene`: content-addressed file names, so every env of one configuration loads
the same files and the mesh cache hits; before, each env wrote a fresh folder and the cache
grew by ~3-4 MiB per ``gym.make``). The folder is removed when the process exits (also in
``multiprocessing`` workers, e.g. of an ``AsyncVectorEnv``).

Rendering: :meth:`JacoMujocoEnv.render` before the first :meth:`reset` raises
``gymnasium.error.ResetNeeded`` (as the ``OrderEnforcing`` wrapper of ``gym.make`` does). An env
that rendered and is never closed is closed at interpreter exit, before the OpenGL (EGL)
display is terminated, so that no tracebacks are printed at exit.

``render_mode="human"`` opens a GLFW window (Gymnasium's ``WindowViewer``). Without a display,
GLFW fails an assertion in native code and *aborts the process* (SIGABRT: no exception, no
cleanup, the whole test run or notebook kernel gone; e.g. ``gymnasium.utils.env_checker.check_env``
tries every declared render mode). So ``human`` raises :class:`NoDisplayError` instead, before GLFW is
asked for a window: at construction when neither ``DISPLAY`` nor ``WAYLAND_DISPLAY`` is set (X11 /
Wayland systems), and at the first ``human`` render when GLFW cannot be initialised or finds no
monitor (e.g. a ``DISPLAY`` whose X server is gone). Off-screen modes (``rgb_array``,
``depth_array``) need no display (``MUJOCO_GL=egl`` or ``osmesa``).
"""

from __future__ import annotations

import atexit
import functools
import hashlib
import math
import multiprocessing.util
import os
import shutil
import sys
import tempfile
import threading
import warnings
import weakref
from typing import Any

import mujoco
import numpy as np
from dm_control import mjcf
from gymnasium import error, logger, spaces
from gymnasium.envs.mujoco.mujoco_env import MujocoEnv

from jaco_env import robot, scene
from jaco_env.checks import is_real_number, real_array
from jaco_env.envs.stepping import MAX_JOINT_SPEED, MAX_MARBLE_SPEED, ControlPeriod, live_view  # noqa: F401
from jaco_env.link_inertials import resolve as link_inertials_option
from jaco_env.sensors import MEASUREMENT_DIM, SensorNoise
from jaco_env.signal_pipeline import PipelineState, SignalPipeline

#: Largest physics step (s); the step is control_dt / ceil(control_dt / MAX_PHYSICS_STEP).
MAX_PHYSICS_STEP = 0.002

# dict[str, Any]: MuJoCo's viewer takes lookat as an array (gymnasium annotates the values as numbers only)
DEFAULT_CAMERA: dict[str, Any] = {"distance": 2.0, "azimuth": 150.0, "elevation": -25.0,
                                  "lookat": np.array([0.3, 0.0, 0.25])}

_N = robot.N_JOINTS


# ------------------------------------------------------------------ scene files (one folder per process)
_export_lock = threading.Lock()
_export_dir: str | None = None
_exported: set[str] = set()


def _forget_exports() -> None:
    """In a forked child: start a folder of its own (the parent removes its folder when it exits)."""
    global _export_dir
    _export_dir = None
    _exported.clear()


os.register_at_fork(after_in_child=_forget_exports)


def _remove_folders_of_dead_processes() -> None:
    """Remove the scene folders of killed processes (``jaco_env_<pid>_*`` whose process is gone):
    a process killed by a signal never runs its exit handlers."""
    root = tempfile.gettempdir()
    try:
        names = os.listdir(root)
    except OSError:
        return
    for name in names:
        parts = name.split("_")
        if len(parts) < 4 or parts[:2] != ["jaco", "env"] or not parts[2].isdigit():
            continue
        try:
            os.kill(int(parts[2]), 0)
        except ProcessLookupError:
            shutil.rmtree(os.path.join(root, name), ignore_errors=True)
        except (PermissionError, OverflowError, ValueError):
            pass  # another user's live process, or not a pid


def _write_once(folder: str, name: str, contents: bytes) -> str:
    path = os.path.join(folder, name)
    if path not in _exported:
        if not os.path.exists(path):
            tmp = f"{path}.{os.getpid()}.tmp"
            with open(tmp, "wb") as f:
                f.write(contents)
            os.replace(tmp, path)
        _exported.add(path)
    return path


def export_scene(root: mjcf.RootElement) -> str:
    """Write the composed scene and its mesh assets to this process's scene folder; return the XML's path.

    The asset files keep ``dm_control``'s content-hashed names and the XML is named by the hash of
    its text, so one configuration always gets the same path (MuJoCo's mesh cache, keyed by path,
    hits) and every scene shares the mesh files. Files are written once and never rewritten. The
    folder (``$TMPDIR/jaco_env_<pid>_*``) is removed at exit by ``multiprocessing.util.Finalize``,
    which runs at interpreter exit in the main process and at the end of ``multiprocessing``
    workers; the folders of processes killed by a signal are removed when the next one is created.
    """
    global _export_dir
    xml = root.to_xml_string()
    assets = root.get_assets()
    with _export_lock:
        if _export_dir is None or not os.path.isdir(_export_dir):
            _remove_folders_of_dead_processes()
            _export_dir = tempfile.mkdtemp(prefix=f"jaco_env_{os.getpid()}_")
            _exported.clear()
            multiprocessing.util.Finalize(None, shutil.rmtree, args=(_export_dir,),
                                          kwargs={"ignore_errors": True}, exitpriority=0)
        for name, contents in assets.items():
            _write_once(_export_dir, name, contents if isinstance(contents, bytes) else contents.encode())
        digest = hashlib.sha256(xml.encode()).hexdigest()[:24]
        return _write_once(_export_dir, f"scene-{digest}.xml", xml.encode())


def _close_at_exit(env_ref: weakref.ref) -> None:
    env = env_ref()
    if env is not None:
        env.close()


# ------------------------------------------------------------------ "human" rendering without a display
class NoDisplayError(error.Error, RuntimeError):
    """``render_mode="human"`` where no window can open (no display). A ``RuntimeError`` and a
    ``gymnasium.error.Error``; the message names what is missing and the off-screen alternatives."""


def no_display_reason() -> str | None:
    """Why a ``human`` window cannot open here, judged from the environment alone (GLFW untouched):
    on X11 / Wayland systems (not macOS or Windows) a display is named by ``DISPLAY`` or
    ``WAYLAND_DISPLAY``. ``None`` when nothing is known to be missing."""
    if sys.platform in ("darwin", "win32", "cygwin"):
        return None
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        return None
    return "neither DISPLAY nor WAYLAND_DISPLAY is set"


def _glfw_failure() -> str | None:
    """Initialise GLFW and look for a monitor, as Gymnasium's ``WindowViewer`` does first (it does not
    check, and GLFW's assertion on the missing monitor aborts the process); the reason when either fails."""
    import glfw

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            ok = bool(glfw.init())
            monitor = glfw.get_primary_monitor() if ok else None
        except Exception as exc:  # noqa: BLE001 - pyGLFW raises instead of warning when so configured
            return f"GLFW could not be initialised ({exc})"
    said = "; ".join(str(w.message) for w in caught)
    if not ok:
        return f"GLFW could not be initialised ({said or 'glfw.init() failed'})"
    if not monitor:
        return f"GLFW finds no monitor ({said or 'glfw.get_primary_monitor() is NULL'})"
    return None


def _no_display_message(reason: str) -> str:
    """The :class:`NoDisplayError` text: ``reason``, the display variables as they are, and what to do."""
    return (f"render_mode='human' opens a window, but there is no display: {reason} "
            f"(DISPLAY={os.environ.get('DISPLAY')!r}, WAYLAND_DISPLAY={os.environ.get('WAYLAND_DISPLAY')!r}, "
            f"MUJOCO_GL={os.environ.get('MUJOCO_GL')!r}). Render off-screen instead: render_mode='rgb_array' "
            "(frames as arrays; gymnasium.wrappers.RecordVideo writes them to MP4) or 'depth_array', with "
            "MUJOCO_GL=egl (GPU) or MUJOCO_GL=osmesa (software). For a window, run where a display is: set "
            "DISPLAY (or WAYLAND_DISPLAY), or start a virtual one (xvfb-run -a python ...).")


def check_options(options: dict | None, allowed: tuple[str, ...]) -> dict:
    """The reset options as a new dict (``{}`` for None) without the options given as ``None``, which leave the
    env's own setting as if they were absent; unknown keys raise ``ValueError``."""
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise TypeError(f"reset options must be a dict, got {type(options).__name__}")
    unknown = sorted((key for key in options if key not in allowed), key=repr)  # keys of any type: sorted by repr
    if unknown:
        raise ValueError(f"unknown reset option(s) {unknown}; allowed: {list(allowed)}")
    return {key: value for key, value in options.items() if value is not None}


class JacoMujocoEnv(MujocoEnv):
    """Common machinery of both environments (not registered).

    Its keyword arguments are the environments' own (``JacoPayloadEnv`` and ``JacoPourEnv`` document them and
    hold the defaults): ``control_mode``, ``control_freq`` (Hz), ``sensor_noise``, ``n_marbles``, ``render_mode``,
    ``width`` / ``height`` (pixels), ``camera_name``, ``sensor_pipeline`` and ``link_inertials``.

    Public read-only attributes besides Gymnasium's: ``control_mode``, ``control_dt`` (s),
    ``torque_limits``, ``n_marbles``, ``payload_mass`` (kg, this episode), ``time`` (s since reset)
    and the MuJoCo addresses of the arm: ``arm_qpos_adr``, ``arm_dof_adr`` (index ``data.qpos`` /
    ``data.qvel``, ``qacc``, ``qfrc_*``) and ``velocity_ref_act_adr`` (``data.act`` of the velocity
    loop's integrators, ``q_ref``; empty in torque mode). :meth:`arm_state` gives the true q, qd.
    """

    metadata = {"render_modes": ["human", "rgb_array", "depth_array"], "render_fps": 40}
    #: ``scene.build_scene`` kind and observation length; set by each environment.
    _scene_kind = "payload"
    _obs_dim = MEASUREMENT_DIM
    action_space: spaces.Box  # a Box of the torque or velocity limits (_set_action_space)

    def __init__(self, *, control_mode: str, control_freq: float, sensor_noise: SensorNoise | None, n_marbles: int,
                 render_mode: str | None, width: int, height: int, camera_name: str | None,
                 sensor_pipeline: str | SignalPipeline, link_inertials: str | None):
        # No defaults here: each environment's signature holds the public defaults.
        if not isinstance(control_mode, str):
            raise TypeError(f"control_mode must be 'torque' or 'velocity', got {type(control_mode).__name__} "
                            f"{control_mode!r}")
        if control_mode not in ("torque", "velocity"):
            raise ValueError(f"control_mode must be 'torque' or 'velocity', got {control_mode!r}")
        if not is_real_number(control_freq):
            raise TypeError(f"control_freq must be a real number (Hz), got {type(control_freq).__name__} "
                            f"{control_freq!r}")
        if not math.isfinite(control_freq) or not (1.0 <= control_freq <= 1000.0):
            raise ValueError(f"control_freq must be a number in [1, 1000] Hz, got {control_freq!r}")
        if sensor_noise is not None and not isinstance(sensor_noise, SensorNoise):
            raise TypeError(f"sensor_noise must be a SensorNoise or None, got {type(sensor_noise).__name__}")
        self.sensor_pipeline = SignalPipeline.resolve(sensor_pipeline)
        #: The arm's link inertials (:mod:`jaco_env.link_inertials`): ``None`` follows the pipeline, Kinova's
        #: URDF values under the full ``"jaco2"`` preset and dm_control's otherwise.
        self.link_inertials = link_inertials_option(link_inertials, self.sensor_pipeline)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        if render_mode == "human" and (reason := no_display_reason()) is not None:
            raise NoDisplayError(_no_display_message(reason))
        for name, size in (("width", width), ("height", height)):
            if isinstance(size, bool) or not isinstance(size, (int, np.integer)):
                raise TypeError(f"{name} must be an integer number of pixels in [1, 16384], got "
                                f"{type(size).__name__} {size!r}")
            if not 1 <= size <= 16384:
                raise ValueError(f"{name} must be an integer number of pixels in [1, 16384], got {size!r}")
        if camera_name is not None and not isinstance(camera_name, str):
            raise TypeError(f"camera_name must be a camera's name or None, got {type(camera_name).__name__}")
        self.control_mode = control_mode
        self.sensor_noise = sensor_noise if sensor_noise is not None else SensorNoise.none()
        self.control_dt = 1.0 / float(control_freq)
        n_sub = int(math.ceil(self.control_dt / MAX_PHYSICS_STEP - 1e-9))
        timestep = self.control_dt / n_sub
        self.n_marbles = int(n_marbles)
        self.torque_limits = robot.TORQUE_LIMITS.copy()
        # MujocoEnv asserts render_fps == round(1 / dt) with dt = timestep * frame_skip, which can fall on the other
        # side of a half-integer control_freq (19.5 Hz: 1 / dt = 19.4999..., 19, against round(19.5) = 20): computed
        # the same way here
        self.metadata = {**type(self).metadata, "render_fps": int(np.round(1.0 / (timestep * n_sub)))}

        # The sensing pipeline (signal_pipeline.py): None for "ideal", whose measurement is the noise alone; its
        # skewed reads are MuJoCo's delayed joint sensors, part of the scene.
        self._signal: PipelineState | None = None
        if not self.sensor_pipeline.is_ideal:
            self._signal = PipelineState(self.sensor_pipeline, self.control_dt, timestep, n_sub)
        root = scene.build_scene(kind=self._scene_kind, n_marbles=self.n_marbles, control_mode=control_mode,
                                 timestep=timestep, link_inertials=self.link_inertials,
                                 delayed_reads=None if self._signal is None else self._signal.reads())
        # MujocoEnv loads from a file: one file per configuration per process (export_scene).
        obs_space = spaces.Box(-np.inf, np.inf, shape=(self._obs_dim,), dtype=np.float64)
        self._exit_closer = None
        MujocoEnv.__init__(
            self, export_scene(root), n_sub, observation_space=obs_space, render_mode=render_mode,
            width=width, height=height, camera_name=camera_name,
            default_camera_config=None if camera_name else DEFAULT_CAMERA,
        )
        m = self.model
        if camera_name and mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_CAMERA, camera_name) < 0:
            cameras = [m.camera(i).name for i in range(m.ncam)]
            self.close()
            raise ValueError(f"camera_name: the scene has no camera {camera_name!r}; its cameras are {cameras}")
        joints = [m.joint(scene.ARM_PREFIX + n).id for n in robot.JOINT_NAMES]
        self.arm_qpos_adr = np.array([m.jnt_qposadr[j] for j in joints])
        self.arm_dof_adr = np.array([m.jnt_dofadr[j] for j in joints])
        self.velocity_ref_act_adr = np.array(
            [m.actuator_actadr[m.actuator(f"int_{i + 1}").id] for i in range(_N)]) if (
            control_mode == "velocity") else np.zeros(0, int)
        self._payload_body = m.body(scene.PAYLOAD_BODY).id
        self._bottle_body = m.body(scene.BOTTLE_BODY).id
        self._tau_sensor = np.array([m.sensor_adr[m.sensor(scene.ARM_PREFIX + n).id] + 2
                                     for n in robot.TORQUE_SENSOR_NAMES])
        # Hot path (step): views of the data arrays fetched once (each attribute read of MjData builds a
        # new array object; the arm's entries are live views), the action bounds as float64 (exact: they
        # are float32); one control period of physics and its checks: ControlPeriod (stepping.py).
        d = self.data
        self._qpos = d.qpos
        self._q_arm, self._qd_arm = live_view(d.qpos, self.arm_qpos_adr), live_view(d.qvel, self.arm_dof_adr)
        self._qacc_arm = live_view(d.qacc, self.arm_dof_adr)
        self._act_low = self.action_space.low.astype(np.float64)
        self._act_high = self.action_space.high.astype(np.float64)
        slots = [slice(0, _N)] + ([slice(_N, 2 * _N)] if control_mode == "velocity" else [])
        self._period = ControlPeriod(m, d, self.frame_skip, slots, self._tau_sensor, self.arm_dof_adr)
        self._pending: np.ndarray | None = None  # this step's pipeline measurement, time not yet set
        if self._signal is not None:  # each early read: a live view of its six delayed sensors' data
            delayed = {}
            for read, _, _ in self._signal.reads():
                names = [scene.ARM_PREFIX + robot.read_sensor_name(read, i) for i in range(_N)]
                delayed[read] = live_view(d.sensordata, np.array([m.sensor_adr[m.sensor(n).id] for n in names]))
            self._signal.attach(delayed, self._q_arm, self._qd_arm)
        self._step_count = 0
        self._unstable = False
        self._last_obs: np.ndarray | None = None
        self._terminated = False
        self._warned_over = False
        self._options: dict = {}
        self.marble_dof_adr = np.zeros(0, dtype=int)
        self.payload_mass = 0.0

    # ------------------------------------------------------------------ plumbing
    def _initialize_simulation(self):
        model = mujoco.MjModel.from_xml_path(self.fullpath)
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

    def arm_state(self) -> tuple[np.ndarray, np.ndarray]:
        """True (noiseless) joint positions and velocities (copies), for analysis only."""
        return self._q_arm.copy(), self._qd_arm.copy()

    def _set_payload(self, total: float, fixed_mass: float) -> None:
        extra = total - fixed_mass
        self.model.body_mass[self._payload_body] = extra
        self.model.body_inertia[self._payload_body] = scene.payload_inertia(extra)
        self.payload_mass = float(total)

    def _validate_action(self, action) -> np.ndarray:
        """The action as float64, clipped to the bounds; TypeError (not real numbers: str, bool, complex,
        ...) or ValueError (shape, NaN/inf) naming ``action`` otherwise, before anything changes."""
        # np.clip(a, low, high) for finite a, without np.clip's Python wrapper; the usual action (a float32 or
        # float64 array of the right shape, every entry finite) skips real_array, whose result it would be.
        # Finiteness entry by entry on Python floats (exact for both dtypes): cheaper than a NumPy reduction or
        # dot product for six entries, and no overflow, underflow or invalid-value warning for any action
        if (type(action) is np.ndarray and action.shape == (_N,) and action.dtype.char in "fd"
                and all(map(math.isfinite, action.tolist()))):
            a = np.maximum(action, self._act_low)  # float64 (float32 entries are converted exactly)
        else:
            a = np.maximum(real_array(action, (_N,), "action"), self._act_low)
        return np.minimum(a, self._act_high, out=a)

    def _simulate(self, a: np.ndarray) -> bool:
        """Advance one control period (:class:`~jaco_env.envs.stepping.ControlPeriod`: the command, the
        physics, the torque sample at the end state); return True when the simulation went unstable."""
        if self._period.run(a):
            return True
        sig = self._signal
        if sig is not None:  # a non-finite measurement is an unstable step
            self._pending = sig.measure(self.np_random, self.sensor_noise, self._q_arm, self._qd_arm,
                                        self._period.tau, True)
            return self._pending is None
        return False

    def _measure(self) -> np.ndarray:
        sig = self._signal
        if sig is not None:
            out = self._pending
            if out is None:  # the reset observation: the state as it is, unfiltered
                out = sig.measure(self.np_random, self.sensor_noise, self._q_arm, self._qd_arm, self._period.tau,
                                  False)
                if out is None:
                    raise ValueError("the sensing pipeline gave a non-finite reset observation")
            self._pending = None
            out[-1] = self._step_count * self.control_dt
            return out
        return self.sensor_noise.measurement(self.np_random, self._q_arm, self._qd_arm, self._period.tau,
                                             self._step_count * self.control_dt)  # self.time

    def _reset_arm(self, q0: np.ndarray) -> None:
        d = self.data
        d.qpos[self.arm_qpos_adr] = q0
        d.qvel[:] = 0.0
        if self.control_mode == "velocity":
            d.act[self.velocity_ref_act_adr] = q0
        self._step_count = 0
        self._unstable = False
        self._period.tau = np.zeros(_N)
        self._period.forget()
        self._pending = None

    # ------------------------------------------------------------------ reset flow
    def _parse_options(self, options: dict | None) -> dict:
        """Check ``reset`` options before the simulation is touched; return what ``reset_model`` uses."""
        return check_options(options, ())

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Check the options first (a bad option leaves the simulation untouched), then
        :meth:`MujocoEnv.reset` (which passes no options to ``reset_model``: they are kept in
        ``self._options`` for it). ``reset_model`` records the first observation in ``_last_obs``."""
        self._options = self._parse_options(options)
        return super().reset(seed=seed)

    def _start_episode(self) -> np.ndarray:
        """End of ``reset_model``: the first observation, recorded (``step`` and ``render`` need a reset)."""
        self._terminated = False
        self._warned_over = False
        if self._signal is not None:  # after the episode's draws (task, payload, marbles): the same for any pipeline
            self._signal.reset(self.np_random)
        self._last_obs = self._get_obs()
        return self._last_obs.copy()  # the caller's own array: changing it changes no later observation

    def _warn_if_over(self) -> None:
        """Gymnasium's convention (as ``CartPole``): warn once per episode when ``step`` is called after
        ``terminated``, or after the truncation of an unstable simulation (whose state no step changes)."""
        if self._warned_over or not (self._terminated or self._unstable):
            return
        if self._terminated:
            logger.warn("You are calling 'step()' even though this environment has already returned terminated = "
                        "True. You should always call 'reset()' once you receive 'terminated = True' -- the "
                        "simulation goes on, but the episode is over (its reward and termination no longer "
                        "mean anything).")
        else:
            logger.warn("You are calling 'step()' even though this environment has already returned truncated = "
                        "True on an unstable simulation (info['unstable']). Call 'reset()': every further step "
                        "returns the same last finite observation, info and reward, and changes nothing.")
        self._warned_over = True

    def render(self):
        """Render a frame (Gymnasium's ``MujocoEnv.render``); ``ResetNeeded`` before the first ``reset``;
        in ``human`` mode, :class:`NoDisplayError` before the window is opened if it cannot be."""
        if self._last_obs is None:
            raise error.ResetNeeded("Cannot call `env.render()` before calling `env.reset()`: the scene is not set up")
        if self.render_mode == "human" and getattr(self.mujoco_renderer, "_viewers", {}).get("human") is None:
            reason = no_display_reason() or _glfw_failure()
            if reason is not None:
                raise NoDisplayError(_no_display_message(reason))
        frame = super().render()
        if self._exit_closer is None:
            # Registered after the renderer's OpenGL context exists, hence after EGL's own atexit
            # handler (eglTerminate): atexit runs last-registered first, so this env is closed
            # while the display is still alive. Unregistered by close() or when the env is collected.
            self._exit_closer = functools.partial(_close_at_exit, weakref.ref(self))
            atexit.register(self._exit_closer)
            weakref.finalize(self, atexit.unregister, self._exit_closer).atexit = False
        return frame

    def close(self):
        """Close the rendering contexts (Gymnasium's ``MujocoEnv.close``); safe to call twice."""
        super().close()
        if getattr(self, "_exit_closer", None) is not None:
            atexit.unregister(self._exit_closer)
            self._exit_closer = None

    def _get_obs(self) -> np.ndarray:
        return self._measure()

    def _get_reset_info(self) -> dict[str, Any]:
        raise NotImplementedError
