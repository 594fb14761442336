"""Spearman rank correlation of joint states and torques (the paper's correlation figure).

Usage::

    python -m scripts.correlation --data out/study/data/jaco_train.npz --out corr.json

Computed by :func:`cascgp_experiments.analyses.spearman_block`.
"""

from __future__ import annotations

import argparse


def main(argv: list[str] | None = None) -> None:
    from cascgp.data import DynamicsData
    from cascgp.io import write_json
    from cascgp_experiments.cli.options import check_input, check_output
    from cascgp_experiments.analyses import spearman_block

    ap = argparse.ArgumentParser(description="Spearman correlation of joint states and torques")
    ap.add_argument("--data", required=True, help="DynamicsData .npz")
    ap.add_argument("--out", required=True, help="JSON file to write")
    ap.add_argument("--hz", type=float, default=10.0, help="subsample to this rate first")
    a = ap.parse_args(argv)
    check_input(ap, a.data, "--data", "file")
    check_output(ap, a.out, "--out", "file")
    d = DynamicsData.load(a.data).subsample(a.hz)
    write_json(a.out, spearman_block(d))


if __name__ == "__main__":
    main()
