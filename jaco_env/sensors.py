"""What the simulated Jaco 2 joint sensors report: the noise model and the observation layout.

Both environments observe the measured joint state first, in one layout defined here:

==========================  ================================================  =====
entries                     observation                                       unit
==========================  ================================================  =====
``OBS_Q``     (0-5)         measured joint positions q                        rad
``OBS_QD``    (6-11)        measured joint velocities qd                      rad/s
``OBS_TAU``   (12-17)       measured link-side joint torques                  N m
``OBS_TIME``  (18)          time since reset                                  s
``OBS_JAR``   (19-21)       jar position (``JacoPour-v0`` only)               m
==========================  ================================================  =====

:func:`split_obs` splits an observation into ``(q, qd, tau, t)``; use it rather than literal
indices. (:mod:`cascgp.episodes`, which may not import ``jaco_env``, splits the same
``[q, qd, tau, t]`` prefix of any N-DOF arm generically.)
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from jaco_env.checks import is_real_number

from jaco_env.robot import N_JOINTS

#: Where an observation holds the measured joint positions (rad): ``obs[OBS_Q]``.
OBS_Q = slice(0, N_JOINTS)
#: Where an observation holds the measured joint velocities (rad/s).
OBS_QD = slice(N_JOINTS, 2 * N_JOINTS)
#: Where an observation holds the measured joint torques (N m).
OBS_TAU = slice(2 * N_JOINTS, 3 * N_JOINTS)
#: The index of the observation's time (s since the reset).
OBS_TIME = 3 * N_JOINTS
#: Length of the measured part ``[q, qd, tau, t]``: the whole ``JacoPayload-v0`` observation.
MEASUREMENT_DIM = 3 * N_JOINTS + 1
#: Where a ``JacoPour-v0`` observation holds the jar's position (m; bottom centre, world frame).
OBS_JAR = slice(MEASUREMENT_DIM, MEASUREMENT_DIM + 3)
#: Length of the ``JacoPour-v0`` observation (measurement + jar position).
POUR_OBS_DIM = MEASUREMENT_DIM + 3


def split_obs(obs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float | np.ndarray]:
    """``(q, qd, tau, t)`` of an observation of either environment (views, not copies).

    ``obs`` of shape (D,) gives three (N_JOINTS,) arrays and a float; a batch (..., D) (e.g. of a
    vector env) gives (..., N_JOINTS) arrays and an array of times.
    """
    obs = np.asarray(obs)
    if obs.ndim == 0 or obs.shape[-1] < MEASUREMENT_DIM:
        raise ValueError(f"observation must end in an axis of at least {MEASUREMENT_DIM} entries "
                         f"([q, qd, tau, t] of {N_JOINTS} joints), got shape {obs.shape}")
    t = obs[..., OBS_TIME]
    return obs[..., OBS_Q], obs[..., OBS_QD], obs[..., OBS_TAU], float(t) if obs.ndim == 1 else t


#: Largest standard deviation of a :class:`SensorNoise` field, in its unit (rad, rad/s, N m): far beyond any sensor
#: (the arm's torque limits are 6.8-30.5 N m), and small enough that noisy measurements stay finite.
MAX_NOISE_STD = 1e3


@dataclass(frozen=True)
class SensorNoise:
    """Additive zero-mean Gaussian noise on each measured joint quantity (standard deviations).

    Defaults are of the order of the Jaco 2's sensors: absolute encoders with a resolution
    of about 0.02 deg (``q_std`` 5e-4 rad, a few counts), velocities estimated from the
    encoders (``qd_std`` 5e-3 rad/s) and strain-gauge joint torque sensors, which are
    the noisiest (``tau_std`` 0.1 N m). Use ``SensorNoise.none()`` (or pass ``None`` to
    the environment) for noiseless measurements.
    """

    q_std: float = 5e-4
    qd_std: float = 5e-3
    tau_std: float = 0.1

    def __post_init__(self) -> None:
        for name in ("q_std", "qd_std", "tau_std"):
            v = getattr(self, name)
            if not is_real_number(v):
                raise TypeError(f"SensorNoise.{name} must be a real number, got {type(v).__name__} {v!r}")
            if not np.isfinite(v) or not 0 <= v <= MAX_NOISE_STD:
                raise ValueError(f"SensorNoise.{name} must be a number in [0, {MAX_NOISE_STD:g}] (rad, rad/s or N m), "
                                 f"got {v!r}")

    @functools.cached_property
    def _std(self) -> np.ndarray:
        """(3, 1) column of the three deviations, for :meth:`measurement` (not a field)."""
        return np.array([[self.q_std], [self.qd_std], [self.tau_std]], dtype=np.float64)

    @classmethod
    def none(cls) -> "SensorNoise":
        return cls(0.0, 0.0, 0.0)

    def apply(self, rng: np.random.Generator, q: np.ndarray, qd: np.ndarray, tau: np.ndarray):
        """Noisy copies of (q, qd, tau), drawn from ``rng`` (always draws, for reproducibility)."""
        n = len(q)
        e = rng.standard_normal((3, n))
        return q + self.q_std * e[0], qd + self.qd_std * e[1], tau + self.tau_std * e[2]

    def measurement(self, rng: np.random.Generator, q: np.ndarray, qd: np.ndarray, tau: np.ndarray,
                    t: float) -> np.ndarray:
        """The measured part of an observation, ``[q, qd, tau, t]`` with noise (layout above)."""
        # The arithmetic of apply() (the same draws; x + std * e, entry by entry) in one array.
        n = len(q)
        e = rng.standard_normal((3, n))
        e *= self._std
        out = np.concatenate((q, qd, tau, (t,)))
        out[:3 * n] += e.ravel()
        return out
