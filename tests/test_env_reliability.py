"""Issue 12, environment half: bounded memory over many ``gym.make``, strict input types, no state change after a
rejected call, a warning when stepping past termination, no render before reset, a clean exit without ``close()``.
Each test failed on the code before its fix (see the commit messages)."""

from __future__ import annotations

import os
import subprocess
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import ResetNeeded

import jaco_env
from jaco_env.envs import JacoPayloadEnv, JacoPourEnv
from jaco_env.oracle import OracleController, PDController
from jaco_env.sensors import SensorNoise
from jaco_env.tasks import DEFAULT_TASKS, PouringTask

REPO = Path(__file__).resolve().parents[1]


def _state(env) -> tuple[np.ndarray, np.ndarray, float, float]:
    u = env.unwrapped
    return u.data.qpos.copy(), u.data.qvel.copy(), float(u.data.time), float(u.payload_mass)


def _assert_same_state(env, before) -> None:
    after = _state(env)
    assert np.array_equal(before[0], after[0]) and np.array_equal(before[1], after[1])
    assert before[2:] == after[2:]


def _rss_mib() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    raise RuntimeError("no VmRSS")


# ------------------------------------------------------------------ memory: the scene files are reused
def test_makes_share_one_exported_scene_file() -> None:
    """MuJoCo caches meshes by file path: every env of one configuration must load the same files."""
    paths = []
    for _ in range(2):
        env = gym.make("JacoPayload-v0")
        paths.append(env.unwrapped.fullpath)
        env.close()
    assert paths[0] == paths[1] and os.path.exists(paths[0])
    env = gym.make("JacoPour-v0", n_marbles=5)
    # Another scene: its own XML, the same mesh files (same folder).
    assert env.unwrapped.fullpath != paths[0]
    assert os.path.dirname(env.unwrapped.fullpath) == os.path.dirname(paths[0])
    env.close()


@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="needs /proc")
def test_repeated_make_close_keeps_memory_flat() -> None:
    """Before the fix each make added ~3-4 MiB (a mesh cache entry per fresh folder): +70 MiB over 20 makes. The
    process's memory climbs by about 25 MiB over the first ten makes and stays there (the allocator's pools; the
    same before this check's last change), so the growth is measured after them."""
    for i in range(10):  # warm-up: the first make fills the mesh cache, the first ten the allocator's pools
        env = gym.make("JacoPayload-v0")
        env.reset(seed=i)
        env.close()
    r0 = _rss_mib()
    for i in range(20):
        env = gym.make("JacoPayload-v0")
        env.reset(seed=i)
        env.close()
    assert _rss_mib() - r0 < 25.0


def test_scene_folder_removed_at_exit(tmp_path: Path) -> None:
    """The exported scene lives in one folder per process, removed at exit (also by vector-env workers); the
    folder of a killed process is removed by the next process that exports a scene."""
    code = (
        "import gymnasium as gym, numpy as np, jaco_env, os\n"
        "env = gym.make('JacoPayload-v0'); print(os.path.dirname(env.unwrapped.fullpath)); env.close()\n"
        "v = gym.make_vec('JacoPayload-v0', num_envs=2, vectorization_mode='async'); v.reset(seed=0)\n"
        "v.step(np.zeros((2, 6), dtype=np.float32)); v.close()\n"
    )
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    stale = tmp_path / f"jaco_env_{int(dead.stdout)}_killed"  # left by a process killed by a signal
    stale.mkdir()
    (stale / "scene.xml").write_text("<mujoco/>")
    env = {**os.environ, "TMPDIR": str(tmp_path), "MUJOCO_GL": "egl"}
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    folder = Path(out.stdout.strip().splitlines()[-1])
    assert folder.parent == tmp_path
    assert not folder.exists()
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------ strict types for masses and actions
@pytest.mark.parametrize("bad", ["1.2", True, np.bool_(True), 1.0 + 0j, None, [1.0]])
def test_payload_mass_must_be_a_real_number(bad) -> None:
    with pytest.raises(TypeError, match="payload_mass"):
        JacoPayloadEnv(payload_mass=bad)
    if bad is not None:  # a task without a payload draws one per episode
        with pytest.raises(TypeError, match="payload_mass"):
            PouringTask("t", jar_pos=DEFAULT_TASKS["front"].jar_pos, payload_mass=bad)


