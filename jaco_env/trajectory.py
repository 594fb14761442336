"""Joint-space trajectory primitives: paths, quintic time scaling and velocity-limited durations.

A trajectory is a list of :class:`Segment`: a path ``q(s)``, ``s`` in [0, 1], time-scaled by the
quintic :func:`quintic` (zero velocity and acceleration at both ends) over a duration. Paths
are callables ``path(s, nu)`` returning the ``nu``-th derivative (``nu`` = 0, 1, 2) at the
points ``s`` (S,), shape (S, N_JOINTS), and come with their peak ``|dq/ds|`` per joint:

* :func:`line_path` -- a straight line in joint space;
* :func:`spline_path` -- a clamped cubic spline through poses, re-parametrised by the
  velocity-limit-weighted arc length (the limiting joint moves at a uniform fraction of its
  limit along the path).

:func:`segment_duration` gives the shortest duration for which no joint exceeds a fraction of
its velocity limit (:data:`jaco_env.robot.VELOCITY_LIMITS`). The pouring tasks that put these
together are in :mod:`jaco_env.tasks`.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from scipy.interpolate import CubicSpline

from jaco_env import robot

#: ``path(s, nu) -> (S, N_JOINTS)``: the ``nu``-th derivative of the path at the points ``s``.
Path = Callable[[np.ndarray, int], np.ndarray]

_N = robot.N_JOINTS


def _quintic_s(tau: np.ndarray) -> np.ndarray:
    """s of :func:`quintic` at ``tau`` already in [0, 1]."""
    return tau**3 * (10 - 15 * tau + 6 * tau**2)


def quintic(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """s, ds/dtau, d2s/dtau2 of the quintic 10 tau^3 - 15 tau^4 + 6 tau^5 on [0, 1]."""
    tau = np.clip(tau, 0.0, 1.0)
    s = _quintic_s(tau)
    ds = 30 * tau**2 * (1 - tau) ** 2
    dds = 60 * tau * (1 - tau) * (1 - 2 * tau)
    return s, ds, dds


class Segment:
    """A path q(s), s in [0, 1], with quintic time scaling over ``duration`` seconds."""

    def __init__(self, path: Path, duration: float):
        self.path = path
        self.duration = float(duration)

    def position(self, t_local: np.ndarray) -> np.ndarray:
        """q (T, N_JOINTS) of :meth:`evaluate` alone (the same arithmetic)."""
        if self.duration <= 0:
            return self.path(np.zeros_like(t_local), 0)
        return self.path(_quintic_s(np.clip(t_local / self.duration, 0.0, 1.0)), 0)

    def evaluate(self, t_local: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q, qd, qdd), each (T, N_JOINTS), at the local times ``t_local`` (T,) in [0, duration]."""
        if self.duration <= 0:
            q = self.path(np.zeros_like(t_local), 0)
            return q, np.zeros_like(q), np.zeros_like(q)
        s, ds, dds = quintic(t_local / self.duration)
        inside = ((t_local > 0) & (t_local < self.duration))[:, None]
        sd = (ds / self.duration)[:, None] * inside
        sdd = (dds / self.duration**2)[:, None] * inside
        q = self.path(s, 0)
        dq = self.path(s, 1)
        ddq = self.path(s, 2)
        return q, dq * sd, ddq * sd**2 + dq * sdd


def line_path(q0: np.ndarray, q1: np.ndarray) -> tuple[Path, np.ndarray]:
    """The straight line from ``q0`` to ``q1`` and its peak ``|dq/ds|`` (N_JOINTS,)."""
    q0 = np.asarray(q0, float)
    dq = np.asarray(q1, float) - q0

    def path(s, nu):
        if nu == 0:
            return q0 + s[:, None] * dq
        if nu == 1:
            return np.broadcast_to(dq, (len(s), _N)).copy()
        return np.zeros((len(s), _N))

    return path, np.abs(dq)


def spline_path(qs: np.ndarray, reverse: bool = False) -> tuple[Path, np.ndarray]:
    """A clamped cubic spline through the poses ``qs`` (K, N_JOINTS) (backwards if ``reverse``),
    re-parametrised by the velocity-limit-weighted arc length; and its peak ``|dq/ds|``."""
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


def segment_duration(max_dqds: np.ndarray, speed: float) -> float:
    """Shortest quintic duration (s) for which no joint exceeds ``speed`` times its velocity limit."""
    # Quintic peak ds/dt = 1.875 / T; require |dq/ds| * 1.875 / T <= speed * vlim.
    return float(np.max(1.875 * max_dqds / (speed * robot.VELOCITY_LIMITS)))
