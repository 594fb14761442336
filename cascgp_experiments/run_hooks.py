"""Hooks of the retrain loop (:class:`cascgp.learning.RunHooks`) that the experiments use.

- :class:`PairedEpisodes`: after every attempt, other controllers run one episode each *on the learner's model*
  (same seed, same task, nothing added to the data), e.g. the gated feedforward beside the ungated one: the
  gate's own effect, free of the differences in data and fits that separate two independent learners.
- :func:`seed_offset_factory`: a model factory whose fits use other random starts (GP seed + offset).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any, Sequence

from cascgp.episodes import run_episode
from cascgp.gp import GPFitConfig
from cascgp.learning import (PLAIN_CONTROLLERS, AttemptContext, Feedback, ModelFactory, RunHooks,
                             default_model_factory, make_controller, parse_controller)

__all__ = ["PairedEpisodes", "seed_offset_factory"]


class PairedEpisodes(RunHooks):
    """Runs ``names`` on the learner's model after each of its episodes; ``record["paired"][p]`` is controller
    ``p``'s episode summary.

    Each of ``names`` must be ``learner``'s model with other gate/online suffixes (``ValueError`` otherwise). Each
    runs one episode with the attempt's seed and reset options on ``env``, adds nothing to the buffer, and leaves
    the model as it found it (an online window it opens is closed).
    """

    def __init__(self, learner: str, names: Sequence[str], env: Any, rbd: Any, feedback: Feedback) -> None:
        base = parse_controller(learner)[0]
        for p in names:
            if parse_controller(p)[0] != base or base in PLAIN_CONTROLLERS:
                raise ValueError(f"paired: {p!r} is not a variant of {learner!r}'s model (expected {base!r} with "
                                 "other '-gated'/'-fgated'/'-vgated'/'-igated'/'-online' suffixes)")
        self.names, self.env, self.rbd, self.feedback = tuple(names), env, rbd, feedback

    def after_episode(self, ctx: AttemptContext, model: Any | None, record: dict[str, Any]) -> None:
        if not self.names:
            return
        out = {}
        for p in self.names:  # each controller's start() opens its own window or closes one left open
            controller = make_controller(p, self.rbd, model, self.feedback)
            out[p] = run_episode(self.env, controller, seed=ctx.seed, options=ctx.options, meta=ctx.meta).summary()
        if model is not None and hasattr(model, "stop_online"):
            model.stop_online()  # leave the model as it was found
        record["paired"] = out


def seed_offset_factory(offset: int, factory: ModelFactory = default_model_factory) -> ModelFactory:
    """``factory`` with ``offset`` added to the GP seed of every fit: only the fits' random starts change (e.g. to
    measure how far two learners that differ in nothing else drift apart). Offset 0 returns ``factory``."""
    if offset == 0:
        return factory

    def offset_factory(name: str, rbd: Any, gp_config: GPFitConfig) -> Any:
        return factory(name, rbd, replace(gp_config, seed=gp_config.seed + offset))
    return offset_factory
