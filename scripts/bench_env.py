"""Benchmark: env steps per second vs raw MuJoCo stepping of the same model.

    python -m scripts.bench_env --out out/bench_env [--steps 400] [--rounds 5] [--env JacoPour-v0]
        [--sensor-pipeline ideal]

The envs run under their default ``sensor_pipeline="jaco2"`` unless ``--sensor-pipeline`` names another; the
gravity-holding torque comes from the oracle started on the env (its payload and link inertials).

Both run the same compiled model from the same state for the same number of control
periods (``frame_skip`` physics steps each) with the same torque: the raw loop only calls
``mujoco.mj_step(model, data, nstep=frame_skip)``; the env loop calls ``env.step`` of the
``gym.make`` env (action checks, sensors, reference, marble bookkeeping, info). Measured side by
side in one run: ``--rounds`` rounds, each stepping the env ``--steps`` times from ``reset(seed=0)``
and the raw loop as many periods from the same state, timed in alternating chunks of 10 control
steps (the same physics, so a change of the machine's load falls on both). The cost ratio (env
time / raw time) is the median over all chunk pairs (a chunk slowed by another process is an
outlier); each round's ratio of totals is kept, and the ratio of the thread's CPU time
(``time.thread_time``: time the core was taken by another process is not counted) is reported
beside it. Steps per second are those of the best round. A third loop in the same alternation is a bare Gymnasium
``MujocoEnv`` on the same model (:class:`BareGymnasiumEnv`: ``do_simulation`` and one read of the arm's q, qd and
torque sensors, nothing of ours), the cost of any Gymnasium MuJoCo env over the raw loop. Also compares raw
stepping with the env's CG solver against MuJoCo's default Newton solver (speed, and the largest
difference of the arm joints and marble positions after the same steps). BLAS/OpenMP limited to
one thread. Then, apart from the timing, where an env step's time goes: the physics, the evaluation at the end of
the period and the rest (the step's Python), each timed inside the step. Prints a table and writes
``bench_env.json`` into ``--out``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

from cascgp_experiments.cli.options import check_output

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import gymnasium as gym  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from gymnasium import spaces  # noqa: E402
from gymnasium.envs.mujoco.mujoco_env import MujocoEnv  # noqa: E402

import jaco_env  # noqa: E402
from jaco_env.oracle import OracleController  # noqa: E402
from scripts.provenance import git_commit  # noqa: E402

#: Control steps per timed chunk: env and raw chunks alternate, so that a change of the machine's load
#: (other processes on the shared cores) falls on both.
CHUNK = 10


class BareGymnasiumEnv(MujocoEnv):
    """Gymnasium's ``MujocoEnv`` with nothing of ours, on a model file: a step is ``do_simulation`` (the action
    into ``ctrl``, ``frame_skip`` physics steps, ``mj_rnePostConstraint``) and one read of the arm's q, qd and
    torque sensor entries (``arm``: the env's ``arm_qpos_adr``, ``arm_dof_adr`` and torque sensor addresses). The
    reference for what a Gymnasium MuJoCo env costs over the raw loop; stepped without ``reset`` (the benchmark
    sets its state)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 40}

    def __init__(self, path: str, frame_skip: int, arm: tuple[np.ndarray, np.ndarray, np.ndarray]):
        self._arm = arm
        obs = spaces.Box(-np.inf, np.inf, shape=(sum(len(a) for a in arm),), dtype=np.float64)
        MujocoEnv.__init__(self, path, frame_skip, observation_space=obs)

    @classmethod
    def like(cls, u) -> "BareGymnasiumEnv":
        """On the model file of the unwrapped Jaco env ``u``, with its frame skip, arm addresses and payload."""
        bare = cls(u.fullpath, u.frame_skip, (u.arm_qpos_adr, u.arm_dof_adr, u._tau_sensor))
        bare.model.body_mass[:], bare.model.body_inertia[:] = u.model.body_mass, u.model.body_inertia
        return bare

    def step(self, action):
        self.do_simulation(action, self.frame_skip)
        d, (qa, va, ta) = self.data, self._arm
        return np.concatenate((d.qpos[qa], d.qvel[va], d.sensordata[ta])), 0.0, False, False, {}

    def reset_model(self) -> np.ndarray:
        return np.zeros(self.observation_space.shape)


