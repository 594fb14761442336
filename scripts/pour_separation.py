"""Pour separation: oracle vs nominal rigid-body feedforward vs PD only, per default task.

    python -m scripts.pour_separation --out out/pour_separation [--tasks front near ...]
        [--payload 1.2] [--seed 0] [--n-marbles 30] [--jobs 2]

For every task of ``jaco_env.tasks.DEFAULT_TASKS`` runs one seed-fixed ``JacoPour-v0`` episode
(torque mode, the default sensing pipeline and noise, payload fixed) with each controller

* ``oracle``: :class:`jaco_env.oracle.OracleController` (MuJoCo inverse dynamics of the true
  rigid scene, marbles lumped) + PD,
* ``nominal``: :class:`cascgp.controller.FeedforwardController` with the nominal rigid-body
  model ``jaco_env.nominal_urdf`` of the env's link inertials (10% calibration error, no payload, no
  friction) + PD,
* ``pd``: the same PD feedback without feedforward,

all with ``jaco_env.DEFAULT_KP/KD``, run by the one episode runner ``cascgp.episodes.run_episode``
(``wall s``: the whole episode, reset included). Prints a table of joint tracking RMSE (rad), the mouth's
horizontal position error while pouring (mean and max over the pour window, cm) and the
fraction of marbles in the jar, and writes ``pour_separation.json`` into ``--out``.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from cascgp_experiments.cli.options import check_output

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402

CONTROLLERS = ("oracle", "nominal", "pd")


def make_controller(controller: str, link_inertials: str = "kinova"):
    """The controller named ``controller`` (one of ``CONTROLLERS``), all with ``jaco_env.DEFAULT_KP/KD``;
    ``"nominal"`` with the nominal URDF of the simulated arm's ``link_inertials`` (the env option)."""
    from jaco_env import DEFAULT_KD, DEFAULT_KP, nominal_urdf, robot
    from jaco_env.oracle import OracleController, PDController

    if controller == "oracle":
        return OracleController()
    if controller == "pd":
        return PDController()
    if controller == "nominal":
        from cascgp.controller import FeedforwardController
        from cascgp.rbd import load_nominal

        return FeedforwardController(load_nominal(nominal_urdf(link_inertials)), DEFAULT_KP, DEFAULT_KD,
                                     robot.TORQUE_LIMITS)
    raise ValueError(f"controller must be one of {CONTROLLERS}, got {controller!r}")


class MouthError:
    """Episode callback: horizontal distance (m) of the bottle mouth from where the reference puts it,
    at every step inside the task's pour window."""

    def __init__(self) -> None:
        self.errors: list[float] = []

    def __call__(self, u, info: dict) -> None:
        from jaco_env import scene
        from jaco_env.kinematics import bottle_pose

        t0, t1 = u.task.pour_window
        t = info["time"]
        if t0 <= t <= t1:
            p_des = bottle_pose(u.task.reference(t)[0])[0]
            self.errors.append(float(np.linalg.norm(u.data.site(scene.MOUTH_SITE).xpos[:2] - p_des[:2])))


def run_one(task: str, controller: str, payload: float, seed: int, n_marbles: int) -> dict:
    """One episode through :func:`cascgp.episodes.run_episode`; returns the metrics (JSON-serialisable)."""
    import gymnasium as gym
    import torch  # cascgp needs it; keep it single-threaded

    torch.set_num_threads(1)
    import jaco_env  # noqa: F401
    from cascgp.episodes import run_episode

    env = gym.make("JacoPour-v0", n_marbles=n_marbles)
    mouth = MouthError()
    t_start = time.perf_counter()
    res = run_episode(env, make_controller(controller, env.unwrapped.link_inertials), seed=seed,
                      options={"task": task, "payload_mass": payload},
                      callback=mouth)
    wall = time.perf_counter() - t_start
    env.close()
    info = res.info
    return {
        "task": task, "controller": controller, "payload_mass": info["payload_mass"],
        "rmse": res.tracking_rmse,
        "mouth_err_mean_cm": 100 * float(np.mean(mouth.errors)),
        "mouth_err_max_cm": 100 * float(np.max(mouth.errors)),
        "in_jar": res.in_jar, "spilled": res.spilled,
        "unstable": res.unstable, "steps": res.steps, "episode_s": float(info["time"]), "wall_s": wall,
    }


def gym_make_default():
    """``JacoPour-v0`` with its default options (the run's env, for the provenance)."""
    import gymnasium as gym

    import jaco_env  # noqa: F401

    return gym.make("JacoPour-v0", n_marbles=1)


def _star(args):
    return run_one(*args)


def main(argv: list[str] | None = None) -> None:
    from jaco_env.tasks import DEFAULT_TASKS

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, help="output folder for pour_separation.json")
    p.add_argument("--tasks", nargs="+", default=sorted(DEFAULT_TASKS), choices=sorted(DEFAULT_TASKS))
    p.add_argument("--controllers", nargs="+", default=list(CONTROLLERS), choices=CONTROLLERS)
    p.add_argument("--payload", type=float, default=1.2, help="total payload in the hand (kg)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--n-marbles", type=int, default=30)
    p.add_argument("--jobs", type=int, default=2, help="worker processes")
    args = p.parse_args(argv)
    check_output(p, args.out, "--out", "folder")
    jobs = [(t, c, args.payload, args.seed, args.n_marbles) for t in args.tasks for c in args.controllers]
    if args.jobs > 1:
        with ProcessPoolExecutor(args.jobs) as ex:
            rows = list(ex.map(_star, jobs))
    else:
        rows = [_star(j) for j in jobs]
    print(f"payload {args.payload} kg, seed {args.seed}, {args.n_marbles} marbles")
    print(f"{'task':12s} {'controller':10s} {'RMSE rad':>9s} {'mouth cm mean/max':>18s} {'in jar':>7s} "
          f"{'spilled':>8s} {'wall s':>7s}")
    for r in rows:
        print(f"{r['task']:12s} {r['controller']:10s} {r['rmse']:9.4f} "
              f"{r['mouth_err_mean_cm']:8.2f} /{r['mouth_err_max_cm']:7.2f} {r['in_jar']:7.0%} "
              f"{r['spilled']:8.0%} {r['wall_s']:7.1f}{'  UNSTABLE' if r['unstable'] else ''}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    import jaco_env

    meta = {k: v for k, v in vars(args).items() if k != "out"}
    # The env's defaults at the time of the run (the JSON outlives them).
    env = gym_make_default()
    meta.update(sensor_pipeline=env.unwrapped.sensor_pipeline.as_dict(), link_inertials=env.unwrapped.link_inertials,
                nominal_urdf=jaco_env.nominal_urdf(env.unwrapped.link_inertials).name, version=jaco_env.__version__)
    env.close()
    (out / "pour_separation.json").write_text(json.dumps({"meta": meta, "results": rows}, indent=2))
    print(f"wrote {out / 'pour_separation.json'}")


if __name__ == "__main__":
    main()