@pytest.fixture(scope="module")
def envs():
    pour, payload = gym.make("JacoPour-v0", n_marbles=5), gym.make("JacoPayload-v0")
    yield {"pour": pour, "payload": payload}
    pour.close()
    payload.close()


@pytest.mark.parametrize("which", ["pour", "payload"])
@pytest.mark.parametrize("bad", ["1.2", True, np.bool_(False), 1.0 + 0j])
def test_reset_payload_mass_must_be_a_real_number(envs, which, bad) -> None:
    env = envs[which]
    env.reset(seed=0)
    env.step(np.full(6, 0.5))
    before = _state(env)
    with pytest.raises(TypeError, match="payload_mass"):
        env.reset(seed=1, options={"payload_mass": bad})
    _assert_same_state(env, before)


@pytest.mark.parametrize("which", ["pour", "payload"])
@pytest.mark.parametrize("action", [
    np.full(6, 1.0 + 2.0j), np.ones(6, dtype=bool), np.array(["1.0"] * 6), [0, 0, 0, 0, 0, 1j],
    np.array([1.0, 2.0, None, 0, 0, 0], dtype=object),
])
def test_non_real_actions_are_refused(envs, which, action) -> None:
    env = envs[which]
    env.reset(seed=0)
    before = _state(env)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no ComplexWarning either: refused before any cast
        with pytest.raises(TypeError, match="action"):
            env.step(action)
    _assert_same_state(env, before)


def test_real_object_and_integer_actions_still_work(envs) -> None:
    env = envs["payload"]
    env.reset(seed=0)
    for a in (np.zeros(6, dtype=np.int64), np.array([0.0] * 6, dtype=object), [0, 0, 0, 0, 0, 0]):
        obs, *_ = env.step(a)
        assert np.all(np.isfinite(obs))


def test_q0_option_must_be_real(envs) -> None:
    env = envs["payload"]
    env.reset(seed=0)
    before = _state(env)
    for bad in (np.zeros(6, dtype=complex), np.zeros(6, dtype=bool), ["0"] * 6):
        with pytest.raises(TypeError, match="q0"):
            env.reset(options={"q0": bad})
        _assert_same_state(env, before)


def test_constructor_numbers_refuse_bools_and_strings() -> None:
    with pytest.raises(TypeError, match="control_freq"):
        JacoPayloadEnv(control_freq=True)
    with pytest.raises(TypeError, match="n_marbles"):
        JacoPourEnv(n_marbles=True)
    with pytest.raises(TypeError, match="payload_range"):
        JacoPourEnv(n_marbles=5, payload_range=("0.6", "1.5"))
    with pytest.raises(TypeError, match="tracking_cost_weight"):
        JacoPourEnv(n_marbles=5, tracking_cost_weight=True)
    with pytest.raises(TypeError, match="SensorNoise.q_std"):
        SensorNoise(q_std=True)
    with pytest.raises(ValueError, match="SensorNoise.tau_std"):
        SensorNoise(tau_std=float("nan"))


# ------------------------------------------------------------------ a rejected reset changes nothing
def test_reset_with_an_unreachable_task_changes_nothing(envs) -> None:
    env = envs["pour"]
    env.reset(seed=0, options={"task": "front"})
    env.step(np.full(6, 0.5))
    before = _state(env)
    with pytest.raises(ValueError, match="not reachable"):
        env.reset(seed=0, options={"task": PouringTask("moon", jar_pos=[3.0, 0.0, 0.0])})
    _assert_same_state(env, before)


