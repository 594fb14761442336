"""Benchmark: a GP fit from a plain user script, with the library's thread rule against the previous behaviour.

Each case runs the *same* fit (``GPBank(GPFitConfig(n_restarts=R)).fit`` on the same standardised data, Matern 5/2
ARD, one GP per output) in a fresh Python process whose environment has no ``OMP_NUM_THREADS``,
``OPENBLAS_NUM_THREADS`` or ``MKL_NUM_THREADS``, as a user's script gets it; the cases alternate, ``--reps`` times
each, so that load on the machine falls on all of them alike:

==================  ===================================================================================
case                what the child process does
==================  ===================================================================================
``user-default``    nothing about threads: ``GPFitConfig()`` (``threads=1``: the fit sets torch and BLAS to
                    one thread and restores them afterwards)
``user-previous``   the behaviour before the rule: torch's default intra-op threads, BLAS held to one thread
                    (``GPFitConfig(threads=None)`` inside ``blas_threads(1)``)
``bench-1thread``   what ``scripts.bench_cascgp --threads 1`` does: ``OMP_NUM_THREADS=1`` etc. set before NumPy
                    is imported, ``torch.set_num_threads(1)``, ``threads=None``
==================  ===================================================================================

``--background-load K`` runs K single-threaded busy processes beside the fits for the whole benchmark, as on a
machine shared with other jobs (the situation in which torch's default threads were measured 11-16x slower).

Usage::

    python -m scripts.bench_fit_threads --out out/bench --sarcos PATH/ias_sarcos_data.mat   # SARCOS n = 300, 7 outputs
    python -m scripts.bench_fit_threads --out out/bench                                      # synthetic data
    python -m scripts.bench_fit_threads --out out/bench_load --sarcos ... --background-load 1  # one busy neighbour

Prints a table (median time per case and its ratio to ``bench-1thread``) and writes ``bench_fit_threads.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from cascgp_experiments.cli.options import check_output, check_sarcos_file

CASES = ("user-default", "user-previous", "bench-1thread")

_CHILD = r"""
import json, os, sys, time
case, n, sarcos, restarts, outputs, seed = sys.argv[1], int(sys.argv[2]), sys.argv[3] or None, int(sys.argv[4]), \
    int(sys.argv[5]), int(sys.argv[6])
import numpy as np
import torch
from cascgp.gp import GPBank, GPFitConfig
from cascgp.gp.likelihood import blas_threads
from cascgp_experiments.audit_suite import benchmark_data
X, Y, desc = benchmark_data(n, sarcos, seed, outputs)
before = torch.get_num_threads()
if case == "user-default":
    cfg, ctx = GPFitConfig(n_restarts=restarts), None
elif case == "user-previous":
    cfg, ctx = GPFitConfig(n_restarts=restarts, threads=None), blas_threads(1)
else:
    torch.set_num_threads(1)
    cfg, ctx = GPFitConfig(n_restarts=restarts, threads=None), blas_threads(1)
t0 = time.perf_counter()
if ctx is None:
    bank = GPBank(cfg).fit([X] * Y.shape[1], [Y[:, j] for j in range(Y.shape[1])])
else:
    with ctx:
        bank = GPBank(cfg).fit([X] * Y.shape[1], [Y[:, j] for j in range(Y.shape[1])])
dt = time.perf_counter() - t0
print(json.dumps({"case": case, "time_s": dt, "torch_threads_before": before, "torch_threads_after":
                  torch.get_num_threads(), "best_nll": [fi["best_nll"] for fi in bank.fit_info], "data": desc,
                  "n_eval": int(bank.fit_summary["n_eval"])}))
"""


def run_case(case: str, args: argparse.Namespace) -> dict:
    """One fit in a fresh process with a user's environment (the thread variables removed)."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
    if case == "bench-1thread":
        env.update(OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    cmd = [sys.executable, "-c", _CHILD, case, str(args.n), args.sarcos or "", str(args.restarts), str(args.outputs),
           str(args.seed)]
    out = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, help="output folder (bench_fit_threads.json)")
    ap.add_argument("--sarcos", default=None, help="IAS SARCOS .mat file (default: synthetic data)")
    ap.add_argument("--n", type=int, default=300)
    ap.add_argument("--outputs", type=int, default=7, choices=(6, 7))
    ap.add_argument("--restarts", type=int, default=10)
    ap.add_argument("--reps", type=int, default=2, help="fits per case (the cases alternate)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--background-load", type=int, default=0,
                    help="busy single-threaded processes running beside the fits (a shared machine)")
    args = ap.parse_args(argv)
    if args.background_load < 0:
        ap.error(f"--background-load: expected an integer >= 0, got {args.background_load}")
    check_output(ap, args.out, "--out", "folder")
    if args.sarcos:
        check_sarcos_file(ap, args.sarcos)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    runs: dict[str, list[dict]] = {c: [] for c in CASES}
    load0 = os.getloadavg()
    t0 = time.perf_counter()
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.background_load)]
    try:
        for r in range(args.reps):
            for case in CASES:
                res = run_case(case, args)
                runs[case].append(res)
                print(f"rep {r + 1}/{args.reps} {case:>13}: {res['time_s']:7.2f} s (torch threads before the fit "
                      f"{res['torch_threads_before']}, after {res['torch_threads_after']})", flush=True)
    finally:
        for h in hogs:
            h.kill()
            h.wait()
    import numpy as np

    med = {c: float(np.median([x["time_s"] for x in runs[c]])) for c in CASES}
    ref = med["bench-1thread"]
    print(f"\n{'case':>13} | {'median s':>8} | {'x bench-1thread':>15} | worst NLL gap to bench-1thread")
    summary = {}
    for c in CASES:
        gap = max(abs(a - b) for a, b in zip(runs[c][0]["best_nll"], runs["bench-1thread"][0]["best_nll"]))
        summary[c] = {"median_s": med[c], "ratio_to_bench_1thread": med[c] / ref, "max_abs_nll_gap": gap}
        print(f"{c:>13} | {med[c]:8.2f} | {med[c] / ref:15.2f} | {gap:.2e}")
    res = {"command": " ".join(["python -m scripts.bench_fit_threads"] + (argv if argv is not None else sys.argv[1:])),
           "cpus": os.cpu_count(), "load_avg_start": load0, "load_avg_end": os.getloadavg(), "n": args.n,
           "outputs": args.outputs, "restarts": args.restarts, "reps": args.reps,
           "background_load": args.background_load, "runs": runs, "summary": summary,
           "wall_s": time.perf_counter() - t0}
    from cascgp.io import write_json

    write_json(out / "bench_fit_threads.json", res)
    print(f"wrote {out / 'bench_fit_threads.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
