"""``python -m scripts.bench_cascgp --scaling N,...``: time per NLL-and-gradient evaluation and peak memory of the
default fit against n (``docs/performance.md``, "Scaling with n"). Each n runs in a fresh process
(``--scaling-one``) so that its peak resident memory is its own.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from cascgp.io import write_json
from scripts.bench_cascgp import blas_threads, load_data

def _peak_rss_bytes() -> int:
    import resource

    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024  # Linux: KiB


def scaling_one(args: argparse.Namespace) -> int:
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


def scaling(args: argparse.Namespace) -> int:
    """Each n of ``--scaling`` in a fresh process (so that its peak memory is its own); a table and JSON."""
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
