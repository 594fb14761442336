"""Rigid-body inverse dynamics: a thin wrapper over Pinocchio's RNEA.

The nominal model of an arm is a URDF (kinematics, masses, centres of mass,
inertias) plus the rotor inertia of each joint ("armature"), which URDF cannot
express. The inverse dynamics computed here is

.. math::

    \\tau_{RBD}(q, \\dot q, \\ddot q) = M(q)\\ddot q + C(q, \\dot q)\\dot q + g(q)
        + \\operatorname{diag}(a)\\,\\ddot q,

with :math:`a` the armature. Pinocchio's ``rnea`` (4.1.0) adds
``model.armature * qdd`` itself (checked in ``tests/test_rbd.py``), so the
armature is stored in ``model.armature`` and nothing is added by hand.

Fixed-base models with one position per joint are accepted: revolute and
prismatic joints, and continuous joints, which become revolute joints whose
position is the angle (:func:`cascgp.rbd_joints.angle_joints`); the callers pass
joint positions as ``(N,)`` vectors. Joints that a log does not have (a
gripper's fingers) can be locked: ``joints=`` names the model's joints and
``locked=`` the others' positions (:func:`cascgp.rbd_joints.lock_joints`); a URDF mimic joint
follows its locked primary.

``load_nominal(urdf_path)`` reads the JSON sidecar written next to the URDF by
:mod:`cascgp_experiments.urdf_export` (armature, torque and velocity limits, gravity,
calibration error and seed) when there is one; without it (a URDF of your own
robot) the armature is zero, the limits come from the URDF's ``<limit>`` tags
and gravity is Pinocchio's default, with a ``UserWarning`` saying so. The
sidecar format is defined here, once:
:func:`sidecar_path` (the path rule), :data:`SIDECAR_FORMAT_VERSION` (written) and
:data:`SUPPORTED_SIDECAR_VERSIONS` (read), :data:`SIDECAR_REQUIRED_FIELDS`.

Not thread-safe: a model owns one ``pinocchio.Data`` workspace.
"""

from __future__ import annotations

import json
import os
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from cascgp.checks import check_real_vector
from cascgp.data import F64, all_finite, as_real_array
from cascgp.rbd_joints import angle_joints, coupling_map, joint_selection, lock_joints, mimic_joints
from cascgp.urdf_checks import check_urdf_path, parse_urdf_file, parse_urdf_text, warn_odd

__all__ = ["RigidBodyModel", "load_nominal", "sidecar_path", "SIDECAR_FORMAT_VERSION",
           "SUPPORTED_SIDECAR_VERSIONS", "SIDECAR_REQUIRED_FIELDS"]

#: Version of the sidecar layout that :mod:`cascgp_experiments.urdf_export` writes.
SIDECAR_FORMAT_VERSION = 1
#: Sidecar layout versions this module can read.
SUPPORTED_SIDECAR_VERSIONS = (SIDECAR_FORMAT_VERSION,)
#: Fields every sidecar must hold (besides ``format_version``).
SIDECAR_REQUIRED_FIELDS = ("armature", "torque_limits", "velocity_limits", "joint_names")
_SIDECAR_FIELDS = (f"a sidecar holds format_version ({SIDECAR_FORMAT_VERSION}), joint_names (the model's joints), "
                   "armature (kg m^2 per joint), torque_limits and velocity_limits (per joint, or null: unknown) "
                   "and optionally gravity ([x, y, z] m/s^2); or remove it to use the URDF alone")


def sidecar_path(urdf_path: str | os.PathLike) -> Path:
    """The JSON sidecar of a URDF: same path with the ``.json`` suffix."""
    return Path(urdf_path).with_suffix(".json")


def _as_vector(name: str, value: Any, n: int) -> np.ndarray:
    arr = check_real_vector(value, name, n, "x, y, z in m/s^2" if name == "gravity" else "one value per joint")
    if name.endswith("_limits") and not np.all(arr > 0):
        raise ValueError(f"{name} must be > 0 (symmetric limits, one per joint), got {arr}")
    return arr


