"""Two runs of the task transfer side by side, attempt by attempt (:func:`cascgp_experiments.compare.compare_transfer`);
a table and a JSON.

Usage::

    python -m scripts.compare_transfer out/transfer_before/results.json out/transfer_after/results.json --json cmp.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from cascgp_experiments.cli.options import check_output
from cascgp_experiments.compare import compare_transfer, format_transfer_comparison


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    ap.add_argument("reference", type=Path, help="results.json of the reference run")
    ap.add_argument("other", type=Path, help="results.json of the run to compare")
    ap.add_argument("--json", type=Path, default=None, help="write the comparison here")
    a = ap.parse_args(argv)
    check_output(ap, a.json, "--json", "file")
    runs = []
    for p in (a.reference, a.other):
        try:
            run = json.loads(p.read_text())
        except (OSError, ValueError) as exc:
            ap.error(f"{p}: expected a task transfer's results.json ({exc})")
        if not isinstance(run, dict) or "controllers" not in run:
            ap.error(f"{p}: expected a task transfer's results.json (no 'controllers')")
        runs.append(run)
    try:
        c = compare_transfer(*runs)
    except ValueError as exc:
        ap.error(str(exc))
    print(format_transfer_comparison(c))
    if a.json is not None:
        a.json.parent.mkdir(parents=True, exist_ok=True)
        a.json.write_text(json.dumps({"reference": str(a.reference), "other": str(a.other), "controllers": c},
                                     indent=1))
        print(f"wrote {a.json}")


if __name__ == "__main__":
    main()
