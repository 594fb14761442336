"""The paper's retrain loop: attempt a task, add the measured episode to a buffer, refit the model (warm-started).

This module owns the loop of the task-transfer experiment and the choice of feedforward for each named
controller; it knows no particular robot or environment. The caller passes in the environment (or a
factory), the attempt plan (which task, in which order), the nominal rigid-body model, the feedback
gains and torque limits (:class:`Feedback`) and, optionally, a model factory and extra reset options
(for the Jaco 2 pouring env, :mod:`cascgp_experiments.transfer` does).

Controllers: ``"pd"`` (feedback only), ``"rbd"`` (nominal rigid-body feedforward) and any model name
of :mod:`cascgp.models`, optionally suffixed with a gate (the feedforward falls back toward the RBD:
:class:`cascgp.controller.FeedforwardController` ``gate=...``): ``-igated`` (``"innovation"``, what ``gate=True`` picks:
where the model has predicted this episode's measured torques worse than the RBD), ``-gated`` (``"wiener"``),
``-fgated`` (``"floor"``) or ``-vgated`` (``"variance"``; the last three where the model is unsure), and
``-online`` (new samples enter the model during each attempt, window :data:`ONLINE_WINDOW`, hyperparameters held
until the next refit), e.g. ``"sp-inward-igated-online"``. Before a learning controller has any data, an SP
model is its RBD mean (RBD feedforward) and an NP model is zero (PD). After every ``"train"`` attempt of a learning
controller, the measured episode joins a :class:`cascgp.buffer.DataBuffer` and a new model is fitted on
everything seen so far (subsampled to ``rate_hz``, at most ``cap`` rows), warm-started from the
previous model's hyperparameters.

Seeds: attempt ``i`` resets the env with seed ``seed * 1000 + i``; the refit after it uses the GP seed
``seed + i`` (:class:`RetrainConfig`; a model factory may change it).

Extension: :class:`RunHooks` objects see every attempt (its context, the model it uses, its record) without
changing the loop: progress bars, video recorders, extra evaluations on the same model.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from cascgp.buffer import DataBuffer
from cascgp.checks import check_count
from cascgp.controller import FeedforwardController
from cascgp.episodes import EpisodeResult, run_episode
from cascgp.gp import GPFitConfig
from cascgp.models import make_model
# defined in a module without torch (command lines check them before importing the library); exported here too
from cascgp.settings import PLAIN_CONTROLLERS, RetrainConfig, check_controller, parse_controller

__all__ = ["PLAIN_CONTROLLERS", "ONLINE_WINDOW", "Attempt", "Feedback", "RetrainConfig", "ControllerRun",
           "AttemptContext", "RunHooks", "check_controller", "parse_controller", "make_controller", "attempt_plan",
           "default_model_factory", "run_controller", "run_controllers"]

#: Online samples a ``-online`` controller keeps per joint during an attempt (15 s at 10 Hz).
ONLINE_WINDOW = 150
#: One attempt: (task, attempt index within the task, phase). Only ``"train"`` attempts feed the buffer.
Attempt = tuple[str, int, str]
#: The phases of an attempt: a ``"train"`` attempt's data enter the buffer and a refit; a ``"revisit"`` (the first task
#: again, after the others) or an ``"eval"`` attempt is scored only.
PHASES = ("train", "revisit", "eval")
#: ``factory(name, rbd, gp_config)`` -> an unfitted model with ``fit(data, init=previous)``.
ModelFactory = Callable[[str, Any, GPFitConfig], Any]


@dataclass(frozen=True)
class Feedback:
    """The robot-specific parts of every controller (each an (N,) array, one entry per joint).

    Attributes:
        kp: proportional gains (N m/rad).
        kd: derivative gains (N m s/rad).
        torque_limits: symmetric torque limits (N m): every command is clipped to ``[-limit, limit]``.
    """

    kp: np.ndarray
    kd: np.ndarray
    torque_limits: np.ndarray


@dataclass(frozen=True)
class AttemptContext:
    """What a hook knows of one attempt: the controller, the attempt's index in the plan, the attempt itself, the
    env seed of its episode and the env's reset options (the task included)."""

    name: str
    index: int
    attempt: Attempt
    seed: int
    options: dict[str, Any]

    @property
    def meta(self) -> dict[str, Any]:
        """The episode's metadata (:func:`cascgp.episodes.run_episode`)."""
        return {"attempt": self.index, "phase": self.attempt[2]}


