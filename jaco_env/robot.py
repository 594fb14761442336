r"""The simulated Kinova Jaco 2 arm: constants and the bare-arm MJCF.

The arm and the three-finger hand come from the Kinova assets that ship with
``dm_control`` (``dm_control/third_party/kinova``); they are composed at run time
with :mod:`dm_control.mjcf` and never copied into this repository.

The fingers are welded in a closed grip (their hinge joints are removed), so the
arm has exactly six degrees of freedom, as the paper's torque controller assumes.

Actuators, torque sensors and the firmware torque loop
------------------------------------------------------
Each Jaco 2 actuator is a brushless motor behind a harmonic drive, with a strain-gauge
joint torque sensor at the drive's output. The sensor reads the **link-side** torque: the
torque passed to the outward links, *after* the rotor inertia and the gear friction. The
firmware closes a torque loop on that sensor. The parameters below were fixed from the
figures and derivation given here, and frozen before the data-efficiency study was run
with them; they are not tuned toward any study outcome. The motor inertias are estimates
(say +-50 %); the reflected inertia scales with the square of the gear ratio, so the figure to
check against a real unit is ``ROTOR_INERTIA`` itself.

==================================  ===============  ===============  =============================================
quantity                            joints 1-3       joints 4-6       derivation / source
                                    (KA-75+)         (KA-58)
==================================  ===============  ===============  =============================================
gear ratio ``GEAR_RATIO``           160              110              Kinova Gen2 actuator figures as recalled;
                                                                      not checked against a datasheet here
rotor + wave generator inertia      1.3e-5 kg m^2    4.0e-6 kg m^2    estimate for the motor class (about 45 mm /
(motor side, ``MOTOR_INERTIA``)                                       32 mm frameless BLDC + wave generator); Kinova
                                                                      publishes no rotor inertia
reflected rotor inertia             0.333 kg m^2     0.048 kg m^2     ``MOTOR_INERTIA * GEAR_RATIO**2``
(``ROTOR_INERTIA``, open loop)
gear dry friction (output side)     1.5 N m          0.34 N m         5 % of the peak torque (harmonic-drive no-load
(``GEAR_FRICTION``, open loop)                                        starting torque class)
gear viscous friction (output)      0.5 N m s/rad    0.1 N m s/rad    about 1 % of peak torque per 0.6 rad/s
(``GEAR_DAMPING``, open loop)
torque-loop gain                    4                4                P loop on the torque-sensor error; the
(``TORQUE_LOOP_GAIN``)                                                residual is 1 / (1 + 4) = 20 % (assumed)
torque-loop time constant           5 ms             5 ms             about 30 Hz closed-loop bandwidth (assumed)
(``TORQUE_LOOP_TAU``)
==================================  ===============  ===============  =============================================

Closed torque loop (what the simulation integrates)
^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^
Per joint, with motor torque :math:`\tau_m`, link-side (sensed) torque :math:`\tau_s`,
commanded torque :math:`\tau_c`, reflected rotor inertia :math:`J_r` and gear friction
:math:`f(\dot q)`:

.. math::

    J_r \ddot q = \tau_m - f(\dot q) - \tau_s, \qquad
    \tau_m = \tau_c + K (\tau_c - \tau_s)
    \;\Longrightarrow\;
    \tau_s = \tau_c - \frac{J_r \ddot q + f(\dot q)}{1 + K}.

So the link sees the command through a joint whose rotor inertia and friction are divided by
:math:`1 + K`. The simulation integrates exactly this closed loop: each arm joint carries the
**residual** armature ``ARMATURE = ROTOR_INERTIA / (1 + K)``, dry friction ``FRICTIONLOSS =
GEAR_FRICTION / (1 + K)`` and damping ``DAMPING = GEAR_DAMPING / (1 + K)``, and in torque mode
the command reaches the joint through a first-order lag of time constant ``TORQUE_LOOP_TAU``
(the loop's bandwidth; MuJoCo ``filterexact`` actuator dynamics). The residual
:math:`\tau_c - \tau_s = J_{r} \ddot q / (1+K) + f / (1+K)` (plus the lag) is what the loop
does not remove: 0.067 / 0.0096 kg m^2, 0.3 / 0.068 N m and 0.1 / 0.02 N m s/rad.

The measured joint torque is read by MuJoCo ``torque`` sensors at a site on each child link
(at the joint anchor, z along the joint axis; :func:`add_torque_sensors`), projected on the
joint axis: the interaction torque between a link and its parent, i.e. the link-side torque.
It contains neither rotor inertia nor gear friction, and equals the rigid-body inverse
dynamics of the links and payload (contact forces of marbles included).

(Before this revision the arm used dm_control's 4 / 2 kg m^2 armature and 2 / 1 N m friction,
meant for its velocity actuators, and the "measured" torque was the motor-side actuator force.)

Actuator limits (Kinova Jaco 2 datasheet): 30.5 N m peak torque for the KA-75+
actuators of joints 1-3, 6.8 N m for the KA-58 actuators of joints 4-6; maximum
joint speeds 36 deg/s (joints 1-3) and 48 deg/s (joints 4-6).
"""

