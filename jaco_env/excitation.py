"""Random sum-of-sinusoids joint excitation (the paper's data-collection motions).

Each joint follows ``q_j(t) = c_j + sum_k a_jk sin(2 pi f_jk t + phi_jk) - offset_j`` with
random amplitudes, frequencies and phases (offset chosen so that q(0) = the start pose).
The velocity command is its derivative. Amplitudes are scaled so that, for every joint,

* the position never leaves the joint's range shrunk by ``margin`` (joints 2 and 3 have
  ranges; the others are limited to ``+-max_excursion`` around the start),
* the commanded speed ``sum_k 2 pi f_jk |a_jk|`` stays below ``speed`` times the joint's
  velocity limit (a bound that holds for every t, not only on a sampled grid).

Frequencies are drawn from 0.1-1 Hz (default): the slow components carry the arm across the
workspace, the fast ones excite the inertia (a commanded speed near the velocity limit at 1 Hz
means accelerations of a few rad/s^2; the firmware velocity loop's 15 rad/s bandwidth tracks
them). The earlier 0.02-0.25 Hz motions were quasi-static (true accelerations of 0.1-0.24 rad/s^2
spread): a model trained on them never saw the inertial terms. ``scripts.collect_jaco_data``
reports the true acceleration spread reached.

Use it with ``JacoPayload-v0`` in velocity mode: ``action = gen.velocity(t)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from jaco_env import robot
from jaco_env.checks import is_real_number

#: Ranges of the joints in dm_control's convention (rad); None = continuous joint.
JOINT_RANGES: tuple[tuple[float, float] | None, ...] = (
    None, (0.820305, 5.462881), (0.331613, 5.951573), None, None, None,
)


@dataclass
class SumOfSinusoids:
    """Seeded random sum-of-sinusoids generator for the 6 joints.

    Args:
        q0: (6,) start pose (rad); the trajectory starts there with q(0) = q0.
        seed: seed of the random amplitudes, frequencies and phases.
        n_sines: sinusoids per joint.
        freq_range: (low, high) frequencies in Hz, drawn uniformly.
        speed: fraction of the velocity limits the commanded speed may reach.
        max_excursion: largest deviation from q0 (rad) for every joint.
        margin: distance kept from the range ends of joints 2 and 3 (rad).
    """

    q0: np.ndarray
    seed: int = 0
    n_sines: int = 4
    freq_range: tuple[float, float] = (0.1, 1.0)
    speed: float = 0.8
    max_excursion: float = 0.8
    margin: float = 0.15
    amplitudes: np.ndarray = field(init=False)
    freqs: np.ndarray = field(init=False)
    phases: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.q0 = np.asarray(self.q0, dtype=float).copy()
        if self.q0.shape != (robot.N_JOINTS,) or not np.all(np.isfinite(self.q0)):
            raise ValueError(f"q0 must be {robot.N_JOINTS} finite joint angles, got {self.q0!r}")
        try:
            lo_f, hi_f = (float(f) for f in self.freq_range)
        except (TypeError, ValueError):
            raise ValueError(f"freq_range must be two frequencies (low, high) in Hz, got {self.freq_range!r}") from None
        if not 0 < lo_f <= hi_f < math.inf:
            raise ValueError(f"freq_range must satisfy 0 < low <= high < inf (Hz), got {self.freq_range!r}")
        for name in ("speed", "max_excursion", "margin"):
            v = getattr(self, name)
            if not is_real_number(v) or not math.isfinite(v):
                raise ValueError(f"{name} must be a finite real number, got {v!r}")
        if not 0 < self.speed <= 1:
            raise ValueError(f"speed must be in (0, 1], got {self.speed!r}")
        if not self.max_excursion > 0 or not self.margin >= 0:
            raise ValueError(f"max_excursion must be > 0 and margin >= 0 (rad), got {self.max_excursion!r} and "
                             f"{self.margin!r}")
        if isinstance(self.n_sines, bool) or not isinstance(self.n_sines, (int, np.integer)) or self.n_sines < 1:
            raise ValueError(f"n_sines must be an integer >= 1, got {self.n_sines!r}")
        rng = np.random.default_rng(self.seed)
        n = robot.N_JOINTS
        self.freqs = rng.uniform(lo_f, hi_f, (n, self.n_sines))
        self.phases = rng.uniform(0, 2 * np.pi, (n, self.n_sines))
        a = rng.uniform(-1.0, 1.0, (n, self.n_sines))
        for j in range(n):
            # Room around q0: q(t) - q0 lies in [-2 sum|a|, 2 sum|a|] (the offset adds sum|a|).
            room = self.max_excursion
            rng_j = JOINT_RANGES[j]
            if rng_j is not None:
                room = min(room, self.q0[j] - rng_j[0] - self.margin, rng_j[1] - self.margin - self.q0[j])
            if room <= 0:
                raise ValueError(f"q0[{j}] = {self.q0[j]:.3f} is within margin of the range of joint {j + 1}")
            s_pos = room / (2 * np.sum(np.abs(a[j])))
            s_vel = self.speed * robot.VELOCITY_LIMITS[j] / np.sum(2 * np.pi * self.freqs[j] * np.abs(a[j]))
            a[j] *= min(s_pos, s_vel)
        self.amplitudes = a
        self._offset = np.sum(a * np.sin(self.phases), axis=1)

    def position(self, t) -> np.ndarray:
        """Joint positions at t (scalar -> (6,), (T,) -> (T, 6))."""
        tt = np.atleast_1d(np.asarray(t, float))
        arg = 2 * np.pi * self.freqs[None] * tt[:, None, None] + self.phases[None]
        q = self.q0 + np.sum(self.amplitudes[None] * np.sin(arg), axis=2) - self._offset
        return q[0] if np.ndim(t) == 0 else q

    def velocity(self, t) -> np.ndarray:
        """Joint velocity command at t (rad/s), within ``speed`` times the velocity limits."""
        tt = np.atleast_1d(np.asarray(t, float))
        w = 2 * np.pi * self.freqs[None]
        qd = np.sum(self.amplitudes[None] * w * np.cos(w * tt[:, None, None] + self.phases[None]), axis=2)
        return qd[0] if np.ndim(t) == 0 else qd


def make_command(seed: int = 0, duration: float | None = None, q0: np.ndarray | None = None,
                 **kwargs) -> Callable[[Any], np.ndarray]:
    """A seeded velocity command ``v(t) -> (6,)`` starting at ``q0`` (default: the home pose).

    ``duration`` is accepted for interface symmetry; the command is valid (within the position
    and velocity limits) for every t >= 0. Further keyword arguments go to :class:`SumOfSinusoids`.
    """
    if duration is not None and not duration > 0:
        raise ValueError(f"duration must be > 0 s, got {duration!r}")
    if q0 is None:
        from jaco_env.kinematics import home_pose

        q0 = home_pose()
    return SumOfSinusoids(q0, seed=seed, **kwargs).velocity