class RunHooks:
    """Callbacks of :func:`run_controller`; subclass and override the ones you need (each does nothing here).

    Per attempt the order is: :meth:`episode_callback`, :meth:`before_episode`, the episode,
    :meth:`after_episode`, the refit (training attempts of a learning controller), :meth:`after_attempt`.
    A hook observes: it must leave the model and the run's data as it found them (it may add keys to the record).

    Example:
        >>> class Print(RunHooks):
        ...     def after_attempt(self, ctx, record):
        ...         print(ctx.name, record["task"], round(record["tracking_rmse"], 3))
        >>> # run_controller("sp-inward", env, plan, rbd, feedback, hooks=[Print()])
    """

    def episode_callback(self, ctx: AttemptContext) -> Any | None:
        """A per-step callback for this attempt's episode (:func:`cascgp.episodes.run_episode`), e.g. a video
        recorder, or None."""
        return None

    def before_episode(self, ctx: AttemptContext, model: Any | None) -> None:
        """Called before the episode with the learned model it uses (None before the first fit), as fitted: an
        online controller's window of an earlier attempt is closed."""

    def after_episode(self, ctx: AttemptContext, model: Any | None, record: dict[str, Any]) -> None:
        """Called after the episode, before any refit, with the same model and the attempt's record (an online
        controller's samples of this episode still in the model's window, which is closed after this call)."""

    def after_attempt(self, ctx: AttemptContext, record: dict[str, Any]) -> None:
        """Called when the attempt is complete (after the refit, whose time is ``record["fit_seconds"]``)."""


@dataclass
class ControllerRun:
    """One controller's sequence of attempts (one record per attempt) and, for a learning controller, ``model``:
    the model of the last refit, fitted on the training set of every training attempt's data (``RetrainConfig``'s
    rate and cap; ``None`` when nothing was fitted, and in the runs of
    :func:`cascgp_experiments.transfer.run_transfer`, whose records come back as JSON), e.g. to save."""

    name: str
    attempts: list[dict[str, Any]] = field(default_factory=list)
    model: Any | None = None


def make_controller(name: str, rbd: Any, model: Any | None, feedback: Feedback) -> FeedforwardController:
    """The controller for ``name`` given the current (possibly unfitted/None) learned model. Every controller but
    ``"pd"`` needs ``rbd`` (the RBD feedforward, an SP model's mean, the fallback): ``ValueError`` without it."""
    base, gate, online = parse_controller(name)
    if base != "pd" and rbd is None:
        raise ValueError(f"rbd: controller {name!r} needs the nominal rigid-body model, got None")
    if model is not None and not hasattr(model, "fitted"):
        raise TypeError(f"model: expected None or a cascgp model, got {type(model).__name__}")
    if base == "pd":
        feedforward = None
    elif base == "rbd":
        feedforward = rbd
    elif model is not None and model.fitted:
        return FeedforwardController(model, feedback.kp, feedback.kd, feedback.torque_limits, fallback=rbd,
                                     gate=gate or False, online=ONLINE_WINDOW if online else None)
    else:  # no data yet: an SP model's mean is the RBD model, an NP model's mean is zero
        feedforward = rbd if base.startswith("sp") else None
    return FeedforwardController(feedforward, feedback.kp, feedback.kd, feedback.torque_limits, fallback=rbd)


def attempt_plan(tasks: Sequence[str], attempts: int, revisit: bool = True) -> list[Attempt]:
    """``attempts`` training attempts of every task in order, then (``revisit``) one more of the first task.
    ``ValueError`` naming ``tasks`` (not a list of task names) or ``attempts`` (not an integer >= 1)."""
    if isinstance(tasks, str) or not isinstance(tasks, Sequence) or not all(isinstance(t, str) for t in tasks):
        raise ValueError(f"tasks: expected a list of task names, got {tasks!r}")
    attempts = check_count(attempts, "attempts")
    plan = [(task, k, "train") for task in tasks for k in range(attempts)]
    if revisit and tasks:
        plan.append((tasks[0], attempts, "revisit"))
    return plan


