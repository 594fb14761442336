"""Generate the nominal URDF of the simulated Jaco 2 arm (plus its JSON sidecar).

Usage::

    python -m scripts.generate_urdf --out assets/jaco2_nominal.urdf --error 0.1 --seed 0

writes ``assets/jaco2_nominal.urdf`` and ``assets/jaco2_nominal.json``.

Source
------
The *bare* simulated robot, ``jaco_env.robot.build_arm_mjcf(armature=None,
frictionloss=None, damping=None)``: the six-joint arm with the welded hand, no
payload, no joint friction or damping. It is compiled with MuJoCo and every
body frame, mass, centre of mass and inertia is read from the compiled
``MjModel`` (``body_pos``/``body_quat``, ``body_mass``, ``body_ipos``/``body_iquat``,
``body_inertia``; MuJoCo computes the mesh inertias at compile time), together
with the hinge axes (``jnt_axis``). Each MuJoCo body becomes one URDF link whose
frame *is* the MuJoCo body frame, so the kinematics agree exactly (up to the
rounding of the printed numbers, 17 significant digits): hinge bodies are joined
to their parent by a ``revolute`` joint, the welded hand and finger bodies by
``fixed`` joints (Pinocchio folds their inertia into link 6 when it parses the
file). The three MuJoCo sites (``wristsite``, ``jaco_hand/gripsite``,
``jaco_hand/pinchsite``) become massless links on fixed joints, i.e. frames
in Pinocchio. No visual or collision geometry is written: the file is for
rigid-body dynamics only.

What is *not* in the URDF
-------------------------
* Armature (rotor inertia): URDF has no field for it; the sidecar JSON has an
  ``armature`` entry that ``cascgp.rbd.load_nominal`` applies. It is zero: the
  Jaco 2's joint torque sensors read the link-side torque, after the rotor inertia
  and the gear friction (``jaco_env.robot``), so the nominal model of the *sensed*
  torque is the links' rigid-body dynamics alone.
* Joint friction and damping, and the payload: deliberately absent from the
  nominal model (a learned model must capture them).
* Joint limits of the unlimited joints (1, 4, 5, 6): written as ``revolute``
  with ``+-UNLIMITED_RAD`` because a URDF ``continuous`` joint is a
  (cos, sin) joint in Pinocchio (nq = 2 per joint), which would break nq = nv.

Calibration error (documented, seeded)
--------------------------------------
With relative error ``e`` (``--error``, default 0.1) and seed ``s`` (``--seed``),
``rng = numpy.random.default_rng(s)``; for every MuJoCo body except the world,
in MuJoCo body order (``b_base, b_1 .. b_6, jaco_hand/, jaco_hand/hand``, then the
fingers), four numbers are drawn: ``u_m = rng.uniform(-1, 1)`` and
``u_c = rng.uniform(-1, 1, size=3)`` (drawn for every body, also massless ones,
so the stream does not depend on which bodies have mass), and

* mass:     ``m' = m * (1 + e * u_m)``;
* inertia:  the rotational inertia about the CoM is scaled by the same factor,
  ``I' = I * (1 + e * u_m)`` (same shape, different density: the inertia stays
  physically consistent);
* CoM:      ``c' = c + e * l * u_c`` (in the body frame), where the characteristic
  length ``l = ||c||`` is the distance of the body's CoM from the body frame
  origin (which lies on the body's joint axis), i.e. each CoM coordinate moves by
  at most ``e`` times the body's lever arm.

``e = 0`` gives the exact simulated rigid-body model (the test that RNEA equals
MuJoCo's ``mj_inverse`` to 1e-8 uses it).
"""

from __future__ import annotations

import argparse
import json
import os
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import quoteattr

import mujoco
import numpy as np
import pinocchio as pin

from cascgp.io import atomic_write_text

#: Position limit written for joints that MuJoCo leaves unlimited (rad).
UNLIMITED_RAD = 1000.0
#: Version of the sidecar JSON layout (read by ``cascgp.rbd.load_nominal``).
SIDECAR_FORMAT_VERSION = 1
DEFAULT_OUT = Path("assets/jaco2_nominal.urdf")


@dataclass
class Link:
    """One URDF link built from a MuJoCo body (or a site, then massless)."""

    name: str
    parent: str | None
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


def build_bare_model() -> mujoco.MjModel:
    """Compile the bare simulated arm: no payload, no friction, no damping, no armature."""
    from jaco_env.robot import build_arm_mjcf

    arm = build_arm_mjcf(armature=None, frictionloss=None, damping=None)
    return mujoco.MjModel.from_xml_string(arm.to_xml_string(), arm.get_assets())


def _name(m: mujoco.MjModel, obj: mujoco.mjtObj, i: int) -> str:
    name = mujoco.mj_id2name(m, obj, i)
    if not name:
        raise ValueError(f"MuJoCo {obj.name} {i} has no name; every body/joint/site needs one for the URDF")
    return name


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
        rot = np.empty(9)
        mujoco.mju_quat2Mat(rot, m.body_iquat[b])
        rot = rot.reshape(3, 3)
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


