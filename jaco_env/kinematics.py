"""Kinematics of the arm + bottle: forward kinematics, the bottle's target frames, IK and the home pose.

This module owns the kinematic model (the ``"payload"`` scene without actuators or marbles,
compiled once per process) and everything computed from it alone:

* :func:`bottle_pose` -- forward kinematics of the bottle mouth and the bottle frame;
* :func:`target_rotation` -- the bottle frame for an approach axis and a tilt;
* :func:`solve_ik` -- damped least squares on MuJoCo's site Jacobians, 6-D pose error (mouth
  position and bottle orientation), joints 2 and 3 kept inside their ranges;
* :func:`home_pose` -- the common start/end pose of every task (bottle upright in front of
  the robot, mouth at ``HOME_MOUTH``).

Why hand-written IK: MuJoCo offers Jacobians but no IK solver; a 6-DOF DLS loop is a dozen
lines and needs no further dependency. The trajectories built from these poses are in
:mod:`jaco_env.trajectory`, the tasks in :mod:`jaco_env.tasks`.

The same on every CPU: the IK's products, factorisation and norms are MuJoCo's ``mju_*`` routines and
element-wise arithmetic, not NumPy's BLAS/LAPACK, whose kernels (chosen at run time for the CPU, with or without
FMA) round differently from one CPU to another. A task's reference is then the same bit for bit everywhere, and so
is a seeded episode under a controller that tracks it.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from jaco_env import robot, scene
from jaco_env.checks import is_real_number, real_array

#: Home pose target: bottle mouth position (m) and approach axis; bottle upright.
HOME_MOUTH = np.array([0.45, 0.0, 0.40])
HOME_APPROACH = np.array([0.0, 1.0, 0.0])
#: Initial guess of the home IK (elbow up; found once by a random-restart search).
HOME_GUESS = np.array([0.549, 2.262, 4.825, -0.212, -2.365, -1.194])

_N = robot.N_JOINTS


@functools.lru_cache(maxsize=1)
def kinematic_model():
    """Arm + hand + bottle, no actuators, no marbles (compiled once per process)."""
    return scene.compile_model(scene.build_scene(kind="payload", control_mode=None))


def bottle_pose(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Forward kinematics: (mouth position (3,), bottle rotation matrix (3, 3)) at joint angles q.

    ``q`` must be 6 finite joint angles (rad): ``ValueError``/``TypeError`` naming it otherwise.
    """
    import mujoco

    q = real_array(q, (_N,), "q")
    m = kinematic_model()
    d = mujoco.MjData(m)
    d.qpos[:_N] = q
    mujoco.mj_kinematics(m, d)
    return d.site(scene.MOUTH_SITE).xpos.copy(), d.body(scene.BOTTLE_BODY).xmat.reshape(3, 3).copy()


def target_rotation(approach: np.ndarray, tilt: float) -> np.ndarray:
    """Bottle frame for a horizontal approach axis and a tilt (rad) from upright about it.

    Bottle frame: z = bottle axis (towards the mouth), x = minus the hand approach axis.
    ``approach`` must be a finite, nonzero, horizontal 3-vector and ``tilt`` a finite angle: ``ValueError``/
    ``TypeError`` naming the argument otherwise.
    """
    a = real_array(approach, (3,), "approach")
    if isinstance(tilt, np.ndarray) and tilt.shape == () and tilt.dtype.kind in "iuf":
        tilt = tilt.item()  # a 0-d array of a real number
    if not is_real_number(tilt):
        raise TypeError(f"tilt must be a real number (rad), got {type(tilt).__name__} {tilt!r}")
    if not math.isfinite(tilt):
        raise ValueError(f"tilt must be finite (rad), got {tilt!r}")
    norm = math.hypot(*a)
    if norm == 0.0 or abs(a[2]) > 1e-12 * norm:
        raise ValueError(f"approach must be a nonzero horizontal vector (z = 0), got {a.tolist()}")
    a = a / norm
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
    Joints 2 and 3 are kept inside their ranges. Every array must be finite and of its shape (``p_target``
    (3,), ``R_target`` (3, 3), ``q0`` (6,)): ``ValueError``/``TypeError`` naming it otherwise.
    """
    import mujoco

    p_target = real_array(p_target, (3,), "p_target")
    R_target = real_array(R_target, (3, 3), "R_target")
    q0 = real_array(q0, (_N,), "q0")
    m = kinematic_model()
    d = mujoco.MjData(m)
    sid = m.site(scene.MOUTH_SITE).id
    bid = m.body(scene.BOTTLE_BODY).id
    q = np.array(q0, dtype=float)
    lo = m.jnt_range[:_N, 0].copy()
    hi = m.jnt_range[:_N, 1].copy()
    limited = m.jnt_limited[:_N].astype(bool)
    jacp = np.zeros((3, m.nv))
    jacr = np.zeros((3, m.nv))
    A = np.empty((6, 6))
    x = np.empty(6)
    dq = np.empty(_N)
    err = np.inf
    for _ in range(iters):
        d.qpos[:_N] = q
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        R = d.xmat[bid].reshape(3, 3)
        e_p = p_target - d.site_xpos[sid]
        e_r = 0.5 * (np.cross(R[:, 0], R_target[:, 0]) + np.cross(R[:, 1], R_target[:, 1])
                     + np.cross(R[:, 2], R_target[:, 2]))
        e = np.concatenate([e_p, e_r])
        err = math.hypot(*e_p) + math.hypot(*e_r)
        if err < tol:
            break
        mujoco.mj_jacSite(m, d, jacp, jacr, sid)
        J = np.vstack([jacp[:, :_N], jacr[:, :_N]])  # (6, N): 6-D pose error (position, orientation)
        # dq = J^T (J J^T + damping^2 I)^-1 e, by MuJoCo's routines (see the module docstring)
        mujoco.mju_mulMatMatT(A, J, J)
        A[np.diag_indices(6)] += damping**2
        mujoco.mju_cholFactor(A, 0.0)
        mujoco.mju_cholSolve(x, A, e)
        mujoco.mju_mulMatTVec(dq, J, x)
        step = np.max(np.abs(dq))
        if step > 0.2:
            dq *= 0.2 / step
        q = q + dq
        q[limited] = np.clip(q[limited], lo[limited] + 1e-3, hi[limited] - 1e-3)
    return q, err


@functools.lru_cache(maxsize=1)
def _home_pose() -> np.ndarray:
    q, err = solve_ik(HOME_MOUTH, target_rotation(HOME_APPROACH, 0.0), HOME_GUESS)
    if err > 1e-4:
        raise RuntimeError(f"home pose IK did not converge (residual {err:.2e})")
    return q


def home_pose() -> np.ndarray:
    """The common start/end pose of every task (bottle upright in front of the robot), a new array each call (the
    IK runs once; changing the array returned changes nothing else)."""
    return _home_pose().copy()
