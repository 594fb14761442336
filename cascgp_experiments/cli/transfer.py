"""Task-transfer pouring episodes: data accumulates across tasks and the model is retrained between attempts.

For every controller, a sequence of pouring tasks in different parts of the workspace
is attempted several times each, then the first task is revisited once. After every
attempt of a learning controller, the measured episode joins a persistent data buffer
(:class:`cascgp.buffer.DataBuffer`) and the model is retrained on everything seen so
far (subsampled to ``--rate`` Hz, at most ``--cap`` samples, warm-started from the
previous hyperparameters). The payload (bottle + marbles + extra mass) is the same
unknown mass throughout, as when a robot keeps holding the same bottle.

Controllers: ``pd`` (feedback only), ``rbd`` (nominal rigid-body feedforward) and any
of the twelve model names of :mod:`cascgp.models`. Before a learning controller has
any data, an SP model is its RBD mean (RBD feedforward) and an NP model is zero (PD).

Usage::

    cascgp transfer --out out/transfer            # full run
    cascgp transfer --out out/demo --quick        # README demo (a few minutes)

    cascgp transfer --out out/transfer --workers 2     # two controllers at a time
    cascgp transfer --out out/transfer --ray local     # the same jobs on a local Ray instance
    cascgp transfer --out out/demo --quick --video out/demo/video   # + side-by-side MP4 clips

Writes ``results.json`` (every attempt's metrics), ``summary.md`` (the summary table),
``transfer.png`` (tracking RMSE and marbles in the jar per attempt) to ``--out``, the
data buffers under ``--out/buffers`` and the job cache (one file per finished controller) under
``--out/cache/transfer``: the same command started again after a kill resumes. The loop:
:mod:`cascgp.learning`; the Jaco experiment: :mod:`cascgp_experiments.transfer`; the parallel
jobs: :mod:`cascgp_experiments.execution`.
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from cascgp_experiments.cli.options import check_output, refuse_other_experiment, settings_error
from cascgp_experiments.execution import add_execution_args, check_args, session
# the presets only: the experiment (torch, MuJoCo) is imported after the options are parsed, so --help is quick
from cascgp_experiments.transfer_presets import FULL_CONTROLLERS, FULL_TASKS, QUICK_CONTROLLERS, QUICK_TASKS

if TYPE_CHECKING:
    from cascgp_experiments.transfer_config import TransferConfig

#: The option that sets each field of :class:`TransferConfig` (error messages name the option).
_OPTIONS = {"rate_hz": "--rate", "payload_mass": "--payload", "attempts": "--attempts", "cap": "--cap",
            "restarts": "--restarts", "seed": "--seed", "sensor_pipeline": "--sensor-pipeline",
            "controllers": "--controllers", "tasks": "--tasks"}


def _config(a: argparse.Namespace) -> TransferConfig:
    """The run's settings from the parsed options (``ValueError`` naming a bad field)."""
    from cascgp_experiments.transfer_config import TransferConfig

    return TransferConfig(
        controllers=tuple(a.controllers.split(",")) if a.controllers is not None else
        (QUICK_CONTROLLERS if a.quick else FULL_CONTROLLERS),
        tasks=tuple(a.tasks.split(",")) if a.tasks is not None else (QUICK_TASKS if a.quick else FULL_TASKS),
        attempts=a.attempts,
        revisit=not a.no_revisit, payload_mass=a.payload, seed=a.seed, rate_hz=a.rate, cap=a.cap,
        restarts=a.restarts, sensor_pipeline=a.sensor_pipeline)


