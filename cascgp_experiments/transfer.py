"""Task-transfer pouring episodes on ``JacoPour-v0``: data accumulates, the model is retrained between attempts.

For every controller, a sequence of pouring tasks in different parts of the workspace is attempted
several times each, then the first task is revisited once. After every attempt of a learning
controller, the measured episode joins a persistent data buffer and the model is retrained on
everything seen so far (:mod:`cascgp.learning`: subsampled to ``rate_hz``, at most ``cap`` samples,
warm-started from the previous hyperparameters). The payload (bottle + marbles + extra mass) is the
same unknown mass throughout, as when a robot keeps holding the same bottle.

This module owns what is Jaco-specific about the experiment: the env (``JacoPour-v0``), its reset
options (``payload_mass``), the gains and torque limits (``jaco_env``), the nominal URDF, the
presets (:data:`FULL_CONTROLLERS` ..., defined in :mod:`cascgp_experiments.transfer_presets`), the summary table
and the figure. The command line is ``cascgp transfer``.

Parallel: every controller is one job (:func:`controller_job`, its own env; a controller's attempts
stay sequential because its data accumulate), run by :mod:`cascgp_experiments.execution` on local
processes or a Ray cluster, cached per controller so that a killed run resumes. Attempt ``i`` is seeded
``seed * 1000 + i`` whatever runs it, so the attempts do not depend on the worker count.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Iterator

import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")


import jaco_env  # registers the environments
from cascgp.io import atomic_write_text, read_json, write_json
from cascgp.learning import (PLAIN_CONTROLLERS, Attempt, AttemptContext, ControllerRun, Feedback, RunHooks,
                             run_controller)
from cascgp.rbd import load_nominal
from cascgp_experiments.common import DISTRIBUTION, machine_info, package_versions, save_figure
from cascgp_experiments.run_hooks import PairedEpisodes
from cascgp_experiments.transfer_config import TransferConfig
# the presets, here too for the callers that take them from this module
from cascgp_experiments.transfer_presets import (ENV_ID, FULL_CONTROLLERS, FULL_TASKS, QUICK_CONTROLLERS,  # noqa: F401
                                                 QUICK_TASKS)
from jaco_env import nominal_urdf


def jaco_feedback() -> Feedback:
    """The Jaco 2's PD gains (``jaco_env.DEFAULT_KP``/``DEFAULT_KD``) and torque limits."""
    return Feedback(jaco_env.DEFAULT_KP, jaco_env.DEFAULT_KD, jaco_env.robot.TORQUE_LIMITS)


@dataclass(frozen=True)
class VideoOptions:
    """What ``--video DIR`` records: the attempts ``attempts`` (plan indices) of ``controllers``, rendered at
    ``width`` x ``height`` every ``fps`` frames per second (``shadow_size`` 0: no shadows, ~10x faster)."""

    folder: str
    controllers: tuple[str, ...]
    attempts: tuple[int, ...]
    fps: float = 10.0
    width: int = 320
    height: int = 240
    shadow_size: int = 0


def video_attempts(plan: list[Attempt]) -> tuple[int, ...]:
    """The attempts worth watching: the first and the last training attempt of every task, and the revisit."""
    chosen = set()
    for task in dict.fromkeys(t for t, _, _ in plan):
        idx = [i for i, (t, _, ph) in enumerate(plan) if t == task and ph == "train"]
        chosen.update(idx[:1] + idx[-1:])
    chosen.update(i for i, (_, _, ph) in enumerate(plan) if ph == "revisit")
    return tuple(sorted(chosen))


def controller_job(config: dict[str, Any], name: str, buffer_dir: str | None,
                   video: dict[str, Any] | None = None, paired: list[str] | None = None,
                   compiled: bool | None = None) -> list[dict[str, Any]]:
    """One job of :func:`run_transfer`: every attempt of one controller, on its own env (the attempts of a
    learning controller are sequential: its data accumulate). ``buffer_dir`` belongs to this job: it is
    emptied first, so a retried or resumed job starts again from no data. ``video``: a
    :class:`VideoOptions` as a dict; the chosen attempts of this controller are written to
    ``<folder>/<controller>/<attempt>.mp4`` (rendering does not change the simulation). ``paired``: controllers
    evaluated on this controller's model after every attempt (:class:`~cascgp_experiments.run_hooks.PairedEpisodes`).
    ``compiled``: whether the control tick and online sample run compiled (the ``fast`` extra), as the run that
    planned the job found (:func:`run_transfer` always says); they agree with the NumPy path to round-off only, and
    a learning loop carries that forward, so the job runs the path it was keyed with (a worker that cannot run the
    compiled loops refuses ``True``). ``None`` leaves the process's setting alone.
    Returns the attempt records."""
    with contextlib.nullcontext() if compiled is None else kernel_path(compiled):
        return _controller_attempts(config, name, buffer_dir, video, paired)


