"""The retrain loop's hooks (:class:`cascgp.learning.RunHooks`) on a tiny two-joint env (no MuJoCo): the order and
context of the calls, the model each attempt uses, that observing changes nothing, and the experiments' hooks
(:mod:`cascgp_experiments.run_hooks`): paired controllers and the GP seed offset."""

from __future__ import annotations

import numpy as np
import pytest

from cascgp.learning import AttemptContext, Feedback, RetrainConfig, RunHooks, default_model_factory, run_controller
from cascgp_experiments.run_hooks import PairedEpisodes, seed_offset_factory
from tests.test_episodes import ExactID, TwoJointEnv

PLAN = [("sine", 0, "train"), ("sine", 1, "train"), ("sine", 2, "train")]
FEEDBACK = Feedback(np.full(2, 20.0), np.full(2, 5.0), np.full(2, 10.0))
SMALL = RetrainConfig(seed=3, restarts=2, cap=60)


def _run(name: str, config: RetrainConfig = SMALL, **kw):
    return run_controller(name, TwoJointEnv(steps=60), PLAN, ExactID(), FEEDBACK, config, **kw)


class Recorder(RunHooks):
    """Logs every call; measures the model before each episode into the record, as a study's hook would."""

    def __init__(self) -> None:
        self.calls: list[tuple] = []
        self.steps = 0

    def episode_callback(self, ctx: AttemptContext):
        self.calls.append(("callback", ctx.index))

        def count(_env, _info) -> None:
            self.steps += 1
        return count

    def before_episode(self, ctx: AttemptContext, model) -> None:
        self.calls.append(("before", ctx.index, ctx.name, ctx.attempt, ctx.seed, ctx.options, model,
                           None if model is None else model.n_train))

    def after_episode(self, ctx: AttemptContext, model, record) -> None:
        self.calls.append(("after_episode", ctx.index, model))
        if model is not None:
            record["before"] = {"n": int(model.n_train)}

    def after_attempt(self, ctx: AttemptContext, record) -> None:
        self.calls.append(("after_attempt", ctx.index, "fit_seconds" in record))


def test_hooks_are_called_in_order_with_the_attempts_context_and_model_and_change_nothing() -> None:
    rec = Recorder()
    hooked = _run("np-inward", hooks=[rec], reset_options={"payload": 1}).attempts
    plain = _run("np-inward", reset_options={"payload": 1}).attempts
    kinds = [c[0] for c in rec.calls]
    assert kinds == ["callback", "before", "after_episode", "after_attempt"] * len(PLAN)
    befores = [c for c in rec.calls if c[0] == "before"]
    for i, (c, attempt) in enumerate(zip(befores, PLAN)):
        assert c[1:6] == (i, "np-inward", attempt, SMALL.seed * 1000 + i, {"task": "sine", "payload": 1})
    assert befores[0][6] is None and "before" not in hooked[0]
    assert befores[1][6] is not befores[2][6]  # a new model after every refit
    for r, c in zip(hooked[1:], befores[1:]):
        assert c[6].fitted and r["before"] == {"n": c[7]} == {"n": r["n_train"]}
    # after_episode sees the model the episode used; after_attempt comes after the refit
    assert [c[2] for c in rec.calls if c[0] == "after_episode"] == [c[6] for c in befores]
    assert all(c[2] for c in rec.calls if c[0] == "after_attempt")
    assert rec.steps == 60 * len(PLAN)

    def strip(a):  # repr: equal floats print equal, and NaN (no marbles here) equals NaN
        return repr({k: v for k, v in a.items() if k not in ("before", "fit_seconds")})

    assert [strip(a) for a in hooked] == [strip(a) for a in plain]


def test_hooks_must_be_run_hooks_objects() -> None:
    with pytest.raises(ValueError, match="hooks"):
        _run("pd", hooks=[lambda *a: None])


