"""Videos of episodes (cascgp_experiments.video): headless render, captions, side by side, a valid MP4."""

from __future__ import annotations

import importlib
import os
import sys

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

import imageio.v3 as iio  # in the test extra: CI checks a real MP4

from cascgp.controller import FeedforwardController
from cascgp_experiments import video


def _read(path):
    frames = iio.imread(path, plugin="FFMPEG", index=None)
    meta = iio.immeta(path, plugin="FFMPEG")
    return frames, meta


def _pd():
    import jaco_env

    return FeedforwardController(None, jaco_env.DEFAULT_KP, jaco_env.DEFAULT_KD, jaco_env.robot.TORQUE_LIMITS)


@pytest.fixture(scope="module")
def rendered():
    """A few headless frames of JacoPour-v0 (160 x 120) with the recorder as the runner's callback would call it."""
    env = video.make_video_env(width=160, height=120, n_marbles=5)
    try:
        ctrl = _pd()
        obs, info = env.reset(seed=0, options={"task": "front", "payload_mass": 1.2})
        ctrl.start(env.unwrapped, info)
        rec = video.EpisodeRecorder("PD", attempt=2, every=2)
        reference = env.unwrapped.task.reference
        errors = []
        for _ in range(8):
            action = ctrl(float(obs[18]), obs[:6], obs[6:12], reference)
            obs, _, _, _, info = env.step(np.asarray(action, np.float32))
            errors.append(info["tracking_error"])
            rec(env.unwrapped, info)
        raw = env.unwrapped.render().copy()  # same state as the last recorded frame
    finally:
        env.close()
    return rec, raw, errors, info


def test_recorder_frames_fps_and_running_rmse(rendered):
    rec, raw, errors, _ = rendered
    assert len(rec.frames) == 4  # ticks 2, 4, 6, 8
    assert rec.frames[0].shape == (120, 160, 3) and rec.frames[0].dtype == np.uint8
    assert rec.fps == pytest.approx(20.0)  # 40 Hz control, every 2nd tick
    assert rec.task == "front"
    assert rec.tracking_rmse == pytest.approx(float(np.sqrt(np.mean(np.square(errors)))))


def test_caption_changes_only_the_band(rendered):
    rec, raw, _, info = rendered
    last = rec.frames[-1]
    assert not np.array_equal(last, raw)
    rows = np.flatnonzero(np.any(last != raw, axis=(1, 2)))
    assert rows.max() < 120 // 2  # caption band at the top, the rest untouched
    np.testing.assert_array_equal(last[60:], raw[60:])
    lines = rec.caption_lines(info)
    assert "PD" in lines[0] and "front" in lines[0] and "attempt 2" in lines[0]
    assert f"RMSE {rec.tracking_rmse:.4f} rad" in lines[1] and f"/{info['n_marbles']}" in lines[1]
    np.testing.assert_array_equal(video.caption_frame(raw, lines), last)


def test_write_mp4_is_valid_with_expected_length(rendered, tmp_path):
    rec, _, _, _ = rendered
    path = video.write_mp4(rec.frames, tmp_path / "ep.mp4", rec.fps)
    assert path.read_bytes()[4:8] == b"ftyp"  # an ISO base media (MP4) file
    frames, meta = _read(path)
    assert frames.shape == (4, 120, 160, 3)
    assert meta["codec"] == "h264" and meta["fps"] == pytest.approx(20.0)
    assert meta["duration"] == pytest.approx(4 / 20.0, abs=0.03)
    assert [p.name for p in tmp_path.iterdir()] == ["ep.mp4"]  # no temporary file left
    # lossy, but the picture is the one recorded
    assert np.mean(np.abs(frames[-1].astype(float) - rec.frames[-1])) < 12


def test_side_by_side_pads_and_odd_sizes_become_even(rendered, tmp_path):
    rec, raw, _, _ = rendered
    right = [raw[:119, :81]]  # one frame, odd size, lower
    both = video.side_by_side(rec.frames, right)
    assert len(both) == len(rec.frames)
    assert both[0].shape == (120, 160 + 81, 3)
    np.testing.assert_array_equal(both[-1][:119, 160:], raw[:119, :81])  # padded with its last frame
    assert not both[-1][119, 160:].any()  # black row below the lower recording
    frames, _ = _read(video.write_mp4(both, tmp_path / "sbs.mp4", 20))
    assert frames.shape == (4, 120, 242, 3)


