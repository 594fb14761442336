"""Checks of a URDF that its parser (urdfdom, inside Pinocchio) accepts but that describes a broken robot.

:func:`parse_urdf_file` parses a URDF file with Pinocchio and refuses (``ValueError`` naming the file and the
element) what would make the rigid-body model silently wrong:

- an ``<inertial>`` the parser could not read and dropped (``mass="heavy"``, NaN: the link has no mass), with the
  parser's words (:func:`cascgp.urdf_parser_output.dropped_inertials`);
- a link that is the child of two joints (the parser drops one of the joints);
- a ``<mimic>`` of a joint the URDF lacks, or of itself (the relation would be ignored);
- a link with more than one ``<inertial>`` (the parser reads the first and drops the others);
- a negative mass, or a principal moment of inertia below -1 % of the link's largest one (not a rigid body: a sign
  or a product of inertia is wrong; rounded CAD values stay far above that);
- a joint axis of (almost) zero length (the joint moves nothing).

:func:`warn_odd` warns (``UserWarning``) about what is odd but usable: a lower position limit above the upper one
(the limits are not checked), and a joint of the model that moves no mass or inertia (no ``<inertial>`` below it:
its rigid-body torque is its armature's only).

:func:`parse_urdf_text` parses a document held in a string (a model file's copy of the URDF it was fitted with) as
the parser reads it, without these checks, so that a model file loads as it was saved.
"""

from __future__ import annotations

import warnings
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import pinocchio as pin

from cascgp.rbd_joints import xml_tag
from cascgp.urdf_parser_output import dropped_inertials, parser_output, parser_reason

__all__ = ["check_urdf_path", "parse_urdf_file", "parse_urdf_text", "warn_odd"]


def _children(element: ET.Element, tag: str) -> list[ET.Element]:
    return [c for c in element if xml_tag(c.tag) == tag]


def _floats(text: str | None, default: list[float]) -> np.ndarray:
    try:
        return np.array([float(v) for v in text.split()] if text else default, dtype=float)
    except ValueError:  # the parser refused it already, or ignores it
        return np.array(default, dtype=float)


def _structure_errors(root: ET.Element) -> list[str]:
    """Links with two parent joints, mimics of a missing joint or of themselves, axes of zero length."""
    errors: list[str] = []
    parents: dict[str | None, str | None] = {}
    joints = [j for j in root if xml_tag(j.tag) == "joint"]
    names = {j.get("name") for j in joints}
    for j in joints:
        name = j.get("name")
        child = next((c.get("link") for c in _children(j, "child")), None)
        if child is not None and child in parents:
            errors.append(f"link {child!r} is the child of two joints ({parents[child]!r} and {name!r})")
        parents.setdefault(child, name)
        for mimic in _children(j, "mimic"):
            of = mimic.get("joint")
            if of is None:  # the parser names that
                continue
            if of == name:
                errors.append(f"joint {name!r} mimics itself")
            elif of not in names:
                errors.append(f"joint {name!r} mimics {of!r}, which the URDF does not have")
        axis = next((a for a in _children(j, "axis")), None)
        if j.get("type") in ("revolute", "continuous", "prismatic") and axis is not None:
            if np.linalg.norm(_floats(axis.get("xyz"), [1.0, 0.0, 0.0])) < 1e-9:
                errors.append(f"joint {name!r} has an axis of zero length ({axis.get('xyz')!r})")
    return errors


def _inertial_errors(root: ET.Element) -> list[str]:
    """Links with several ``<inertial>``, a negative mass or a principal moment of inertia below -1 % of their
    largest (rounded CAD values may also break the triangle inequality of the principal moments, which no rigid body
    does; that leaves the mass matrix positive definite and is not reported)."""
    errors = []
    for link in (e for e in root if xml_tag(e.tag) == "link"):
        inertials = _children(link, "inertial")
        if len(inertials) > 1:  # the parser reads the first and drops the others
            errors.append(f"link {link.get('name')!r} has {len(inertials)} <inertial> elements "
                          "(URDF allows one: merge them into one body's mass, centre of mass and inertia)")
        for inertial in inertials:
            mass = next((_floats(m.get("value"), [0.0])[0] for m in _children(inertial, "mass")), 0.0)
            if mass < 0:
                errors.append(f"link {link.get('name')!r} has a negative mass ({mass:g} kg)")
            el = next(iter(_children(inertial, "inertia")), None)
            if el is None:
                continue
            k = {n: _floats(el.get(n), [0.0])[0] for n in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}
            inertia = np.array([[k["ixx"], k["ixy"], k["ixz"]], [k["ixy"], k["iyy"], k["iyz"]],
                                [k["ixz"], k["iyz"], k["izz"]]])
            lam = np.linalg.eigvalsh(inertia)
            if lam[0] < -0.01 * float(np.abs(lam).max()):  # rounded CAD values of a thin link: far smaller
                errors.append(f"link {link.get('name')!r} has an inertia with a negative principal moment "
                              f"({lam[0]:.3g} kg m^2, its largest {lam[2]:.3g}): not a rigid body")
    return errors


