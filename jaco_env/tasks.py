"""Pouring tasks and their reference trajectories.

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

The poses are computed once by inverse kinematics (damped least squares on MuJoCo's
site Jacobians of the arm + bottle model, 6-D pose error: mouth position and bottle
orientation). The tip phase is solved at ``N_TIP_POINTS`` tilt angles (warm-started
one from the next) and interpolated by a cubic spline, re-parametrised by the
velocity-limit-weighted arc length (the limiting joint moves at a uniform fraction of
its limit along the path); the other phases are straight lines in joint space. Every
phase is time-scaled by a quintic s(t) (zero velocity and acceleration at both ends)
whose duration is the shortest for which no joint exceeds ``speed`` (``tip_speed``
while tipping) times its velocity limit (:data:`jaco_env.robot.VELOCITY_LIMITS`).
Default tasks last 15-20 s (the tip, ~5 s each way, is limited by the wrist roll).

Why hand-written IK: MuJoCo offers Jacobians but no IK solver; a 6-DOF DLS loop is
a dozen lines and needs no further dependency.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline

from jaco_env import robot, scene

#: Home pose target: bottle mouth position (m) and approach axis; bottle upright.
HOME_MOUTH = np.array([0.45, 0.0, 0.40])
HOME_APPROACH = np.array([0.0, 1.0, 0.0])
#: Initial guess of the home IK (elbow up; found once by a random-restart search).
HOME_GUESS = np.array([0.549, 2.262, 4.825, -0.212, -2.365, -1.194])
N_TIP_POINTS = 13
_PREFIX = "jaco_arm/jaco_hand/"
MOUTH_SITE = _PREFIX + "bottle_mouth"
BOTTLE_BODY = _PREFIX + "bottle"


@functools.lru_cache(maxsize=1)
def _kinematic_model():
    """Arm + hand + bottle, no actuators, no marbles (compiled once per process)."""
    return scene.compile_model(scene.build_scene(kind="payload", control_mode=None))


def bottle_pose(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Forward kinematics: (mouth position (3,), bottle rotation matrix (3, 3)) at joint angles q."""
    import mujoco

    m = _kinematic_model()
    d = mujoco.MjData(m)
    d.qpos[:6] = q
    mujoco.mj_kinematics(m, d)
    return d.site(MOUTH_SITE).xpos.copy(), d.body(BOTTLE_BODY).xmat.reshape(3, 3).copy()


def target_rotation(approach: np.ndarray, tilt: float) -> np.ndarray:
    """Bottle frame for a horizontal approach axis and a tilt (rad) from upright about it.

    Bottle frame: z = bottle axis (towards the mouth), x = minus the hand approach axis.
    """
    a = np.asarray(approach, float)
    a = a / np.linalg.norm(a)
    up = np.array([0.0, 0.0, 1.0])
    side = np.cross(a, up)
    z = np.cos(tilt) * up + np.sin(tilt) * side
    x = -a
    y = np.cross(z, x)
    return np.column_stack([x, y, z])


def solve_ik(p_target: np.ndarray, R_target: np.ndarray, q0: np.ndarray, *, iters: int = 300,
             damping: float = 1e-2, tol: float = 1e-7) -> tuple[np.ndarray, float]:
    """Damped-least-squares IK for the mouth position and bottle orientation.

    Returns (q, residual) with residual = |position error| + |orientation error| at the end.
    Joints 2 and 3 are kept inside their ranges.
    """
    import mujoco

    m = _kinematic_model()
    d = mujoco.MjData(m)
    sid = m.site(MOUTH_SITE).id
    bid = m.body(BOTTLE_BODY).id
    q = np.array(q0, dtype=float)
    lo = m.jnt_range[:6, 0].copy()
    hi = m.jnt_range[:6, 1].copy()
    limited = m.jnt_limited[:6].astype(bool)
    jacp = np.zeros((3, m.nv))
    jacr = np.zeros((3, m.nv))
    err = np.inf
    for _ in range(iters):
        d.qpos[:6] = q
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        R = d.xmat[bid].reshape(3, 3)
        e_p = p_target - d.site_xpos[sid]
        e_r = 0.5 * sum(np.cross(R[:, k], R_target[:, k]) for k in range(3))
        e = np.concatenate([e_p, e_r])
        err = float(np.linalg.norm(e_p) + np.linalg.norm(e_r))
        if err < tol:
            break
        mujoco.mj_jacSite(m, d, jacp, jacr, sid)
        J = np.vstack([jacp[:, :6], jacr[:, :6]])
        dq = J.T @ np.linalg.solve(J @ J.T + damping**2 * np.eye(6), e)
        step = np.max(np.abs(dq))
        if step > 0.2:
            dq *= 0.2 / step
        q = q + dq
        q[limited] = np.clip(q[limited], lo[limited] + 1e-3, hi[limited] - 1e-3)
    return q, err


