"""Videos of pouring episodes: captioned frames recorded during :func:`cascgp.episodes.run_episode`,
side-by-side comparisons of controllers, MP4 files (H.264).

=============================  ==================================================================
piece                          what it does
=============================  ==================================================================
:class:`EpisodeRecorder`       the runner's ``callback``: renders every ``every``-th control tick
                               and writes a caption on it (controller label, task, attempt, the
                               running tracking RMSE so far and the marbles in the jar)
:func:`caption_frame`          writes lines of text on a dark band at the top of a frame (Pillow)
:func:`side_by_side`           composes recordings left to right, frame by frame
:func:`write_mp4`              H.264 / yuv420p MP4 (imageio + imageio-ffmpeg), written atomically
:func:`record_episode`         one episode with a recorder
:func:`record_comparison`      every controller on the same task, seed and payload, one MP4 with
                               the recordings side by side
:func:`make_video_env`         ``JacoPour-v0`` that renders (``render_mode="rgb_array"``), closer camera
=============================  ==================================================================

The running RMSE on a frame is ``sqrt(mean(tracking_error**2))`` over every control tick so far
(rendered or not), so the last frame shows the episode's
:attr:`~cascgp.episodes.EpisodeResult.tracking_rmse`.

Frame rate: the recorder renders ticks ``every, 2 every, ...``; a video plays in real time at
``fps = 1 / (control_dt * every)`` (20 fps for ``every=2`` at the Jaco's 40 Hz control,
:func:`every_for_fps`). An episode of ``steps`` ticks gives ``steps // every`` frames.

Writing MP4 needs the optional packages ``imageio`` and ``imageio-ffmpeg`` (the ``video`` extra,
:data:`INSTALL_HINT`; ffmpeg comes bundled with imageio-ffmpeg). This module imports them only when a
file is written, so recording and composing work without them; :func:`write_mp4` raises an
``ImportError`` naming the install command when they are missing. Rendering is headless with
``MUJOCO_GL=egl`` (set by default here, as in :mod:`cascgp_experiments.transfer`).
"""

from __future__ import annotations

import math
import os
from functools import lru_cache
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")

from cascgp.episodes import EpisodeResult, run_episode
from cascgp.io import atomic_write
from cascgp_experiments.common import install_hint

__all__ = ["DEFAULT_FPS", "INSTALL_HINT", "EpisodeRecorder", "caption_frame", "every_for_fps", "side_by_side",
           "write_mp4", "check_video_writer", "record_episode", "record_comparison", "make_video_env", "VIDEO_CAMERA"]

#: Default frame rate of the videos (frames per second of simulated time, played in real time).
DEFAULT_FPS = 20.0
INSTALL_HINT = install_hint("video")
_BAND_ALPHA = 0.6  # opacity of the dark band behind the caption


# --------------------------------------------------------------------------- captions
@lru_cache(maxsize=16)
def _font(size: int) -> Any:
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)  # scalable with FreeType (Pillow >= 10.1)
    except (TypeError, ImportError, OSError):  # Pillow without FreeType: the fixed bitmap font
        return ImageFont.load_default()


def _text_width(draw: Any, text: str, font: Any) -> float:
    return float(draw.textlength(text, font=font))