class _TimedMujoco:
    """``mujoco`` as :mod:`jaco_env.envs.stepping` sees it during :func:`breakdown`: the physics calls
    (``mj_step``, ``mj_step2``) and the end-of-period evaluation (``mj_forward``) timed, everything else passed
    through."""

    def __init__(self) -> None:
        self.physics = self.evaluation = 0.0

    def mj_step(self, *args, **kwargs) -> None:
        t0 = time.perf_counter()
        mujoco.mj_step(*args, **kwargs)
        self.physics += time.perf_counter() - t0

    def mj_step2(self, *args) -> None:
        t0 = time.perf_counter()
        mujoco.mj_step2(*args)
        self.physics += time.perf_counter() - t0

    def mj_forward(self, *args) -> None:
        t0 = time.perf_counter()
        mujoco.mj_forward(*args)
        self.evaluation += time.perf_counter() - t0

    def __getattr__(self, name: str):
        return getattr(mujoco, name)


def breakdown(env, tau: np.ndarray, options: dict, steps: int, rounds: int) -> dict:
    """Where an env step's time goes (µs per step, median over ``rounds`` runs of ``steps`` steps from the same
    reset): the physics, the evaluation at the end of the period (the torque sensors' sample), and the rest (the
    step's Python: action check, measurement, checks, info, the wrappers). Measured after the side-by-side timing,
    with the physics calls timed one by one (a fraction of a microsecond each)."""
    from jaco_env.envs import stepping

    timed = _TimedMujoco()
    runs = []
    stepping.mujoco = timed
    try:
        for _ in range(rounds):
            env.reset(seed=0, options=options)
            timed.physics = timed.evaluation = 0.0
            t0 = time.perf_counter()
            for _ in range(steps):
                env.step(tau)
            runs.append((time.perf_counter() - t0, timed.physics, timed.evaluation))
    finally:
        stepping.mujoco = mujoco
    total, physics, evaluation = 1e6 * np.median(np.array(runs), axis=0) / steps
    return {"env_step_us": total, "physics_us": physics, "end_of_period_evaluation_us": evaluation,
            "rest_us": total - physics - evaluation}


