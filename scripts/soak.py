"""Soak test: random tasks, payloads and actions on both Jaco envs, repeated make/close, buffer appends and model
retrains for a bounded time; fails on NaN, an exception or memory growth beyond a bound (issue 12).

    python -m scripts.soak --minutes 10 --out out/soak [--seed 0] [--rss-bound-mib 150]

Prints a progress line every 15 s and a summary; writes ``soak.json`` into ``--out``; exits 1 with the failure
on stderr when a check fails. What one cycle does and the checks: :mod:`cascgp_experiments.soak`.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

from cascgp_experiments.cli.options import check_output  # noqa: E402
from cascgp_experiments.soak import FAULTS, RSS_BOUND_MIB, SoakConfig, run_soak  # noqa: E402


def parse_args(argv: list[str] | None = None) -> tuple[SoakConfig, Path]:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--minutes", type=float, required=True, help="time budget (min); the last cycle finishes")
    p.add_argument("--out", type=Path, required=True, help="output folder (soak.json; scratch files removed)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--rss-bound-mib", type=float, default=RSS_BOUND_MIB,
                   help="allowed resident-memory growth after the warm-up (MiB)")
    p.add_argument("--warmup-cycles", type=int, default=2, help="cycles before the memory baseline is taken")
    p.add_argument("--max-steps", type=int, default=200, help="longest episode (control steps)")
    p.add_argument("--fault", choices=FAULTS, default=None, help="inject a failure (to check the checks)")
    a = p.parse_args(argv)
    check_output(p, a.out, "--out", "folder")
    try:
        cfg = SoakConfig(minutes=a.minutes, seed=a.seed, rss_bound_mib=a.rss_bound_mib,
                         warmup_cycles=a.warmup_cycles, max_steps=a.max_steps, fault=a.fault)
    except ValueError as exc:
        p.error(str(exc).replace("SoakConfig.", "--").replace("_", "-"))
    return cfg, a.out


def main(argv: list[str] | None = None) -> int:
    cfg, out = parse_args(argv)
    print(f"soak: {cfg.minutes:g} min, seed {cfg.seed}, RSS bound {cfg.rss_bound_mib:g} MiB after "
          f"{cfg.warmup_cycles} warm-up cycles -> {out / 'soak.json'}", flush=True)
    result = run_soak(cfg, out, log=lambda line: print(line, flush=True))
    print(result.summary(), flush=True)
    if not result.passed:
        print(f"soak FAILED: {result.failure}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