def default_model_factory(name: str, rbd: Any, gp_config: GPFitConfig) -> Any:
    """:func:`cascgp.models.make_model` with the RBD mean for SP models."""
    return make_model(name, rbd.dof, rbd=rbd if name.startswith("sp") else None, gp_config=gp_config)


def run_controller(name: str, env: Any, plan: Iterable[Attempt], rbd: Any, feedback: Feedback,
                   config: RetrainConfig = RetrainConfig(), *, reset_options: dict[str, Any] | None = None,
                   model_factory: ModelFactory = default_model_factory, buffer_dir: str | Path | None = None,
                   hooks: Sequence[RunHooks] = ()) -> ControllerRun:
    """Run every attempt of ``plan`` with one controller; a learning controller is refitted after every
    ``"train"`` attempt on all data so far.

    Args:
        name: controller name (:func:`check_controller`).
        env: a Gymnasium env that :func:`cascgp.episodes.run_episode` can run; reset with
            ``options={"task": task, **reset_options}``.
        plan: the attempts (:func:`attempt_plan` or any list of :data:`Attempt`).
        rbd: the nominal rigid-body model (RBD feedforward, SP models' mean, fallback).
        feedback: gains and torque limits.
        config: seeds and refit settings.
        reset_options: env reset options besides the task (e.g. the payload).
        model_factory: makes the unfitted model of each refit (:func:`default_model_factory`). Another model
            needs ``fit(data, init=previous)`` returning itself, ``fitted``, ``n_train``, ``dof`` and what the
            controller calls (:class:`cascgp.controller.FeedforwardController`): ``predict_one(q, qd, qdd,
            q_hist=None)``; with a variance gate also ``predict_one_var``, ``signal_var`` and
            ``prepare_variance()``; with ``-online``, ``start_online``, ``add_sample`` and ``stop_online``.
            A hook or model that raises ends the run with its error: the records of the attempts so far are not
            returned, and the episodes stay in ``buffer_dir``.
        buffer_dir: folder that persists the buffer (must be empty); ``None``: in memory.
        hooks: :class:`RunHooks` called in order around every attempt (progress, video, extra evaluations).

    Returns:
        The run; each record holds ``attempt``, ``task``, ``task_attempt``, ``phase``, ``n_train`` (rows the
        controller's model was fitted on), the episode's :meth:`EpisodeResult.summary`, ``online_samples`` for an
        online controller and, after a refit, ``fit_seconds``; hooks may add keys. ``run.model`` is the model of
        the last refit (the one after the last ``"train"`` attempt, on the training set of all the run's data).
    """
    base, _, _ = parse_controller(name)
    if not isinstance(config, RetrainConfig):
        raise TypeError(f"config: expected a RetrainConfig, got {type(config).__name__}")
    plan = _checked_plan(plan)
    if reset_options is not None and "task" in reset_options:
        raise ValueError("reset_options: the plan sets each attempt's task; leave 'task' out")
    hooks = tuple(hooks)
    for h in hooks:
        if not isinstance(h, RunHooks):
            raise ValueError(f"hooks: expected RunHooks objects, got {type(h).__name__}")
    learns = base not in PLAIN_CONTROLLERS
    buffer = DataBuffer(buffer_dir) if learns else None
    if buffer is not None and len(buffer):
        raise ValueError(f"buffer_dir: {buffer_dir} already holds data; use an empty folder")
    options = dict(reset_options or {})
    model = None
    run = ControllerRun(name)
    for i, (task, k, phase) in enumerate(plan):
        ctx = AttemptContext(name, i, (task, k, phase), seed=config.seed * 1000 + i,
                             options={"task": task, **options})
        callbacks = [c for c in (h.episode_callback(ctx) for h in hooks) if c is not None]
        for h in hooks:
            h.before_episode(ctx, model)
        controller = make_controller(name, rbd, model, feedback)
        result: EpisodeResult = run_episode(env, controller, seed=ctx.seed, options=ctx.options, meta=ctx.meta,
                                            callback=_one_callback(callbacks))
        record = {"attempt": i, "task": task, "task_attempt": k, "phase": phase,
                  "n_train": 0 if model is None else int(model.n_train), **result.summary()}
        if controller.online:
            record["online_samples"] = controller.n_online_samples
        for h in hooks:
            h.after_episode(ctx, model, record)
        stop = getattr(model, "stop_online", None) if controller.online else None
        if stop is not None:  # the next attempt, and its hooks, start from the fitted model
            stop()
        if buffer is not None and phase == "train":  # buffer: a learning controller
            buffer.append(result.data)
            t0 = time.perf_counter()
            new = model_factory(base, rbd, GPFitConfig(n_restarts=config.restarts, seed=config.seed + i))
            model = new.fit(buffer.training_set(config.rate_hz, config.cap), init=model)
            record["fit_seconds"] = time.perf_counter() - t0
        run.attempts.append(record)
        for h in hooks:
            h.after_attempt(ctx, record)
    run.model = model
    return run


