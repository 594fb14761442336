"""The one episode runner: run a controller in an episode and record what the robot measured.

:func:`run_episode` runs any :class:`~cascgp.controller.Controller` (the learned-feedforward
:class:`~cascgp.controller.FeedforwardController`, or e.g. ``jaco_env.oracle``'s oracle and PD
controllers). This is the one piece of glue between the learning library and a simulated (or
real) robot. It does not import any environment package: it works with any Gymnasium
environment whose observation starts with the measured ``[q, qd, tau, t]`` of an
N-DOF arm and whose unwrapped environment exposes ``task.reference(t)`` (e.g.
``JacoPour-v0``; ``jaco_env.split_obs`` is that layout for the Jaco). The recorded data
contain measurements only, as on a real robot:

==================  ===========================================================
recorded            source
==================  ===========================================================
``t, q, qd``        the observation at each control tick (noisy sensors)
``tau``             the measured joint torque during the period that started at that tick
                    (reported by the next observation)
``qdd``             central differences of the measured ``qd``
                    (:meth:`cascgp.data.DynamicsData.from_measurements`)
==================  ===========================================================
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from cascgp.controller import Controller
from cascgp.data import DynamicsData
from cascgp.derivatives import as_savgol


@dataclass
class EpisodeResult:
    """What one episode measured and how well it went.

    Attributes:
        data: the measured record at the control rate (one segment; one more after each run of left-out
            ticks).
        tracking_rmse: RMSE of the true joint-position error over the episode (rad), from
            ``info["tracking_error"]`` when the environment reports it, else from the measured q.
        joint_rmse: per-joint RMSE of ``q_d - q_measured`` (rad), shape (N,).
        in_jar: fraction of marbles in the jar at the end (NaN when the env has no marbles).
        spilled: fraction of marbles spilled at the end (NaN when the env has no marbles).
        episode_return: sum of rewards.
        steps: control ticks run.
        unstable: the environment flagged an unstable simulation.
        n_fallbacks: ticks on which the model's output was not finite and the controller fell back.
        info: the final ``info`` dict.
    """

    data: DynamicsData
    tracking_rmse: float
    joint_rmse: np.ndarray
    in_jar: float
    spilled: float
    episode_return: float
    steps: int
    unstable: bool
    n_fallbacks: int
    info: dict[str, Any] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        """JSON-serialisable metrics (no arrays but ``joint_rmse`` as a list)."""
        return {
            "tracking_rmse": self.tracking_rmse,
            "joint_rmse": self.joint_rmse.tolist(),
            "in_jar": self.in_jar,
            "spilled": self.spilled,
            "return": self.episode_return,
            "steps": self.steps,
            "unstable": self.unstable,
            "n_fallbacks": self.n_fallbacks,
            "payload_mass": self.info.get("payload_mass"),
        }


def _split_obs(obs: np.ndarray, dof: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """``(q, qd, tau, t)`` of an observation that starts with ``[q, qd, tau, t]`` of ``dof`` joints."""
    obs = np.asarray(obs, dtype=float)
    if obs.ndim != 1 or obs.shape[0] < 3 * dof + 1:
        raise ValueError(f"observation must be a flat vector starting with [q, qd, tau, t] of {dof} joints, "
                         f"got shape {obs.shape}")
    return obs[:dof], obs[dof:2 * dof], obs[2 * dof:3 * dof], float(obs[3 * dof])


def _long_runs(ok: np.ndarray, min_len: int) -> np.ndarray:
    """``ok`` with the runs of True shorter than ``min_len`` set to False."""
    out = ok.copy()
    edges = np.flatnonzero(np.diff(np.r_[0, ok.astype(np.int8), 0]))  # starts and ends of the runs of True
    for lo, hi in zip(edges[::2], edges[1::2]):
        if hi - lo < min_len:
            out[lo:hi] = False
    return out


def run_episode(
    env: Any,
    controller: Controller,
    *,
    seed: int | None = None,
    options: dict[str, Any] | None = None,
    smoothing: int | None = None,
    meta: dict[str, Any] | None = None,
    callback: Callable[[Any, dict[str, Any]], None] | None = None,
) -> EpisodeResult:
    """Run ``controller`` on ``env`` from ``reset(seed, options)`` until the episode ends.

    Args:
        env: a Gymnasium environment (see the module docstring for what it must offer).
        controller: the controller; ``controller.start(env.unwrapped, info)`` is called right after
            the reset, then ``controller(t, q, qd, task.reference)`` every tick (its output is sent
            to ``env.step`` as float32).
        seed, options: passed to ``env.reset`` (e.g. ``options={"task": "front", "payload_mass": 1.0}``).
        smoothing: optional smoothing window for the numerical differentiation of ``qd``
            (:meth:`~cascgp.data.DynamicsData.from_measurements`).
        meta: extra metadata stored in the record (a JSON-serialisable dict).
        callback: optional ``callback(env.unwrapped, info)`` called after every step (e.g. to log
            extra metrics from the simulator's state).

    ``env``, ``controller``, ``smoothing``, ``meta`` and ``callback`` are checked before the reset (``TypeError`` /
    ``ValueError`` naming them: the env's observation space must hold ``[q, qd, tau, t]`` of the controller's
    joints, its actions one per joint). A tick whose
    measured ``q``, ``qd`` or torque is not finite (a sensor fault; the controller copes with it) is left out
    of the record (so is one with a non-finite ``t``, which a :class:`~cascgp.controller.FeedforwardController`
    refuses, naming ``t``), which starts a new segment after it, and so is a run of good ticks between faults too
    short to differentiate (under 3 ticks, or the ``smoothing`` window); ``data.meta["n_dropped_ticks"]`` counts
    them. The errors are computed on the recorded ticks.
    """
    if not all(hasattr(env, a) for a in ("reset", "step", "unwrapped")):
        raise TypeError(f"env: expected a Gymnasium environment, got {type(env).__name__}")
    if not (callable(controller) and all(hasattr(controller, a) for a in ("dof", "name", "start"))):
        raise TypeError("controller: expected a controller (dof, name, start(env, info), controller(t, q, qd, "
                        f"reference); cascgp.controller.Controller), got {type(controller).__name__}")
    if callback is not None and not callable(callback):
        raise TypeError(f"callback: expected a callable or None, got {type(callback).__name__}")
    dof = controller.dof
    shape = getattr(getattr(env, "observation_space", None), "shape", None)
    actions = getattr(getattr(env, "action_space", None), "shape", None)
    if (shape is not None and (len(shape) != 1 or shape[0] < 3 * dof + 1)) or (actions is not None
                                                                                and tuple(actions) != (dof,)):
        raise ValueError(f"controller: {dof} joints, but the env's actions have shape {actions} and its observations "
                         f"{shape} (one torque per joint, and [q, qd, tau, t] of the joints first)")
    savgol = as_savgol(smoothing)  # checked before the episode runs
    if meta is not None:
        if not isinstance(meta, dict):
            raise TypeError(f"meta: expected a dict, got {type(meta).__name__}")
        try:
            json.dumps(meta)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"meta: expected a JSON-serialisable dict ({exc})") from None
    obs, info = env.reset(seed=seed, options=options)
    unwrapped = env.unwrapped
    task = unwrapped.task
    reference = task.reference
    controller.start(unwrapped, info)
    observe = getattr(controller, "observe", None)  # controllers that learn from what the robot measures
    ts, qs, qds, taus, errors = [], [], [], [], []
    total, steps, unstable = 0.0, 0, False
    while True:
        q, qd, _, t = _split_obs(obs, dof)
        action = controller(t, q, qd, reference)
        obs, reward, terminated, truncated, info = env.step(np.asarray(action, dtype=np.float32))
        ts.append(t)
        qs.append(q)
        qds.append(qd)
        taus.append(_split_obs(obs, dof)[2])
        if observe is not None:
            observe(*_split_obs(obs, dof))
        if "tracking_error" in info:
            errors.append(float(info["tracking_error"]))
        total += float(reward)
        steps += 1
        unstable = unstable or bool(info.get("unstable", False))
        if callback is not None:
            callback(unwrapped, info)
        if terminated or truncated:
            break
    t_arr, q_arr, qd_arr, tau_arr = np.asarray(ts), np.asarray(qs), np.asarray(qds), np.asarray(taus)
    ok = np.isfinite(t_arr) & np.isfinite(q_arr).all(1) & np.isfinite(qd_arr).all(1) & np.isfinite(tau_arr).all(1)
    if not ok.all():  # runs of good ticks between faults too short to differentiate are left out too
        min_run = 3 if savgol is None else max(3, savgol.window)
        ok = _long_runs(ok, min_run)
        if not ok.any():
            raise ValueError(f"run_episode: no {min_run} consecutive ticks of the {steps} had finite measurements "
                             "(t, q, qd, torque); nothing to record")
    record_meta = {"source": "episode", "task": getattr(task, "name", None),
                   "controller": controller.name, "payload_mass": info.get("payload_mass")}
    if not ok.all():
        record_meta["n_dropped_ticks"] = int((~ok).sum())
    record_meta.update(meta or {})
    segment = np.cumsum(~ok)[ok]  # a new segment after every left-out tick
    t_arr, q_arr = t_arr[ok], q_arr[ok]
    data = DynamicsData.from_measurements(t_arr, q_arr, qd_arr[ok], tau_arr[ok], smoothing=savgol,
                                          meta=record_meta, segment=segment)
    err_meas = np.array([reference(t)[0] for t in t_arr.tolist()]).reshape(len(t_arr), dof) - q_arr
    joint_rmse = np.sqrt(np.mean(err_meas**2, axis=0))
    tracking = float(np.sqrt(np.mean(np.square(errors)))) if errors else float(np.sqrt(np.mean(err_meas**2) * dof))
    n_marbles = info.get("n_marbles", 0) or 0
    in_jar = info["marbles_in_jar"] / n_marbles if n_marbles else float("nan")
    spilled = info["marbles_spilled"] / n_marbles if n_marbles else float("nan")
    return EpisodeResult(
        data=data, tracking_rmse=tracking, joint_rmse=joint_rmse, in_jar=float(in_jar), spilled=float(spilled),
        episode_return=total, steps=steps, unstable=unstable, n_fallbacks=int(getattr(controller, "n_fallbacks", 0)),
        info=dict(info),
    )
