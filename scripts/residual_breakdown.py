"""What the nominal rigid-body model misses on the simulated Jaco 2: a per-joint breakdown.

Usage::

    python -m scripts.residual_breakdown --out out/residual [--seconds 20] [--seed 0]

Writes ``residual_breakdown.json`` and prints a table; what is computed:
:mod:`cascgp_experiments.residual`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cascgp.io import write_json
from cascgp_experiments.cli.options import check_output
from cascgp_experiments.residual import ROWS, breakdown


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--seconds", type=float, default=20.0)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    check_output(p, a.out, "--out", "folder")
    res = breakdown(a.seconds, a.seed)
    write_json(a.out / "residual_breakdown.json", {"seconds": a.seconds, "seed": a.seed, **res}, indent=2)
    print("| N m, per joint | " + " | ".join(f"J{i + 1}" for i in range(6)) + " |")
    print("|---|" + "---|" * 6)
    for key, label in ROWS:
        print(f"| {label} | " + " | ".join(f"{v:.2f}" for v in res[key]) + " |")


if __name__ == "__main__":
    main()
