"""The settings of one task-transfer run (:class:`TransferConfig`), checked on construction.

A module without torch: ``cascgp transfer`` builds its settings from the options, and refuses a bad one, before it
imports the experiment (:mod:`cascgp_experiments.transfer`, which exports the same class). The checks import
``jaco_env`` (MuJoCo) for the task names and the payload's bounds; the methods that run something import what they
need.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

from cascgp.checks import check_count
from cascgp.settings import RetrainConfig, check_controller
from cascgp_experiments.transfer_presets import ENV_ID, FULL_CONTROLLERS, FULL_TASKS

#: Most training attempts per task a run takes (each is an episode and a refit): more would only fill the memory.
MAX_ATTEMPTS = 1000

if TYPE_CHECKING:
    import gymnasium as gym

    from cascgp.learning import Attempt, ModelFactory

__all__ = ["TransferConfig"]


@dataclass(frozen=True)
class TransferConfig:
    """Settings of one task-transfer run (``cascgp transfer --help`` describes each); every field is checked on
    construction."""

    controllers: tuple[str, ...] = FULL_CONTROLLERS
    tasks: tuple[str, ...] = FULL_TASKS
    attempts: int = 3
    revisit: bool = True
    payload_mass: float = 1.2
    seed: int = 0
    rate_hz: float = 10.0
    cap: int = 500
    restarts: int = 3
    n_marbles: int = 30
    fit_seed_offset: int = 0  # added to every refit's GP seed (run_hooks.seed_offset_factory); 0 in the product
    #: The env's ``sensor_pipeline`` (``jaco_env.signal_pipeline``): ``"jaco2"`` (the real arm's signal and
    #: Kinova's link inertials, the env's default) or ``"ideal"``; the nominal model follows the env's inertials.
    sensor_pipeline: str = "jaco2"

    def __post_init__(self) -> None:
        """Every field checked now, so that a bad setting is refused before any episode runs (``ValueError`` or
        ``TypeError`` naming the field); numbers are kept as Python ints and floats, names as tuples."""
        from cascgp_experiments.collect import check_pipeline
        from jaco_env import scene
        from jaco_env.tasks import get_task

        def store(name: str, value: Any) -> None:
            object.__setattr__(self, name, value)

        check_pipeline(self.sensor_pipeline)  # the one rule (collection, study, transfer)
        for name, check in (("controllers", check_controller), ("tasks", get_task)):
            values = getattr(self, name)
            if not isinstance(values, (tuple, list)) or not values or not all(isinstance(v, str) for v in values) \
                    or len(set(values)) != len(values):
                raise ValueError(f"{name}: expected a non-empty sequence of distinct names, got {values!r}")
            for v in values:
                try:
                    check(v)
                except ValueError as exc:  # the message names the field (a command line names its option)
                    raise ValueError(f"{name}: {exc}") from None
            store(name, tuple(values))
        store("attempts", check_count(self.attempts, "attempts"))
        if self.attempts > MAX_ATTEMPTS:
            raise ValueError(f"attempts: expected at most {MAX_ATTEMPTS} per task, got {self.attempts}")
        store("n_marbles", check_count(self.n_marbles, "n_marbles"))
        if self.n_marbles > scene.MAX_MARBLES:
            raise ValueError(f"n_marbles: expected at most {scene.MAX_MARBLES}, got {self.n_marbles}")
        store("fit_seed_offset", check_count(self.fit_seed_offset, "fit_seed_offset", minimum=0))
        store("payload_mass", scene.check_payload_mass(self.payload_mass, scene.bottle_mass(self.n_marbles),
                                                       "payload_mass (total in the hand)"))
        r = self.retrain()  # seed, rate_hz, cap, restarts: RetrainConfig's checks, and its Python numbers
        for name in ("seed", "rate_hz", "cap", "restarts"):
            store(name, getattr(r, name))

    def plan(self) -> list[Attempt]:
        """Every attempt, in order (:func:`cascgp.learning.attempt_plan`)."""
        from cascgp.learning import attempt_plan

        return attempt_plan(self.tasks, self.attempts, self.revisit)

    def retrain(self) -> RetrainConfig:
        """The seeds and refit settings of :mod:`cascgp.learning`."""
        return RetrainConfig(seed=self.seed, rate_hz=self.rate_hz, cap=self.cap, restarts=self.restarts)

    def model_factory(self) -> ModelFactory:
        """The refits' model factory: the default one, its GP seeds offset by ``fit_seed_offset``."""
        from cascgp_experiments.run_hooks import seed_offset_factory

        return seed_offset_factory(self.fit_seed_offset)

    def reset_options(self) -> dict[str, Any]:
        """Reset options besides the task: the unknown payload."""
        return {"payload_mass": self.payload_mass}

    def make_env(self) -> gym.Env:
        """The run's ``JacoPour-v0`` (``n_marbles``, ``sensor_pipeline``)."""
        import gymnasium as gym

        import jaco_env  # noqa: F401 - registers the environments

        return gym.make(ENV_ID, n_marbles=self.n_marbles, sensor_pipeline=self.sensor_pipeline)

    def to_dict(self) -> dict[str, Any]:
        """The settings as JSON-ready values (tuples as lists)."""
        return {**asdict(self), "controllers": list(self.controllers), "tasks": list(self.tasks)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "TransferConfig":
        """The settings of :meth:`to_dict`; a record without ``sensor_pipeline`` was run under ``"ideal"``."""
        return cls(**{"sensor_pipeline": "ideal", **d})