def apply_calibration_error(links: list[Link], n_bodies: int, error: float, seed: int) -> list[Link]:
    """Perturb masses, inertias and CoMs of the first ``n_bodies`` links (see the module docstring).

    Returns new links; the input is not modified.
    """
    if not np.isfinite(error) or error < 0.0 or error >= 1.0:
        raise ValueError(f"error must be a finite relative error in [0, 1), got {error!r}")
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


def _f(x: float) -> str:
    """Shortest round-trip text of a float (17 significant digits at most)."""
    x = float(x)
    return repr(x + 0.0)  # + 0.0 turns -0.0 into 0.0


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
            lines += [
                f'    <axis xyz="{_v(link.axis)}"/>',
                f'    <limit lower="{_f(link.limit[0])}" upper="{_f(link.limit[1])}"'
                f' effort="{_f(link.effort)}" velocity="{_f(link.velocity)}"/>',
            ]
        lines.append("  </joint>")
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


def generate(error: float = 0.1, seed: int = 0, urdf_name: str = DEFAULT_OUT.name) -> tuple[str, dict]:
    """Build the nominal URDF text and the sidecar dict (nothing written).

    Args:
        error: relative calibration error ``e`` in [0, 1) (module docstring).
        seed: seed of the calibration error.
        urdf_name: file name of the URDF recorded in the sidecar.

    Returns:
        ``(urdf_text, sidecar)``.
    """
    from importlib.metadata import version

    from jaco_env import robot

    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative int, got {seed!r}")
    m = build_bare_model()
    if m.nv != robot.N_JOINTS or m.nq != m.nv:
        raise ValueError(f"expected {robot.N_JOINTS} hinge joints, compiled model has nq={m.nq}, nv={m.nv}")
    links = extract_links(m, robot.TORQUE_LIMITS, robot.VELOCITY_LIMITS)
    links = apply_calibration_error(links, m.nbody - 1, float(error), int(seed))
    joint_names = [_name(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(m.njnt)]
    source = (
        "jaco_env.robot.build_arm_mjcf(armature=None, frictionloss=None, damping=None) "
        f"compiled with MuJoCo {mujoco.__version__} (dm_control {version('dm-control')})"
    )
    header = (
        "Generated by `python -m scripts.generate_urdf`; do not edit by hand (a test regenerates it). "
        f"Nominal Jaco 2 arm from {source}; calibration error {_f(error)} (seed {int(seed)}) on link masses, "
        "inertias and centres of mass; armature, torque and velocity limits in the sidecar JSON."
    )
    text = urdf_text(links, "jaco2_nominal", header)
    sidecar = {
        "format_version": SIDECAR_FORMAT_VERSION,
        "urdf": urdf_name,
        "robot": "Kinova Jaco 2 (6 DOF, welded 3-finger hand)",
        "source": source,
        "generator": "python -m scripts.generate_urdf",
        "dof": int(m.nv),
        "joint_names": joint_names,
        # Link-side torque sensors: the sensed torque holds no rotor inertia (jaco_env.robot).
        "armature": [0.0] * robot.N_JOINTS,
        "torque_limits": [float(a) for a in robot.TORQUE_LIMITS],
        "velocity_limits": [float(a) for a in robot.VELOCITY_LIMITS],
        "gravity": [float(g) + 0.0 for g in m.opt.gravity],
        "calibration_error": float(error),
        "seed": int(seed),
        "calibration_error_definition": (
            "rng = numpy.random.default_rng(seed); per MuJoCo body in body order: u_m = rng.uniform(-1, 1), "
            "u_c = rng.uniform(-1, 1, 3); mass *= 1 + e u_m; inertia about CoM *= 1 + e u_m; "
            "com += e ||com|| u_c (body frame)"
        ),
        "excluded": ["rotor inertia (link-side torque sensors)", "joint frictionloss", "joint damping", "payload"],
    }
    return text, sidecar


def sidecar_path(urdf_path: str | os.PathLike) -> Path:
    """The JSON sidecar next to a URDF: same name, ``.json`` suffix."""
    return Path(urdf_path).with_suffix(".json")


def sidecar_text(sidecar: dict) -> str:
    return json.dumps(sidecar, indent=2) + "\n"


def write(out: str | os.PathLike = DEFAULT_OUT, error: float = 0.1, seed: int = 0) -> tuple[Path, Path]:
    """Generate and write the URDF and its sidecar JSON; returns both paths."""
    out = Path(out)
    if out.suffix != ".urdf":
        raise ValueError(f"out must end in .urdf, got {str(out)!r}")
    text, sidecar = generate(error=error, seed=seed, urdf_name=out.name)
    json_path = sidecar_path(out)
    atomic_write_text(out, text)
    atomic_write_text(json_path, sidecar_text(sidecar))
    return out, json_path


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default=str(DEFAULT_OUT), help="URDF path (the .json sidecar goes next to it)")
    parser.add_argument("--error", type=float, default=0.1, help="relative calibration error e in [0, 1)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the calibration error")
    args = parser.parse_args(argv)
    urdf, js = write(args.out, args.error, args.seed)
    print(f"wrote {urdf} and {js}")


if __name__ == "__main__":
    main()
