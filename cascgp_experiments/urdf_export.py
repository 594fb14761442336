"""Export a compiled MuJoCo arm model to a URDF for rigid-body dynamics, plus its JSON sidecar.

This module owns the conversion (MuJoCo ``MjModel`` -> URDF text), the seeded calibration error and
the writing of the URDF + sidecar pair. It knows no particular robot: the caller compiles the model
(for the Jaco 2, :mod:`cascgp_experiments.nominal_urdf` builds it with ``jaco_env``) and passes the
robot's limits and descriptions in. The sidecar's format (path rule, version, required fields) is
defined once, in :mod:`cascgp.rbd`, which reads it back (:func:`cascgp.rbd.load_nominal`).

Conversion
----------
Every body frame, mass, centre of mass and inertia is read from the compiled ``MjModel``
(``body_pos``/``body_quat``, ``body_mass``, ``body_ipos``/``body_iquat``, ``body_inertia``; MuJoCo
computes mesh inertias at compile time), together with the hinge axes (``jnt_axis``). Each MuJoCo
body becomes one URDF link whose frame *is* the MuJoCo body frame, so the kinematics agree exactly
(up to the rounding of the printed numbers, 17 significant digits): hinge bodies are joined to their
parent by a ``revolute`` joint, bodies without joints by ``fixed`` joints (Pinocchio folds their
inertia into the parent link when it parses the file). MuJoCo sites become massless links on fixed
joints, i.e. frames in Pinocchio. No visual or collision geometry is written: the file is for
rigid-body dynamics only.

Not in the URDF: armature (rotor inertia; URDF has no field for it, the sidecar's ``armature`` entry
holds it and ``load_nominal`` applies it), joint friction and damping. Joints that MuJoCo leaves
unlimited are written as ``revolute`` with ``+-UNLIMITED_RAD``: a URDF ``continuous`` joint is a (cos, sin)
joint in Pinocchio (nq = 2 per joint), which :mod:`cascgp.rbd_joints` would convert back to a revolute one
on loading; writing it revolute keeps the file the model it is loaded as.

Calibration error (documented, seeded)
--------------------------------------
With relative error ``e`` and seed ``s``, ``rng = numpy.random.default_rng(s)``; for every MuJoCo
body except the world, in MuJoCo body order, four numbers are drawn: ``u_m = rng.uniform(-1, 1)`` and
``u_c = rng.uniform(-1, 1, size=3)`` (drawn for every body, also massless ones, so the stream does
not depend on which bodies have mass), and

* mass:     ``m' = m * (1 + e * u_m)``;
* inertia:  the rotational inertia about the CoM is scaled by the same factor,
  ``I' = I * (1 + e * u_m)`` (same shape, different density: the inertia stays physically
  consistent);
* CoM:      ``c' = c + e * l * u_c`` (in the body frame), where the characteristic length
  ``l = ||c||`` is the distance of the body's CoM from the body frame origin (which lies on the
  body's joint axis), i.e. each CoM coordinate moves by at most ``e`` times the body's lever arm.

``e = 0`` gives the exact rigid-body model of the compiled MuJoCo model.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable
from xml.sax.saxutils import quoteattr

import mujoco
import numpy as np
import pinocchio as pin

from cascgp.io import atomic_write_text
from cascgp.rbd import SIDECAR_FORMAT_VERSION, sidecar_path

__all__ = ["Link", "UNLIMITED_RAD", "CALIBRATION_ERROR_DEFINITION", "extract_links", "apply_calibration_error",
           "urdf_text", "convert", "joint_names", "make_sidecar", "sidecar_text", "check_urdf_path", "write_urdf",
           "format_float"]

#: Position limit written for joints that MuJoCo leaves unlimited (rad).
UNLIMITED_RAD = 1000.0
#: The calibration error rule in one line (recorded in every sidecar).
CALIBRATION_ERROR_DEFINITION = (
    "rng = numpy.random.default_rng(seed); per MuJoCo body in body order: u_m = rng.uniform(-1, 1), "
    "u_c = rng.uniform(-1, 1, 3); mass *= 1 + e u_m; inertia about CoM *= 1 + e u_m; "
    "com += e ||com|| u_c (body frame)"
)


@dataclass
class Link:
    """One URDF link built from a MuJoCo body (or a site, then massless)."""

    name: str
    parent: str  # "world" for the first link
    joint_name: str
    joint_type: str  # "revolute" | "fixed"
    origin_xyz: np.ndarray  # (3,) position in the parent frame
    origin_rpy: np.ndarray  # (3,) URDF roll-pitch-yaw of the frame in the parent frame
    axis: np.ndarray | None  # (3,) joint axis in the link frame (revolute only)
    limit: tuple[float, float] | None  # (lower, upper) rad (revolute only)
    effort: float | None
    velocity: float | None
    mass: float
    com: np.ndarray  # (3,) CoM in the link frame
    inertia: np.ndarray  # (3, 3) about the CoM, axes of the link frame


def _name(m: mujoco.MjModel, obj: mujoco.mjtObj, i: int) -> str:
    name = mujoco.mj_id2name(m, obj, i)
    if not name:
        raise ValueError(f"MuJoCo {obj.name} {i} has no name; every body/joint/site needs one for the URDF")
    return name


def joint_names(m: mujoco.MjModel) -> list[str]:
    """Names of the model's joints, in MuJoCo (= URDF/Pinocchio) order."""
    return [_name(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(m.njnt)]


def _rpy(quat: np.ndarray) -> np.ndarray:
    mat = np.empty(9)
    mujoco.mju_quat2Mat(mat, np.asarray(quat, dtype=float))
    return np.asarray(pin.rpy.matrixToRpy(mat.reshape(3, 3)), dtype=float)


def extract_links(
    m: mujoco.MjModel,
    torque_limits: np.ndarray,
    velocity_limits: np.ndarray,
) -> list[Link]:
    """Read every body (and site) of a compiled MuJoCo model into URDF links.

    Args:
        m: compiled model with a fixed base and only hinge joints.
        torque_limits: (nv,) effort limits written on the revolute joints, in joint order.
        velocity_limits: (nv,) velocity limits, in joint order.

    Returns:
        Links in MuJoCo body order (parents before children); the first link's parent is ``"world"``.
    """
    links: list[Link] = []
    for b in range(1, m.nbody):
        name = _name(m, mujoco.mjtObj.mjOBJ_BODY, b)
        parent_id = int(m.body_parentid[b])
        parent = "world" if parent_id == 0 else _name(m, mujoco.mjtObj.mjOBJ_BODY, parent_id)
        njnt = int(m.body_jntnum[b])
        flat = np.empty(9)
        mujoco.mju_quat2Mat(flat, m.body_iquat[b])
        rot = flat.reshape(3, 3)
        inertia = rot @ np.diag(m.body_inertia[b]) @ rot.T
        inertia = 0.5 * (inertia + inertia.T)
        common = dict(
            name=name,
            parent=parent,
            origin_xyz=m.body_pos[b].copy(),
            origin_rpy=_rpy(m.body_quat[b]),
            mass=float(m.body_mass[b]),
            com=m.body_ipos[b].copy(),
            inertia=inertia,
        )
        if njnt == 0:
            links.append(
                Link(joint_name=f"{name}_fixed", joint_type="fixed", axis=None, limit=None, effort=None,
                     velocity=None, **common)
            )
            continue
        if njnt != 1:
            raise ValueError(f"body {name!r} has {njnt} joints; the URDF generator supports at most one")
        j = int(m.body_jntadr[b])
        if m.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE:
            raise ValueError(f"joint of body {name!r} is not a hinge (type {int(m.jnt_type[j])})")
        if np.any(m.jnt_pos[j] != 0.0):
            # A URDF joint axis passes through the child link origin; a hinge placed elsewhere in
            # the body would need the link frame moved, which the Jaco never needs.
            raise ValueError(f"joint of body {name!r} has non-zero pos {m.jnt_pos[j]}; expected 0")
        dof = int(m.jnt_dofadr[j])
        limit = (
            (float(m.jnt_range[j, 0]), float(m.jnt_range[j, 1]))
            if m.jnt_limited[j]
            else (-UNLIMITED_RAD, UNLIMITED_RAD)
        )
        links.append(
            Link(
                joint_name=_name(m, mujoco.mjtObj.mjOBJ_JOINT, j),
                joint_type="revolute",
                axis=m.jnt_axis[j].copy(),
                limit=limit,
                effort=float(torque_limits[dof]),
                velocity=float(velocity_limits[dof]),
                **common,
            )
        )
    body_names = {link.name for link in links} | {"world"}
    for s in range(m.nsite):
        name = _name(m, mujoco.mjtObj.mjOBJ_SITE, s)
        if name in body_names:
            raise ValueError(f"site name {name!r} collides with a body name")
        links.append(
            Link(
                name=name,
                parent=_name(m, mujoco.mjtObj.mjOBJ_BODY, int(m.site_bodyid[s])) if m.site_bodyid[s] else "world",
                joint_name=f"{name}_fixed",
                joint_type="fixed",
                origin_xyz=m.site_pos[s].copy(),
                origin_rpy=_rpy(m.site_quat[s]),
                axis=None,
                limit=None,
                effort=None,
                velocity=None,
                mass=0.0,
                com=np.zeros(3),
                inertia=np.zeros((3, 3)),
            )
        )
    return links


def _check_error(error: float) -> None:
    if not np.isfinite(error) or error < 0.0 or error >= 1.0:
        raise ValueError(f"error must be a finite relative error in [0, 1), got {error!r}")


def _check_seed(seed: int) -> None:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative int, got {seed!r}")


def apply_calibration_error(links: list[Link], n_bodies: int, error: float, seed: int) -> list[Link]:
    """Perturb masses, inertias and CoMs of the first ``n_bodies`` links (see the module docstring).

    Returns new links; the input is not modified.
    """
    _check_error(error)
    rng = np.random.default_rng(seed)
    out: list[Link] = []
    for i, link in enumerate(links):
        if i >= n_bodies:  # sites: massless frames, not perturbed
            out.append(link)
            continue
        u_m = rng.uniform(-1.0, 1.0)
        u_c = rng.uniform(-1.0, 1.0, size=3)
        scale = 1.0 + error * u_m
        length = float(np.linalg.norm(link.com))
        out.append(
            Link(
                **{
                    **link.__dict__,
                    "mass": link.mass * scale,
                    "inertia": link.inertia * scale,
                    "com": link.com + error * length * u_c,
                }
            )
        )
    return out


def format_float(x: float) -> str:
    """Shortest round-trip text of a float (17 significant digits at most)."""
    x = float(x)
    return repr(x + 0.0)  # + 0.0 turns -0.0 into 0.0


_f = format_float


def _v(xs: np.ndarray) -> str:
    return " ".join(_f(x) for x in xs)


def urdf_text(links: list[Link], robot_name: str, header: str) -> str:
    """Serialise links to URDF XML text (deterministic)."""
    lines = ['<?xml version="1.0"?>', f"<!-- {header} -->", f"<robot name={quoteattr(robot_name)}>"]
    lines.append('  <link name="world"/>')
    for link in links:
        lines.append(f"  <link name={quoteattr(link.name)}>")
        if link.mass > 0.0:
            inertia = link.inertia
            lines += [
                "    <inertial>",
                f'      <origin xyz="{_v(link.com)}" rpy="0 0 0"/>',
                f'      <mass value="{_f(link.mass)}"/>',
                f'      <inertia ixx="{_f(inertia[0, 0])}" ixy="{_f(inertia[0, 1])}" ixz="{_f(inertia[0, 2])}"'
                f' iyy="{_f(inertia[1, 1])}" iyz="{_f(inertia[1, 2])}" izz="{_f(inertia[2, 2])}"/>',
                "    </inertial>",
            ]
        lines.append("  </link>")
        lines += [
            f"  <joint name={quoteattr(link.joint_name)} type={quoteattr(link.joint_type)}>",
            f"    <parent link={quoteattr(link.parent)}/>",
            f"    <child link={quoteattr(link.name)}/>",
            f'    <origin xyz="{_v(link.origin_xyz)}" rpy="{_v(link.origin_rpy)}"/>',
        ]
        if link.joint_type == "revolute":
            if link.axis is None or link.limit is None or link.effort is None or link.velocity is None:
                raise ValueError(f"revolute joint {link.joint_name!r} needs its axis, limit, effort and velocity")
            lines += [
                f'    <axis xyz="{_v(link.axis)}"/>',
                f'    <limit lower="{_f(link.limit[0])}" upper="{_f(link.limit[1])}"'
                f' effort="{_f(link.effort)}" velocity="{_f(link.velocity)}"/>',
            ]
        lines.append("  </joint>")
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


def convert(m: mujoco.MjModel, *, torque_limits: np.ndarray, velocity_limits: np.ndarray, error: float = 0.0,
            seed: int = 0, robot_name: str, header: str) -> str:
    """URDF text of a compiled model, with the seeded calibration error ``error`` (module docstring).

    Args:
        m: compiled model (fixed base, hinge joints only).
        torque_limits, velocity_limits: (nv,) limits written on the revolute joints.
        error: relative calibration error ``e`` in [0, 1).
        seed: seed of the calibration error (non-negative int).
        robot_name: the URDF ``<robot name>``.
        header: text of the XML comment at the top of the file.
    """
    _check_seed(seed)
    links = extract_links(m, torque_limits, velocity_limits)
    links = apply_calibration_error(links, m.nbody - 1, float(error), int(seed))
    return urdf_text(links, robot_name, header)


def make_sidecar(m: mujoco.MjModel, *, urdf_name: str, robot: str, source: str, generator: str,
                 armature: Iterable[float], torque_limits: Iterable[float], velocity_limits: Iterable[float],
                 error: float, seed: int, excluded: Iterable[str]) -> dict:
    """The sidecar dict of a URDF exported from ``m`` (format :data:`cascgp.rbd.SIDECAR_FORMAT_VERSION`).

    ``robot``, ``source``, ``generator`` and ``excluded`` are provenance text; ``armature`` and the
    limits are per joint; ``error`` and ``seed`` are those given to :func:`convert`.
    """
    return {
        "format_version": SIDECAR_FORMAT_VERSION,
        "urdf": urdf_name,
        "robot": robot,
        "source": source,
        "generator": generator,
        "dof": int(m.nv),
        "joint_names": joint_names(m),
        "armature": [float(a) for a in armature],
        "torque_limits": [float(a) for a in torque_limits],
        "velocity_limits": [float(a) for a in velocity_limits],
        "gravity": [float(g) + 0.0 for g in m.opt.gravity],
        "calibration_error": float(error),
        "seed": int(seed),
        "calibration_error_definition": CALIBRATION_ERROR_DEFINITION,
        "excluded": list(excluded),
    }


def sidecar_text(sidecar: dict) -> str:
    """The sidecar's file text (indented JSON, trailing newline)."""
    return json.dumps(sidecar, indent=2) + "\n"


def check_urdf_path(out: str | os.PathLike) -> Path:
    """``out`` as a Path; ``ValueError`` unless it ends in ``.urdf``."""
    out = Path(out)
    if out.suffix != ".urdf":
        raise ValueError(f"out must end in .urdf, got {str(out)!r}")
    return out


def write_urdf(out: str | os.PathLike, text: str, sidecar: dict) -> tuple[Path, Path]:
    """Write the URDF text to ``out`` and the sidecar next to it (:func:`cascgp.rbd.sidecar_path`), each
    atomically; returns both paths."""
    out = check_urdf_path(out)
    json_path = sidecar_path(out)
    atomic_write_text(out, text)
    atomic_write_text(json_path, sidecar_text(sidecar))
    return out, json_path
