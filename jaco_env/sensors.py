"""Sensor noise model of the simulated Jaco 2 joint sensors."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
            if not isinstance(v, (int, float, np.floating)) or not np.isfinite(v) or v < 0:
                raise ValueError(f"SensorNoise.{name} must be a finite number >= 0, got {v!r}")

    @classmethod
    def none(cls) -> "SensorNoise":
        return cls(0.0, 0.0, 0.0)

    def apply(self, rng: np.random.Generator, q: np.ndarray, qd: np.ndarray, tau: np.ndarray):
        """Noisy copies of (q, qd, tau), drawn from ``rng`` (always draws, for reproducibility)."""
        n = len(q)
        e = rng.standard_normal((3, n))
        return q + self.q_std * e[0], qd + self.qd_std * e[1], tau + self.tau_std * e[2]
