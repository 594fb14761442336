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
  named (the log's, in Pinocchio's order of the URDF's joints: depth first from the base) and locks every
  other one at a given position (default 0, the URDF's zero), with Pinocchio's ``buildReducedModel``: the
  locked joint's bodies become rigid parts of their parent body, inertia included. Pinocchio reads a URDF
  ``<mimic>`` joint as a joint of its own, so a locked mimic joint needs its own position too.

Spherical, planar and floating joints are refused: the log format gives each joint one position.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pinocchio as pin

__all__ = ["angle_joints", "lock_joints", "check_joint_selection"]

#: Per-dof vectors of a ``pinocchio.Model`` that :func:`angle_joints` copies as they are (those present).
_PER_VELOCITY = ("armature", "damping", "lowerDryFrictionLimit", "upperDryFrictionLimit", "lowerEffortLimit",
                 "upperEffortLimit", "lowerVelocityLimit", "upperVelocityLimit")
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
    r"""A copy of ``model`` in which every continuous (unbounded revolute) joint is a revolute joint in its angle.

    The joints keep their order, names, placements, bodies, limits (a continuous joint's position limits
    become :math:`\pm\infty`), armature, friction and damping, and the frames are copied, so the inverse
    dynamics at angle :math:`q` equals Pinocchio's at :math:`(\cos q, \sin q)`. ``model`` is not changed.

    Args:
        model: a fixed-base Pinocchio model, e.g. from ``pinocchio.buildModelFromUrdf``.

    Returns:
        A new model with one position per joint (``nq == nv``).

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
        return pin.Model(model)
    out = pin.Model()
    out.name = model.name
    out.gravity = model.gravity
    for j in range(1, model.njoints):
        old, jm = model.joints[j], new_joints[j - 1]
        if jm is None:
            q, nq = model.idx_qs[j], old.nq
            lo, hi = model.lowerPositionLimit[q:q + nq], model.upperPositionLimit[q:q + nq]
            jm = old
        else:
            lo, hi = np.full(1, -np.inf), np.full(1, np.inf)
        v, nv = model.idx_vs[j], old.nv
        jid = out.addJoint(model.parents[j], jm, model.jointPlacements[j], model.names[j],
                           np.array(model.effortLimit[v:v + nv]), np.array(model.velocityLimit[v:v + nv]),
                           np.array(lo), np.array(hi))
        out.appendBodyToJoint(jid, model.inertias[j], pin.SE3.Identity())
    for f in list(model.frames)[1:]:  # frame 0 is the universe, which a new model already has
        out.addFrame(pin.Frame(f.name, f.parentJoint, f.parentFrame, f.placement, f.type, f.inertia), False)
    for name in _PER_VELOCITY:  # the per-dof vectors that addJoint's arguments do not set (nv is unchanged)
        if hasattr(model, name):
            setattr(out, name, np.array(getattr(model, name)))
    return out


def check_joint_selection(model: pin.Model, joints: Sequence[str] | None,
                          locked: Mapping[str, float] | None) -> dict[str, float]:
    """The positions of the joints to lock, ``joints`` and ``locked`` checked against ``model``'s joints.

    Args:
        model: a model with one position per joint (see :func:`angle_joints`).
        joints: the joints to keep, distinct names of ``model``'s joints in its order (depth first from the
            base); default: every joint not in ``locked``.
        locked: positions (rad or m, the URDF's zero at 0) of joints not kept; default 0 for each.

    Returns:
        ``{name: position}`` of every joint not in ``joints`` (empty when all are kept).

    Raises:
        ValueError: naming ``joints`` or ``locked`` and what was expected (a name not in the URDF, another
            order, a repeated name, a position that is not a finite number or is outside the joint's limits).
    """
    names = list(model.names)[1:]
    if isinstance(joints, (str, bytes)):
        raise ValueError(f"joints: expected a list of joint names, got the string {joints!r}")
    if locked is not None and not isinstance(locked, Mapping):
        raise ValueError(f"locked: expected a mapping of joint names to positions, got {type(locked).__name__}")
    given = dict(locked or {})
    keep = [n for n in names if n not in given] if joints is None else [str(n) for n in joints]
    unknown = [n for n in [*keep, *given] if n not in names]
    if unknown:
        field = "joints" if unknown[0] in keep else "locked"
        raise ValueError(f"{field}: {unknown} are not joints of the URDF; its joints are {names}")
    if len(set(keep)) != len(keep) or not keep:
        raise ValueError(f"joints: expected distinct joint names (at least one), got {keep}")
    ordered = [n for n in names if n in keep]
    if ordered != keep:
        raise ValueError(f"joints: list them in the URDF model's order (depth first from the base), {ordered}; "
                         f"got {keep}")
    values: dict[str, float] = {}
    for name in names:
        if name in keep:
            if name in given:
                raise ValueError(f"locked: {name!r} is one of the model's joints (joints= names them); only the "
                                 "other joints are locked")
            continue
        value = given.get(name, 0.0)
        try:
            x = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"locked: {name!r}: expected a number (rad or m), got {value!r}") from None
        j = model.getJointId(name)
        lo, hi = model.lowerPositionLimit[model.idx_qs[j]], model.upperPositionLimit[model.idx_qs[j]]
        if not np.isfinite(x) or not lo <= x <= hi:
            where = "" if name in given else " (the default; give its position in locked=)"
            raise ValueError(f"locked: {name!r}: expected a finite position within the joint's limits "
                             f"[{lo:g}, {hi:g}], got {value!r}{where}")
        values[name] = x
    return values


def lock_joints(model: pin.Model, locked: Mapping[str, float]) -> pin.Model:
    """``model`` with the joints of ``locked`` fixed at their positions; ``model`` itself when ``locked`` is empty.

    Args:
        model: a model with one position per joint (see :func:`angle_joints`).
        locked: ``{name: position}`` as returned by :func:`check_joint_selection`.

    Returns:
        Pinocchio's ``buildReducedModel`` of ``model`` (the locked joints' bodies welded to their parents).
    """
    if not locked:
        return model
    q_ref = pin.neutral(model)
    drop = []
    for name, x in locked.items():
        j = model.getJointId(name)
        q_ref[model.idx_qs[j]] = x
        drop.append(j)
    return pin.buildReducedModel(model, sorted(drop), q_ref)
