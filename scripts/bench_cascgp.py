"""Benchmark: cascgp's batched GP fit against GPy, side by side in one run.

Fits a 6-output model (one Matern 5/2 ARD GP per joint, ``n`` samples, d = 18 inputs: q, qd, qdd of joints 1-6)
with 10 restarts per output, once with :class:`cascgp.gp.GPBank` (all 6 x 10 starts in one batch) and once with
GPy (``GPRegression`` + ``Matern52(ARD=True)``, ``optimize_restarts(10)``, its default L-BFGS-B), on the *same*
standardised data, and reports the fit times and the best negative log marginal likelihood each reached per output
(normalised units; the same objective, including the ``n/2 log 2 pi`` constant). If ``cascgp.models`` is present it
also measures the latency of one single-query prediction of a 6-joint NP inward cascade (``predict_one``).

Data: the SARCOS IAS file when ``--sarcos`` is given (training rows subsampled to 10 Hz, the first ``n``; joints 1-6;
torques of joints 1-6 as the 6 outputs; ``--outputs 7``: all 21 inputs and all 7 torques), otherwise a smooth
synthetic inverse-dynamics-like function (both from :func:`cascgp_experiments.audit_suite.benchmark_data`). For
every cascgp setting it also reports evaluations per start, the cost of one NLL+gradient evaluation and its
breakdown (kernel, Cholesky, inverse, gradient, optimiser and the rest; from ``cascgp.gp.likelihood.PROFILE``).
``--scaling`` instead measures time per evaluation and peak memory against n.

Usage::

    python -m scripts.bench_cascgp --out out/bench --sarcos /work/shared/data/sarcos/ias_sarcos_data.mat --threads 1
    python -m scripts.bench_cascgp --out out/bench --sarcos ... --n 300 --outputs 7
    python -m scripts.bench_cascgp --out out/bench --skip-gpy               # cascgp only
    python -m scripts.bench_cascgp --out out/bench --configs default        # one of the settings in CONFIGS
    python -m scripts.bench_cascgp --out out/bench --scaling 250,500,1000,2000 --scaling-iter 2

GPy is an optional extra (``pip install -e '.[bench]'``). Threads: torch uses ``--threads`` (default 1) for the
cascgp fit; GPy's NumPy BLAS is limited to ``--threads`` as well (with threadpoolctl when installed; the script also
sets ``OMP_NUM_THREADS``/``OPENBLAS_NUM_THREADS`` before NumPy is imported when they are unset).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import time
from pathlib import Path

if __name__ == "__main__":  # BLAS reads these when NumPy is first imported
    _t = next((a.split("=", 1)[1] for a in sys.argv if a.startswith("--threads=")), None)
    if _t is None and "--threads" in sys.argv[:-1]:
        _t = sys.argv[sys.argv.index("--threads") + 1]
    for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_v, _t or "1")

import numpy as np

from cascgp.io import write_json
from cascgp_experiments.audit_suite import benchmark_data as load_data


#: cascgp settings of the benchmark. "default" is ``GPFitConfig()`` as a new user gets it (every GP's leading start
#: runs to convergence; the other starts stop once they stall: less than 0.01 nat gained over 5 iterations, or
#: less than a tenth of their gap to the leader). "converge-all" runs all 10 starts to convergence (the library
#: default before the early-stopping rule; the equivalence audit's reference).
CONFIGS = {
    "default": {},
    "converge-all": {"stall_window": None},
}


@contextlib.contextmanager
def blas_threads(k: int):
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # optional
        yield
        return
    with threadpool_limits(limits=k, user_api="blas"):
        yield


def bench_cascgp(X: np.ndarray, Y: np.ndarray, restarts: int, threads: int, config_kw: dict) -> dict:
    import torch

    from cascgp.gp import GPBank, GPFitConfig

    import cascgp.gp.likelihood as gp_mod

    torch.set_num_threads(threads)
    cfg = GPFitConfig(kernel="matern52", n_restarts=restarts, **config_kw)
    gp_mod.PROFILE = {}
    try:
        with blas_threads(1):  # NumPy/SciPy in the optimiser loop are tiny; keep OpenBLAS threads from spinning
            t0 = time.perf_counter()
            bank = GPBank(cfg).fit([X] * Y.shape[1], [Y[:, j] for j in range(Y.shape[1])])
            dt = time.perf_counter() - t0
        prof = dict(gp_mod.PROFILE)
    finally:
        gp_mod.PROFILE = None
    members = max(int(prof.pop("members", 0)), 1)
    phases = {k: float(v) for k, v in prof.items()}
    phases["optimiser_and_rest"] = dt - sum(phases.values())
    return {
        "breakdown_s": phases,
        "breakdown_us_per_eval": {k: 1e6 * v / members for k, v in phases.items()},
        "ms_per_eval": 1e3 * dt / max(bank.fit_summary["n_eval"], 1),
        "evals_per_start": float(bank.fit_summary["n_eval"]) / (restarts * Y.shape[1]),
        "time_s": dt,
        "best_nll": [fi["best_nll"] for fi in bank.fit_info],
        "nll_per_restart": [fi["nll"] for fi in bank.fit_info],
        "n_iter": [fi["n_iter"] for fi in bank.fit_info],
        "n_eval": [fi["n_eval"] for fi in bank.fit_info],
        "reason": [fi["reason"] for fi in bank.fit_info],
        "best": [fi["best"] for fi in bank.fit_info],
        "jitter": [fi["jitter"] for fi in bank.fit_info],
        "total_evals": bank.fit_summary["n_eval"],
        "batch_rounds": bank.fit_summary["batch_rounds"],
        "config": {k: getattr(cfg, k) for k in cfg.__dataclass_fields__},
        "torch_threads": threads,
    }


def bench_gpy(X: np.ndarray, Y: np.ndarray, restarts: int, threads: int) -> dict:
    import GPy

    times, best, per, iters = [], [], [], []
    with blas_threads(threads):
        for j in range(Y.shape[1]):
            np.random.seed(j)  # noqa: NPY002 - GPy draws its restarts from NumPy's global generator
            t0 = time.perf_counter()
            m = GPy.models.GPRegression(X, Y[:, j : j + 1], GPy.kern.Matern52(X.shape[1], ARD=True))
            m.optimize_restarts(num_restarts=restarts, verbose=False, robust=True)
            times.append(time.perf_counter() - t0)
            best.append(float(-m.log_likelihood()))
            runs = m.optimization_runs[-restarts:]
            per.append([float(r.f_opt) for r in runs])
            iters.append([int(getattr(r, "funct_eval", -1) or -1) for r in runs])
    return {"time_s": float(sum(times)), "time_per_output_s": times, "best_nll": best, "nll_per_restart": per,
            "n_eval": iters, "version": GPy.__version__}


def bench_cascade(X: np.ndarray, Y: np.ndarray, n_queries: int) -> dict | None:
    """Median latency of one single-query 6-joint NP inward cascade prediction (needs cascgp.models)."""
    try:
        from cascgp import models
        from cascgp.data import DynamicsData
    except ImportError:
        return None
    import torch

    from cascgp.gp import GPFitConfig

    torch.set_num_threads(1)
    n = X.shape[0]
    q, qd, qdd = X[:, 0:6], X[:, 6:12], X[:, 12:18]
    t = np.arange(n) * 0.1
    data = DynamicsData(q=q, qd=qd, qdd=qdd, tau=Y.copy(), t=t, segment=np.zeros(n, dtype=np.int64),
                        meta={"source": "bench"})
    model = models.make_model("np-inward", 6, gp_config=GPFitConfig(n_restarts=1, max_iter=50))
    model.fit(data)
    for i in range(min(n, 20)):  # warm-up, not timed
        model.predict_one(q[i], qd[i], qdd[i])
    lat = []
    for i in range(n_queries):
        k = i % n
        t0 = time.perf_counter_ns()
        model.predict_one(q[k], qd[k], qdd[k])
        lat.append(time.perf_counter_ns() - t0)
    lat = np.array(lat) / 1e3
    return {"median_us": float(np.median(lat)), "p90_us": float(np.percentile(lat, 90)), "n_queries": len(lat)}


def _peak_rss_bytes() -> int:
    import resource

    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024  # Linux: KiB


def _scaling_one(args: argparse.Namespace) -> int:
    """One n: a default fit capped at ``--scaling-iter`` iterations per start; prints one JSON line."""
    import torch

    import cascgp.gp.likelihood as gp_mod
    from cascgp.gp import GPBank, GPFitConfig, estimate_fit_bytes, plan_chunk

    torch.set_num_threads(args.threads)
    n = args.scaling_one
    X, Y, _ = load_data(n, args.sarcos, args.seed, args.outputs)
    base = _peak_rss_bytes()
    cfg = GPFitConfig(n_restarts=args.restarts, max_iter=args.scaling_iter)
    gp_mod.PROFILE = {}
    with blas_threads(1):
        t0 = time.perf_counter()
        GPBank(cfg).fit([X] * Y.shape[1], [Y[:, j] for j in range(Y.shape[1])])
        dt = time.perf_counter() - t0
    members = gp_mod.PROFILE.pop("members")
    B, d = Y.shape[1], X.shape[1]
    print(json.dumps({"n": n, "d": d, "outputs": B, "starts": args.restarts, "evals": members,
                      "ms_per_eval": 1e3 * dt / members,
                      "us_per_eval": {k: 1e6 * v / members for k, v in gp_mod.PROFILE.items()},
                      "estimate_bytes": estimate_fit_bytes(n, d, B, args.restarts, plan_chunk(cfg, n, d, B)),
                      "peak_rss_bytes": _peak_rss_bytes(), "rss_before_fit_bytes": base,
                      "fit_time_s": dt}))
    return 0


def _scaling(args: argparse.Namespace) -> int:
    import subprocess

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for n in [int(v) for v in args.scaling.split(",") if v]:
        cmd = [sys.executable, "-m", "scripts.bench_cascgp", "--out", str(out), "--scaling-one", str(n),
               "--threads", str(args.threads), "--restarts", str(args.restarts), "--outputs", str(args.outputs),
               "--scaling-iter", str(args.scaling_iter)] + (["--sarcos", args.sarcos] if args.sarcos else [])
        r = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout.strip().splitlines()[-1])
        rows.append(r)
        print(f"n={n:5d}: {r['ms_per_eval']:8.2f} ms per evaluation ("
              + ", ".join(f"{k} {v / 1e3:.2f} ms" for k, v in r["us_per_eval"].items())
              + f"); estimate {r['estimate_bytes'] / 2**20:.0f} MiB, peak RSS {r['peak_rss_bytes'] / 2**20:.0f} MiB "
              f"(process before the fit {r['rss_before_fit_bytes'] / 2**20:.0f} MiB)", flush=True)
    write_json(out / "bench_scaling.json", rows)
    print(f"wrote {out / 'bench_scaling.json'}")
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, help="output directory (bench_cascgp.json is written there)")
    ap.add_argument("--n", type=int, default=500)
    ap.add_argument("--restarts", type=int, default=10)
    ap.add_argument("--threads", type=int, default=1,
                    help="torch / BLAS threads for both libraries (default 1: on a shared 2-core box two OpenMP "
                         "threads spin against other processes and were measured 16x slower per evaluation)")
    ap.add_argument("--sarcos", default=None, help="path of ias_sarcos_data.mat (default: synthetic data)")
    ap.add_argument("--skip-gpy", action="store_true")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--queries", type=int, default=2000, help="single queries for the cascade latency")
    ap.add_argument("--configs", default=",".join(CONFIGS),
                    help=f"comma-separated cascgp settings to run, of {list(CONFIGS)} (default: all)")
    ap.add_argument("--outputs", type=int, default=6, choices=(6, 7),
                    help="SARCOS outputs: 6 (joints 1-6, 18 inputs) or 7 (all joints, 21 inputs)")
    ap.add_argument("--scaling", default=None,
                    help="comma-separated n values: instead of the GPy comparison, measure per-evaluation time and "
                         "peak memory of the default fit at each n (each in a fresh process), e.g. 500,1000,2000")
    ap.add_argument("--scaling-one", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--scaling-iter", type=int, default=3, help="L-BFGS iterations per start in --scaling runs")
    args = ap.parse_args(argv)
    if args.scaling_one is not None:
        return _scaling_one(args)
    if args.scaling is not None:
        return _scaling(args)
    names = [c for c in args.configs.split(",") if c]
    unknown = [c for c in names if c not in CONFIGS]
    if unknown or not names:
        ap.error(f"--configs: unknown setting(s) {unknown}; expected some of {list(CONFIGS)}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    X, Y, desc = load_data(args.n, args.sarcos, args.seed, args.outputs)
    print(f"data: {desc}; X {X.shape}, Y {Y.shape}; {os.cpu_count()} CPUs, threads={args.threads}", flush=True)
    res: dict = {"data": desc, "n": args.n, "d": X.shape[1], "outputs": Y.shape[1], "restarts": args.restarts,
                 "configs": {name: CONFIGS[name] for name in names}, "cascgp": {}}
    for name in names:
        res["cascgp"][name] = c = bench_cascgp(X, Y, args.restarts, args.threads, CONFIGS[name])
        print(f"cascgp fit ({name}): {c['time_s']:.2f} s, {c['total_evals']} NLL+grad evaluations "
              f"({c['evals_per_start']:.1f} per start, {c['ms_per_eval']:.2f} ms each) in {c['batch_rounds']} "
              "batched rounds; per evaluation: " + ", ".join(
                  f"{k} {v:.0f} us" for k, v in c["breakdown_us_per_eval"].items()), flush=True)
    if not args.skip_gpy:
        try:
            res["gpy"] = bench_gpy(X, Y, args.restarts, args.threads)
        except ImportError:
            print("GPy is not installed (pip install -e '.[bench]'); skipping it", file=sys.stderr)
    X6, Y6, _ = (X, Y, None) if args.outputs == 6 else load_data(args.n, args.sarcos, args.seed, 6)
    res["cascade"] = bench_cascade(X6, Y6, args.queries)

    g = res.get("gpy")
    hdr = f"{'output':>6} | {'GPy NLL':>10} | " + " | ".join(
        f"{name + ' NLL':>14} | {'gap':>7} | {'evals':>6}" for name in names)
    print(hdr)
    print("-" * len(hdr))
    for j in range(Y.shape[1]):
        gn = g["best_nll"][j] if g else float("nan")
        cells = []
        for name in names:
            c = res["cascgp"][name]
            cells.append(f"{c['best_nll'][j]:>14.3f} | {c['best_nll'][j] - gn:>+7.3f} | {sum(c['n_eval'][j]):>6d}")
        print(f"{j + 1:>6} | {gn:>10.3f} | " + " | ".join(cells))
    res["summary"] = {}
    for name in names:
        c = res["cascgp"][name]
        line = f"fit time ({name}): cascgp {c['time_s']:.2f} s"
        if g:
            speedup = g["time_s"] / c["time_s"]
            gap = float(max(a - b for a, b in zip(c["best_nll"], g["best_nll"])))
            res["summary"][name] = {"speedup": speedup, "max_nll_gap": gap,
                                    "meets_issue_9": bool(speedup >= 20 and gap <= 0.1)}
            line += f", GPy {g['time_s']:.2f} s, speed-up {speedup:.1f}x; worst NLL gap (cascgp - GPy) {gap:+.3f} nats"
        print(line)
    if res["cascade"] is None:
        print("cascade latency: cascgp.models not available (skipped)")
    else:
        print(f"single-query 6-joint NP inward cascade: median {res['cascade']['median_us']:.1f} us, "
              f"p90 {res['cascade']['p90_us']:.1f} us")
    write_json(out / "bench_cascgp.json", res)
    print(f"wrote {out / 'bench_cascgp.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
