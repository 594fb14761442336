"""Compare calibration runs (the arms of ``docs/studies/calibration.md``): decision statistics and per-joint tables.

    python -m studies.commands.calibration_compare noisy=out/cal/noisy noiseless=out/cal/noiseless [...] [--base noisy]
    python -m studies.commands.calibration_compare base=out/floor/none floor=out/floor/sensor --floor-effect

Each ``NAME=DIR`` is a folder with a ``calibration.json`` of ``python -m studies.commands.calibration``; prints Markdown
(:func:`studies.calibration.compare_arms` and :func:`~studies.calibration.combined_table`);
with ``--floor-effect`` also :func:`~studies.calibration.floor_effect` of the second arm against the
first, and the per-joint held-out RMSE.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("arms", nargs="+", metavar="NAME=DIR")
    ap.add_argument("--base", default=None, help="the arm the changes are taken against (default: the first)")
    ap.add_argument("--floor-effect", action="store_true",
                    help="also the noise-floor statistics of the second arm against the first (two arms)")
    a = ap.parse_args(argv)
    from cascgp.io import read_json
    from studies.calibration import combined_table, compare_arms, floor_effect

    arms = {}
    for spec in a.arms:
        name, sep, folder = spec.partition("=")
        if not sep or not name or not folder:
            ap.error(f"expected NAME=DIR, got {spec!r}")
        path = Path(folder) / "calibration.json"
        if not path.is_file():
            ap.error(f"{name}: no {path}")
        arms[name] = read_json(path)
    if a.base is not None and a.base not in arms:
        ap.error(f"--base {a.base!r}: not one of {list(arms)}")
    try:
        for field, title in (("coverage_propagated", "propagated"), ("coverage_mean_input", "given mean input")):
            print(f"Coverage, {title} variance, over all cells:\n\n{compare_arms(arms, field, a.base)}\n")
            print(f"Per joint ({title}):\n\n{combined_table(arms, field)}\n")
        if a.floor_effect:
            if len(arms) != 2:
                ap.error("--floor-effect: expected exactly two arms (no floor, floor)")
            b, f = arms.values()
            for field in ("coverage_propagated", "coverage_input_noise", "coverage_mean_input"):
                if field in next(iter(b["summary"].values())) and field in next(iter(f["summary"].values())):
                    print(f"Noise-floor effect, {field}:\n\n{floor_effect(b, f, field)}\n")
            for field in ("rmse", "noise_std"):
                print(f"Per joint ({field}, N m):\n\n{combined_table(arms, field)}\n")
    except ValueError as e:
        ap.error(str(e))


if __name__ == "__main__":
    main()
