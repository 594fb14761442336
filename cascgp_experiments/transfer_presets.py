"""The task-transfer experiment's environment and its named sets of controllers and tasks.

A module without heavy imports (no torch, no MuJoCo), so that ``cascgp transfer --help``, whose text lists them,
answers at once; :mod:`cascgp_experiments.transfer` runs the experiment.
"""

from __future__ import annotations

__all__ = ["ENV_ID", "FULL_CONTROLLERS", "FULL_TASKS", "QUICK_CONTROLLERS", "QUICK_TASKS"]

ENV_ID = "JacoPour-v0"
FULL_CONTROLLERS = ("pd", "rbd", "sp-standard", "sp-inward", "sp-outward", "np-inward", "sp-inward-gated",
                    "sp-inward-gated-online")
FULL_TASKS = ("front", "left", "right", "far")
#: The README demo: PD, RBD and the best of the uncertainty-aware controllers (README table).
QUICK_CONTROLLERS = ("pd", "rbd", "sp-inward-igated-online")
QUICK_TASKS = ("front", "left")
