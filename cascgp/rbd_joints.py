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
  named (the log's, in Pinocchio's order of the URDF's joints: depth first from the base, branches by joint name)
  and locks every other one at a given position (default 0, the URDF's zero), with Pinocchio's
  ``buildReducedModel``: the locked joint's bodies become rigid parts of their parent body, inertia included.
* **Mimic joints.** A URDF ``<mimic>`` joint (a gripper's second finger) moves with another joint:
  :math:`q = m\\,q_\\text{primary} + o`. Pinocchio reads it as a joint of its own; :func:`mimic_joints` reads the
  relation from the URDF, and :func:`joint_selection` locks a mimic joint whose primary is locked at the
  position the relation gives. A mimic joint of one of the model's joints that ``joints`` leaves out moves with
  it: it stays in the Pinocchio model, and :class:`cascgp.rbd.RigidBodyModel` sets its position, velocity and
  acceleration from its primary's and adds its torque to its primary's (the coupling's virtual work: the
  primary's generalised force is :math:`\\tau_\\text{primary} + m\\,\\tau_\\text{mimic}`), as Pinocchio's own mimic
  joints do. A mimic joint's position given in ``locked`` is used (with a warning if it disagrees with the
  relation: model files saved before mimic joints were followed hold such positions).

Spherical, planar and floating joints are refused: the log format gives each joint one position.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import warnings
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin

__all__ = ["angle_joints", "lock_joints", "check_joint_selection", "joint_selection", "mimic_joints", "coupling_map",
           "xml_tag"]

#: How far (rad or m) a mimic joint's given position may be from the one its relation gives.
MIMIC_TOL = 1e-9

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
        ValueError: a joint has more than one position (spherical, planar, floating) or none (a Pinocchio mimic
            joint); names the joints.
    """
    new_joints = [_with_angle(model.joints[j]) for j in range(1, model.njoints)]
    other = [model.names[j] for j in range(1, model.njoints)
             if new_joints[j - 1] is None and model.joints[j].nq != model.joints[j].nv]
    if other:
        raise ValueError(f"joints {other} have more than one position (spherical, planar or floating joints); "
                         "only revolute, continuous and prismatic joints are supported")
    still = [model.names[j] for j in range(1, model.njoints) if model.joints[j].nv == 0]
    if still:  # Pinocchio's own mimic joints (buildModelFromUrdf(..., mimic=True)): no position of their own
        raise ValueError(f"joints {still} have no position of their own (Pinocchio mimic joints, a model built with "
                         "mimic=True): build it without mimic=True and pass urdf_text= (RigidBodyModel.from_urdf "
                         "does both); the mimic joints then move with their joints")
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


def mimic_joints(urdf_text: str | None) -> dict[str, tuple[str, float, float]]:
    """The URDF's ``<mimic>`` relations: ``{joint: (primary, multiplier, offset)}`` (URDF defaults 1 and 0);
    empty for ``None`` or a document that does not parse as XML (Pinocchio parsed it: then it has none)."""
    if not urdf_text:
        return {}
    try:
        root = ET.fromstring(urdf_text)
    except (ET.ParseError, ValueError):
        return {}
    out = {}
    for joint in root.iter():
        if xml_tag(joint.tag) != "joint":
            continue
        mimic = next((c for c in joint if xml_tag(c.tag) == "mimic"), None)
        if mimic is not None and joint.get("name") and mimic.get("joint"):
            out[joint.get("name", "")] = (mimic.get("joint", ""), float(mimic.get("multiplier", 1.0)),
                                          float(mimic.get("offset", 0.0)))
    return out


def xml_tag(tag: object) -> str:
    """An element's tag without its XML namespace (``{uri}joint`` -> ``joint``)."""
    return tag.rsplit("}", 1)[-1] if isinstance(tag, str) else ""


def check_joint_selection(model: pin.Model, joints: Sequence[str] | None,
                          locked: Mapping[str, float] | None,
                          mimics: Mapping[str, tuple[str, float, float]] | None = None) -> dict[str, float]:
    """The positions of the joints to lock: :func:`joint_selection`'s first part."""
    return joint_selection(model, joints, locked, mimics)[0]


def joint_selection(model: pin.Model, joints: Sequence[str] | None, locked: Mapping[str, float] | None,
                    mimics: Mapping[str, tuple[str, float, float]] | None = None
                    ) -> tuple[dict[str, float], dict[str, tuple[str, float, float]]]:
    """The positions of the joints to lock and the mimic joints that move with the model's joints, ``joints`` and
    ``locked`` checked against ``model``'s joints.

    Args:
        model: a model with one position per joint (see :func:`angle_joints`).
        joints: the joints to keep, distinct names of ``model``'s joints in its order (depth first from the
            base); default: every joint not in ``locked``.
        locked: positions (rad or m, the URDF's zero at 0) of joints not kept; default 0 for each, and for a
            mimic joint (``mimics``) the position its locked primary gives it (without ``joints``, a mimic joint
            of a locked joint is locked too).
        mimics: :func:`mimic_joints` of the URDF.

    Returns:
        ``(locked, coupled)``: ``{name: position}`` of every joint to lock (empty when all are kept), and
        ``{name: (joint, multiplier, offset)}`` of the mimic joints left out of ``joints`` and ``locked`` whose
        primary is one of the model's joints, directly or through other such mimic joints: each stays a joint of
        the Pinocchio model at :math:`q = m\\,q_\\text{joint} + o` (the relations composed along a chain).

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
    mimics = {k: v for k, v in (mimics or {}).items() if k in names and v[0] in names}
    if joints is None:
        following = _following(mimics, set(given))
        keep = [n for n in names if n not in given and n not in following]
    else:
        keep = [str(n) for n in joints]
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
    for name in keep:
        if name in given:
            raise ValueError(f"locked: {name!r} is one of the model's joints (joints= names them); only the "
                             "other joints are locked")
    values: dict[str, float] = {}
    mimics = {k: v for k, v in mimics.items() if k not in keep}
    coupled: dict[str, tuple[str, float, float]] = {}
    for name in [n for n in names if n not in keep and n not in mimics] + _primaries_first(mimics):
        if name in mimics and name not in given and (mimics[name][0] in keep or mimics[name][0] in coupled):
            primary, mult, offset = mimics[name]  # moves with a joint of the model: stays, coupled to it
            if primary in coupled:
                primary, m0, o0 = coupled[primary]
                mult, offset = mult * m0, mult * o0 + offset
            coupled[name] = (primary, mult, offset)
            continue
        value = given.get(name, 0.0)
        try:
            x = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"locked: {name!r}: expected a number (rad or m), got {value!r}") from None
        if name in mimics:
            x = _mimic_position(name, mimics[name], keep, coupled, values, given, x)
        j = model.getJointId(name)
        lo, hi = model.lowerPositionLimit[model.idx_qs[j]], model.upperPositionLimit[model.idx_qs[j]]
        if not np.isfinite(x) or (hi > lo and not lo <= x <= hi):  # lower = upper (URDF's default 0, 0): no limits
            where = ("" if name in given else f" (from {mimics[name][0]!r}, which it mimics)" if name in mimics
                     else " (the default; give its position in locked=)")
            shown = repr(value) if name in given or name not in mimics else f"{x:g}"
            raise ValueError(f"locked: {name!r}: expected a finite position within the joint's limits "
                             f"[{lo:g}, {hi:g}], got {shown}{where}")
        values[name] = x
    return values, coupled


def _following(mimics: Mapping[str, tuple[str, float, float]], locked: set[str]) -> set[str]:
    """The mimic joints not in ``locked`` that follow a joint in it, directly or through other mimic joints."""
    out: set[str] = set()
    grew = True
    while grew:
        new = {m for m, (p, *_) in mimics.items() if m not in locked | out and p in locked | out}
        out |= new
        grew = bool(new)
    return out


def _primaries_first(mimics: Mapping[str, tuple[str, float, float]]) -> list[str]:
    """The mimic joints, each after the mimic joint it follows (if any)."""
    order: list[str] = []
    while len(order) < len(mimics):
        ready = [m for m, (p, *_) in mimics.items() if m not in order and (p not in mimics or p in order)]
        if not ready:
            raise ValueError(f"locked: the URDF's mimic joints {sorted(set(mimics) - set(order))} follow each other "
                             "in a cycle")
        order += ready
    return order


def _mimic_position(name: str, relation: tuple[str, float, float], keep: Sequence[str], coupled: Mapping[str, Any],
                    values: Mapping[str, float], given: Mapping[str, Any], x: float) -> float:
    """The locked position of mimic joint ``name``, given as ``x``, or its relation applied to its primary's locked
    position. A position given otherwise is kept, with a warning (also for a primary that moves: one of ``keep``,
    or ``coupled`` to one)."""
    primary, mult, offset = relation
    if primary in keep or primary in coupled:  # given (left out of locked=, it moves with it: joint_selection)
        which = "one of the model's joints" if primary in keep else "which moves with one of the model's joints"
        warnings.warn(f"locked: {name!r} mimics {primary!r}, {which}, so it moves with it; it is locked at {x:g} as "
                      "given (leave it out of locked= and it moves with it)", UserWarning, stacklevel=4)
        return x
    follow = mult * values[primary] + offset
    if name in given and not abs(x - follow) <= MIMIC_TOL:
        warnings.warn(f"locked: {name!r} mimics {primary!r} (multiplier {mult:g}, offset {offset:g}), which puts it "
                      f"at {follow:g}; it is locked at {x:g} as given (leave it out and it follows)", UserWarning,
                      stacklevel=4)
        return x
    return x if name in given else follow


def coupling_map(names: Sequence[str], joints: Sequence[str], coupled: Mapping[str, tuple[str, float, float]]
                 ) -> tuple[np.ndarray, np.ndarray]:
    r"""``(E, b)``: the Pinocchio model's positions from the model's, :math:`q_\text{full} = E q + b` (velocities and
    accelerations :math:`E \dot q`, :math:`E \ddot q`; torques :math:`E^T \tau_\text{full}`, derivatives
    :math:`E^T D E`), for the Pinocchio model's joints ``names`` (one position each), the model's ``joints`` and the
    ``coupled`` mimic joints of :func:`joint_selection`. Written here rather than with Pinocchio's own mimic
    joints (``buildModelFromUrdf(..., mimic=True)``) because its RNEA derivatives refuse them; the torque is the
    same."""
    E, b = np.zeros((len(names), len(joints))), np.zeros(len(names))
    for k, name in enumerate(joints):
        E[list(names).index(name), k] = 1.0
    for name, (joint, mult, offset) in coupled.items():
        E[list(names).index(name), list(joints).index(joint)] = mult
        b[list(names).index(name)] = offset
    return E, b


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