def test_seed_offset_factory_changes_only_the_gp_seed_of_each_refit() -> None:
    seeds = []

    def factory(name, rbd, gp_config):
        seeds.append(gp_config.seed)
        return default_model_factory(name, rbd, gp_config)

    _run("np-inward", model_factory=seed_offset_factory(100, factory))
    assert seeds == [103, 104, 105]
    seeds.clear()
    _run("np-inward", model_factory=factory)
    assert seeds == [3, 4, 5]
    assert seed_offset_factory(0, factory) is factory


@pytest.mark.parametrize("name, paired", [("sp-inward", ["np-inward-gated"]), ("sp-inward", ["rbd"]),
                                          ("rbd", ["rbd"]), ("sp-inward", ["sp-sideways"])])
def test_paired_controllers_must_be_variants_of_the_same_model(name, paired) -> None:
    with pytest.raises(ValueError, match="paired|unknown controller"):
        PairedEpisodes(name, paired, env=None, rbd=None, feedback=FEEDBACK)


def test_paired_episodes_run_on_the_learners_model_and_change_nothing() -> None:
    env = TwoJointEnv(steps=60)
    paired = PairedEpisodes("np-inward", ["np-inward-gated", "np-inward"], env, ExactID(), FEEDBACK)
    hooked = run_controller("np-inward", env, PLAN, ExactID(), FEEDBACK, SMALL, hooks=[paired]).attempts
    plain = _run("np-inward").attempts
    for h, p in zip(hooked, plain):
        assert set(h["paired"]) == {"np-inward-gated", "np-inward"}
        # the learner's own controller, run again on its model with the attempt's seed: the same episode
        assert repr(h["paired"]["np-inward"]) == repr({k: v for k, v in h.items()
                                                      if k in h["paired"]["np-inward"]})
        assert repr({k: v for k, v in h.items() if k not in ("paired", "fit_seconds")}) == \
            repr({k: v for k, v in p.items() if k != "fit_seconds"})
    # once a model is fitted, the gate acts
    assert hooked[2]["paired"]["np-inward-gated"]["tracking_rmse"] != hooked[2]["tracking_rmse"]


class OnlineProbe(RunHooks):
    """Records the number of online samples in the model each hook sees."""

    def __init__(self) -> None:
        self.seen: list[tuple[str, int, int]] = []

    def before_episode(self, ctx: AttemptContext, model) -> None:
        if model is not None:
            self.seen.append(("before", ctx.index, model.n_online))

    def after_episode(self, ctx: AttemptContext, model, record) -> None:
        if model is not None:
            self.seen.append(("after", ctx.index, model.n_online))


def test_before_episode_sees_the_fitted_model_without_an_earlier_attempts_online_samples() -> None:
    """With a plan whose later attempts do not refit, the same model object came to the next attempt's
    before_episode with the previous episode's online window still in it (its predictions changed)."""
    probe = OnlineProbe()
    plan = [("sine", 0, "train"), ("sine", 0, "eval"), ("sine", 1, "eval")]
    run_controller("np-inward-online", TwoJointEnv(steps=60), plan, ExactID(), FEEDBACK, SMALL, hooks=[probe])
    befores = [n for kind, _, n in probe.seen if kind == "before"]
    afters = [n for kind, _, n in probe.seen if kind == "after"]
    assert befores == [0, 0] and all(n > 0 for n in afters[1:]), probe.seen


def test_the_run_returns_the_model_of_its_last_refit() -> None:
    """The refit after the last training attempt was computed and dropped; the run now returns it."""
    run = _run("np-inward")
    assert run.model is not None and run.model.fitted
    # fitted on all three attempts' data: more rows than the model the last attempt ran on
    assert run.model.n_train > run.attempts[-1]["n_train"] > 0
    # with an evaluation after the training: the model that attempt ran on, its online window closed
    seen = Recorder()
    online = run_controller("np-inward-online", TwoJointEnv(steps=60), PLAN + [("sine", 3, "eval")], ExactID(),
                            FEEDBACK, SMALL, hooks=[seen])
    last_model = [c[6] for c in seen.calls if c[0] == "before"][-1]
    assert online.model is last_model and online.model.n_online == 0
    assert online.attempts[-1]["n_train"] == online.model.n_train
    assert _run("rbd").model is None