from __future__ import annotations

import os

import numpy as np
from dm_control import mjcf
from numpy.typing import ArrayLike

from jaco_env import link_inertials as link_inertials_module

#: Number of arm joints (the fingers are welded).
N_JOINTS = 6
#: Names of the arm joints in the MJCF, base to wrist.
JOINT_NAMES: tuple[str, ...] = tuple(f"joint_{i}" for i in range(1, N_JOINTS + 1))
#: Peak joint torques (N m), the actuators' limits (datasheet; module docstring): the torque action's bounds.
TORQUE_LIMITS = np.array([30.5, 30.5, 30.5, 6.8, 6.8, 6.8])
#: Maximum joint speeds (rad/s): 36 deg/s for joints 1-3, 48 deg/s for joints 4-6 (datasheet).
VELOCITY_LIMITS = np.deg2rad([36.0, 36.0, 36.0, 48.0, 48.0, 48.0])

#: Gear ratios of the harmonic drives (module docstring's table).
GEAR_RATIO = np.array([160.0, 160.0, 160.0, 110.0, 110.0, 110.0])
#: Rotor and wave-generator inertia on the motor side (kg m^2), an estimate (module docstring's table).
MOTOR_INERTIA = np.array([1.3e-5, 1.3e-5, 1.3e-5, 4.0e-6, 4.0e-6, 4.0e-6])
#: Reflected rotor inertia (kg m^2), open loop: MOTOR_INERTIA * GEAR_RATIO**2.
ROTOR_INERTIA = MOTOR_INERTIA * GEAR_RATIO**2
#: Gear dry friction referred to the output, open loop (N m).
GEAR_FRICTION = 0.05 * TORQUE_LIMITS
#: Gear viscous friction referred to the output, open loop (N m s/rad).
GEAR_DAMPING = np.array([0.5, 0.5, 0.5, 0.1, 0.1, 0.1])
#: Proportional gain of the firmware torque loop on the torque-sensor error (dimensionless).
TORQUE_LOOP_GAIN = 4.0
#: Time constant of the closed torque loop (s): about 30 Hz bandwidth.
TORQUE_LOOP_TAU = 0.005
#: Residual rotor inertia seen by the links with the torque loop closed (kg m^2; module docstring).
ARMATURE = ROTOR_INERTIA / (1.0 + TORQUE_LOOP_GAIN)
#: Residual dry friction seen by the links with the torque loop closed (N m).
FRICTIONLOSS = GEAR_FRICTION / (1.0 + TORQUE_LOOP_GAIN)
#: Residual viscous friction seen by the links with the torque loop closed (N m s/rad).
DAMPING = GEAR_DAMPING / (1.0 + TORQUE_LOOP_GAIN)
#: Diagonal of the links' joint-space inertia (kg m^2) at the home pose with a 1 kg payload in the
#: hand (MuJoCo ``mj_fullM``), plus the residual armature: the inertia each joint's feedback loops
#: (``scene.FIRMWARE_KV/KI``, ``gains.DEFAULT_KP/KD``) are designed for.
DESIGN_INERTIA = np.array([0.62, 0.59, 0.20, 0.11, 0.046, 0.0074]) + ARMATURE

#: Closing angle of the welded finger hinges (rad, within the asset's 0.15-1.35 range).
FINGER_CLOSED_ANGLE = 0.9


#: Names of the link-side joint torque sensors (MuJoCo ``torque`` sensors, 3 values each).
TORQUE_SENSOR_NAMES: tuple[str, ...] = tuple(f"joint_torque_{i}" for i in range(1, N_JOINTS + 1))


def kinova_asset_dir() -> str:
    """Path of the Kinova MJCF assets inside the installed ``dm_control``."""
    import dm_control

    return os.path.join(os.path.dirname(dm_control.__file__), "third_party", "kinova")


def axis_angle_quat(axis: ArrayLike, angle: float) -> np.ndarray:
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis])


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


