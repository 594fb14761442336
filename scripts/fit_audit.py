"""Equivalence audit of the default GP fit (rerunnable): default vs 10 cold starts run to convergence.

Usage::

    python -m scripts.fit_audit --out out/audit --sarcos /work/shared/data/sarcos/ias_sarcos_data.mat
    python -m scripts.fit_audit --out out/audit --quick          # synthetic only, small

Writes ``fit_audit.json`` (every gap) and ``fit_audit.md`` (a summary table); exits 1 unless the default is
within ``--tol`` of the reference on >= 95 % of the GPs. The suite and the report:
:mod:`cascgp_experiments.audit_suite`.
"""

from __future__ import annotations

import argparse
import os
import sys

if __name__ == "__main__":
    for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_v, "1")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, help="output directory")
    ap.add_argument("--sarcos", default=None, help="path of ias_sarcos_data.mat (default: synthetic data only)")
    ap.add_argument("--cold", type=int, default=10, help="cold starts of the reference fit")
    ap.add_argument("--seed", type=int, default=0, help="seed of the reference's starts")
    ap.add_argument("--quick", action="store_true", help="smallest data sets only")
    ap.add_argument("--tol", type=float, default=0.1)
    args = ap.parse_args(argv)
    from cascgp_experiments.audit_suite import run_audit
    from cascgp_experiments.cli.options import check_output, check_sarcos_file

    check_output(ap, args.out, "--out", "folder")
    if args.sarcos:
        check_sarcos_file(ap, args.sarcos)

    command = "python -m scripts.fit_audit " + " ".join(argv if argv is not None else sys.argv[1:])
    res, text = run_audit(args.out, sarcos=args.sarcos, cold=args.cold, seed=args.seed, quick=args.quick,
                          tol=args.tol, command=command)
    print(text)
    summ = res["summary"]
    ok = summ["frac_within"] >= 0.95
    print(f"{'PASS' if ok else 'FAIL'}: {summ['frac_within'] * 100:.1f} % of {summ['n']} GPs within {args.tol} nat "
          f"(max gap {summ['max_gap']:+.4f})")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
