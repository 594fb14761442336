"""cascgp: cascaded Gaussian processes for robot inverse dynamics (N-DOF, numpy + torch).

Public names are imported lazily (so ``import cascgp.data`` does not import torch):

==================  =====================  =================================================
name                module                 what
==================  =====================  =================================================
DynamicsData        cascgp.data            samples q, qd, qdd, tau, t, segment, meta
SavGol              cascgp.derivatives     Savitzky-Golay derivative (centred or causal)
state_features      cascgp.features        db / df per-joint states
input_spec          cascgp.features        inputs of joint i's GP (standard/inward/outward)
build_inputs        cascgp.features        GP input matrices of every joint
load_ias            cascgp.sarcos          IAS SARCOS file -> (train, test)
load_gpml           cascgp.sarcos          GPML SARCOS file -> DynamicsData
nrmse, rmse         cascgp.metrics         per-joint errors
MODEL_NAMES         cascgp.models          the twelve model variants
make_model          cascgp.models          build a model by name
CascadedGPModel     cascgp.models          the model class (fit, predict, predict_one, save)
load_model          cascgp.models          read a saved model
GPBank              cascgp.gp              batched exact GPs
GPFitConfig         cascgp.gp              GP fit options
audit_bank          cascgp.fit_audit       a fit's NLL against cold starts run to convergence
audit_model         cascgp.fit_audit       the same for each GP of a fitted model
RigidBodyModel      cascgp.rbd             Pinocchio RNEA wrapper
load_nominal        cascgp.rbd             RBD model from a URDF (+ its sidecar JSON, if any)
read_log            cascgp.logs            CSV / .npz log -> DynamicsData (the CSV format's reference)
write_log           cascgp.logs            DynamicsData -> CSV log (atomic)
FeedforwardController cascgp.controller    tau = f(q_d, qd_d, qdd_d) + Kp e + Kd e_dot (eq. 2)
DataBuffer          cascgp.buffer          episodes persisted across tasks
run_episode         cascgp.episodes        run a controller in a Gymnasium env, record data
==================  =====================  =================================================
"""

from __future__ import annotations

import importlib
from typing import Any

#: Version of the ``cascgp-jaco`` distribution (``cascgp``, ``jaco_env`` and the experiments share it).
__version__ = "0.2.0"

_EXPORTS = {
    "DynamicsData": "cascgp.data",
    "SavGol": "cascgp.derivatives",
    "state_features": "cascgp.features",
    "input_spec": "cascgp.features",
    "build_inputs": "cascgp.features",
    "load_ias": "cascgp.sarcos",
    "load_gpml": "cascgp.sarcos",
    "nrmse": "cascgp.metrics",
    "rmse": "cascgp.metrics",
    "MODEL_NAMES": "cascgp.models",
    "make_model": "cascgp.models",
    "CascadedGPModel": "cascgp.models",
    "load_model": "cascgp.models",
    "GPBank": "cascgp.gp",
    "GPFitConfig": "cascgp.gp",
    "audit_bank": "cascgp.fit_audit",
    "audit_model": "cascgp.fit_audit",
    "RigidBodyModel": "cascgp.rbd",
    "load_nominal": "cascgp.rbd",
    "read_log": "cascgp.logs",
    "write_log": "cascgp.logs",
    "FeedforwardController": "cascgp.controller",
    "DataBuffer": "cascgp.buffer",
    "run_episode": "cascgp.episodes",
}

__all__ = sorted(_EXPORTS)  # noqa: PLE0605 - sorted() returns a list


def __getattr__(name: str) -> Any:
    mod = _EXPORTS.get(name)
    if mod is None:
        raise AttributeError(f"module 'cascgp' has no attribute {name!r}")
    value = getattr(importlib.import_module(mod), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