def build_arm_mjcf(
    *,
    armature: np.ndarray | None = ARMATURE,
    frictionloss: np.ndarray | None = FRICTIONLOSS,
    damping: np.ndarray | None = DAMPING,
    link_inertials: str = "dm_control",
) -> mjcf.RootElement:
    """Compose the bare Jaco 2 arm (6 hinge joints) with its welded three-finger hand.

    Args:
        armature: per-joint rotor inertia (kg m^2); ``None`` sets zero.
        frictionloss: per-joint dry friction (N m); ``None`` sets zero.
        damping: per-joint viscous damping (N m s / rad); ``None`` sets zero.
        link_inertials: ``"dm_control"`` (the assets' masses, inertia from the meshes) or ``"kinova"``
            (Kinova's URDF values, :mod:`jaco_env.link_inertials`).

    Returns:
        The MJCF root of the arm; the hand is attached at the ``wristsite`` and
        can be found as the attached model ``jaco_hand``. No actuators, no payload.
    """
    asset_dir = kinova_asset_dir()
    arm = mjcf.from_path(os.path.join(asset_dir, "jaco_arm.xml"))
    hand = mjcf.from_path(os.path.join(asset_dir, "jaco_hand.xml"))
    # Weld the fingers: remove each finger hinge and rotate the finger body by the
    # closing angle about the former hinge axis (MJCF's default hinge axis is z).
    for body in hand.worldbody.find_all("body"):
        joints = list(body.joint)
        for joint in joints:
            axis = np.array(joint.axis if joint.axis is not None else [0.0, 0.0, 1.0])
            quat = np.array(body.quat if body.quat is not None else [1.0, 0.0, 0.0, 0.0])
            body.quat = quat_mul(quat, axis_angle_quat(axis, FINGER_CLOSED_ANGLE))
            joint.remove()
    arm.find("site", "wristsite").attach(hand)
    link_inertials_module.apply(arm, link_inertials)

    zeros = np.zeros(N_JOINTS)
    armature = zeros if armature is None else np.broadcast_to(armature, (N_JOINTS,))
    frictionloss = zeros if frictionloss is None else np.broadcast_to(frictionloss, (N_JOINTS,))
    damping = zeros if damping is None else np.broadcast_to(damping, (N_JOINTS,))
    for i, name in enumerate(JOINT_NAMES):
        joint = arm.find("joint", name)
        joint.armature = float(armature[i])
        joint.frictionloss = float(frictionloss[i])
        joint.damping = float(damping[i])
    return arm


def add_torque_sensors(arm: mjcf.RootElement) -> None:
    """Add the link-side joint torque sensors of the six arm joints.

    One site per joint on the joint's child link, at the joint anchor with its z axis along the
    joint axis, and a MuJoCo ``torque`` sensor at it: the sensor's z component is the torque
    that the parent link exerts on the child about the joint axis (the Jaco 2's strain-gauge
    joint torque sensor at the actuator output). Rotor inertia and gear friction act on the
    joint degree of freedom, not between the bodies, so they are not part of it.
    """
    for i, name in enumerate(JOINT_NAMES):
        joint = arm.find("joint", name)
        axis = np.array(joint.axis if joint.axis is not None else [0.0, 0.0, 1.0], float)
        axis = axis / np.linalg.norm(axis)
        z = np.array([0.0, 0.0, 1.0])
        c = float(np.clip(z @ axis, -1.0, 1.0))
        rot_axis = np.cross(z, axis)
        if np.linalg.norm(rot_axis) < 1e-12:
            quat = np.array([1.0, 0.0, 0.0, 0.0]) if c > 0 else np.array([0.0, 1.0, 0.0, 0.0])
        else:
            quat = axis_angle_quat(rot_axis, float(np.arccos(c)))
        pos = joint.pos if joint.pos is not None else [0.0, 0.0, 0.0]
        site = joint.parent.add("site", name=f"torque_site_{i + 1}", pos=pos, quat=quat, size=[0.005],
                                group=5)
        arm.sensor.add("torque", name=TORQUE_SENSOR_NAMES[i], site=site)


def read_sensor_name(read: str, joint: int) -> str:
    """Name of the delayed read sensor ``read`` (a :class:`~jaco_env.signal_pipeline.PipelineState`
    attribute) of joint ``joint`` (0-based)."""
    return f"read_{read}_{joint + 1}"


def add_delayed_reads(arm: mjcf.RootElement, reads: list[tuple[str, str, int]], timestep: float) -> None:
    """Add MuJoCo's delayed ``jointpos`` / ``jointvel`` sensors of the six arm joints, one set per read.

    ``reads``: ``(name, sensor type, lead)``, the lead in physics steps (at least 1). Each sensor keeps a
    history of its last ``lead + 2`` values, one per physics step (the sensor stage of each step), and reports
    with zero-order hold the newest value at or before ``lead - 0.5`` steps ago: the value after the physics
    step ``lead`` steps before the current one, exactly (the half step keeps the look-up clear of the sample
    times' round-off). This is how the sensing pipeline reads q and q̇ ``lead`` steps before the torque without
    stopping the physics within the control period.
    """
    for read, kind, lead in reads:
        if lead < 1:
            raise ValueError(f"a delayed read needs a lead of at least 1 physics step, got {lead} for {read!r}")
        for i, name in enumerate(JOINT_NAMES):
            arm.sensor.add(kind, name=read_sensor_name(read, i), joint=arm.find("joint", name),
                           nsample=lead + 2, delay=(lead - 0.5) * timestep, interp="zoh")