def _checked_plan(plan: Iterable[Attempt]) -> list[Attempt]:
    """``plan`` as a list of ``(task, task_attempt, phase)``, checked before anything runs or is written."""
    out = []
    for i, entry in enumerate(plan):
        if not (isinstance(entry, (tuple, list)) and len(entry) == 3 and isinstance(entry[0], str)
                and isinstance(entry[1], (int, np.integer)) and not isinstance(entry[1], bool)
                and entry[2] in PHASES):
            raise ValueError(f"plan[{i}]: expected (task name, attempt number, phase in {PHASES}), got {entry!r}")
        out.append((entry[0], int(entry[1]), entry[2]))
    return out


def _one_callback(callbacks: list[Any]) -> Any | None:
    """The episode callbacks of several hooks as one (None when there are none)."""
    if len(callbacks) <= 1:
        return callbacks[0] if callbacks else None

    def both(*args: Any, **kwargs: Any) -> None:
        for c in callbacks:
            c(*args, **kwargs)
    return both


def run_controllers(names: Sequence[str], make_env: Callable[[], Any], plan: Sequence[Attempt], rbd: Any,
                    feedback: Feedback, config: RetrainConfig = RetrainConfig(), *,
                    reset_options: dict[str, Any] | None = None, model_factory: ModelFactory = default_model_factory,
                    buffer_root: str | Path | None = None, hooks: Sequence[RunHooks] = ()) -> list[ControllerRun]:
    """:func:`run_controller` for each of ``names`` in turn on one env from ``make_env()`` (closed at the end).

    Args:
        names: distinct controller names (:func:`check_controller`), all checked before the env is made, and so
            are their buffer folders.
        make_env: makes the env that every controller runs on (closed at the end, also after an error).
        plan, rbd, feedback, config, reset_options, model_factory, hooks: as for :func:`run_controller`.
        buffer_root: folder under which controller ``name``'s buffer is kept, as ``buffer_root / name`` (each
            must be empty); ``None``: in memory.

    Returns:
        One :class:`ControllerRun` per name, in the order of ``names``.
    """
    for name in names:
        check_controller(name)
    if len(set(names)) != len(names):
        raise ValueError(f"names: expected distinct controllers (each keeps its own buffer), got {list(names)}")
    if buffer_root is not None:  # every folder now, not after the controllers before it have run
        for name in names:
            if parse_controller(name)[0] not in PLAIN_CONTROLLERS and len(DataBuffer(Path(buffer_root) / name)):
                raise ValueError(f"buffer_root: {Path(buffer_root) / name} already holds data; use an empty folder")
    env = make_env()
    try:
        return [run_controller(name, env, plan, rbd, feedback, config, reset_options=reset_options,
                               model_factory=model_factory,
                               buffer_dir=None if buffer_root is None else Path(buffer_root) / name,
                               hooks=hooks)
                for name in names]
    finally:
        env.close()
