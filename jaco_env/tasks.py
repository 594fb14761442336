"""Pouring tasks: the task description, its reference trajectory and the catalogue of default tasks.

A :class:`PouringTask` names a jar position, a payload and timing. Its reference
trajectory q_d(t), qd_d(t), qdd_d(t) has five phases:

==========  ===========================================================================
phase       motion
==========  ===========================================================================
approach    from the common home pose (bottle upright, in front of the robot) to the
            pre-pour pose: bottle upright, its mouth ``pre_height`` above the jar centre
tip         the bottle is tilted about the hand's approach axis to ``tilt`` (rad from
            upright) while its mouth stays over the jar (``pour_height`` above the rim,
            offset ``pour_offset`` back along the tilt direction so the stream of
            marbles leaving the lower lip lands in the middle of the jar)
hold        the tilted pose is held for ``hold`` seconds
return      tilt back to upright (the tip path reversed), then back to the home pose
settle      the home pose is held for ``settle`` seconds (marbles land and come to rest)
==========  ===========================================================================

The poses are computed once by inverse kinematics (:mod:`jaco_env.kinematics`). The tip phase
is solved at ``N_TIP_POINTS`` tilt angles (warm-started one from the next) and interpolated by
a spline re-parametrised by the velocity-limit-weighted arc length; the other phases are
straight lines in joint space; every phase is time-scaled by a quintic whose duration is the
shortest for which no joint exceeds ``speed`` (``tip_speed`` while tipping) times its velocity
limit (primitives in :mod:`jaco_env.trajectory`). Default tasks last 14.6-19.5 s (the tip, ~5 s
each way, is limited by the wrist roll).

:data:`DEFAULT_TASKS` holds the named tasks of ``JacoPour-v0``; :func:`get_task` resolves a
name or a task.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from jaco_env import robot, scene
from jaco_env.checks import is_real_number, real_array
from jaco_env.kinematics import HOME_MOUTH, home_pose, solve_ik, target_rotation
from jaco_env.trajectory import Segment, line_path, segment_duration, spline_path

#: Tilt angles at which the tip phase is solved by IK (the spline's knots).
N_TIP_POINTS = 13


#: Slowest ``speed`` / ``tip_speed`` of a :class:`PouringTask` (a fraction of the velocity limits: with both at 0.01 a
#: default task lasts about 20 minutes; slower ones overflow the time scaling's arithmetic long before any use).
MIN_SPEED = 0.01
#: Longest ``hold`` / ``settle`` of a :class:`PouringTask` (s).
MAX_HOLD_S = 600.0


@dataclass
class PouringTask:
    """A pouring task: where the jar stands, what the hand carries, and how fast to pour.

    Attributes:
        name: task name.
        jar_pos: (3,) jar bottom centre (m, world frame; robot base at origin): on the table top
            (z = 0) or above it, and clear of the robot's base (its axis at least 0.083 m from the z axis).
        payload_mass: total mass held in the hand (bottle + marbles + extra rigid mass, kg), or
            ``None`` to draw it per episode (see ``JacoPourEnv``); at most 1.6 kg.
        tilt: final bottle tilt from upright (rad).
        pour_height: height of the mouth centre above the jar rim at full tilt (m).
        pre_height: height of the mouth above the rim before tipping (m).
        pour_offset: horizontal offset (m) of the mouth centre from the jar axis, against the
            tilt direction, so that the marbles leaving the lower lip fall into the middle.
        hold: time the tilted pose is held (s), at most ``MAX_HOLD_S``.
        settle: time the home pose is held at the end (s), at most ``MAX_HOLD_S``.
        speed: fraction of the joint velocity limits used by the time scaling, in [``MIN_SPEED``, 1].
        tip_speed: fraction of the velocity limits used while tipping and un-tipping, in [``MIN_SPEED``, 1].
    """

    name: str
    jar_pos: np.ndarray
    payload_mass: float | None = None
    tilt: float = np.deg2rad(125.0)
    pour_height: float = 0.05
    pre_height: float = 0.12
    pour_offset: float = 0.02
    hold: float = 1.0
    settle: float = 0.5
    speed: float = 0.8
    tip_speed: float = 0.9
    _segments: list[Segment] | None = field(default=None, init=False, repr=False, compare=False)
    _bounds: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise TypeError(f"PouringTask.name must be a non-empty string, got {type(self.name).__name__} "
                            f"{self.name!r}")
        self.jar_pos = real_array(self.jar_pos, (3,), "PouringTask.jar_pos")  # 3 finite real numbers
        if self.jar_pos[2] < 0:
            raise ValueError(f"PouringTask.jar_pos: the jar's bottom must be on the table top (z = 0) or above "
                             f"it, got z = {self.jar_pos[2]} m")
        clearance = scene.BASE_RADIUS + scene.JAR_INNER_RADIUS + scene.JAR_WALL
        if np.hypot(self.jar_pos[0], self.jar_pos[1]) < clearance:
            raise ValueError(f"PouringTask.jar_pos: the jar would stand inside the robot's base; its axis must "
                             f"be at least {clearance:.3f} m from the base's axis (x = y = 0), got "
                             f"{self.jar_pos[:2].tolist()}")
        if self.payload_mass is not None:
            if not is_real_number(self.payload_mass):
                raise TypeError(f"PouringTask.payload_mass must be a real number (kg) or None, got "
                                f"{type(self.payload_mass).__name__} {self.payload_mass!r}")
            pm = float(self.payload_mass)
            if not np.isfinite(pm) or pm <= 0 or pm > scene.MAX_PAYLOAD:
                raise ValueError(
                    f"PouringTask.payload_mass must be in (0, {scene.MAX_PAYLOAD}] kg or None, got {pm}")
            self.payload_mass = pm
        for f in ("tilt", "pour_height", "pre_height", "pour_offset", "hold", "settle", "speed", "tip_speed"):
            v = getattr(self, f)
            if not is_real_number(v):
                raise TypeError(f"PouringTask.{f} must be a finite real number, got {type(v).__name__} {v!r}")
            if not np.isfinite(v):
                raise ValueError(f"PouringTask.{f} must be finite, got {v!r}")
            setattr(self, f, float(v))
        if not 0 < self.tilt <= np.pi:
            raise ValueError(f"PouringTask.tilt must be in (0, pi] rad, got {self.tilt}")
        for f in ("hold", "settle"):
            if not 0 <= getattr(self, f) <= MAX_HOLD_S:
                raise ValueError(f"PouringTask.{f} must be in [0, {MAX_HOLD_S:g}] s, got {getattr(self, f)}")
        for f in ("speed", "tip_speed"):
            if not MIN_SPEED <= getattr(self, f) <= 1:
                raise ValueError(f"PouringTask.{f} must be in [{MIN_SPEED:g}, 1] (a fraction of the velocity limits; "
                                 f"with both speeds at {MIN_SPEED:g} a task lasts about 20 minutes), got "
                                 f"{getattr(self, f)}")

    def __eq__(self, other: object) -> bool:
        """Equal fields (the generated ``__eq__`` compared ``jar_pos`` as a tuple item, which NumPy refuses)."""
        if other.__class__ is not self.__class__:
            return NotImplemented
        fields = [f.name for f in dataclasses.fields(self) if f.compare]
        return all(np.array_equal(getattr(self, f), getattr(other, f)) if f == "jar_pos"
                   else getattr(self, f) == getattr(other, f) for f in fields)

    def __getstate__(self) -> dict:
        """Pickled without the cached reference (its paths are closures, which ``pickle`` cannot store);
        the copy rebuilds it on first use, bit for bit the same."""
        state = self.__dict__.copy()
        state["_segments"] = state["_bounds"] = None
        return state

    def replace(self, **changes) -> "PouringTask":
        """A copy with some fields changed (the reference is recomputed lazily)."""
        return dataclasses.replace(self, **changes)

    # ------------------------------------------------------------------ geometry
    @property
    def approach(self) -> np.ndarray:
        """Horizontal hand approach axis: tangential (90 deg counter-clockwise from the radial
        direction base -> jar), so that a positive tilt pours radially outward."""
        phi = np.arctan2(self.jar_pos[1], self.jar_pos[0])
        return np.array([-np.sin(phi), np.cos(phi), 0.0])

    def mouth_target(self, tilt: float) -> np.ndarray:
        """Mouth centre target (3,) at a given tilt."""
        a = self.approach
        side = np.cross(a, [0.0, 0.0, 1.0])
        frac = np.sin(tilt) / max(np.sin(self.tilt), 1e-9) if tilt > 0 else 0.0
        rim = self.jar_pos[2] + scene.JAR_HEIGHT
        h = self.pre_height + (self.pour_height - self.pre_height) * min(tilt / self.tilt, 1.0)
        return np.array([self.jar_pos[0], self.jar_pos[1], rim + h]) - self.pour_offset * frac * side

    def _plan(self) -> tuple[list[Segment], np.ndarray]:
        """The reference's segments and their start times (s), built on first use."""
        if self._segments is None or self._bounds is None:
            self._segments, self._bounds = self._build()
        return self._segments, self._bounds

    def _build(self) -> tuple[list[Segment], np.ndarray]:
        q_home = home_pose()
        tilts = np.linspace(0.0, self.tilt, N_TIP_POINTS)
        # Pre-pour pose by continuation: move the target from the home pose to the pre-pour pose
        # in small steps (keeps the IK on the home pose's branch: no wrist flips on the way).
        guess = q_home.copy()
        phi = np.arctan2(self.jar_pos[1], self.jar_pos[0])
        p_home = HOME_MOUTH
        p_pre = self.mouth_target(0.0)
        for lam in np.linspace(0.0, 1.0, 9)[1:]:
            ang = lam * phi
            a = np.array([-np.sin(ang), np.cos(ang), 0.0])
            ca, sa = np.cos(ang), np.sin(ang)
            # p_home rotated by ang about z, element-wise (a matrix product's BLAS kernel rounds differently
            # from one CPU to another; jaco_env.kinematics)
            rot_home = np.array([ca * p_home[0] - sa * p_home[1], sa * p_home[0] + ca * p_home[1], p_home[2]])
            p = (1 - lam) * rot_home + lam * p_pre
            guess, _ = solve_ik(p, target_rotation(a, 0.0), guess)
        sols = []
        for th in tilts:
            q, err = solve_ik(self.mouth_target(th), target_rotation(self.approach, th), guess)
            if err > 1e-4:
                raise ValueError(
                    f"task {self.name!r}: jar_pos {self.jar_pos.tolist()} is not reachable "
                    f"(IK residual {err:.3g} at tilt {np.rad2deg(th):.0f} deg)")
            sols.append(q)
            guess = q
        qs = np.array(sols)
        q_pre = qs[0]
        segs = []
        path, mx = line_path(q_home, q_pre)
        segs.append(Segment(path, segment_duration(mx, self.speed)))
        path, mx = spline_path(qs)
        segs.append(Segment(path, segment_duration(mx, self.tip_speed)))
        path, _ = line_path(qs[-1], qs[-1])
        segs.append(Segment(path, self.hold))
        path, mx = spline_path(qs, reverse=True)
        segs.append(Segment(path, segment_duration(mx, self.tip_speed)))
        path, mx = line_path(q_pre, q_home)
        segs.append(Segment(path, segment_duration(mx, self.speed)))
        path, _ = line_path(q_home, q_home)
        segs.append(Segment(path, self.settle))
        return segs, np.cumsum([0.0] + [s.duration for s in segs])

    @property
    def phase_times(self) -> dict[str, float]:
        """Start times (s) of the phases approach, tip, hold, untip, return, settle, and 'end'."""
        _, bounds = self._plan()
        names = ("approach", "tip", "hold", "untip", "return", "settle", "end")
        return dict(zip(names, (float(b) for b in bounds)))

    @property
    def duration(self) -> float:
        """Total duration of the reference (s)."""
        return float(self._plan()[1][-1])  # phase_times["end"]

    @property
    def pour_window(self) -> tuple[float, float]:
        """(start of tipping, end of un-tipping) (s)."""
        p = self.phase_times
        return p["tip"], p["return"]

    def reference(self, t):
        """Reference (q_d, qd_d, qdd_d) at time(s) t >= 0 (s since reset).

        Scalar t gives three (N_JOINTS,) arrays; an array (T,) gives three (T, N_JOINTS) arrays. Before 0 the
        start pose and after ``duration`` the final pose are held (zero velocity/acceleration).
        A ``t`` that is not real (str, bool, complex) raises ``TypeError``, a NaN/inf one ``ValueError``.
        """
        segments, bounds = self._plan()
        scalar = np.ndim(t) == 0
        raw = np.asarray(t)
        if raw.dtype.kind not in "iuf":  # a string, bool or complex t is refused, not cast
            raise TypeError(f"PouringTask.reference: t must be a real number or array (s), got {t!r}")
        tt = np.atleast_1d(raw.astype(float))
        if tt.ndim != 1 or not np.all(np.isfinite(tt)):
            raise ValueError(f"PouringTask.reference: t must be a finite scalar or 1-D array, got {t!r}")
        n = robot.N_JOINTS
        q = np.empty((len(tt), n))
        qd = np.zeros((len(tt), n))
        qdd = np.zeros((len(tt), n))
        idx = np.clip(np.searchsorted(bounds, tt, side="right") - 1, 0, len(segments) - 1)
        for k, seg in enumerate(segments):
            sel = idx == k
            if np.any(sel):
                local = np.clip(tt[sel] - bounds[k], 0.0, seg.duration)
                q[sel], qd[sel], qdd[sel] = seg.evaluate(local)
        if scalar:
            return q[0], qd[0], qdd[0]
        return q, qd, qdd


    def reference_position(self, t: float) -> np.ndarray:
        """``reference(t)[0]`` for one finite real time ``t`` (s), without the derivatives: q_d (N_JOINTS,)
        (the same arithmetic, bit for bit; the environment's step needs only q_d). ``TypeError`` / ``ValueError``
        naming ``t`` for another ``t``."""
        if type(t) is not float and not is_real_number(t):
            raise TypeError(f"PouringTask.reference_position: t must be a real number (s), got {t!r}")
        if not math.isfinite(t):
            raise ValueError(f"PouringTask.reference_position: t must be finite, got {t!r}")
        segments, bounds = self._plan()
        tt = np.array([t], dtype=float)
        k = min(max(int(np.searchsorted(bounds, tt[0], side="right")) - 1, 0), len(segments) - 1)
        seg = segments[k]
        return seg.position(np.clip(tt - bounds[k], 0.0, seg.duration))[0]


def _task(name: str, x: float, y: float, **kw) -> PouringTask:
    return PouringTask(name=name, jar_pos=np.array([x, y, 0.0]), **kw)


#: Named default tasks, jars spread over the robot's front workspace (robot base at origin,
#: x forward, y left). Payload None: drawn per episode.
DEFAULT_TASKS: dict[str, PouringTask] = {
    "front": _task("front", 0.55, 0.0),
    "left": _task("left", 0.35, 0.42),
    "right": _task("right", 0.35, -0.42),
    "front_left": _task("front_left", 0.50, 0.28),
    "front_right": _task("front_right", 0.50, -0.28),
    "near": _task("near", 0.44, 0.13),
    "far": _task("far", 0.62, -0.10),
}


def get_task(task) -> PouringTask:
    """Resolve a task name or a :class:`PouringTask` (clear error otherwise)."""
    if isinstance(task, PouringTask):
        return task
    if isinstance(task, str):
        if task not in DEFAULT_TASKS:
            raise ValueError(f"unknown task {task!r}; known tasks: {sorted(DEFAULT_TASKS)}")
        return DEFAULT_TASKS[task]
    raise TypeError(f"task must be a task name (str) or a PouringTask, got {type(task).__name__}")
