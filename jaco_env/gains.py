"""Recommended feedback gains for controllers at the default 40 Hz control rate.

``tau = feedforward + DEFAULT_KP * (q_d - q) + DEFAULT_KD * (qd_d - qd)`` (N m/rad, N m s/rad).

Derived from the inertia each joint sees with the firmware torque loop closed
(``robot.DESIGN_INERTIA``: links at the home pose with a 1 kg payload plus the residual rotor
inertia, 0.69 / 0.66 / 0.27 / 0.12 / 0.056 / 0.017 kg m^2): a natural frequency of 10 rad/s and
a damping ratio of 0.7 per joint, ``KP = I 10^2``, ``KD = 2 * 0.7 * I * 10``. Then
``KD * dt / I = 0.35`` at 40 Hz, well inside the stability region of a zero-order-hold loop,
and the velocity noise of ``SensorNoise()`` costs at most ``KD * 5e-3`` = 0.05 N m.
PD alone leaves a steady gravity error of about 13 N m / 66 N m/rad = 0.2 rad on joint 2.
"""

from __future__ import annotations

from jaco_env.robot import DESIGN_INERTIA

#: Closed-loop natural frequency (rad/s) of the recommended PD.
NATURAL_FREQUENCY = 10.0
#: Closed-loop damping ratio of the recommended PD.
DAMPING_RATIO = 0.7
#: Recommended proportional gains (N m/rad), one per joint: ``DESIGN_INERTIA * NATURAL_FREQUENCY**2``.
DEFAULT_KP = NATURAL_FREQUENCY**2 * DESIGN_INERTIA
#: Recommended derivative gains (N m s/rad), one per joint: ``2 * DAMPING_RATIO * NATURAL_FREQUENCY *
#: DESIGN_INERTIA``.
DEFAULT_KD = 2.0 * DAMPING_RATIO * NATURAL_FREQUENCY * DESIGN_INERTIA