def _massless_joints(model: pin.Model, joints: Sequence[str]) -> list[str]:
    """Joints whose diagonal entry of the mass matrix is 0 at the neutral and at a seeded random configuration."""
    data = model.createData()
    q0 = pin.neutral(model)
    q1 = pin.integrate(model, q0, np.random.default_rng(0).uniform(-1.0, 1.0, model.nv))
    zero = np.ones(model.nv, dtype=bool)
    for q in (q0, q1):
        zero &= np.abs(np.diag(pin.crba(model, data, q))) <= 1e-12
    return [model.names[j] for j in range(1, model.njoints)
            if model.names[j] in joints and model.joints[j].nv == 1 and zero[model.joints[j].idx_v]]


def _refuse_broken_xml(urdf_text: str, what: str) -> None:
    """``ValueError`` starting with ``what`` (the file) if the URDF's XML describes a broken robot (the module
    docstring's refusals but the parser's dropped inertials, which :func:`parse_urdf_file` checks after the
    parse)."""
    try:
        root = ET.fromstring(urdf_text)
    except (ET.ParseError, ValueError):  # Pinocchio parses it or says why not; ElementTree is stricter (a DTD, say)
        return
    errors = _structure_errors(root) + _inertial_errors(root)
    if errors:
        raise ValueError(f"{what}: " + "; ".join(errors))


def warn_odd(model: pin.Model, what: str, joints: Sequence[str]) -> None:
    """A ``UserWarning`` starting with ``what`` (the file) for each oddity of the module docstring of a URDF that
    :func:`parse_urdf_file` accepted; ``model``: Pinocchio's model of it, ``joints``: the rigid-body model's joints
    (not the locked ones)."""
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    notes, inverted = [], []
    for j in range(1, model.njoints):
        i = model.idx_qs[j]
        if model.joints[j].nq == 1 and lo[i] > hi[i]:
            inverted.append(f"{model.names[j]!r} ({lo[i]:g} > {hi[i]:g})")
    if inverted:
        notes.append(f"joints with lower limit > upper limit, not checked against positions: {', '.join(inverted)}")
    massless = _massless_joints(model, joints)
    if massless:
        notes.append(f"joints that move no mass or inertia (no <inertial> in the links they move), whose rigid-body "
                     f"torque is only their armature's: {', '.join(map(repr, massless))}")
    for note in notes:
        warnings.warn(f"{what}: {note}", UserWarning, stacklevel=3)


def parse_urdf_file(path: Path) -> tuple[pin.Model, str]:
    """Pinocchio's model of the URDF file ``path`` and its text. ``FileNotFoundError`` if it does not exist;
    ``ValueError`` naming it if it is not a file, does not parse (with the parser's reason) or describes a broken
    robot (the XML's problems first: Pinocchio's message for a link with two parents, say, is terse or missing)."""
    check_urdf_path(path)
    said: list[str] = []  # what the parser printed (none if reading the file fails first)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"cannot parse URDF {str(path)!r}: {exc}") from exc
    _refuse_broken_xml(text, f"URDF {str(path)!r}")  # before the parse: Pinocchio's own message is terse or none
    try:
        with parser_output() as said:
            model = pin.buildModelFromUrdf(str(path))
    except Exception as exc:  # Pinocchio raises a bare ValueError/RuntimeError with a terse message
        raise ValueError(f"cannot parse URDF {str(path)!r}: {exc}{parser_reason(said)}") from exc
    dropped = dropped_inertials(said)
    if dropped:
        raise ValueError(f"URDF {str(path)!r}: the parser dropped an <inertial> it could not read (urdfdom: "
                         f"{'; '.join(dropped)})")
    return model, text


def check_urdf_path(path: Path) -> None:
    """``FileNotFoundError`` if ``path`` does not exist, ``ValueError`` naming it if it is not a file."""
    if not path.exists():
        raise FileNotFoundError(f"URDF file not found: {str(path)!r}")
    if not path.is_file():
        raise ValueError(f"URDF {str(path)!r}: not a file (a folder?)")


def parse_urdf_text(text: Any) -> pin.Model:
    """Pinocchio's model of the URDF document ``text`` (e.g. embedded in a model file), as the parser reads it
    (without the checks of :func:`parse_urdf_file`: a model file loads as it was saved); ``ValueError`` naming
    ``urdf_text`` if it does not parse."""
    if not isinstance(text, str) or not text.strip():
        raise ValueError("urdf_text: expected a non-empty URDF document")
    said: list[str] = []
    try:
        with parser_output() as said:
            model = pin.buildModelFromXML(text)
    except Exception as exc:
        raise ValueError(f"urdf_text: cannot parse the URDF document: {exc}{parser_reason(said)}") from exc
    return model