@contextlib.contextmanager
def kernel_path(compiled: bool) -> Iterator[None]:
    """Run the block on the compiled loops (``compiled``; ``RuntimeError`` where Numba is missing) or on the NumPy
    path (``CASCGP_JIT=0`` for the block, restored afterwards)."""
    from cascgp.models.fastkernel import jit_enabled

    if compiled:
        if not jit_enabled():
            raise RuntimeError("this job was planned with the compiled control tick (the fast extra, Numba), which "
                               "this worker cannot run (Numba missing, or CASCGP_JIT=0 set here): install "
                               f"{DISTRIBUTION}[fast] on every worker, or run the whole command with CASCGP_JIT=0")
        yield
        return
    old = os.environ.get("CASCGP_JIT")
    os.environ["CASCGP_JIT"] = "0"
    try:
        yield
    finally:
        if old is None:
            del os.environ["CASCGP_JIT"]
        else:
            os.environ["CASCGP_JIT"] = old


def _controller_attempts(config: dict[str, Any], name: str, buffer_dir: str | None, video: dict[str, Any] | None,
                         paired: list[str] | None) -> list[dict[str, Any]]:
    cfg = TransferConfig.from_dict(config)
    if buffer_dir is not None:
        shutil.rmtree(buffer_dir, ignore_errors=True)
    opts = VideoOptions(**{**video, "controllers": tuple(video["controllers"]),
                           "attempts": tuple(video["attempts"])}) if video else None
    recording = opts is not None and name in opts.controllers
    if recording:
        from cascgp_experiments.video import make_video_env

        env = make_video_env(opts.width, opts.height, shadow_size=opts.shadow_size, n_marbles=cfg.n_marbles,
                             sensor_pipeline=cfg.sensor_pipeline)
    else:
        env = cfg.make_env()
    # The nominal model has the simulated arm's link inertials (the env option link_inertials); the payload stays
    # unknown to it.
    rbd = load_nominal(nominal_urdf(env.unwrapped.link_inertials))
    try:
        hooks: list[RunHooks] = [_JobProgress(opts if recording else None, env)]
        if paired:
            hooks.append(PairedEpisodes(name, paired, env, rbd, jaco_feedback()))
        run = run_controller(name, env, cfg.plan(), rbd, jaco_feedback(), cfg.retrain(),
                             reset_options=cfg.reset_options(), buffer_dir=buffer_dir,
                             model_factory=cfg.model_factory(), hooks=hooks)
    finally:
        env.close()
    return run.attempts


class _JobProgress(RunHooks):
    """A job's progress line after every attempt and, with ``opts``, its chosen attempts as MP4 files."""

    def __init__(self, opts: VideoOptions | None, env: Any) -> None:
        self.opts, self.env = opts, env
        self.recorders: dict[int, Any] = {}

    def episode_callback(self, ctx: AttemptContext) -> Any | None:
        if self.opts is None or ctx.index not in self.opts.attempts:
            return None
        from cascgp_experiments.video import EpisodeRecorder, every_for_fps

        self.recorders[ctx.index] = EpisodeRecorder(
            ctx.name, task=ctx.attempt[0], attempt=ctx.attempt[1] + 1,
            every=every_for_fps(self.env.unwrapped.control_dt, self.opts.fps))
        return self.recorders[ctx.index]

    def after_attempt(self, ctx: AttemptContext, record: dict[str, Any]) -> None:
        from cascgp_experiments.execution import report_progress

        rec = self.recorders.pop(ctx.index, None)
        if self.opts is not None and rec is not None and rec.frames:
            from cascgp_experiments.video import write_mp4

            write_mp4(rec.frames, Path(self.opts.folder) / ctx.name / f"{ctx.index:02d}.mp4", rec.fps)
        report_progress(1, f"{ctx.name} {record['task']}#{record['task_attempt']} "
                           f"rmse={record['tracking_rmse']:.3f} jar={record['in_jar']:.2f}")


def compose_videos(opts: VideoOptions, plan: list[Attempt]) -> list[Path]:
    """Side-by-side clips, ``<folder>/<attempt>_<task>_attempt<k>.mp4``: the controllers of ``opts`` left to
    right (RBD first when recorded), each captioned with its running RMSE and marbles in the jar."""
    import imageio.v3 as iio

    from cascgp_experiments.video import side_by_side, write_mp4

    folder = Path(opts.folder)
    made = []
    for i in opts.attempts:
        parts = [folder / name / f"{i:02d}.mp4" for name in opts.controllers]
        if not all(p.exists() for p in parts):
            continue
        clips = [list(iio.imiter(p)) for p in parts]
        task, k, _ = plan[i]
        made.append(write_mp4(side_by_side(*clips), folder / f"{i:02d}_{task}_attempt{k + 1}.mp4", opts.fps))
    return made


