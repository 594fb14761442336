"""Retrain-loop hooks (:class:`cascgp.learning.RunHooks`) of the studies."""

from __future__ import annotations

from typing import Any, Callable

from cascgp.learning import AttemptContext, RunHooks


class BeforeEachAttempt(RunHooks):
    """``record["before"] = measure(ctx, model)`` (when not None), measured before the episode on the model the
    attempt uses (None before the first fit). ``measure`` must not change the model."""

    def __init__(self, measure: Callable[[AttemptContext, Any], dict[str, Any] | None]) -> None:
        self.measure = measure
        self._pending: dict[str, Any] | None = None

    def before_episode(self, ctx: AttemptContext, model: Any | None) -> None:
        self._pending = self.measure(ctx, model)

    def after_episode(self, ctx: AttemptContext, model: Any | None, record: dict[str, Any]) -> None:
        if self._pending is not None:
            record["before"] = self._pending
        self._pending = None


class Progress(RunHooks):
    """One progress step per attempt (:func:`cascgp_experiments.execution.report_progress`) labelled ``label``."""

    def __init__(self, label: str) -> None:
        self.label = label

    def after_attempt(self, ctx: AttemptContext, record: dict[str, Any]) -> None:
        from cascgp_experiments.execution import report_progress

        report_progress(1, f"{self.label} {record['task']}#{record['task_attempt']} "
                           f"rmse={record['tracking_rmse']:.3f}")
