"""A seeded ``JacoPour-v0`` episode is the same bit for bit whatever BLAS kernels the CPU gets.

NumPy's OpenBLAS picks its kernels at run time for the CPU (with or without FMA, other blockings), so a matrix
product or a LAPACK solve rounds differently from one CPU to another; the marbles' contacts turn such a last-bit
difference into a different episode. The environment therefore keeps BLAS out of everything that reaches the
physics, the observations or the reward (the marbles' placement, the tasks' inverse kinematics, the tracking error).
This test runs the same seeded episode in two processes, one with this CPU's kernels and one with OpenBLAS's
Nehalem kernels (SSE4.2, which any x86-64 CPU runs), checks that the switch changes a matrix product's bits, and
compares the episodes' digests.
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys

import pytest

_EPISODE = r"""
import hashlib
import numpy as np
import gymnasium as gym
import jaco_env  # noqa: F401

rng = np.random.default_rng(0)
a, b = rng.standard_normal((200, 200)), rng.standard_normal((200, 200))
print("blas", hashlib.sha256((a @ b).tobytes()).hexdigest())
h = hashlib.sha256()
env = gym.make("JacoPour-v0", n_marbles=12)
obs, info = env.reset(seed=3, options={"task": "far", "payload_mass": 0.9})
u = env.unwrapped
h.update(np.asarray([np.concatenate(u.task.reference(t)) for t in np.linspace(0.0, u.task.duration, 60)]).tobytes())
h.update(u.marble_positions().tobytes())
lim = env.action_space.high
for _ in range(25):
    obs, r, term, trunc, info = env.step((0.3 * lim * rng.uniform(-1, 1, lim.shape)).astype(np.float32))
    h.update(np.asarray(obs, float).tobytes())
    keys = ("tracking_error", "marbles_in_jar", "marbles_in_bottle", "marbles_spilled")
    h.update(np.asarray([r, *(info[k] for k in keys)], float).tobytes())
env.close()
print("episode", h.hexdigest())
"""


def _run(extra_env: dict[str, str]) -> dict[str, str]:
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), **extra_env}
    r = subprocess.run([sys.executable, "-c", _EPISODE], env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    return dict(line.split() for line in r.stdout.splitlines() if line.startswith(("blas ", "episode ")))


@pytest.mark.skipif(platform.machine().lower() not in ("x86_64", "amd64"), reason="OpenBLAS's x86-64 kernel names")
def test_a_seeded_pour_episode_does_not_depend_on_the_blas_kernels():
    here = _run({})
    other = _run({"OPENBLAS_CORETYPE": "Nehalem"})
    if here["blas"] == other["blas"]:
        pytest.skip("this NumPy's BLAS does not switch kernels with OPENBLAS_CORETYPE (or already runs Nehalem's)")
    assert here["episode"] == other["episode"]