def transfer_cache(out: Path) -> Path:
    """Where a run in ``out`` keeps its job cache (one finished controller per file) and its settings."""
    return Path(out) / "cache" / "transfer"


def claim_output(cfg: TransferConfig, out: Path, overwrite: bool = False) -> str:
    """Make ``out`` ready for a run of ``cfg``; returns ``"new"``, ``"resume"`` or ``"overwrite"``.

    An earlier run's buffers are deleted with ``overwrite``; a run of the same settings that was
    stopped is resumed (the controllers it finished come from the job cache); anything else in
    ``out/buffers`` is an error (``ValueError``), so that no data are mixed or lost."""
    from cascgp.models.fastkernel import jit_enabled

    out = Path(out)
    buffers, cache = out / "buffers", transfer_cache(out)
    settings = cache / "settings.json"
    want = {**cfg.to_dict(), "compiled_kernels": jit_enabled()}  # the kernel path changes a learner's attempts
    have = read_json(settings) if settings.exists() else None
    if overwrite:
        had = buffers.exists() or cache.exists()
        shutil.rmtree(buffers, ignore_errors=True)
        shutil.rmtree(cache, ignore_errors=True)
        state = "overwrite" if had else "new"
    elif have == want:
        state = "resume"
    elif buffers.exists() and any(buffers.iterdir()):
        path = ""
        if isinstance(have, dict) and {k: v for k, v in have.items() if k != "compiled_kernels"} == cfg.to_dict():
            ran = "with" if have.get("compiled_kernels") else "without"
            path = (f" (it ran {ran} the fast extra's compiled loops, this run "
                    f"{'with' if want['compiled_kernels'] else 'without'}; CASCGP_JIT=0 turns them off)")
        raise ValueError(f"{buffers} holds data from an earlier run with other settings{path}; choose a new --out "
                         "folder or pass --overwrite")
    else:
        shutil.rmtree(cache, ignore_errors=True)
        state = "new"
    write_json(settings, want)
    return state


def run_transfer(cfg: TransferConfig, out: Path | None = None, show_progress: bool = True, *,
                 workers: int | None = None, ray_address: str | None = None, stats: dict[str, Any] | None = None,
                 video: VideoOptions | None = None) -> list[ControllerRun]:
    """Run the whole experiment: one job per controller (:func:`controller_job`) through
    :func:`cascgp_experiments.execution.run_jobs` (``workers`` local processes, ``None``: every core, or
    the Ray cluster at ``ray_address``); the attempts do not depend on either.

    ``out`` (if given) receives the data buffers under ``out/buffers/<controller>`` and the job cache
    under ``out/cache/transfer`` (:func:`claim_output` checks it: buffers of a run with other settings are
    refused with ``ValueError``): a killed run started again with the same settings resumes with the
    controllers that had not finished. ``stats`` (a dict), if given, receives the job statistics
    (:meth:`cascgp_experiments.execution.JobResults.stats`). ``video``: record the chosen attempts
    (:func:`controller_job`) and compose the side-by-side clips (:func:`compose_videos`)."""
    from cascgp.models.fastkernel import jit_enabled
    from cascgp_experiments.execution import run_jobs

    if out is not None:
        claim_output(cfg, out)  # refuses buffers of a run with other settings (the CLI may have cleared them)
    plan = cfg.plan()
    config = cfg.to_dict()
    jobs = [{"config": config, "name": name,
             "buffer_dir": None if out is None else str(Path(out).resolve() / "buffers" / name)}
            for name in cfg.controllers]
    compiled = jit_enabled()
    for job in jobs:  # the kernel path is part of the job's key, and the job runs on it
        job["compiled"] = compiled
    if video is not None:  # only then: the job cache keys of runs without video stay the same
        for job in jobs:
            job["video"] = {**asdict(video), "controllers": list(video.controllers), "attempts": list(video.attempts)}
    res = run_jobs(controller_job, jobs, workers=workers, ray_address=ray_address,
                   cache_dir=None if out is None else transfer_cache(out), desc="attempts",
                   units=[len(plan)] * len(jobs), unit="attempt",
                   priority=[name not in PLAIN_CONTROLLERS for name in cfg.controllers],
                   label=lambda j: j["name"], show_progress=show_progress)
    runs = [ControllerRun(name, list(attempts)) for name, attempts in zip(cfg.controllers, res)]
    if video is not None:
        compose_videos(video, plan)
    if stats is not None:
        stats.update(res.stats(), labels=list(cfg.controllers), compiled_kernels=compiled)
    return runs