def test_errors(tmp_path):
    with pytest.raises(ValueError, match="frames"):
        video.write_mp4([], tmp_path / "x.mp4", 20)
    with pytest.raises(ValueError, match="same shape"):
        video.write_mp4([np.zeros((4, 4, 3), np.uint8), np.zeros((6, 4, 3), np.uint8)], tmp_path / "x.mp4")
    with pytest.raises(ValueError, match="fps"):
        video.write_mp4([np.zeros((4, 4, 3), np.uint8)], tmp_path / "x.mp4", 0)
    with pytest.raises(ValueError, match="uint8"):
        video.write_mp4([np.zeros((4, 4, 3))], tmp_path / "x.mp4")
    with pytest.raises(ValueError, match="recording 1"):
        video.side_by_side([np.zeros((4, 4, 3), np.uint8)], [])
    with pytest.raises(ValueError, match="every"):
        video.EpisodeRecorder("x", every=0)
    assert not list(tmp_path.iterdir())


def test_failed_write_keeps_the_old_file(tmp_path, monkeypatch):
    path = tmp_path / "v.mp4"
    path.write_bytes(b"old")

    def boom(fh, *args, **kwargs):
        fh.write(b"partial")
        raise RuntimeError("encoder died")

    monkeypatch.setattr(iio, "imwrite", boom)
    with pytest.raises(RuntimeError, match="encoder died"):
        video.write_mp4([np.zeros((4, 4, 3), np.uint8)], path)
    assert path.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["v.mp4"]


def test_missing_imageio_fails_only_when_writing(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "imageio", None)
    monkeypatch.setitem(sys.modules, "imageio.v3", None)
    mod = importlib.reload(video)  # imports fine without imageio
    try:
        frames = mod.side_by_side([np.zeros((4, 4, 3), np.uint8)], [np.zeros((4, 4, 3), np.uint8)])
        hint = (r"install the 'video' extra: pip install 'cascgp_jaco-[0-9.]+-py3-none-any\.whl\[video\]' .*, or in a "
                r"source checkout pip install -e '\.\[video\]'")
        with pytest.raises(ImportError, match=hint):
            mod.write_mp4(frames, tmp_path / "x.mp4")
    finally:
        monkeypatch.undo()
        importlib.reload(video)


def test_transfer_video_without_imageio_stops_before_any_episode(tmp_path):
    """``cascgp transfer --video`` without the video extra: a one-line ``error:`` (status 2) naming the install
    command, before any episode runs (nothing written to --out)."""
    import subprocess
    from pathlib import Path

    fake = tmp_path / "noimageio" / "imageio"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("raise ImportError('no imageio here')\n")
    repo = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path / "noimageio"), str(repo)])}
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "cascgp_experiments.cli", "transfer", "--out", str(out), "--quick",
                          "--video", str(out / "video")], env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 2, run.stderr[-2000:]
    assert "--video" in run.stderr and "py3-none-any.whl[video]'" in run.stderr
    assert "Traceback" not in run.stderr and not out.exists()


class _FakeEnv:
    """Minimal env with the runner's observation layout; renders a constant colour; records close()."""

    control_dt = 0.025
    metadata = {"render_fps": 40}
    closed: list[str] = []

    def __init__(self, steps=6):
        self.steps, self.k = steps, 0
        self.task = type("T", (), {"name": "front", "reference": staticmethod(
            lambda t: (np.zeros(6), np.zeros(6), np.zeros(6)))})()

    @property
    def unwrapped(self):
        return self

    def _obs(self):
        return np.concatenate([np.zeros(18), [self.k * self.control_dt]])

    def reset(self, seed=None, options=None):
        self.k, self.options = 0, options
        return self._obs(), {}

    def step(self, action):
        self.k += 1
        info = {"tracking_error": 0.1 * self.k, "marbles_in_jar": self.k, "n_marbles": 10, "time": self.k * 0.025,
                "marbles_spilled": 0}
        return self._obs(), 0.0, self.k >= self.steps, False, info

    def render(self):
        return np.full((12, 16, 3), 80, np.uint8)

    def close(self):
        _FakeEnv.closed.append("closed")


class _Raises:
    dof, name = 6, "raises"

    def start(self, env, info):
        pass

    def __call__(self, *args):
        raise RuntimeError("controller failed")


def test_record_comparison_and_env_closed_on_error(tmp_path):
    _FakeEnv.closed = []
    results = video.record_comparison(_FakeEnv, {"RBD": _pd(), "PD": _pd()}, "front", 0, 1.2, tmp_path / "c.mp4")
    assert list(results) == ["RBD", "PD"] and results["PD"].steps == 6
    assert _FakeEnv.closed == ["closed", "closed"]
    frames, meta = _read(tmp_path / "c.mp4")
    assert frames.shape == (3, 12, 32, 3) and meta["fps"] == pytest.approx(20.0)
    _FakeEnv.closed = []
    with pytest.raises(RuntimeError, match="controller failed"):
        video.record_comparison(_FakeEnv, {"bad": _Raises()}, "front", 0, 1.2, tmp_path / "d.mp4")
    assert _FakeEnv.closed == ["closed"] and not (tmp_path / "d.mp4").exists()