class RigidBodyModel:
    """Inverse dynamics of a fixed-base N-DOF arm from Pinocchio's RNEA.

    Attributes:
        dof: number of joints N (one position each: a continuous joint's is its angle).
        joint_names: names of the N joints, in URDF/Pinocchio order (the URDF's joints less the locked and the
            coupled ones).
        locked: the URDF's joints that are not the model's, locked at a position (rad or m), ``{name: q}``;
            empty when the model has every joint.
        coupled: the URDF's mimic joints that move with one of the model's joints (left out of ``joints`` and
            ``locked``), ``{name: (joint, multiplier, offset)}``: the Pinocchio model keeps them at
            :math:`q = m\\,q_\\text{joint} + o` (velocity and acceleration scaled by :math:`m`), and their torque
            times :math:`m` adds to the joint's (:mod:`cascgp.rbd_joints`).
        armature: (N,) rotor inertia per joint (kg m^2), included in the inverse dynamics.
        gravity: (3,) gravity vector in the world frame (m/s^2).
        torque_limits, velocity_limits: (N,) or ``None`` (from the sidecar).
        meta: the sidecar dict (empty for :meth:`from_urdf`).
        source: the URDF path it was read from (``None`` when built from text).
        urdf_text: the URDF document itself (``None`` when built from a ``pinocchio.Model``): model files
            embed it, so a saved semi-parametric model loads without the URDF file.
        pin_model: the underlying ``pinocchio.Model`` (do not change its shape); with ``coupled`` joints it has
            more joints than the model.

    Args:
        model: a fixed-base Pinocchio model; it is copied (continuous joints converted to revolute joints in
            their angle, :func:`cascgp.rbd_joints.angle_joints`), never changed.
        armature: rotor inertia per joint, (N,) or a scalar; ``None`` keeps the model's.
        gravity: (3,) world gravity; ``None`` keeps the model's.
        torque_limits, velocity_limits: (N,) symmetric limits, or ``None`` (unknown).
        meta: provenance (a sidecar's fields), kept as :attr:`meta`.
        source, urdf_text: the URDF's path and document, kept as attributes.
        joints: the model's joints, in Pinocchio's order of the URDF's joints (default: every joint not in
            ``locked``).
        locked: positions (rad or m; 0 is the URDF's zero) of the joints not in ``joints``; default 0 for each
            (a mimic joint of ``urdf_text``: what its locked primary gives, or, if its primary is one of
            ``joints``, coupled to it: :attr:`coupled`).

    Raises:
        ValueError: a joint with more than one position, no movable joint, a bad joint selection or a vector of
            the wrong shape; the message names the argument.
    """

    def __init__(
        self,
        model: pin.Model,
        *,
        armature: Any = None,
        gravity: Any = None,
        torque_limits: Any = None,
        velocity_limits: Any = None,
        meta: dict | None = None,
        source: str | None = None,
        urdf_text: str | None = None,
        joints: Sequence[str] | None = None,
        locked: Mapping[str, float] | None = None,
    ) -> None:
        model = angle_joints(model)  # a copy: the caller's model is never changed
        values: dict[str, float] = {}
        coupled: dict[str, tuple[str, float, float]] = {}
        if joints is not None or locked:
            values, coupled = joint_selection(model, joints, locked, mimic_joints(urdf_text))
            model = lock_joints(model, values)
        if model.nv == 0:
            raise ValueError(f"{'the model' if source is None else repr(source)}: no degrees of freedom (no "
                             "revolute, continuous or prismatic joint)")
        self.locked: dict[str, float] = values
        self.coupled: dict[str, tuple[str, float, float]] = coupled
        self.pin_model = model
        names = list(model.names[1:])  # one position and one velocity each (angle_joints)
        self._kept = np.array([i for i, n in enumerate(names) if n not in coupled], dtype=np.intp)
        self.dof: int = int(self._kept.size)
        self.joint_names: tuple[str, ...] = tuple(names[i] for i in self._kept)
        # q_full = E q + b with coupled mimic joints (None without: Pinocchio's arrays are the model's)
        self._E: np.ndarray | None = None
        self._b: np.ndarray | None = None
        if coupled:
            self._E, self._b = coupling_map(names, self.joint_names, coupled)
        if armature is not None:
            arm = _as_vector("armature", armature, self.dof).copy()
            if np.any(arm < 0):
                raise ValueError(f"armature must be >= 0 (rotor inertia, kg m^2), got {armature!r}")
            full = np.array(model.armature, dtype=float)
            full[self._kept] = arm
            model.armature = full
        if gravity is not None:
            g = _as_vector("gravity", gravity, 3)
            model.gravity = pin.Motion(g, np.zeros(3))
        self.torque_limits = None if torque_limits is None else _as_vector("torque_limits", torque_limits, self.dof)
        self.velocity_limits = (
            None if velocity_limits is None else _as_vector("velocity_limits", velocity_limits, self.dof)
        )
        self.meta: dict = dict(meta or {})
        self.source = source
        self.urdf_text = urdf_text
        self._data = model.createData()

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_urdf(
        cls,
        path: str | os.PathLike,
        armature: Any = None,
        *,
        gravity: Any = None,
        dof: int | None = None,
        joints: Sequence[str] | None = None,
        locked: Mapping[str, float] | None = None,
    ) -> "RigidBodyModel":
        """Build from a fixed-base URDF.

        Args:
            path: URDF file.
            armature: rotor inertia per joint, (N,) or a scalar; ``None`` keeps the URDF's (zero).
            gravity: (3,) world gravity; ``None`` keeps Pinocchio's default (0, 0, -9.81).
            dof: if given, the expected number of joints; a mismatch raises ``ValueError``.
            joints: the model's joints, in Pinocchio's order of the URDF's joints (default: every joint not in
                ``locked``).
            locked: positions (rad or m) of the joints not in ``joints``, ``{name: q}``; default 0 for each
                (a mimic joint: what its locked primary gives; the mimic joint of a kept joint moves with it,
                :attr:`RigidBodyModel.coupled`).
        """
        path = Path(path)
        model, text = parse_urdf_file(path)
        try:
            rbd = cls(model, armature=armature, gravity=gravity, source=str(path), urdf_text=text, joints=joints,
                      locked=locked)
        except ValueError as exc:  # the URDF's joint types ("joints [...] have ..."): name the file, as a parse error
            if not str(exc).startswith("joints ["):  # does; an argument's error names the argument
                raise
            raise ValueError(f"URDF {str(path)!r}: {exc}") from exc
        rbd._check_dof(dof, f"URDF {str(path)!r}")
        warn_odd(model, f"URDF {str(path)!r}", rbd.joint_names)
        return rbd

    @classmethod
    def from_urdf_text(cls, text: str, *, dof: int | None = None, **kwargs: Any) -> "RigidBodyModel":
        """Build from a URDF document held in a string (e.g. embedded in a model file); ``kwargs`` are those of
        the constructor (``armature``, ``gravity``, ``torque_limits``, ``velocity_limits``, ``meta``,
        ``source``, ``joints``, ``locked``). ``ValueError`` if it does not parse or has another number of joints
        than ``dof``."""
        rbd = cls(parse_urdf_text(text), urdf_text=text, **kwargs)
        rbd._check_dof(dof, "urdf_text: the URDF")
        return rbd

    def _check_dof(self, dof: int | None, what: str) -> None:
        """``ValueError`` naming ``what`` and its joints unless the model has ``dof`` joints (or ``dof`` is None)."""
        if dof is not None and self.dof != dof:
            hint = ("; name the model's joints with joints= (the others are locked, at 0 unless locked= says)"
                    if self.dof > dof else "")
            less = f" less its locked joints ({', '.join(self.locked)})" if self.locked else ""
            raise ValueError(f"dof mismatch: expected {dof} joints, {what}{less} has {self.dof} "
                             f"({', '.join(self.joint_names)}){hint}")

    def _replace(self, **fields: Any) -> "RigidBodyModel":
        """A model of the same (converted, locked) Pinocchio model and URDF with other constructor ``fields``."""
        joints = list(self.joint_names) if self.coupled else None  # the coupling again, from the URDF's mimics
        out = RigidBodyModel(self.pin_model, source=self.source, urdf_text=self.urdf_text, joints=joints, **fields)
        out.locked = dict(self.locked)  # self.pin_model has them locked already
        return out

    # ------------------------------------------------------------------ properties
    @property
    def armature(self) -> np.ndarray:
        return np.array(self.pin_model.armature, dtype=float)[self._kept]

    @property
    def position_limits(self) -> np.ndarray:
        """``(N, 2)``: each joint's lower and upper position limit from the URDF (rad or m; ``-inf, inf`` for a
        continuous joint)."""
        m = self.pin_model
        return np.stack([np.asarray(m.lowerPositionLimit, float)[self._kept],
                         np.asarray(m.upperPositionLimit, float)[self._kept]], axis=1)

    def _per_joint(self, full: Any) -> np.ndarray:
        """A per-joint vector of the Pinocchio model (its joints, coupled ones included) for the model's joints."""
        return np.asarray(full, dtype=float)[self._kept]

    @property
    def gravity(self) -> np.ndarray:
        return np.array(self.pin_model.gravity.linear, dtype=float)

    # ------------------------------------------------------------------ dynamics
    def _check(self, name: str, x: Any) -> np.ndarray:
        arr = as_real_array(name, x, f"({self.dof},) or (T, {self.dof})")  # TypeError for complex, bool, text
        if arr.ndim not in (1, 2) or arr.shape[-1] != self.dof:
            raise ValueError(f"{name} must have shape ({self.dof},) or (T, {self.dof}), got {arr.shape}")
        if not np.isfinite(arr).all():
            bad = np.argwhere(~np.isfinite(arr))[0]
            raise ValueError(f"{name} must be finite; first non-finite entry at index {tuple(int(i) for i in bad)}")
        return arr

    def _check_states(self, q: Any, qd: Any, qdd: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        q, qd, qdd = self._check("q", q), self._check("qd", qd), self._check("qdd", qdd)
        if not (q.shape == qd.shape == qdd.shape):
            raise ValueError(f"q, qd, qdd must have the same shape, got {q.shape}, {qd.shape}, {qdd.shape}")
        return q, qd, qdd

    def inverse_dynamics(self, q: Any, qd: Any, qdd: Any) -> np.ndarray:
        """Joint torques ``tau = M(q) qdd + C(q, qd) qd + g(q) + armature * qdd``.

        Args:
            q, qd, qdd: joint positions (rad), velocities (rad/s), accelerations (rad/s^2),
                each (N,) or all (T, N).

        Returns:
            tau: (N,) or (T, N) in N m, float64. ``ValueError`` naming the argument for non-finite or non-real
            input, or naming ``q, qd, qdd`` when finite input overflows the torque.
        """
        model, data = self.pin_model, self._data
        if (self._E is None and type(q) is np.ndarray and type(qd) is np.ndarray and type(qdd) is np.ndarray
                and q.dtype == qd.dtype == qdd.dtype == F64 and q.shape == qd.shape == qdd.shape == (self.dof,)
                and q.flags.c_contiguous and qd.flags.c_contiguous and qdd.flags.c_contiguous):
            # One configuration of float64 arrays (what a controller passes every tick): RNEA first, the checks
            # only if the torque is not finite (a NaN or inf input always gives one), so that bad input still
            # raises the checks' error below and good input skips their cost.
            tau = pin.rnea(model, data, q, qd, qdd)
            if all_finite(tau):
                return tau.copy()
        states = q, qd, qdd = self._check_states(q, qd, qdd)
        if self._E is not None:
            E = self._E
            q, qd, qdd = q @ E.T + self._b, qd @ E.T, qdd @ E.T
        if q.ndim == 1:
            out = pin.rnea(model, data, q, qd, qdd).copy()
        else:
            out = np.empty_like(q)
            for t in range(q.shape[0]):
                out[t] = pin.rnea(model, data, q[t], qd[t], qdd[t])
        if not np.isfinite(out).all():  # finite inputs (checked) whose products overflow: |qd| of 1e300, say
            raise ValueError("q, qd, qdd: the torque overflowed (largest |q|, |qd|, |qdd|: "
                             f"{', '.join(f'{np.abs(x).max():.3g}' for x in states)}); expected states a robot reaches")
        return out if self._E is None else (self._E.T @ out if out.ndim == 1 else out @ self._E)

    def inverse_dynamics_derivatives(self, q: Any, qd: Any, qdd: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        r"""Partial derivatives of :meth:`inverse_dynamics`, by Pinocchio's analytic RNEA derivatives
        (``pinocchio.computeRNEADerivatives``, armature included):

        .. math::

            \frac{\partial \tau}{\partial q}, \quad \frac{\partial \tau}{\partial \dot q}, \quad
            \frac{\partial \tau}{\partial \ddot q} = M(q) + \operatorname{diag}(\text{armature}).

        Args:
            q, qd, qdd: as for :meth:`inverse_dynamics`, each (N,) or all (T, N).

        Returns:
            ``(dtau_dq, dtau_dqd, dtau_dqdd)``, each (N, N) or (T, N, N); row i is joint i's torque.
        """
        q, qd, qdd = self._check_states(q, qd, qdd)
        model, data = self.pin_model, self._data
        E = self._E
        if E is not None:  # the chain rule through q_full = E q + b: E^T (d tau_full / d x_full) E
            q, qd, qdd = q @ E.T + self._b, qd @ E.T, qdd @ E.T
        if q.ndim == 1:
            parts = [np.array(d) for d in pin.computeRNEADerivatives(model, data, q, qd, qdd)]
            return tuple(p if E is None else E.T @ p @ E for p in parts)  # type: ignore[return-value]
        out = np.empty((3, q.shape[0], self.dof, self.dof))
        for t in range(q.shape[0]):
            for c, d in enumerate(pin.computeRNEADerivatives(model, data, q[t], qd[t], qdd[t])):
                out[c, t] = d if E is None else E.T @ d @ E
        return out[0], out[1], out[2]

    def gravity_torque(self, q: Any) -> np.ndarray:
        """Generalised gravity ``g(q)`` (= inverse dynamics at zero velocity and acceleration).

        Args:
            q: (N,) or (T, N) joint positions (rad).

        Returns:
            (N,) or (T, N) in N m.
        """
        q = self._check("q", q)
        model, data = self.pin_model, self._data
        if self._E is not None:
            return self.inverse_dynamics(q, np.zeros_like(q), np.zeros_like(q))
        if q.ndim == 1:
            return pin.computeGeneralizedGravity(model, data, q).copy()
        out = np.empty_like(q)
        for t in range(q.shape[0]):
            out[t] = pin.computeGeneralizedGravity(model, data, q[t])
        return out

    def mass_matrix(self, q: Any) -> np.ndarray:
        r"""Joint-space inertia ``M(q) + diag(armature)``, (N, N), for a single (N,) configuration (with
        :attr:`coupled` joints :math:`E^T (M_\text{full} + \operatorname{diag}(\text{armature}_\text{full})) E`,
        the coupled joints' inertia included)."""
        q = self._check("q", q)
        if q.ndim != 1:
            raise ValueError(f"q must have shape ({self.dof},) for mass_matrix, got {q.shape}")
        E = self._E
        M = pin.crba(self.pin_model, self._data, q if E is None else E @ q + self._b)
        M = np.triu(M) + np.triu(M, 1).T  # crba fills the upper triangle only
        return M if E is None else E.T @ M @ E

    def __repr__(self) -> str:
        lock = f", locked={self.locked}" if self.locked else ""
        lock += f", coupled={self.coupled}" if self.coupled else ""
        return f"RigidBodyModel(dof={self.dof}, joints={list(self.joint_names)}{lock}, source={self.source!r})"


def _urdf_limits(values: np.ndarray) -> np.ndarray | None:
    """The URDF's per-joint limits, or ``None`` unless every joint has a finite positive one."""
    v = np.asarray(values, dtype=float)
    return v.copy() if v.size and np.all(np.isfinite(v)) and np.all(v > 0) else None


def _without_sidecar(urdf_path: Path, js: Path, dof: int | None, joints: Sequence[str] | None,
                     locked: Mapping[str, float] | None) -> RigidBodyModel:
    """:func:`load_nominal` for a URDF without a sidecar (see its docstring)."""
    rbd = RigidBodyModel.from_urdf(urdf_path, dof=dof, joints=joints, locked=locked)
    model = rbd.pin_model
    torque = _urdf_limits(rbd._per_joint(model.effortLimit))
    velocity = _urdf_limits(rbd._per_joint(model.velocityLimit))
    gravity = rbd.gravity
    assumed = {"sidecar": None, "armature": "zero (not in the URDF)",
               "torque_limits": "URDF <limit effort>" if torque is not None else "unknown",
               "velocity_limits": "URDF <limit velocity>" if velocity is not None else "unknown",
               "gravity": gravity.tolist()}
    warnings.warn(
        f"URDF {str(urdf_path)!r} has no sidecar JSON ({str(js)!r}): assuming zero armature (rotor inertia), "
        f"torque limits {'from the URDF' if torque is not None else 'unknown (a joint has no positive effort)'}, "
        f"velocity limits {'from the URDF' if velocity is not None else 'unknown (a joint has no positive velocity)'}, "
        f"gravity {tuple(gravity.tolist())} m/s^2", UserWarning, stacklevel=3)
    return rbd._replace(armature=np.zeros(rbd.dof), torque_limits=torque, velocity_limits=velocity, meta=assumed)


def load_nominal(urdf_path: str | os.PathLike, *, dof: int | None = None, joints: Sequence[str] | None = None,
                 locked: Mapping[str, float] | None = None) -> RigidBodyModel:
    """Load a nominal model: the URDF plus, when present, its JSON sidecar (same name, ``.json``).

    Example:
        >>> import numpy as np, jaco_env
        >>> rbd = load_nominal(jaco_env.NOMINAL_URDF)           # the Jaco 2's nominal URDF and its sidecar
        >>> rbd.dof
        6
        >>> q = np.zeros((1, 6))
        >>> np.allclose(rbd.inverse_dynamics(q, q, q), rbd.gravity_torque(q))   # at rest: gravity alone
        True

    The sidecar (written by :func:`cascgp_experiments.urdf_export.write_urdf`) holds ``armature``,
    ``torque_limits``, ``velocity_limits``, ``gravity``, ``calibration_error``,
    ``seed``, ``joint_names``, ``dof`` and provenance; the whole dict is kept as
    ``model.meta``.

    Without a sidecar (e.g. the URDF of your own robot) the model is the URDF alone and a
    ``UserWarning`` names the URDF and what was assumed:

    * armature zero (URDF cannot express rotor inertia);
    * ``torque_limits`` / ``velocity_limits`` from the URDF's ``<limit effort=... velocity=...>``
      (Pinocchio's ``effortLimit`` / ``velocityLimit``) when every joint has a finite positive value,
      otherwise ``None`` (unknown: a limit of 0 or a missing tag is not taken as "no torque");
    * gravity Pinocchio's default :math:`(0, 0, -9.81)` m/s² (world z up);
    * ``model.meta`` records these assumptions (``meta["sidecar"]`` is ``None``).

    A manufacturer's URDF often has joints that a log does not (a gripper's fingers): ``joints`` names the
    model's joints, in Pinocchio's order of the URDF's joints (depth first from the base, branches by joint
    name), and the others are locked, at 0 (the URDF's zero) or at the positions ``locked`` gives; a sidecar then
    lists the model's joints only. Continuous joints are revolute joints whose position is the angle in rad, zero
    at the URDF's zero, in any range (:mod:`cascgp.rbd_joints`).

    Args:
        urdf_path: the URDF file.
        dof: if given, the expected number of joints.
        joints: the model's joints (default: every joint not in ``locked``).
        locked: positions (rad or m) of the joints not in ``joints``, ``{name: q}``; default 0 for each
            (a mimic joint: what its locked primary gives; the mimic joint of a kept joint moves with it,
            :attr:`RigidBodyModel.coupled`).

    Raises:
        FileNotFoundError: the URDF is missing.
        ValueError: the URDF does not parse or has another number of joints than ``dof``; the sidecar
            is not valid JSON, lacks a field, or disagrees with the URDF.
    """
    urdf_path = Path(urdf_path)
    check_urdf_path(urdf_path)
    js = sidecar_path(urdf_path)
    if not js.exists():
        return _without_sidecar(urdf_path, js, dof, joints, locked)
    try:
        meta = json.loads(js.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"sidecar {str(js)!r} is not valid JSON: {exc}") from exc
    if not isinstance(meta, dict):
        raise ValueError(f"sidecar {str(js)!r} must hold a JSON object, got {type(meta).__name__}")
    if "format_version" in meta and meta["format_version"] not in SUPPORTED_SIDECAR_VERSIONS:  # another layout
        raise ValueError(f"sidecar {str(js)!r}: format_version must be one of {SUPPORTED_SIDECAR_VERSIONS}, got "
                         f"{meta['format_version']!r}")
    missing = [key for key in ("format_version", *SIDECAR_REQUIRED_FIELDS) if key not in meta]
    if missing:  # every missing field at once, and what a sidecar holds
        raise ValueError(f"sidecar {str(js)!r} lacks the field{'s' if len(missing) > 1 else ''} "
                         f"{', '.join(map(repr, missing))}; {_SIDECAR_FIELDS}")
    rbd = RigidBodyModel.from_urdf(urdf_path, dof=dof, joints=joints, locked=locked)
    if "dof" in meta and meta["dof"] != rbd.dof:
        what = (f"the model's {rbd.dof} joints (the URDF's with {', '.join(rbd.locked)} locked: a sidecar lists the "
                "model's joints only)" if rbd.locked else f"the URDF's {rbd.dof} joints")
        raise ValueError(f"sidecar {str(js)!r}: dof {meta['dof']} does not match {what}")
    if list(meta["joint_names"]) != list(rbd.joint_names):
        raise ValueError(
            f"sidecar {str(js)!r}: joint_names {meta['joint_names']} do not match the URDF's {list(rbd.joint_names)}"
        )
    try:
        return rbd._replace(armature=meta["armature"], gravity=meta.get("gravity"), torque_limits=meta["torque_limits"],
                         velocity_limits=meta["velocity_limits"], meta=meta)
    except ValueError as exc:
        raise ValueError(f"sidecar {str(js)!r}: {exc}") from exc