def test_reset_with_a_too_light_task_payload_changes_nothing(envs) -> None:
    env = envs["pour"]  # 5 marbles: bottle + marbles weigh 0.225 kg
    env.reset(seed=0, options={"task": "front"})
    env.step(np.full(6, 0.5))
    before = _state(env)
    light = DEFAULT_TASKS["front"].replace(name="light", payload_mass=0.21)
    with pytest.raises(ValueError, match="payload_mass"):
        env.reset(seed=0, options={"task": light})
    _assert_same_state(env, before)


# ------------------------------------------------------------------ episode end, render order, exit
def test_step_after_termination_warns() -> None:
    env = gym.make("JacoPour-v0", n_marbles=1, task="front")
    env.reset(seed=0)
    terminated = False
    for _ in range(10_000):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            _, _, terminated, truncated, _ = env.step(np.zeros(6))
        if terminated or truncated:
            break
    assert terminated
    with pytest.warns(UserWarning, match="terminated"):
        env.step(np.zeros(6))
    env.reset(seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a new episode: no warning
        env.step(np.zeros(6))
    env.close()


def test_unwrapped_render_before_reset_raises() -> None:
    env = JacoPayloadEnv(render_mode="rgb_array", width=32, height=24)
    with pytest.raises(ResetNeeded, match="reset"):
        env.render()
    env.reset(seed=0)
    assert env.render().shape == (24, 32, 3)
    env.close()


def test_render_without_close_exits_cleanly() -> None:
    """A script that renders and exits without close(): before the fix EGL printed tracebacks at exit."""
    code = (
        "import gymnasium as gym, jaco_env\n"
        "env = gym.make('JacoPayload-v0', render_mode='rgb_array', width=32, height=24)\n"
        "env.reset(seed=0)\n"
        "print(env.render().shape)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, env={**os.environ, "MUJOCO_GL": "egl"},
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and out.stdout.strip() == "(24, 32, 3)"
    assert out.stderr == ""


# ------------------------------------------------------------------ reference controllers
@pytest.mark.parametrize("cls", [PDController, OracleController])
@pytest.mark.parametrize("field", ["kp", "kd"])
@pytest.mark.parametrize("bad", [np.inf, np.nan, -1.0, np.ones(5), "1"])
def test_reference_controller_gains_are_checked(cls, field, bad) -> None:
    with pytest.raises((ValueError, TypeError), match=field):
        cls(**{field: bad})


@pytest.mark.parametrize("cls", [PDController, lambda: OracleController(1.0)])
def test_reference_controllers_never_output_nan(cls) -> None:
    ctrl = cls()
    ref = DEFAULT_TASKS["front"].reference
    for q, qd in ((np.full(6, np.nan), np.zeros(6)), (np.zeros(6), np.full(6, np.inf)),
                  (np.full(6, 1e308), np.full(6, -1e308))):
        tau = ctrl(0.0, q, qd, ref)
        assert tau.shape == (6,) and np.all(np.isfinite(tau))
        assert np.all(np.abs(tau) <= jaco_env.robot.TORQUE_LIMITS)
    assert ctrl.n_bad_measurements == 2
    with pytest.raises(ValueError, match="q "):
        ctrl(0.0, np.zeros(5), np.zeros(6), ref)
    with pytest.raises(TypeError, match="qd"):
        ctrl(0.0, np.zeros(6), np.zeros(6, dtype=complex), ref)


@pytest.mark.parametrize("env_cls", ["JacoPayloadEnv", "JacoPourEnv"])
def test_unwrapped_step_before_reset_raises_reset_needed(env_cls: str) -> None:
    import jaco_env.envs as envs

    env = getattr(envs, env_cls)()
    with pytest.raises(ResetNeeded, match="reset"):
        env.step(np.zeros(6, dtype=np.float32))
    env.close()