def caption_frame(frame: np.ndarray, lines: Sequence[str]) -> np.ndarray:
    """A copy of ``frame`` (H, W, 3) uint8 with ``lines`` written in white on a dark band at the top.

    The font size follows the frame height (about H/18 px, at least 8) and shrinks until the
    longest line fits the width. Pixels below the band are unchanged.
    """
    from PIL import Image, ImageDraw

    img = _as_rgb(frame, "frame")
    lines = [str(s) for s in lines if str(s)]
    if not lines:
        return img.copy()
    h, w = img.shape[:2]
    size = max(8, h // 18)
    probe = ImageDraw.Draw(Image.new("RGB", (1, 1)))
    while size > 8 and max(_text_width(probe, s, _font(size)) for s in lines) > w - 8:
        size -= 1
    font = _font(size)
    line_h = size + max(2, size // 4)
    band = min(h, 4 + line_h * len(lines) + 2)
    out = img.copy()
    out[:band] = (out[:band].astype(np.float32) * (1.0 - _BAND_ALPHA)).astype(np.uint8)
    pil = Image.fromarray(out)
    draw = ImageDraw.Draw(pil)
    for i, text in enumerate(lines):
        draw.text((4, 3 + i * line_h), text, fill=(255, 255, 255), font=font)
    result = np.asarray(pil).copy()
    result[band:] = img[band:]  # only the band changes
    return result


def _as_rgb(frame: Any, what: str) -> np.ndarray:
    a = np.asarray(frame)
    if a.ndim != 3 or a.shape[2] not in (3, 4) or a.shape[0] < 1 or a.shape[1] < 1:
        raise ValueError(f"{what} must be an RGB image of shape (H, W, 3), got shape {a.shape}")
    if a.dtype != np.uint8:
        raise ValueError(f"{what} must have dtype uint8, got {a.dtype}")
    return a[..., :3]


# --------------------------------------------------------------------------- recording
def every_for_fps(control_dt: float, fps: float = DEFAULT_FPS) -> int:
    """Render every how many control ticks for about ``fps`` frames per second (at least 1)."""
    if not (math.isfinite(control_dt) and control_dt > 0):
        raise ValueError(f"control_dt must be a positive number of seconds, got {control_dt!r}")
    if not (math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be a positive number, got {fps!r}")
    return max(1, int(round(1.0 / (control_dt * fps))))


class EpisodeRecorder:
    """Callback for :func:`cascgp.episodes.run_episode` that records captioned frames.

    Args:
        label: the controller's label on the frames (e.g. ``"RBD"``, ``"SP-Inward"``).
        task: task name on the frames; ``None``: read ``env.task.name`` at the first tick.
        attempt: attempt number on the frames, shown as given (``None``: not shown).
        every: render every ``every``-th control tick (ticks ``every, 2 every, ...``).
        caption: write the caption (``False``: the raw renders).

    The environment must render RGB arrays (``render_mode="rgb_array"``). After the episode,
    :attr:`frames` holds the frames, :attr:`fps` the real-time frame rate
    (``1 / (env.control_dt * every)``, or ``metadata["render_fps"] / every``) and
    :attr:`tracking_rmse` the RMSE of ``info["tracking_error"]`` over all ticks. One recorder per
    episode.
    """

    def __init__(self, label: str, *, task: str | None = None, attempt: int | None = None, every: int = 2,
                 caption: bool = True) -> None:
        if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
            raise ValueError(f"every must be a positive integer, got {every!r}")
        self.label = str(label)
        self.task = task
        self.attempt = attempt
        self.every = int(every)
        self.caption = bool(caption)
        self.frames: list[np.ndarray] = []
        self.fps: float | None = None
        self.ticks = 0
        self._sq_sum = 0.0
        self._n_err = 0

    @property
    def tracking_rmse(self) -> float:
        """RMSE of ``info["tracking_error"]`` over the ticks so far (rad; NaN before any)."""
        return math.sqrt(self._sq_sum / self._n_err) if self._n_err else float("nan")

    def caption_lines(self, info: Mapping[str, Any]) -> list[str]:
        """The caption of the frame of the current tick."""
        head = self.label
        if self.task is not None:
            head += f" | task {self.task}"
        if self.attempt is not None:
            head += f" | attempt {self.attempt}"
        rmse = self.tracking_rmse
        body = [f"RMSE {rmse:.4f} rad" if math.isfinite(rmse) else "RMSE -"]
        n = info.get("n_marbles") or 0
        if n:
            body.append(f"jar {int(info.get('marbles_in_jar', 0))}/{int(n)}")
        if "time" in info:
            body.append(f"t {float(info['time']):.1f} s")
        return [head, " | ".join(body)]

    def __call__(self, env: Any, info: Mapping[str, Any]) -> None:
        self.ticks += 1
        err = info.get("tracking_error")
        if err is not None and math.isfinite(float(err)):
            self._sq_sum += float(err) ** 2
            self._n_err += 1
        if self.task is None:
            task = getattr(env, "task", None)
            self.task = getattr(task, "name", None) if task is not None else info.get("task")
        if self.fps is None:
            dt = getattr(env, "control_dt", None)
            if dt:
                self.fps = 1.0 / (float(dt) * self.every)
            else:
                self.fps = float(getattr(env, "metadata", {}).get("render_fps", DEFAULT_FPS * self.every)) / self.every
        if self.ticks % self.every:
            return
        frame = env.render()
        if not isinstance(frame, np.ndarray) or frame.ndim != 3:
            raise RuntimeError(f"env.render() returned {type(frame).__name__}, not an RGB array: make the env with "
                               "render_mode='rgb_array' (e.g. cascgp_experiments.video.make_video_env)")
        frame = _as_rgb(frame, "env.render()")
        self.frames.append(caption_frame(frame, self.caption_lines(info)) if self.caption else frame.copy())


# --------------------------------------------------------------------------- composing and writing
def side_by_side(*recordings: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Compose recordings left to right: frame k is the recordings' frames k next to each other.

    A shorter recording is padded with its last frame; a lower one with black rows at the bottom.
    The width is the sum of the widths. Usual call: ``side_by_side(left_frames, right_frames)``.
    """
    if not recordings:
        raise ValueError("side_by_side needs at least one recording")
    recs = []
    for i, rec in enumerate(recordings):
        rec = list(rec)
        if not rec:
            raise ValueError(f"recording {i} of side_by_side has no frames")
        shapes = {np.shape(f) for f in rec}
        if len(shapes) != 1:
            raise ValueError(f"recording {i} of side_by_side has frames of different shapes: {sorted(shapes)}")
        recs.append([_as_rgb(f, f"frame of recording {i}") for f in rec])
    n = max(len(r) for r in recs)
    height = max(r[0].shape[0] for r in recs)
    out = []
    for k in range(n):
        parts = []
        for r in recs:
            f = r[min(k, len(r) - 1)]
            if f.shape[0] < height:
                f = np.concatenate([f, np.zeros((height - f.shape[0],) + f.shape[1:], np.uint8)], axis=0)
            parts.append(f)
        out.append(np.concatenate(parts, axis=1))
    return out


def check_video_writer() -> None:
    """``ImportError`` naming the install command (:data:`INSTALL_HINT`) unless MP4 files can be written, e.g.
    before a run that records video, so that it fails at once rather than after its episodes."""
    _imageio()


def _imageio() -> Any:
    try:
        import imageio.v3 as iio
        import imageio_ffmpeg  # noqa: F401  (the FFMPEG plugin needs it; fail here with the hint)
    except ImportError as exc:
        raise ImportError(f"writing MP4 video needs imageio and imageio-ffmpeg: {INSTALL_HINT}") from exc
    return iio


def _even(frame: np.ndarray) -> np.ndarray:
    h, w = frame.shape[:2]
    if h % 2 == 0 and w % 2 == 0:
        return frame
    return np.pad(frame, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")


def write_mp4(frames: Sequence[np.ndarray], path: str | os.PathLike, fps: float = DEFAULT_FPS) -> Path:
    """Write ``frames`` ((H, W, 3) uint8, all the same size) to ``path`` as an H.264 MP4 (yuv420p).

    An odd height or width is padded by one row/column (repeating the edge), as yuv420p needs
    even sizes; the file has ``len(frames)`` frames at ``fps`` (duration ``len(frames) / fps``).
    The file is written atomically (:func:`cascgp.io.atomic_write`): a temporary file in the same
    folder, then ``os.replace``; on any error ``path`` is left as it was and no temporary file stays.
    Returns ``path``. Needs ``imageio`` and ``imageio-ffmpeg`` (:data:`INSTALL_HINT`).
    """
    frames = list(frames)
    if not frames:
        raise ValueError("frames is empty: nothing to write (did the env render? render_mode='rgb_array')")
    shapes = {np.shape(f) for f in frames}
    if len(shapes) != 1:
        raise ValueError(f"frames must all have the same shape, got {sorted(shapes)}")
    frames = [_even(_as_rgb(f, "each of frames")) for f in frames]
    if isinstance(fps, bool) or not isinstance(fps, (int, float, np.integer, np.floating)) or \
            not math.isfinite(fps) or fps <= 0:
        raise ValueError(f"fps must be a positive number, got {fps!r}")
    iio = _imageio()

    def write(fh: Any) -> None:
        # imageio encodes through ffmpeg into its own temporary file and copies it into fh.
        iio.imwrite(fh, frames, plugin="FFMPEG", extension=".mp4", is_batch=True, fps=float(fps),
                    codec="libx264", pixelformat="yuv420p", macro_block_size=1,
                    output_params=["-movflags", "+faststart"])

    return atomic_write(path, write)


# --------------------------------------------------------------------------- episodes
#: Camera of :func:`make_video_env`: the env's default view (``jaco_env.envs.base.DEFAULT_CAMERA``), closer,
#: framing the arm and every default task's jar.
VIDEO_CAMERA: dict[str, Any] = {"distance": 1.5, "azimuth": 150.0, "elevation": -22.0,
                                "lookat": np.array([0.35, 0.0, 0.3])}


def make_video_env(width: int = 320, height: int = 240, camera: Mapping[str, Any] | None = VIDEO_CAMERA,
                   shadow_size: int | None = 2048, **kwargs: Any) -> Any:
    """``gym.make("JacoPour-v0", render_mode="rgb_array", width=width, height=height, **kwargs)`` viewed
    from ``camera`` (free-camera settings; ``None``: the env's default camera).

    ``shadow_size``: side of the shadow map (px; ``None``: the model's 4096; ``0``: no shadows). With
    software EGL (measured at 320 x 240 on a shared CPU) a frame takes about 0.2-0.3 s with 4096, 0.15 s
    with 2048 (same picture), 0.02-0.03 s without shadows; 1024 shows speckle artefacts. Only rendering
    changes: the simulation is the same as without ``render_mode``.
    """
    import gymnasium as gym

    import jaco_env  # noqa: F401  (registers the environments)

    env = gym.make("JacoPour-v0", render_mode="rgb_array", width=width, height=height, **kwargs)
    u = env.unwrapped
    # Both are read when Gymnasium's MujocoRenderer creates its viewer and GL context (first render).
    if camera is not None:
        u.mujoco_renderer.default_cam_config = {k: (np.array(v, dtype=float) if k == "lookat" else v)
                                                for k, v in camera.items()}
    if shadow_size is not None:
        if int(shadow_size) <= 0:
            u.model.light_castshadow[:] = 0
        else:
            u.model.vis.quality.shadowsize = int(shadow_size)
    return env


def record_episode(env: Any, controller: Any, label: str, *, seed: int | None = None,
                   options: dict[str, Any] | None = None, attempt: int | None = None, fps: float = DEFAULT_FPS,
                   meta: dict[str, Any] | None = None) -> tuple[EpisodeResult, EpisodeRecorder]:
    """Run one episode (:func:`cascgp.episodes.run_episode`) with an :class:`EpisodeRecorder` at about ``fps``.

    ``env`` must render RGB arrays; it is not closed here. Returns the result and the recorder
    (``recorder.frames``, ``recorder.fps``).
    """
    dt = getattr(env.unwrapped, "control_dt", None)
    every = every_for_fps(float(dt), fps) if dt else 1
    task = (options or {}).get("task")
    recorder = EpisodeRecorder(label, task=None if task is None else getattr(task, "name", str(task)),
                               attempt=attempt, every=every)
    result = run_episode(env, controller, seed=seed, options=options, meta=meta, callback=recorder)
    return result, recorder


def record_comparison(env_factory: Callable[[], Any] | None, controllers: Mapping[str, Any], task: str,
                      seed: int | None, payload: float | None, path: str | os.PathLike, *,
                      attempt: int | None = None, fps: float = DEFAULT_FPS,
                      options: dict[str, Any] | None = None) -> dict[str, EpisodeResult]:
    """Run every controller on the same task, seed and payload with rendering, and write one MP4
    with the recordings side by side (in the order of ``controllers``).

    Args:
        env_factory: ``() -> env`` rendering RGB arrays (one fresh env per controller, closed after
            its episode, also on error); ``None``: :func:`make_video_env` (320 x 240 per side).
        controllers: label on the frames -> controller (e.g. ``{"RBD": ..., "SP-Inward": ...}``).
        task: the task, reset option ``"task"``.
        seed: the reset seed, the same for every controller.
        payload: reset option ``"payload_mass"`` (kg); ``None``: not set.
        path: the MP4 file (written atomically by :func:`write_mp4`).
        attempt: attempt number on the frames (shown as given).
        fps: frame rate (the recorders render every :func:`every_for_fps` ticks).
        options: further reset options.

    Returns:
        label -> the :class:`~cascgp.episodes.EpisodeResult` of its episode.
    """
    if not controllers:
        raise ValueError("controllers is empty: give at least one label -> controller")
    _imageio()  # fail before minutes of rendering if the video packages are missing
    factory = env_factory if env_factory is not None else make_video_env
    opts = {**(options or {}), "task": task}
    if payload is not None:
        opts["payload_mass"] = payload
    results: dict[str, EpisodeResult] = {}
    recordings = []
    rate = None
    for label, controller in controllers.items():
        env = factory()
        try:
            result, recorder = record_episode(env, controller, label, seed=seed, options=opts, attempt=attempt,
                                              fps=fps)
        finally:
            env.close()
        results[label] = result
        recordings.append(recorder.frames)
        rate = rate or recorder.fps
    write_mp4(side_by_side(*recordings), path, rate or fps)
    return results
