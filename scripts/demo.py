"""Temporary scripted demo episode (to be replaced by the task-transfer demo).

    python -m scripts.demo --out out/demo [--task front] [--payload 1.2]

Runs the computed-torque oracle (true inverse dynamics + PD) and PD-only feedback on one
pouring task of ``JacoPour-v0``, prints tracking RMSE and marbles in the jar, and saves
``demo.png`` (joint tracking errors over time) and ``demo.json`` into ``--out``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import gymnasium as gym
import numpy as np

import jaco_env  # noqa: F401
from jaco_env import oracle
from jaco_env.tasks import DEFAULT_TASKS


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True)
    p.add_argument("--task", default="front", choices=sorted(DEFAULT_TASKS))
    p.add_argument("--payload", type=float, default=1.2, help="total payload in the hand (kg)")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    env = gym.make("JacoPour-v0")
    results = {}
    for name, factory in (("oracle", oracle.oracle_factory), ("pd", oracle.pd_factory)):
        results[name] = oracle.run_episode(env, factory, task=args.task, payload_mass=args.payload, seed=args.seed)
    env.close()

    print(f"task {args.task}, payload {args.payload} kg")
    print(f"{'controller':10s} {'RMSE (rad)':>11s} {'in jar':>7s} {'spilled':>8s}")
    for name, r in results.items():
        print(f"{name:10s} {r['rmse']:11.4f} {r['in_jar']:7.0%} {r['spilled']:8.0%}")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4))
    for name, r in results.items():
        ax.plot(r["t"], np.linalg.norm(r["q_d"] - r["q"], axis=1), label=f"{name} ({r['in_jar']:.0%} in jar)")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("||q_d - q|| (rad)")
    ax.set_title(f"JacoPour-v0, task {args.task}")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "demo.png", dpi=100)
    summary = {k: {kk: v for kk, v in r.items() if not isinstance(v, np.ndarray)} for k, r in results.items()}
    (out / "demo.json").write_text(json.dumps(summary, indent=2))
    print(f"wrote {out / 'demo.png'} and {out / 'demo.json'}")


if __name__ == "__main__":
    main()
