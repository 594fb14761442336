"""Two runs of the data-efficiency study side by side (:mod:`cascgp_experiments.compare`); a table and a JSON.

Usage::

    python -m scripts.compare_study out/study_before/results.json out/study_after/results.json --json cmp.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from cascgp_experiments.cli.options import check_output
from cascgp_experiments.compare import compare_results, format_comparison


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("reference", type=Path, help="results.json of the reference run")
    ap.add_argument("other", type=Path, help="results.json of the run to compare")
    ap.add_argument("--json", type=Path, default=None, help="write the comparison here")
    a = ap.parse_args(argv)
    check_output(ap, a.json, "--json", "file")
    runs = []
    for p in (a.reference, a.other):
        try:
            runs.append(json.loads(p.read_text()))
        except (OSError, ValueError) as exc:
            ap.error(f"{p}: expected a study's results.json ({exc})")
        if not isinstance(runs[-1], dict) or not ({"jaco", "sarcos"} & set(runs[-1])):
            ap.error(f"{p}: expected a study's results.json (no 'jaco' or 'sarcos' results)")
    try:
        c = compare_results(*runs)
    except ValueError as exc:
        ap.error(f"the runs cannot be compared: {exc}")
    except (KeyError, TypeError, AttributeError) as exc:  # a JSON with the top-level keys but not their contents
        what = f"no {exc}" if isinstance(exc, KeyError) else str(exc)
        ap.error(f"expected two study results.json files; one lacks what a study writes ({what})")
    print(format_comparison(c))
    if a.json is not None:
        a.json.parent.mkdir(parents=True, exist_ok=True)
        a.json.write_text(json.dumps({"reference": str(a.reference), "other": str(a.other), **c}, indent=1))
        print(f"wrote {a.json}")


if __name__ == "__main__":
    main()
