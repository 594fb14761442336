"""Model files: :func:`save_model` / :func:`load_model` (``.npz``, no pickle, written atomically).

A file holds the format kind and version, the model's config as JSON (the cascgp version that wrote it, name, dof,
df_delta, train_on_predicted, GP config, a reference to the rigid-body model, the caller's provenance if given;
:func:`saved_config` reads it), every GP bank's saved state (:mod:`cascgp.gp.state`), and check queries with the
predictions made at save time; :func:`load_model` recomputes them and refuses a file that does not reproduce them.

Self-contained semi-parametric models: when the rigid-body model is a :class:`cascgp.rbd.RigidBodyModel` built from
a URDF, the file embeds the URDF document, its SHA-256, the armature, gravity, limits and sidecar metadata
(``rbd/*`` entries), so :func:`load_model` rebuilds the same model from any folder without the URDF file. A
rigid-body model of another type cannot be embedded; such files need ``load_model(path, rbd=...)``.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import asdict
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from cascgp.checks import check_count
from cascgp.gp import GPBank, GPFitConfig
from cascgp.io import atomic_savez, check_format_header, read_npz
from cascgp.models.cascade import CascadedGPModel, parse_name

__all__ = ["FORMAT_VERSION", "save_model", "load_model", "saved_config"]

#: Version of the saved-model ``.npz`` layout.
FORMAT_VERSION = 1
_KIND = "cascgp.CascadedGPModel"
_N_CHECK = 5  # stored check queries (save -> load verification)


def model_config(model: CascadedGPModel) -> dict[str, Any]:
    """The JSON config stored in a model file (everything but the banks and the check set)."""
    rbd_ref = None
    if model.rbd is not None:
        src = getattr(model.rbd, "source", None)
        arm = getattr(model.rbd, "armature", None)
        rbd_ref = {"source": None if src is None else str(src),
                   "nominal": bool(getattr(model.rbd, "meta", None)),
                   "armature": None if arm is None else np.asarray(arm, float).tolist(),
                   "type": type(model.rbd).__name__}
    from cascgp import __version__

    return {"cascgp_version": __version__, "name": model.name, "dof": model.dof, "df_delta": model.df_delta,
            "train_on_predicted": model.train_on_predicted, "gp_config": asdict(model.gp_config),
            "where": [list(w) for w in model.where], "n_banks": len(model.banks), "n_train": model.n_train,
            "rbd": rbd_ref}


def save_model(model: CascadedGPModel, path: str | os.PathLike, *,
               provenance: Mapping[str, Any] | None = None) -> Path:
    """Write the fitted model to ``path`` (``.npz``, atomically).

    Contents: format kind/version, config JSON (name, dof, df_delta, train_on_predicted,
    GP config, RBD reference, ``provenance``), every bank's ``state_dict`` (normalisation, hyperparameters,
    training inputs and targets), the rigid-body model of an SP model when it carries its URDF document (embedded
    with its SHA-256, armature, gravity, limits and sidecar metadata: see the module docstring), and check queries
    with their predictions (verified by :func:`load_model`). An online window is not saved: the file holds the
    fitted model.

    ``provenance`` (optional): what the model was trained on and how, as a JSON object (say the log's file name and
    SHA-256, the command line; ``cascgp fit`` records these), stored as JSON writes it (tuples become lists, inner
    keys strings) and returned by :func:`saved_config` under ``"provenance"``. ``TypeError`` naming ``provenance``
    if it is not a mapping with string keys that JSON can write (finite numbers, strings, booleans, ``None``, lists
    and such mappings).
    """
    if not model.fitted:
        raise RuntimeError(f"model {model.name!r}: not fitted; nothing to save")
    config = model_config(model)
    if provenance is not None:
        config["provenance"] = _json_provenance(provenance)
    arrays: dict[str, np.ndarray] = {
        "format_kind": np.array(_KIND), "format_version": np.array(FORMAT_VERSION),
        "config_json": np.array(json.dumps(config)),
    }
    for k, bank in enumerate(model.banks):
        for key, val in bank.state_dict().items():
            arrays[f"bank{k}/{key}"] = np.asarray(val)
    arrays.update(_embedded_rbd(model.rbd))
    # check queries: seeded random states in [-1, 1] and training states (check_set) with their predictions
    chk = check_set(model)
    arrays.update({f"check/{k}": v for k, v in chk.items()})
    return atomic_savez(path, arrays)


def _embedded_rbd(rbd: Any) -> dict[str, np.ndarray]:
    """The ``rbd/*`` entries of a model file (empty unless ``rbd`` carries its URDF document)."""
    text = getattr(rbd, "urdf_text", None)
    if not text:
        return {}
    opt = {k: getattr(rbd, k, None) for k in ("torque_limits", "velocity_limits")}
    return {
        "rbd/urdf": np.array(text), "rbd/sha256": np.array(hashlib.sha256(text.encode("utf-8")).hexdigest()),
        "rbd/armature": np.asarray(rbd.armature, float), "rbd/gravity": np.asarray(rbd.gravity, float),
        "rbd/meta_json": np.array(json.dumps(getattr(rbd, "meta", {}) or {})),
        "rbd/limits_json": np.array(json.dumps({k: None if v is None else np.asarray(v, float).tolist()
                                                for k, v in opt.items()})),
        **_embedded_joints(rbd),
    }


def _embedded_joints(rbd: Any) -> dict[str, np.ndarray]:
    """``rbd/joints_json`` (the model's joints and the URDF's locked ones) when the URDF has locked joints or mimic
    joints that move with the model's (not among its joints: rebuilt from the joints and the URDF)."""
    locked = getattr(rbd, "locked", None)
    if not locked and not getattr(rbd, "coupled", None):
        return {}
    return {"rbd/joints_json": np.array(json.dumps({"joints": list(rbd.joint_names), "locked": dict(locked or {})}))}


def _rbd_from_file(z: dict[str, np.ndarray], path: str | os.PathLike, dof: int) -> Any:
    """Rebuild the embedded rigid-body model; ``ValueError`` naming the file and field if it is damaged."""
    from cascgp.rbd import RigidBodyModel

    try:
        text = str(z["rbd/urdf"])
        if hashlib.sha256(text.encode("utf-8")).hexdigest() != str(z["rbd/sha256"]):
            raise ValueError("rbd/urdf: the embedded URDF does not match its SHA-256 (corrupt file)")
        limits = _json_object(z, "rbd/limits_json")
        meta = _json_object(z, "rbd/meta_json")
        for key in ("rbd/armature", "rbd/gravity"):
            if z[key].dtype.kind not in "fiu":
                raise ValueError(f"{key}: expected real numbers, got dtype {z[key].dtype}")
        sel = _joints_from_file(z)
    except KeyError as exc:
        raise ValueError(f"{path}: {exc.args[0]}: missing (the file embeds only part of its rigid-body model)") \
            from exc
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from exc
    try:
        rbd = RigidBodyModel.from_urdf_text(
            text, armature=z["rbd/armature"], gravity=z["rbd/gravity"],
            torque_limits=limits.get("torque_limits"), velocity_limits=limits.get("velocity_limits"),
            meta=meta, source=None, joints=sel.get("joints"), locked=sel.get("locked"))
    except (ValueError, TypeError, AttributeError) as exc:
        raise ValueError(f"{path}: rbd/*: the embedded rigid-body model: {exc}") from exc
    if rbd.dof != dof:
        raise ValueError(f"{path}: config_json.dof: {dof} joints, but the embedded rigid-body model (rbd/urdf) has "
                         f"{rbd.dof} ({', '.join(rbd.joint_names)})")
    return rbd


def _json_object(z: dict[str, np.ndarray], key: str) -> dict[str, Any]:
    """The JSON object stored under ``key``; ``ValueError`` naming ``key`` if it is not valid JSON or not an object."""
    try:
        value = json.loads(str(z[key]))
    except json.JSONDecodeError as exc:
        raise ValueError(f"{key}: not valid JSON ({exc})") from None
    if not isinstance(value, dict):
        raise ValueError(f"{key}: expected a JSON object, got {type(value).__name__}")
    return value


def _joints_from_file(z: dict[str, np.ndarray]) -> dict[str, Any]:
    """``rbd/joints_json``'s ``{"joints": [...], "locked": {...}}`` ({} when absent); ``ValueError`` naming it."""
    if "rbd/joints_json" not in z:
        return {}
    try:
        sel = json.loads(str(z["rbd/joints_json"]))
    except json.JSONDecodeError as exc:
        raise ValueError(f"rbd/joints_json: not valid JSON ({exc})") from None
    if not isinstance(sel, dict) or not isinstance(sel.get("joints"), list) or not isinstance(sel.get("locked"), dict):
        raise ValueError("rbd/joints_json: expected an object with a 'joints' list and a 'locked' object")
    return sel


def _rbd_from_recorded_path(cfg: dict[str, Any], path: str | os.PathLike, name: str, dof: int) -> Any:
    """Files without an embedded rigid-body model (written before it was embedded): the recorded URDF path."""
    from cascgp.rbd import RigidBodyModel, load_nominal, sidecar_path

    ref = cfg.get("rbd") or {}
    src = ref.get("source") if isinstance(ref, dict) else None
    if not src or not Path(src).is_file():
        raise ValueError(f"{path}: rbd: the semi-parametric model {name!r} needs its rigid-body model; pass "
                         f"load_model(path, rbd=...) (recorded URDF {src!r} not available)")
    if ref.get("nominal") and sidecar_path(src).is_file():
        return load_nominal(src, dof=dof)
    return RigidBodyModel.from_urdf(src, armature=ref.get("armature"), dof=dof)


def check_set(model: CascadedGPModel) -> dict[str, np.ndarray]:
    """Deterministic check queries and their predictions (stored by save, verified by load): ``_N_CHECK`` seeded
    random states in [-1, 1], then up to ``_N_CHECK`` of the model's training states (evenly spaced rows of its GP
    that sees every joint's state), where its GPs are informed: far from the data every prediction is the prior's,
    which would not show a changed hyperparameter or training row."""
    rng = np.random.default_rng(12345)
    N, m = model.dof, _N_CHECK
    q = rng.uniform(-1.0, 1.0, (m, N))
    qd = rng.uniform(-1.0, 1.0, (m, N))
    qdd = rng.uniform(-1.0, 1.0, (m, N))
    qh = np.stack([q - 0.1 * qd, q - 0.2 * qd], axis=1)
    S = _training_states(model)  # (k, N, 3)
    if model.feature_kind == "db":
        q, qd, qdd = (np.concatenate([a, S[:, :, c]]) for c, a in enumerate((q, qd, qdd)))
        qh = np.concatenate([qh, np.stack([q[m:] - 0.1 * qd[m:], q[m:] - 0.2 * qd[m:]], axis=1)])
    else:  # q(t), q(t - delta), q(t - 2 delta); qd and qdd (an SP model's rigid-body part) by differences
        dt = model.df_delta
        q, qh = np.concatenate([q, S[:, :, 0]]), np.concatenate([qh, S[:, :, 1:].transpose(0, 2, 1)])
        qd = np.concatenate([qd, (S[:, :, 0] - S[:, :, 1]) / dt])
        qdd = np.concatenate([qdd, (S[:, :, 0] - 2.0 * S[:, :, 1] + S[:, :, 2]) / dt**2])
    mean, var = model.predict(q, qd, qdd, qh if model.feature_kind == "df" else None)
    return {"q": q, "qd": qd, "qdd": qdd, "q_hist": qh, "mean": mean, "var": var}


def _training_states(model: CascadedGPModel) -> np.ndarray:
    """Up to ``_N_CHECK`` evenly spaced training states ``(k, N, 3)`` of ``model``: the inputs of a GP that sees
    every joint's state (each structure has one; its columns come joint by joint)."""
    j = next(j for j, (sj, tj) in enumerate(model.specs) if tj is None and len(sj) == model.dof)
    k, b = model.where[j]
    X = model.banks[k].training_data()[0][b]
    rows = np.unique(np.linspace(0, X.shape[0] - 1, _N_CHECK).round().astype(int))
    return X[rows].reshape(len(rows), model.dof, 3)


def saved_config(path: str | os.PathLike) -> dict[str, Any]:
    """The config JSON of a model file (:func:`model_config` at save time: ``cascgp_version``, which files before
    it was recorded lack, ``name``, ``dof``, ``gp_config``, ..., and ``provenance`` when the model was saved with
    one), read without rebuilding the model; ``ValueError`` naming the file if it is not a model file."""
    return _read_file(path)[1]


def _json_provenance(provenance: Any) -> dict[str, Any]:
    """``provenance`` as a JSON object (a copy, through JSON), or ``TypeError`` naming it."""
    if not isinstance(provenance, Mapping):
        raise TypeError(f"provenance: expected a mapping (a JSON object) or None, got {type(provenance).__name__}")
    try:  # json.dumps refuses non-string keys only when sort_keys; check them here for a clear message
        bad = [k for k in provenance if not isinstance(k, str)]
        if bad:
            raise TypeError(f"keys must be strings, got {bad[0]!r}")
        return dict(json.loads(json.dumps(provenance, allow_nan=False)))
    except (TypeError, ValueError) as exc:
        raise TypeError(f"provenance: expected values JSON can write (finite numbers, strings, booleans, None, lists "
                        f"and mappings): {exc}") from None


def _read_file(path: str | os.PathLike) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """A model file's arrays and its config JSON object, the format header checked; ``ValueError`` naming the file."""
    z = read_npz(path, "cascgp model")
    check_format_header(z, path, _KIND, FORMAT_VERSION)
    try:
        return z, _json_object(z, "config_json")
    except KeyError:
        raise ValueError(f"{path}: config_json: missing") from None
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None


def load_model(path: str | os.PathLike, rbd: Any = None) -> CascadedGPModel:
    """Read a model written by :meth:`CascadedGPModel.save`.

    Args:
        path: the model file (``.npz``).
        rbd: the rigid-body model of an SP model (an object with ``dof`` and ``inverse_dynamics``). Without it
            the model embedded in the file is rebuilt (see the module docstring); a file without one falls back
            to the URDF path recorded at save time (``rbd.source``). NP models ignore it, as :func:`make_model`
            does.

    After loading, the stored check predictions are recomputed; any difference (corrupt file, another RBD)
    raises ``ValueError``. Missing file: ``FileNotFoundError``; corrupt/truncated archive, missing fields or
    another format version: ``ValueError`` naming the file.
    """
    z, cfg = _read_file(path)
    try:
        gp_config = GPFitConfig.from_dict(cfg["gp_config"])
        name, dof = cfg["name"], check_count(cfg["dof"], "dof")
        where = [tuple(check_count(v, "where", 0) for v in w) for w in cfg["where"]]
        n_banks = check_count(cfg["n_banks"], "n_banks")
        df_delta, train_on_predicted = float(cfg["df_delta"]), cfg["train_on_predicted"]
        if not isinstance(train_on_predicted, bool):
            raise TypeError(f"train_on_predicted: expected true or false, got {train_on_predicted!r}")
        parse_name(name)
    except (KeyError, ValueError, TypeError) as exc:
        raise ValueError(f"{path}: config_json: missing or invalid ({type(exc).__name__}: {exc})") from exc
    if parse_name(name)[0] == "sp" and rbd is None:
        rbd = _rbd_from_file(z, path, dof) if "rbd/urdf" in z else _rbd_from_recorded_path(cfg, path, name, dof)
    try:
        model = CascadedGPModel(name, dof, rbd, gp_config=gp_config, df_delta=df_delta,
                                train_on_predicted=train_on_predicted)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"{path}: {exc}") from exc
    banks = []
    for k in range(n_banks):
        pre = f"bank{k}/"
        sd = {key[len(pre):]: val for key, val in z.items() if key.startswith(pre)}
        if not sd:
            raise ValueError(f"{path}: {pre}*: missing GP bank {k}")
        try:
            banks.append(GPBank.from_state_dict(sd))
        except (ValueError, TypeError, RuntimeError) as exc:
            raise ValueError(f"{path}: bank {k}: {exc}") from exc
    if not banks:
        raise ValueError(f"{path}: config_json.n_banks: expected at least one GP bank, got {n_banks}")
    try:
        n_train = cfg["n_train"] if "n_train" in cfg else int(banks[0].n_train)
        model.adopt_banks(banks, where, n_train)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"{path}: {exc}") from exc
    need = [f"check/{k}" for k in ("q", "qd", "qdd", "q_hist", "mean", "var")]
    if any(k not in z for k in need):
        raise ValueError(f"{path}: missing check fields {[k for k in need if k not in z]}")
    try:
        mean, var = model.predict(z["check/q"], z["check/qd"], z["check/qdd"],
                                  z["check/q_hist"] if model.feature_kind == "df" else None)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"{path}: check queries: {exc}") from exc
    ref_m, ref_v = z["check/mean"], z["check/var"]
    for key, ref in (("check/mean", ref_m), ("check/var", ref_v)):
        if ref.shape != mean.shape or ref.dtype.kind != "f":
            raise ValueError(f"{path}: {key}: expected float64 of shape {mean.shape}, got {ref.dtype} {ref.shape}")
    # 1e-6 of the torque (at least 1e-6 N m): round-off of another thread count or CPU's BLAS kernels used up to a
    # quarter of 1e-8 (n = 600; a bound of 1e-8 could refuse a good file on another machine), while another
    # rigid-body model or a damaged hyperparameter moves the predictions by far more
    tol_m = 1e-6 * (1.0 + np.abs(ref_m))
    # a variance near the data is the prior's minus nearly all of it (s_f^2 - |L^-1 k|^2): its round-off is relative
    # to the prior variance, up to cond(K) x 1e-16 of it (cond(K) <= 1 + n snr_max; the README's tour rerun on its
    # own buffer, every row twice, moved one training row's variance by 5.7e-5 of itself, 5e-8 of its prior)
    prior = np.array([p.signal_var * p.y_std**2 for p in model.posteriors()])
    tol_v = 1e-6 * (np.abs(ref_v) + prior) + 1e-10
    if not (np.abs(mean - ref_m) <= tol_m).all() or not (np.abs(var - ref_v) <= tol_v).all():
        raise ValueError(f"{path}: the loaded model does not reproduce its stored check predictions "
                         "(corrupt file, or a different rigid-body model than at save time)")
    return model
