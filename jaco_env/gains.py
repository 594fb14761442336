"""Recommended feedback gains for controllers at the default 40 Hz control rate.

``tau = feedforward + DEFAULT_KP * (q_d - q) + DEFAULT_KD * (qd_d - qd)`` (N m/rad, N m s/rad).

Chosen for the true robot's joint inertia, dominated by the rotor armature (about
4.5 kg m^2 on joints 1-3, 2.1 kg m^2 on joints 4-6): natural frequencies of about 6-7
rad/s (joints 1-3) and 5 rad/s (joints 4-6), damping ratios 0.6-0.7, and
``KD * dt / I`` about 0.2, well inside the stability region of a 40 Hz zero-order-hold
loop with the measurement noise of ``SensorNoise()`` (Kd * qd noise = 0.2 N m).
Stiffer gains would hide the payload; weaker ones would not hold the arm up.
"""

from __future__ import annotations

import numpy as np

DEFAULT_KP = np.array([120.0, 120.0, 120.0, 40.0, 40.0, 40.0])
DEFAULT_KD = np.array([30.0, 30.0, 30.0, 9.0, 9.0, 9.0])