@functools.lru_cache(maxsize=1)
def home_pose() -> np.ndarray:
    """The common start/end pose of every task (bottle upright in front of the robot)."""
    q, err = solve_ik(HOME_MOUTH, target_rotation(HOME_APPROACH, 0.0), HOME_GUESS)
    if err > 1e-4:
        raise RuntimeError(f"home pose IK did not converge (residual {err:.2e})")
    return q


def _quintic(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """s, ds/dtau, d2s/dtau2 of the quintic 10 tau^3 - 15 tau^4 + 6 tau^5 on [0, 1]."""
    tau = np.clip(tau, 0.0, 1.0)
    s = tau**3 * (10 - 15 * tau + 6 * tau**2)
    ds = 30 * tau**2 * (1 - tau) ** 2
    dds = 60 * tau * (1 - tau) * (1 - 2 * tau)
    return s, ds, dds


class _Segment:
    """A path q(s), s in [0, 1], with quintic time scaling over ``duration`` seconds."""

    def __init__(self, path, duration: float):
        self.path = path  # callable (s, nu) -> nu-th derivative (S, 6)
        self.duration = float(duration)

    def evaluate(self, t_local: np.ndarray):
        if self.duration <= 0:
            q = self.path(np.zeros_like(t_local), 0)
            return q, np.zeros_like(q), np.zeros_like(q)
        s, ds, dds = _quintic(t_local / self.duration)
        inside = ((t_local > 0) & (t_local < self.duration))[:, None]
        sd = (ds / self.duration)[:, None] * inside
        sdd = (dds / self.duration**2)[:, None] * inside
        q = self.path(s, 0)
        dq = self.path(s, 1)
        ddq = self.path(s, 2)
        return q, dq * sd, ddq * sd**2 + dq * sdd


def _line(q0: np.ndarray, q1: np.ndarray):
    q0 = np.asarray(q0, float)
    dq = np.asarray(q1, float) - q0

    def path(s, nu):
        if nu == 0:
            return q0 + s[:, None] * dq
        if nu == 1:
            return np.broadcast_to(dq, (len(s), 6)).copy()
        return np.zeros((len(s), 6))

    return path, np.abs(dq)


def _spline(qs: np.ndarray, reverse: bool = False):
    qs = qs[::-1] if reverse else qs
    sgrid = np.linspace(0.0, 1.0, len(qs))
    cs = CubicSpline(sgrid, qs, axis=0, bc_type="clamped")
    # Re-parametrise by the velocity-limit-weighted arc length sigma(s) = int max_j |dq_j/ds| /
    # vlim_j ds, so that the limiting joint moves at a uniform fraction of its limit along the
    # path (with a uniform s, the peak |dq/ds| of the tip sets the time scale of the whole tip
    # and the rest of it crawls). Small floor: no division by zero where the path pauses.
    fine = np.linspace(0.0, 1.0, 2001)
    g = np.max(np.abs(cs(fine, 1)) / robot.VELOCITY_LIMITS, axis=1)
    g = np.maximum(g, 0.05 * g.max())
    sigma = np.concatenate([[0.0], np.cumsum(0.5 * (g[1:] + g[:-1]) * np.diff(fine))])
    sigma /= sigma[-1]
    grid = np.linspace(0.0, 1.0, 61)
    cs2 = CubicSpline(grid, cs(np.interp(grid, sigma, fine)), axis=0, bc_type="not-a-knot")
    fine2 = np.linspace(0, 1, 2001)
    # Peak |dq/dsigma| (the quintic time scaling has zero speed at both ends).
    return (lambda s, nu: cs2(s, nu)), np.max(np.abs(cs2(fine2, 1)), axis=0)


def _duration(max_dqds: np.ndarray, speed: float) -> float:
    # Quintic peak ds/dt = 1.875 / T; require |dq/ds| * 1.875 / T <= speed * vlim.
    return float(np.max(1.875 * max_dqds / (speed * robot.VELOCITY_LIMITS)))


@dataclass
class PouringTask:
    """A pouring task: where the jar stands, what the hand carries, and how fast to pour.

    Attributes:
        name: task name.
        jar_pos: (3,) jar bottom centre on the table (m, world frame; robot base at origin).
        payload_mass: total mass held in the hand (bottle + marbles + extra rigid mass, kg), or
            ``None`` to draw it per episode (see ``JacoPourEnv``); at most 1.6 kg.
        tilt: final bottle tilt from upright (rad).
        pour_height: height of the mouth centre above the jar rim at full tilt (m).
        pre_height: height of the mouth above the rim before tipping (m).
        pour_offset: horizontal offset (m) of the mouth centre from the jar axis, against the
            tilt direction, so that the marbles leaving the lower lip fall into the middle.
        hold: time the tilted pose is held (s).
        settle: time the home pose is held at the end (s).
        speed: fraction of the joint velocity limits used by the time scaling.
        tip_speed: fraction of the velocity limits used while tipping and un-tipping.
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
    _segments: list = field(default=None, init=False, repr=False, compare=False)
    _bounds: np.ndarray = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        self.jar_pos = np.asarray(self.jar_pos, dtype=float).copy()
        if self.jar_pos.shape != (3,) or not np.all(np.isfinite(self.jar_pos)):
            raise ValueError(f"PouringTask.jar_pos must be 3 finite numbers, got {self.jar_pos!r}")
        if self.payload_mass is not None:
            pm = float(self.payload_mass)
            if not np.isfinite(pm) or pm <= 0 or pm > scene.MAX_PAYLOAD:
                raise ValueError(
                    f"PouringTask.payload_mass must be in (0, {scene.MAX_PAYLOAD}] kg or None, got {pm}")
            self.payload_mass = pm
        for f in ("hold", "settle"):
            if not getattr(self, f) >= 0:
                raise ValueError(f"PouringTask.{f} must be >= 0, got {getattr(self, f)}")
        for f in ("speed", "tip_speed"):
            if not 0 < getattr(self, f) <= 1:
                raise ValueError(f"PouringTask.{f} must be in (0, 1], got {getattr(self, f)}")

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

    def _build(self) -> None:
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
            rot = np.array([[np.cos(ang), -np.sin(ang), 0], [np.sin(ang), np.cos(ang), 0], [0, 0, 1]])
            p = (1 - lam) * (rot @ p_home) + lam * p_pre
            guess, _ = solve_ik(p, target_rotation(a, 0.0), guess)
        qs = []
        for th in tilts:
            q, err = solve_ik(self.mouth_target(th), target_rotation(self.approach, th), guess)
            if err > 1e-4:
                raise ValueError(
                    f"task {self.name!r}: jar_pos {self.jar_pos.tolist()} is not reachable "
                    f"(IK residual {err:.3g} at tilt {np.rad2deg(th):.0f} deg)")
            qs.append(q)
            guess = q
        qs = np.array(qs)
        q_pre = qs[0]
        segs = []
        path, mx = _line(q_home, q_pre)
        segs.append(_Segment(path, _duration(mx, self.speed)))
        path, mx = _spline(qs)
        segs.append(_Segment(path, _duration(mx, self.tip_speed)))
        path, _ = _line(qs[-1], qs[-1])
        segs.append(_Segment(path, self.hold))
        path, mx = _spline(qs, reverse=True)
        segs.append(_Segment(path, _duration(mx, self.tip_speed)))
        path, mx = _line(q_pre, q_home)
        segs.append(_Segment(path, _duration(mx, self.speed)))
        path, _ = _line(q_home, q_home)
        segs.append(_Segment(path, self.settle))
        self._segments = segs
        self._bounds = np.cumsum([0.0] + [s.duration for s in segs])

    @property
    def phase_times(self) -> dict[str, float]:
        """Start times (s) of the phases approach, tip, hold, untip, return, settle, and 'end'."""
        if self._segments is None:
            self._build()
        names = ("approach", "tip", "hold", "untip", "return", "settle", "end")
        return dict(zip(names, (float(b) for b in self._bounds)))

    @property
    def duration(self) -> float:
        """Total duration of the reference (s)."""
        return self.phase_times["end"]

    @property
    def pour_window(self) -> tuple[float, float]:
        """(start of tipping, end of un-tipping) (s)."""
        p = self.phase_times
        return p["tip"], p["return"]

    def reference(self, t):
        """Reference (q_d, qd_d, qdd_d) at time(s) t >= 0 (s since reset).

        Scalar t gives three (6,) arrays; an array (T,) gives three (T, 6) arrays. Before 0 the
        start pose and after ``duration`` the final pose are held (zero velocity/acceleration).
        """
        if self._segments is None:
            self._build()
        scalar = np.ndim(t) == 0
        tt = np.atleast_1d(np.asarray(t, dtype=float))
        if tt.ndim != 1 or not np.all(np.isfinite(tt)):
            raise ValueError("PouringTask.reference: t must be a finite scalar or 1-D array")
        q = np.empty((len(tt), 6))
        qd = np.zeros((len(tt), 6))
        qdd = np.zeros((len(tt), 6))
        idx = np.clip(np.searchsorted(self._bounds, tt, side="right") - 1, 0, len(self._segments) - 1)
        for k, seg in enumerate(self._segments):
            sel = idx == k
            if np.any(sel):
                local = np.clip(tt[sel] - self._bounds[k], 0.0, seg.duration)
                q[sel], qd[sel], qdd[sel] = seg.evaluate(local)
        if scalar:
            return q[0], qd[0], qdd[0]
        return q, qd, qdd


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