def parse_args(argv: list[str] | None = None, prog: str | None = None
               ) -> tuple[TransferConfig, Path, bool, argparse.Namespace]:
    p = argparse.ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, required=True,
                   help="output folder (created): a new or empty one, or that of an earlier run with the same "
                        "settings, which resumes (--overwrite starts it again)")
    p.add_argument("--quick", action="store_true",
                   help=f"short demo: controllers {','.join(QUICK_CONTROLLERS)}, tasks {','.join(QUICK_TASKS)}")
    p.add_argument("--controllers", type=str, default=None,
                   help=f"comma-separated controller names: pd, rbd, or a model name optionally followed by a gate "
                        f"(-gated, -fgated, -vgated, -igated) and -online (default: "
                        f"{','.join(FULL_CONTROLLERS)}; with --quick, {','.join(QUICK_CONTROLLERS)})")
    p.add_argument("--tasks", type=str, default=None,
                   help=f"comma-separated JacoPour-v0 task names (default: {','.join(FULL_TASKS)}; with --quick, "
                        f"{','.join(QUICK_TASKS)})")
    p.add_argument("--attempts", type=int, default=3, help="attempts per task (default: %(default)s)")
    p.add_argument("--no-revisit", action="store_true", help="do not revisit the first task at the end")
    p.add_argument("--payload", type=float, default=1.2,
                   help="unknown payload mass in the hand (kg; default: %(default)s)")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of the run: attempt i's episode is seeded seed * 1000 + i, the refit after it seed + i "
                        "(default: %(default)s)")
    p.add_argument("--rate", type=float, default=10.0, help="training data rate (Hz; default: %(default)s)")
    p.add_argument("--cap", type=int, default=500, help="maximum training-set size (default: %(default)s)")
    p.add_argument("--restarts", type=int, default=3,
                   help="GP optimiser restarts per retraining (default: %(default)s)")
    p.add_argument("--sensor-pipeline", default="jaco2",
                   help="the env's sensing pipeline: jaco2 (default: the real Jaco 2's signal and link inertials), "
                        "ideal or ideal+FACTOR[+FACTOR...]")
    p.add_argument("--overwrite", action="store_true",
                   help="delete the data buffers and job cache of an earlier run in --out (without it, the same "
                        "command resumes a stopped run)")
    p.add_argument("--video", type=Path, default=None, metavar="DIR",
                   help="write MP4 clips into the folder DIR (needs the 'video' extra, as README's "
                        "install shows): the first and last attempt of every task and the revisit, RBD and the "
                        "learned controller side by side, with RMSE and marbles on the frame. The clips are recorded "
                        "during the attempts: adding or changing --video on a rerun runs the controllers again")
    p.add_argument("--video-controller", type=str, default=None,
                   help="the learned controller shown next to RBD (default: the last controller that learns)")
    add_execution_args(p)
    a = p.parse_args(argv)
    check_output(p, a.out, "--out", "folder")
    refuse_other_experiment(p, a.out, "transfer")
    check_output(p, a.video, "--video", "folder")
    if a.video is not None:
        from cascgp_experiments.video import check_video_writer

        try:
            check_video_writer()  # now, not after the episodes (and before the settings' checks import the env)
        except ImportError as exc:
            p.error(f"--video: {exc}")
    try:  # the settings' checks import no torch: a bad setting is refused at once
        cfg = _config(a)
    except (ValueError, TypeError) as exc:
        settings_error(p, exc, _OPTIONS)
    check_args(p, a)
    if a.video is not None:
        learned = a.video_controller or next((c for c in reversed(cfg.controllers) if c not in ("pd", "rbd")), None)
        if learned is None or learned not in cfg.controllers or "rbd" not in cfg.controllers:
            p.error("--video needs 'rbd' and a learning controller among --controllers")
        from cascgp_experiments.transfer import VideoOptions, video_attempts

        a.video_options = VideoOptions(str(a.video.resolve()), ("rbd", learned), video_attempts(cfg.plan()))
    else:
        if a.video_controller is not None:
            p.error("--video-controller: chooses the learner of --video's clips; give --video DIR too")
        a.video_options = None
    return cfg, a.out, a.overwrite, a


def main(argv: list[str] | None = None, prog: str | None = None) -> None:
    """``cascgp transfer``: parse ``argv`` (``sys.argv[1:]`` when ``None``) and run."""
    cfg, out, overwrite, a = parse_args(argv, prog)
    from cascgp_experiments.transfer import claim_output, run_transfer, write_outputs

    try:
        state = claim_output(cfg, out, overwrite)
    except ValueError as exc:  # an --out folder of another run: an argument error, as argparse reports one
        print(f"{prog or Path(sys.argv[0]).name}: error: {exc}", file=sys.stderr)
        sys.exit(2)
    if state == "resume":
        print(f"resuming the run in {out} (controllers that finished in this folder come from its job cache)",
              file=sys.stderr)
    t0 = time.perf_counter()
    jobs: dict = {}
    with session(a.ray, a.workers):
        runs = run_transfer(cfg, out, workers=a.workers, ray_address=a.ray, stats=jobs, video=a.video_options)
    command = shlex.join([*(prog or "cascgp transfer").split(), *(argv if argv is not None else sys.argv[1:])])
    write_outputs(runs, cfg, out, time.perf_counter() - t0, jobs=jobs, command=command)
    print((out / "summary.md").read_text())
    if a.video_options is not None:
        print(f"videos:  {a.video}/*.mp4")
    print(f"results: {out / 'results.json'}\nplot:    {out / 'transfer.png'}\n"
          f"wall time {time.perf_counter() - t0:.0f} s")
    if jobs.get("n_cached"):
        print(f"({jobs['n_cached']} of {jobs['n_jobs']} controllers came from an earlier run in this folder; the wall "
              f"time is this run's, each controller's own is in results.json's jobs.job_seconds)")


if __name__ == "__main__":
    main()
