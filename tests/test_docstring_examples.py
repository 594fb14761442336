"""The ``Example:`` blocks of the public docstrings run and print what they say (doctest)."""

from __future__ import annotations

import doctest
import importlib

import pytest

MODULES = ["cascgp.data", "cascgp.buffer", "cascgp.metrics", "cascgp.logs", "cascgp.rbd", "cascgp.learning",
           "cascgp.models", "cascgp.controller",
           "jaco_env.envs.pour_v0", "jaco_env.envs.payload_v0"]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples_run(name: str) -> None:
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.NORMALIZE_WHITESPACE, verbose=False)
    assert result.attempted > 0, f"{name}: no example"
    assert result.failed == 0, f"{name}: {result.failed} of {result.attempted} example lines failed (see above)"
