"""Gymnasium's ``RecordVideo`` wrapper on ``JacoPour-v0`` (``rgb_array``, headless): an MP4 of the episode.

``RecordVideo`` writes its clips with MoviePy (the ``video`` extra: ``the video extra, pip install '.[video]'``);
without it the test is skipped. Small frames and a truncated episode keep it to a few seconds.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering (set before MuJoCo is imported)

pytest.importorskip("moviepy", reason="RecordVideo needs MoviePy: the video extra (pip install '.[video]')")

import gymnasium as gym
from gymnasium.wrappers import RecordVideo

import jaco_env  # noqa: F401  (registers the environments)

WIDTH, HEIGHT, STEPS = 96, 80, 6


def test_record_video_writes_the_episode_as_mp4(tmp_path: Path) -> None:
    env = gym.make("JacoPour-v0", render_mode="rgb_array", width=WIDTH, height=HEIGHT, n_marbles=2,
                   max_episode_steps=STEPS)
    videos = tmp_path / "videos"
    env = RecordVideo(env, video_folder=str(videos), episode_trigger=lambda episode: episode == 0,
                      name_prefix="pour", disable_logger=True)
    try:
        env.reset(seed=0)
        n, terminated, truncated = 0, False, False
        while not (terminated or truncated):
            _, _, terminated, truncated, _ = env.step(np.zeros(env.action_space.shape, np.float32))
            n += 1
        assert truncated and not terminated and n == STEPS
    finally:
        env.close()  # the clip is written when the episode ends (at the latest on close)

    clips = sorted(videos.glob("*.mp4"))
    assert [c.name for c in clips] == ["pour-episode-0.mp4"], sorted(p.name for p in videos.iterdir())
    assert clips[0].stat().st_size > 0

    iio = pytest.importorskip("imageio.v3", reason="decoding the MP4 needs imageio (the video extra)")
    frames = iio.imread(clips[0], plugin="FFMPEG", index=None)
    meta = iio.immeta(clips[0], plugin="FFMPEG")
    # the frame of the reset and one per step, at the env's render_fps (its control frequency)
    assert frames.shape == (STEPS + 1, HEIGHT, WIDTH, 3)
    assert meta["fps"] == pytest.approx(env.metadata["render_fps"]) == 40
    assert frames.std() > 5.0  # the scene, not a blank frame