def bench(env_id: str, steps: int, rounds: int = 5, sensor_pipeline: str = "jaco2") -> dict:
    kwargs = {} if env_id == "JacoPayload-v0" else {"task": "front"}
    kwargs["sensor_pipeline"] = sensor_pipeline
    env = gym.make(env_id, **kwargs)
    options = {"payload_mass": 1.0}
    _, info = env.reset(seed=0, options=options)
    u = env.unwrapped
    # A gravity-holding torque keeps both runs in the same regime (arm still, marbles in the bottle):
    # the oracle's rigid inverse dynamics (marbles lumped at rest) at the current pose, at rest, built by
    # start() for this env's payload and link inertials.
    q, _ = u.arm_state()
    zero = np.zeros_like(q)
    oracle = OracleController(follow_marbles=False)
    oracle.start(env, info)
    tau = oracle.feedforward(q, zero, zero)
    tau = np.clip(tau, -u.torque_limits, u.torque_limits).astype(np.float32)

    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state0 = np.empty(mujoco.mj_stateSize(u.model, spec))
    mujoco.mj_getState(u.model, u.data, state0, spec)
    d = mujoco.MjData(u.model)
    bare = BareGymnasiumEnv.like(u)

    def one_round(r: int) -> np.ndarray:
        """Wall and CPU time (s) of each chunk of the ``steps`` control steps, env, raw and bare Gymnasium env,
        timed in alternation (the order rotates from chunk to chunk): (chunks, env/raw/bare, wall/cpu)."""
        env.reset(seed=0, options=options)  # the same state0 (seeded)
        mujoco.mj_setState(u.model, d, state0, spec)
        mujoco.mj_setState(bare.model, bare.data, state0, spec)
        d.ctrl[:jaco_env.robot.N_JOINTS] = tau
        starts = range(0, steps, CHUNK)
        t = np.zeros((len(starts), 3, 2))
        for c, start in enumerate(starts):
            n = min(CHUNK, steps - start)
            for k in range(3):
                which = (c + r + k) % 3
                w0, c0 = time.perf_counter(), time.thread_time()
                if which == 0:
                    for _ in range(n):
                        env.step(tau)
                elif which == 1:
                    for _ in range(n):
                        mujoco.mj_step(u.model, d, nstep=u.frame_skip)
                else:
                    for _ in range(n):
                        bare.step(tau)
                t[c, which] = time.perf_counter() - w0, time.thread_time() - c0
        return t

    chunks = np.array([one_round(r) for r in range(rounds)])  # (rounds, chunks, env/raw/bare, wall/cpu)
    times = chunks.sum(axis=1)  # (rounds, env/raw/bare, wall/cpu)
    t_env, t_raw = times[:, 0, 0].min(), times[:, 1, 0].min()
    costs = times[:, 0, 0] / times[:, 1, 0]
    costs_cpu = times[:, 0, 1] / times[:, 1, 1]
    # the median over all chunk pairs (the same physics each): a chunk slowed by another process is an outlier
    cost_chunks = float(np.median(chunks[:, :, 0, 0] / chunks[:, :, 1, 0]))
    cost_bare = float(np.median(chunks[:, :, 2, 0] / chunks[:, :, 1, 0]))

    # The env uses MuJoCo's CG solver (scene.py); compare with the default Newton solver: time,
    # and how far the arm and the marbles drift apart over the same steps (physics unchanged
    # up to solver tolerance if both are small).
    solver_cmp = {}
    for name, solver in (("newton", mujoco.mjtSolver.mjSOL_NEWTON), ("cg", mujoco.mjtSolver.mjSOL_CG)):
        m2 = u.model.__copy__()
        m2.opt.solver = solver
        d2 = mujoco.MjData(m2)
        mujoco.mj_setState(m2, d2, state0, mujoco.mjtState.mjSTATE_FULLPHYSICS)
        d2.ctrl[:jaco_env.robot.N_JOINTS] = tau
        t0 = time.perf_counter()
        for _ in range(steps):
            mujoco.mj_step(m2, d2, nstep=u.frame_skip)
        solver_cmp[name] = (time.perf_counter() - t0, d2.qpos.copy())
    parts = breakdown(env, tau, options, steps, rounds)
    parts["raw_period_us"] = 1e6 * float(np.median(times[:, 1, 0])) / steps  # the median round, as the parts
    q_n, q_c = solver_cmp["newton"][1], solver_cmp["cg"][1]
    arm = u.arm_qpos_adr
    marb = getattr(u, "marble_qpos_adr", np.zeros(0, int))
    env.close()
    bare.close()
    return {
        "newton_raw_steps_per_s": steps / solver_cmp["newton"][0],
        "cg_raw_steps_per_s": steps / solver_cmp["cg"][0],
        "cg_vs_newton_arm_max_diff_rad": float(np.max(np.abs(q_n[arm] - q_c[arm]))),
        "cg_vs_newton_marble_max_diff_m": float(np.max(np.abs(q_n[marb[:, None] + np.arange(3)]
                                                             - q_c[marb[:, None] + np.arange(3)]))) if len(marb)
        else 0.0,
        "env_id": env_id,
        "sensor_pipeline": u.sensor_pipeline.as_dict(),
        "link_inertials": u.link_inertials,
        "control_steps": steps,
        "physics_steps_per_control_step": u.frame_skip,
        "physics_timestep_s": float(u.model.opt.timestep),
        "rounds": rounds,
        "env_steps_per_s": steps / t_env,
        "raw_steps_per_s": steps / t_raw,
        "ratio_env_over_raw": 1.0 / cost_chunks,
        "env_cost_over_raw": cost_chunks,
        "env_cost_over_raw_per_round": costs.tolist(),
        "env_cost_over_raw_cpu": float(np.median(costs_cpu)),
        "env_cost_over_raw_cpu_per_round": costs_cpu.tolist(),
        "bare_gymnasium_cost_over_raw": cost_bare,
        "bare_gymnasium_steps_per_s": steps / times[:, 2, 0].min(),
        "breakdown": parts,
    }


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, help="output folder for bench_env.json")
    p.add_argument("--steps", type=int, default=400, help="control steps per measurement")
    p.add_argument("--rounds", type=int, default=5, help="timing rounds (median ratio reported)")
    p.add_argument("--env", nargs="+", default=["JacoPour-v0", "JacoPayload-v0"])
    p.add_argument("--sensor-pipeline", default="jaco2", help="the envs' sensor_pipeline (default: theirs, jaco2)")
    args = p.parse_args(argv)
    if args.steps < 1 or args.rounds < 1:
        p.error("--steps and --rounds must be >= 1")
    check_output(p, args.out, "--out", "folder")
    rows = [bench(e, args.steps, args.rounds, args.sensor_pipeline) for e in args.env]
    print(f"{'env':16s} {'env steps/s':>12s} {'raw steps/s':>12s} {'cost':>6s} {'cost per round':>24s} "
          f"{'cpu cost':>8s} {'bare Gym cost':>13s} {'raw Newton':>11s} {'raw CG':>8s} "
          f"{'CG-Newton arm rad / marbles m':>30s}")
    for r in rows:
        per_round = " ".join(f"{c:.2f}" for c in r["env_cost_over_raw_per_round"])
        print(f"{r['env_id']:16s} {r['env_steps_per_s']:12.1f} {r['raw_steps_per_s']:12.1f} "
              f"{r['env_cost_over_raw']:6.3f} {per_round:>24s} {r['env_cost_over_raw_cpu']:8.3f} "
              f"{r['bare_gymnasium_cost_over_raw']:13.3f} "
              f"{r['newton_raw_steps_per_s']:11.1f} {r['cg_raw_steps_per_s']:8.1f} "
              f"{r['cg_vs_newton_arm_max_diff_rad']:15.2e} / {r['cg_vs_newton_marble_max_diff_m']:.2e}")
    for r in rows:
        b = r["breakdown"]
        print(f"{r['env_id']}: an env step {b['env_step_us']:.1f} us = physics {b['physics_us']:.1f} + end-of-period "
              f"evaluation {b['end_of_period_evaluation_us']:.1f} + the rest (Python) {b['rest_us']:.1f}; a raw "
              f"period {b['raw_period_us']:.1f} us (median rounds)")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    head = git_commit()
    meta = {"mujoco": mujoco.__version__, "python": platform.python_version(), "machine": platform.machine(),
            "command": "python -m scripts.bench_env " + " ".join(sys.argv[1:] if argv is None else argv),
            "git_commit": head, "load_average_end": list(os.getloadavg()), "cpu_count": os.cpu_count(),
            "note": "one run; env and raw timed in alternating chunks of 10 control steps, in --rounds rounds; "
                    "env_cost_over_raw = env wall time / raw wall time of the same chunk, median over all chunks "
                    "(1 = no overhead), ratio_env_over_raw = its inverse, per_round = the ratio of each round's "
                    "totals; env_cost_over_raw_cpu = the median over rounds of the ratio of the thread's CPU time "
                    "(time the core was taken by other processes not counted); steps/s of the best round; "
                    "bare_gymnasium_cost_over_raw: the same median for a bare Gymnasium MujocoEnv on the same "
                    "model (do_simulation and one read of the arm's q, qd, torque), timed in the same alternation "
                    "(env, raw, bare; the order rotates per chunk)"}
    (out / "bench_env.json").write_text(json.dumps({"meta": meta, "results": rows}, indent=2))
    print(f"wrote {out / 'bench_env.json'}")


if __name__ == "__main__":
    main()
