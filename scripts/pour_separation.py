"""Pour separation: oracle vs nominal rigid-body feedforward vs PD only, per default task.

    python -m scripts.pour_separation --out out/pour_separation [--tasks front near ...]
        [--payload 1.2] [--seed 0] [--n-marbles 30] [--jobs 2]

For every task of ``jaco_env.tasks.DEFAULT_TASKS`` runs one seed-fixed ``JacoPour-v0`` episode
(torque mode, default sensor noise, payload fixed) with each controller

* ``oracle``: :class:`jaco_env.oracle.OracleController` (MuJoCo inverse dynamics of the true
  rigid scene, marbles lumped) + PD,
* ``nominal``: :class:`cascgp.controller.FeedforwardController` with the nominal rigid-body
  model ``assets/jaco2_nominal.urdf`` (10% calibration error, no payload, no friction) + PD,
* ``pd``: the same PD feedback without feedforward,

all with ``jaco_env.DEFAULT_KP/KD``. Prints a table of joint tracking RMSE (rad), the mouth's
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

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402

CONTROLLERS = ("oracle", "nominal", "pd")
NOMINAL_URDF = Path(__file__).resolve().parents[1] / "assets" / "jaco2_nominal.urdf"


def run_one(task: str, controller: str, payload: float, seed: int, n_marbles: int) -> dict:
    """One episode; returns the metrics (JSON-serialisable)."""
    import gymnasium as gym

    import jaco_env  # noqa: F401
    from jaco_env import DEFAULT_KD, DEFAULT_KP, oracle
    from jaco_env.kinematics import bottle_pose
    from jaco_env.scene import MOUTH_SITE

    env = gym.make("JacoPour-v0", n_marbles=n_marbles)
    u = env.unwrapped
    obs, info = env.reset(seed=seed, options={"task": task, "payload_mass": payload})
    tk = u.task
    if controller == "oracle":
        policy = oracle.OracleController(tk, info["payload_mass"], info["n_marbles"]).bind(u)
    elif controller == "pd":
        policy = oracle.PDController(tk)
    elif controller == "nominal":
        import torch  # noqa: F401,PLC0415  (cascgp needs it; keep it single-threaded)

        torch.set_num_threads(1)
        from cascgp.controller import FeedforwardController  # noqa: PLC0415
        from cascgp.rbd import load_nominal  # noqa: PLC0415

        ff = FeedforwardController(load_nominal(str(NOMINAL_URDF)), DEFAULT_KP, DEFAULT_KD, u.torque_limits)

        def policy(o):
            return ff(float(o[18]), o[0:6], o[6:12], tk.reference)
    else:
        raise ValueError(f"controller must be one of {CONTROLLERS}, got {controller!r}")
    t0, t1 = tk.pour_window
    sid = u.model.site(MOUTH_SITE).id
    errs, mouth_err = [], []
    t_start = time.perf_counter()
    while True:
        obs, _, term, trunc, info = env.step(np.asarray(policy(obs), dtype=np.float32))
        errs.append(info["tracking_error"])
        t = info["time"]
        if t0 <= t <= t1:
            p_des = bottle_pose(tk.reference(t)[0])[0]
            mouth_err.append(float(np.linalg.norm(u.data.site_xpos[sid, :2] - p_des[:2])))
        if term or trunc:
            break
    wall = time.perf_counter() - t_start
    env.close()
    return {
        "task": task, "controller": controller, "payload_mass": info["payload_mass"],
        "rmse": float(np.sqrt(np.mean(np.square(errs)))),
        "mouth_err_mean_cm": 100 * float(np.mean(mouth_err)), "mouth_err_max_cm": 100 * float(np.max(mouth_err)),
        "in_jar": info["marbles_in_jar"] / info["n_marbles"], "spilled": info["marbles_spilled"] / info["n_marbles"],
        "unstable": bool(info["unstable"]), "steps": len(errs), "episode_s": float(t), "wall_s": wall,
    }


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
    meta = {k: v for k, v in vars(args).items() if k != "out"}
    (out / "pour_separation.json").write_text(json.dumps({"meta": meta, "results": rows}, indent=2))
    print(f"wrote {out / 'pour_separation.json'}")


if __name__ == "__main__":
    main()
