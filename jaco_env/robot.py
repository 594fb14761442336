"""The simulated Kinova Jaco 2 arm: constants and the bare-arm MJCF.

The arm and the three-finger hand come from the Kinova assets that ship with
``dm_control`` (``dm_control/third_party/kinova``); they are composed at run time
with :mod:`dm_control.mjcf` and never copied into this repository.

The fingers are welded in a closed grip (their hinge joints are removed), so the
arm has exactly six degrees of freedom, as the paper's torque controller assumes.

Passive joint properties of the simulated "true" robot
------------------------------------------------------
==========  ==========  ============  ===========  ==========================================
joints      armature    frictionloss  damping      source
==========  ==========  ============  ===========  ==========================================
1-3 (large) 4.0 kg m^2  2.0 N m       0.01 N m s   dm_control Kinova model (``jaco_arm.xml``,
                                                   classes ``large_joint`` / default joint)
4-6 (small) 2.0 kg m^2  1.0 N m       0.01 N m s   dm_control Kinova model (``small_joint``)
==========  ==========  ============  ===========  ==========================================

The armature values model the reflected rotor inertia of the geared actuators;
the dry friction (``frictionloss``) and viscous damping are *not* part of the
nominal rigid-body model, so a learned model has to capture them.

Actuator limits (Kinova Jaco 2 datasheet): 30.5 N m peak torque for the KA-75+
actuators of joints 1-3, 6.8 N m for the KA-58 actuators of joints 4-6; maximum
joint speeds 36 deg/s (joints 1-3) and 48 deg/s (joints 4-6).
"""

from __future__ import annotations

import os

import numpy as np
from dm_control import mjcf

N_JOINTS = 6
JOINT_NAMES: tuple[str, ...] = tuple(f"joint_{i}" for i in range(1, N_JOINTS + 1))
TORQUE_LIMITS = np.array([30.5, 30.5, 30.5, 6.8, 6.8, 6.8])
VELOCITY_LIMITS = np.deg2rad([36.0, 36.0, 36.0, 48.0, 48.0, 48.0])
ARMATURE = np.array([4.0, 4.0, 4.0, 2.0, 2.0, 2.0])
FRICTIONLOSS = np.array([2.0, 2.0, 2.0, 1.0, 1.0, 1.0])
DAMPING = np.full(N_JOINTS, 0.01)

#: Closing angle of the welded finger hinges (rad, within the asset's 0.15-1.35 range).
FINGER_CLOSED_ANGLE = 0.9


def kinova_asset_dir() -> str:
    """Path of the Kinova MJCF assets inside the installed ``dm_control``."""
    import dm_control

    return os.path.join(os.path.dirname(dm_control.__file__), "third_party", "kinova")


def _axis_angle_quat(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis])


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
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
) -> mjcf.RootElement:
    """Compose the bare Jaco 2 arm (6 hinge joints) with its welded three-finger hand.

    Args:
        armature: per-joint rotor inertia (kg m^2); ``None`` sets zero.
        frictionloss: per-joint dry friction (N m); ``None`` sets zero.
        damping: per-joint viscous damping (N m s / rad); ``None`` sets zero.

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
            body.quat = _quat_mul(quat, _axis_angle_quat(axis, FINGER_CLOSED_ANGLE))
            joint.remove()
    arm.find("site", "wristsite").attach(hand)

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
