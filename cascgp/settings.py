"""The names of the model variants and of the controllers, and the retrain loop's settings, with their checks.

A module without torch or MuJoCo, so that a command line can refuse a bad name or setting at once, before it imports
the library (``cascgp transfer --controllers ...``). :mod:`cascgp.models` exports :data:`MODEL_NAMES` and
:func:`parse_name`, and :mod:`cascgp.learning` the controllers' names and :class:`RetrainConfig`: the same objects.
"""

from __future__ import annotations

from dataclasses import dataclass

from cascgp.checks import MAX_RESTARTS, check_count, check_positive
from cascgp.features import STRUCTURES
from cascgp.gates import GATE_SUFFIXES

__all__ = ["MODEL_NAMES", "PLAIN_CONTROLLERS", "RetrainConfig", "check_controller", "parse_controller", "parse_name"]

#: The twelve model names.
MODEL_NAMES: tuple[str, ...] = tuple(
    f"{p}-{s}{d}" for p in ("np", "sp") for s in STRUCTURES for d in ("", "-df"))


def parse_name(name: str) -> tuple[str, str, str]:
    """``"sp-inward-df"`` -> ``("sp", "inward", "df")``; unknown names raise ``ValueError``."""
    if not isinstance(name, str) or name not in MODEL_NAMES:
        raise ValueError(f"name: expected one of {MODEL_NAMES}, got {name!r}")
    parts = name.split("-")
    return parts[0], parts[1], ("df" if len(parts) == 3 else "db")


#: Controllers that never learn.
PLAIN_CONTROLLERS = ("pd", "rbd")


def parse_controller(name: str) -> tuple[str, str | None, bool]:
    """``"sp-inward-gated-online"`` -> ``("sp-inward", "wiener", True)``: the base controller or model name,
    the gate (``-gated``: ``"wiener"``, ``-fgated``: ``"floor"``, ``-vgated``: ``"variance"``,
    ``-igated``: ``"innovation"``, else None; see
    :class:`cascgp.controller.FeedforwardController`), online. ``ValueError`` naming the controller for anything
    unknown (suffixes apply to models only; online needs derivative-based states)."""
    if not isinstance(name, str):
        raise ValueError(f"controller: expected a name, got {name!r}")
    base, online = (name[: -len("-online")], True) if name.endswith("-online") else (name, False)
    gate = None
    for rule, suffix in GATE_SUFFIXES.items():
        if base.endswith(suffix):
            base, gate = base[: -len(suffix)], rule
            break
    if base not in PLAIN_CONTROLLERS and base not in MODEL_NAMES or (base in PLAIN_CONTROLLERS and (gate or online)):
        raise ValueError(f"unknown controller {name!r}; expected 'pd', 'rbd' or one of {list(MODEL_NAMES)}, "
                         "a model name optionally followed by '-gated' (or '-fgated', '-vgated', '-igated') "
                         "and/or '-online'")
    if gate == "floor" and not base.startswith("sp-"):
        raise ValueError(f"unknown controller {name!r}: '-fgated' needs a semi-parametric model ('sp-...')")
    if gate == "innovation" and base.endswith("-df"):
        raise ValueError(f"unknown controller {name!r}: '-igated' needs a derivative-based model (not '-df')")
    if online and base.endswith("-df"):
        raise ValueError(f"unknown controller {name!r}: '-online' needs a derivative-based model (not '-df')")
    return base, gate, online


def check_controller(name: str) -> None:
    """``ValueError`` unless ``name`` is ``"pd"``, ``"rbd"`` or a model name (with optional suffixes,
    :func:`parse_controller`)."""
    parse_controller(name)


@dataclass(frozen=True)
class RetrainConfig:
    """How episodes are seeded and how a learning controller is refitted after a training attempt.

    Attributes:
        seed: attempt ``i`` resets the env with seed ``seed * 1000 + i`` and refits with GP seed ``seed + i``
            (an integer >= 0).
        rate_hz: rate (Hz) to which the buffer's episodes are subsampled for a refit.
        cap: the most training rows of a refit (evenly spaced over the subsampled buffer; at least 2).
        restarts: GP optimiser starts per joint's GP in a refit (1 to 1000).
    """

    seed: int = 0
    rate_hz: float = 10.0
    cap: int = 500
    restarts: int = 3

    def __post_init__(self) -> None:
        # As Python numbers (the settings go into JSON records); episode seeds are seed * 1000 + i, and Gymnasium
        # takes seeds >= 0.
        for name, least in (("seed", 0), ("cap", 2), ("restarts", 1)):  # a GP needs two rows
            object.__setattr__(self, name, check_count(getattr(self, name), name, least))
        if self.restarts > MAX_RESTARTS:
            raise ValueError(f"restarts: expected at most {MAX_RESTARTS} starts per GP, got {self.restarts}")
        object.__setattr__(self, "rate_hz", check_positive(self.rate_hz, "rate_hz", "Hz"))
