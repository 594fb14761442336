"""``render_mode="human"`` on a machine without a display raises :class:`jaco_env.envs.base.NoDisplayError`
(a ``RuntimeError``), never aborts the process.

Without a display GLFW fails an assertion in native code and the process dies of SIGABRT (Gymnasium's
``WindowViewer`` does not check ``glfw.init()``), so every check runs in a subprocess: an abort there is a
negative exit status and a failed test, not a dead test run.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
ENV_IDS = ("JacoPour-v0", "JacoPayload-v0")
#: An X display number with no server behind it (checked below).
DEAD_DISPLAY = ":9873"


def _headless_env(**extra: str) -> dict[str, str]:
    """This process's environment without a display, MUJOCO_GL left to jaco_env (it picks egl when headless)."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("DISPLAY", "WAYLAND_DISPLAY", "MUJOCO_GL", "PYOPENGL_PLATFORM")}
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), env.get("PYTHONPATH", "")])
    env.update(extra)
    return env


def _run(code: str, *args: str, **extra_env: str) -> subprocess.CompletedProcess:
    """``python -c code args...`` without a display (``extra_env`` added)."""
    return subprocess.run([sys.executable, "-c", code, *args], env=_headless_env(**extra_env), cwd=REPO,
                          capture_output=True, text=True, timeout=300)


def _report(run: subprocess.CompletedProcess) -> dict:
    """The JSON line the subprocess printed before raising."""
    lines = [ln for ln in run.stdout.splitlines() if ln.startswith("{")]
    assert lines, f"exit status {run.returncode}; stdout: {run.stdout[-2000:]}; stderr: {run.stderr[-3000:]}"
    return json.loads(lines[-1])


def _assert_exited_with_no_display_error(run: subprocess.CompletedProcess) -> None:
    """Exit status 1 (an uncaught Python exception), not a signal (negative: e.g. -6, SIGABRT from GLFW)."""
    assert run.returncode == 1, (f"expected the Python exception (exit status 1), got {run.returncode} "
                                 f"(negative: killed by a signal); stderr: {run.stderr[-3000:]}")
    last = run.stderr.strip().splitlines()[-1]
    assert last.startswith("jaco_env.envs.base.NoDisplayError: "), run.stderr[-3000:]


_MAKE_HUMAN = """
import json, sys
import gymnasium as gym
import jaco_env
from gymnasium import error
try:
    env = gym.make(sys.argv[1], render_mode="human")
    print(json.dumps({"constructed": True}), flush=True)
    env.reset(seed=0)
except Exception as exc:
    print(json.dumps({"type": type(exc).__name__, "runtime_error": isinstance(exc, RuntimeError),
                      "gym_error": isinstance(exc, error.Error), "message": str(exc)}), flush=True)
    raise
print(json.dumps({"rendered": True}), flush=True)
"""


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_human_without_display_raises_at_construction(env_id: str) -> None:
    run = _run(_MAKE_HUMAN, env_id)
    _assert_exited_with_no_display_error(run)
    rep = _report(run)
    assert "constructed" not in run.stdout  # before the scene is built or GLFW is touched
    assert rep["type"] == "NoDisplayError" and rep["runtime_error"] and rep["gym_error"]
    msg = rep["message"]
    for text in ("render_mode='human'", "neither DISPLAY nor WAYLAND_DISPLAY is set", "render_mode='rgb_array'",
                 "MUJOCO_GL=egl", "MUJOCO_GL=osmesa", "xvfb-run"):
        assert text in msg, msg


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="an X11 display name (Linux)")
def test_human_with_an_unreachable_display_raises_at_the_first_render() -> None:
    """DISPLAY names an X server that is not there: construction passes (nothing is known to be missing), the
    first ``human`` render (``reset`` renders in this mode) raises instead of GLFW aborting the process."""
    if Path(f"/tmp/.X11-unix/X{DEAD_DISPLAY[1:]}").exists():
        pytest.skip(f"an X server answers on {DEAD_DISPLAY} here")
    run = _run(_MAKE_HUMAN, "JacoPour-v0", DISPLAY=DEAD_DISPLAY)
    _assert_exited_with_no_display_error(run)
    assert '{"constructed": true}' in run.stdout
    rep = _report(run)
    assert rep["type"] == "NoDisplayError" and "GLFW could not be initialised" in rep["message"]
    assert f"DISPLAY='{DEAD_DISPLAY}'" in rep["message"]


def test_check_env_without_display_does_not_kill_the_process() -> None:
    """``check_env`` without ``skip_render_check`` makes an env in every declared render mode, ``human`` too:
    that raises (or the check passes); the process is never killed."""
    code = """
import gymnasium as gym
import jaco_env
from gymnasium.utils.env_checker import check_env
env = gym.make("JacoPour-v0", n_marbles=2)
check_env(env.unwrapped)
print("check_env returned")
"""
    run = _run(code)
    assert run.returncode in (0, 1), (f"check_env ended the process with status {run.returncode} (negative: a "
                                      f"signal); stderr: {run.stderr[-3000:]}")
    if run.returncode == 1:
        _assert_exited_with_no_display_error(run)
    else:
        assert "check_env returned" in run.stdout


def test_no_display_reason_reads_the_environment(monkeypatch) -> None:
    from jaco_env.envs.base import no_display_reason

    if sys.platform in ("darwin", "win32", "cygwin"):
        pytest.skip("no DISPLAY needed for a window on this platform")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert no_display_reason() == "neither DISPLAY nor WAYLAND_DISPLAY is set"
    monkeypatch.setenv("DISPLAY", ":0")
    assert no_display_reason() is None
    monkeypatch.delenv("DISPLAY")
    monkeypatch.setenv("WAYLAND_DISPLAY", "wayland-0")
    assert no_display_reason() is None
    monkeypatch.setenv("WAYLAND_DISPLAY", "")
    assert no_display_reason() is not None
