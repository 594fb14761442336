"""Helpers of the execution layer's tests (test_execution*.py): the environment of the commands they start,
Ray's optional import, a kill at a given state of a run, and a module fixture that keeps Ray's token out of the
user's home."""

from __future__ import annotations

import os
import secrets
import signal
import subprocess
import time
from pathlib import Path
from typing import Iterator

import pytest

REPO = Path(__file__).resolve().parents[1]
HERE = Path(__file__).resolve().parent


def subprocess_env() -> dict[str, str]:
    """This process's environment for a command the tests start."""
    env = dict(os.environ)
    # the repo (scripts) and this folder (the toy jobs of test_execution, for Ray workers started from a subprocess)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), str(HERE), env.get("PYTHONPATH", "")])
    env.setdefault("MUJOCO_GL", "egl")
    return env


def needs_ray():
    return pytest.importorskip("ray", exc_type=ImportError)  # also a broken install


#: Ray's variables that decide whether and which token a process sends (and RAY_ADDRESS, which ray.init reads).
RAY_AUTH_VARS = ("RAY_AUTH_MODE", "RAY_AUTH_TOKEN", "RAY_AUTH_TOKEN_PATH", "RAY_ADDRESS")


@pytest.fixture(scope="module", autouse=True)
def ray_token_outside_home(tmp_path_factory) -> Iterator[None]:
    """Local Ray instances of a module (in its process and in the commands it runs) read their token from a
    temporary file, not ``~/.ray/auth_token`` (which Ray would otherwise create). Autouse in every module
    that imports it."""
    if os.environ.get("RAY_AUTH_TOKEN") or os.environ.get("RAY_AUTH_TOKEN_PATH"):
        yield
        return
    token = tmp_path_factory.mktemp("ray_token") / "auth_token"
    token.write_text(secrets.token_hex(32))
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("RAY_AUTH_TOKEN_PATH", str(token))
        yield


def kill_when(proc: subprocess.Popen, ready) -> None:
    """SIGKILL ``proc``'s process group as soon as ``ready()`` is true (fails if it ends first). No clock:
    the wait ends when the run reaches the state or ends."""
    while not ready():
        assert proc.poll() is None, "the run finished before it could be killed"
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(timeout=60)
