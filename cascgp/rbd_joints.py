"""Which joints of a URDF a rigid-body model has, and how their positions are written.

Manufacturers' URDFs often differ from the arm a log records in two ways, both handled here on the
Pinocchio model before :class:`cascgp.rbd.RigidBodyModel` uses it:

* **Continuous joints.** A URDF ``continuous`` joint is a revolute joint without position limits. Pinocchio
  represents it by :math:`(\\cos q, \\sin q)` (two configuration entries, one velocity), so a log's joint
  angle could not be passed as it is. Its dynamics is that of a revolute joint on the same axis, whatever the
  angle's range, so :func:`angle_joints` replaces each by a revolute joint (Pinocchio's ``JointModelR*`` or
  ``JointModelRevoluteUnaligned``) with the same axis, placement, body inertia and limits: the joint's
  position is then its angle, in any range (multi-turn angles included). The Kinova Jaco 2's own URDF has
  three such joints.
* **Joints the log does not have.** A gripper's fingers, for instance. :func:`lock_joints` keeps the joints
  named (the log's, in the URDF's order from the base) and locks every other one at a given position
  (default 0), with Pinocchio's ``buildReducedModel``: the locked joint's bodies become rigid parts of their
  parent body, inertia included.

Spherical, planar and floating joints are refused: the log format gives each joint one position.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pinocchio as pin

__all__ = ["angle_joints", "lock_joints", "check_joint_selection"]

# Pinocchio's unbounded revolute joints and the bounded joint on the same axis.
_ANGLE_JOINT = {"JointModelRUBX": pin.JointModelRX, "JointModelRUBY": pin.JointModelRY,
                "JointModelRUBZ": pin.JointModelRZ}


def _with_angle(jm: Any) -> Any | None:
    """The bounded revolute joint of an unbounded one, or None when ``jm`` is not unbounded revolute."""
    kind = jm.shortname()
    if kind in _ANGLE_JOINT:
        return _ANGLE_JOINT[kind]()
    if kind == "JointModelRevoluteUnboundedUnaligned":
        # the bindings do not expose the axis; it is the angular part of the joint's motion subspace
        data = jm.createData()
        jm.calc(data, np.array([1.0, 0.0]))
        return pin.JointModelRevoluteUnaligned(np.array(data.S, dtype=float).reshape(6)[3:])
    return None


def angle_joints(model: pin.Model) -> pin.Model:
    """``model`` with every continuous (unbounded revolute) joint made a revolute joint whose position is its angle.

    Returns ``model`` itself when it has none. The joints keep their order, names, placements, bodies, limits
    (a continuous joint's position limits become :math:`\\pm\\infty`), armature and frames, so the inverse
    dynamics at angle :math:`q` equals Pinocchio's at :math:`(\\cos q, \\sin q)`.

    Raises:
        ValueError: a joint has more than one position (spherical, planar, floating); names the joints.
    """
    new_joints = [_with_angle(model.joints[j]) for j in range(1, model.njoints)]
    other = [model.names[j] for j in range(1, model.njoints)
             if new_joints[j - 1] is None and model.joints[j].nq != model.joints[j].nv]
    if other:
        raise ValueError(f"joints {other} have more than one position (spherical, planar or floating joints); "
                         "only revolute, continuous and prismatic joints are supported")
    if all(jm is None for jm in new_joints):
        return model
    out = pin.Model()
    out.name = model.name
    out.gravity = model.gravity
    for j in range(1, model.njoints):
        old, jm = model.joints[j], new_joints[j - 1]
        v, nv = model.idx_vs[j], old.nv
        if jm is None:
            q, nq = model.idx_qs[j], old.nq
            lo, hi = model.lowerPositionLimit[q:q + nq], model.upperPositionLimit[q:q + nq]
            jm = old
        else:
            lo, hi = np.full(1, -np.inf), np.full(1, np.inf)
        jid = out.addJoint(model.parents[j], jm, model.jointPlacements[j], model.names[j],
                           np.array(model.effortLimit[v:v + nv]), np.array(model.velocityLimit[v:v + nv]),
                           np.array(lo), np.array(hi))
        out.appendBodyToJoint(jid, model.inertias[j], pin.SE3.Identity())
    for f in list(model.frames)[1:]:  # frame 0 is the universe, which a new model already has
        out.addFrame(pin.Frame(f.name, f.parentJoint, f.parentFrame, f.placement, f.type, f.inertia), False)
    out.armature = np.array(model.armature)
    return out


def check_joint_selection(all_names: Sequence[str], joints: Sequence[str] | None,
                          locked: Mapping[str, float] | None) -> tuple[list[str], dict[str, float]]:
    """``(joints, locked)`` checked against the URDF's joint names ``all_names``; ``ValueError`` naming the field.

    ``joints`` (default: all) must be distinct names of ``all_names`` in their order (from the base);
    ``locked`` may give a finite position (rad or m) of joints not in ``joints``; the others lock at 0.
    """
    all_names = list(all_names)
    keep = all_names if joints is None else [str(n) for n in joints]
    unknown = [n for n in keep if n not in all_names]
    if unknown:
        raise ValueError(f"joints: {unknown} are not joints of the URDF; its joints are {all_names}")
    if len(set(keep)) != len(keep) or not keep:
        raise ValueError(f"joints: expected distinct joint names (at least one), got {keep}")
    ordered = [n for n in all_names if n in keep]
    if ordered != keep:
        raise ValueError(f"joints: list them in the URDF's order from the base, {ordered}; got {keep}")
    values: dict[str, float] = {}
    for name, value in dict(locked or {}).items():
        if name not in all_names:
            raise ValueError(f"locked: {name!r} is not a joint of the URDF; its joints are {all_names}")
        if name in keep:
            raise ValueError(f"locked: {name!r} is one of the model's joints (joints= names them, default all); "
                             "only the other joints are locked")
        try:
            x = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"locked: {name!r}: expected a number (rad or m), got {value!r}") from None
        if not np.isfinite(x):
            raise ValueError(f"locked: {name!r}: expected a finite position, got {value!r}")
        values[name] = x
    return keep, values


def lock_joints(model: pin.Model, joints: Sequence[str], locked: Mapping[str, float]) -> pin.Model:
    """``model`` with only ``joints`` movable; every other joint fixed at ``locked.get(name, 0.0)``.

    ``model`` must have one position per joint (see :func:`angle_joints`); the arguments as checked by
    :func:`check_joint_selection`. Returns ``model`` itself when every joint is kept.
    """
    names = list(model.names)[1:]
    drop = [j for j, n in enumerate(names, start=1) if n not in joints]
    if not drop:
        return model
    q_ref = pin.neutral(model)
    for j in drop:
        q_ref[model.idx_qs[j]] = locked.get(names[j - 1], 0.0)
    return pin.buildReducedModel(model, drop, q_ref)