def summary_table(runs: list[ControllerRun]) -> str:
    """Markdown table: per controller, tracking RMSE and marbles in the jar on first/last attempts."""
    def fmt(attempt: dict[str, Any] | None, key: str, spec: str) -> str:
        return "-" if attempt is None else format(attempt[key], spec)

    lines = ["| controller | first attempt RMSE (rad) | last train attempt RMSE (rad) | revisit RMSE (rad) "
             "| mean in jar | last train in jar | revisit in jar |",
             "|---|---|---|---|---|---|---|"]
    for run in runs:
        train = [a for a in run.attempts if a["phase"] == "train"]
        revisit = next((a for a in run.attempts if a["phase"] == "revisit"), None)
        mean_jar = np.mean([a["in_jar"] for a in run.attempts])
        lines.append(f"| {run.name} | {fmt(train[0], 'tracking_rmse', '.4f')} "
                     f"| {fmt(train[-1], 'tracking_rmse', '.4f')} "
                     f"| {fmt(revisit, 'tracking_rmse', '.4f')} | {mean_jar:.2f} | {fmt(train[-1], 'in_jar', '.2f')} "
                     f"| {fmt(revisit, 'in_jar', '.2f')} |")
    return "\n".join(lines)


def per_task_table(results: dict[str, Any]) -> str:
    """Markdown: per controller and task, tracking RMSE (rad) and marbles in the jar on the first and on the last
    training attempt (the revisit is in :func:`summary_table`), from ``results.json`` alone."""
    tasks = list(results["config"]["tasks"])
    head = "| controller | " + " | ".join(f"{t}: first | {t}: last" for t in tasks) + " | mean in jar |"
    lines = [head, "|---|" + "---|---|" * len(tasks) + "---|"]
    for name, attempts in results["controllers"].items():
        cells = []
        for task in tasks:
            tr = [a for a in attempts if a["task"] == task and a["phase"] == "train"]
            for a in (tr[0], tr[-1]):
                cells.append(f"{a['tracking_rmse']:.3f} ({a['in_jar']:.0%})")
        jar = np.mean([a["in_jar"] for a in attempts])
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {jar:.2f} |")
    return "\n".join(lines)


def plot(results: dict[str, Any], path: Path) -> None:
    """Tracking RMSE and fraction of marbles in the jar against attempt number (from the JSON alone)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    for name, attempts in results["controllers"].items():
        x = [a["attempt"] + 1 for a in attempts]
        axes[0].plot(x, [a["tracking_rmse"] for a in attempts], "o-", label=name)
        axes[1].plot(x, [a["in_jar"] for a in attempts], "o-", label=name)
    first = next(iter(results["controllers"].values()))
    for a in first:
        if a["task_attempt"] == 0 or a["phase"] == "revisit":
            for ax in axes:
                ax.axvline(a["attempt"] + 0.5, color="0.85", lw=1, zorder=0)
            axes[0].annotate(a["task"] + (" (revisit)" if a["phase"] == "revisit" else ""),
                             (a["attempt"] + 0.6, 1.0), xycoords=("data", "axes fraction"),
                             va="top", fontsize=8, color="0.4")
    axes[0].set_yscale("log")
    axes[0].set_ylabel("tracking RMSE (rad)")
    axes[1].set_ylabel("fraction of marbles in jar")
    axes[1].set_ylim(-0.05, 1.05)
    axes[1].set_xlabel("attempt (results.json's \"attempt\" + 1)")
    axes[0].legend(fontsize=8, ncol=3)
    fig.suptitle(f"Task transfer, unknown payload {results['config']['payload_mass']} kg")
    fig.tight_layout()
    save_figure(fig, path, dpi=120)
    plt.close(fig)


def write_outputs(runs: list[ControllerRun], cfg: TransferConfig, out: Path, wall_s: float,
                  jobs: dict[str, Any] | None = None, command: str = "") -> dict[str, Any]:
    """Write ``results.json``, ``summary.md`` and ``transfer.png`` into ``out``; returns the results dict.
    ``jobs``: the job statistics of the run (workers, backend, seconds per controller), stored as ``"jobs"``;
    ``command``: the command line that ran it, stored in ``"provenance"``."""
    from cascgp.models.fastkernel import jit_enabled

    compiled = (jobs or {}).get("compiled_kernels", jit_enabled())  # the path the jobs were planned and run on
    results = {
        "config": cfg.to_dict(),
        "wall_seconds": wall_s,
        "controllers": {run.name: run.attempts for run in runs},
        "provenance": {"command": command, "versions": package_versions(), "compiled_kernels": compiled,
                       "machine": machine_info(),
                       "written_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())},
    }
    if jobs is not None:
        results["jobs"] = jobs
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "results.json", results, indent=2)
    atomic_write_text(out / "summary.md", summary_table(runs) + "\n")
    plot(results, out / "transfer.png")
    return results
