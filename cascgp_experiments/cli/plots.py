"""``cascgp plots``: a study's figures, tables, CSVs and claims, redrawn from its ``results.json`` alone.

Usage::

    cascgp plots --json out/study/results.json --out DIR     # or a `cascgp sarcos` run's sarcos.json

What is written: :mod:`cascgp_experiments.plots`; from a ``sarcos.json``, the files ``cascgp sarcos`` writes
(``fig_sarcos.png``, ``curves_sarcos.csv``, ``sarcos_claims.md`` and ``sarcos_table.md``).
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
from pathlib import Path

from cascgp_experiments.cli.options import check_input, check_output


def main(argv: list[str] | None = None, prog: str | None = None) -> None:
    """``cascgp plots``: parse ``argv`` (``sys.argv[1:]`` when ``None``) and redraw."""
    ap = argparse.ArgumentParser(prog=prog, description="Redraw a study's figures, tables, CSVs and claims from its "
                                                        "results.json (or a cascgp sarcos run's sarcos.json)")
    ap.add_argument("--json", required=True, help="the run's results.json (cascgp study) or sarcos.json")
    ap.add_argument("--out", required=True, metavar="DIR", help="folder for the figures and tables")
    a = ap.parse_args(argv)
    check_input(ap, a.json, "--json", "file")
    check_output(ap, a.out, "--out", "folder")
    from cascgp_experiments.plots import as_results, render_results

    try:
        run = json.loads(Path(a.json).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        ap.error(f"--json: {a.json}: expected a study's results.json ({exc})")
    res = as_results(run)
    if res is None:
        ap.error(f"--json: {a.json}: expected a study's results.json or a sarcos.json (no 'jaco' or 'sarcos' "
                 f"results)")
    out = Path(a.out)
    near = next(p for p in (out, *out.parents) if p.exists())  # check_output: a folder this process can write
    with tempfile.TemporaryDirectory(dir=near) as tmp:  # drawn aside, moved into --out once all are drawn
        from_sarcos = res.get("sarcos") is run  # a cascgp sarcos run's sarcos.json: the files that command writes
        try:
            drawn = render_results(res, tmp, claims="sarcos_claims.md" if from_sarcos else "claims.md")
            if from_sarcos:
                from cascgp.io import atomic_write_text
                from cascgp_experiments.cli.sarcos import summary_table

                drawn.append(Path(tmp) / "sarcos_table.md")
                atomic_write_text(drawn[-1], summary_table(run) + "\n")
        except KeyError as exc:  # a hand-edited or truncated file: --out is left as it was
            ap.error(f"--json: {a.json}: not a complete study results file (missing entry {exc.args[0]!r})")
        except (ValueError, TypeError, IndexError, StopIteration) as exc:  # an entry of another type or length
            ap.error(f"--json: {a.json}: not a complete study results file (an entry cannot be drawn: "
                     f"{type(exc).__name__}{': ' + str(exc) if str(exc) else ''})")
        out.mkdir(parents=True, exist_ok=True)
        for p in drawn:
            dest = out / p.relative_to(tmp)
            dest.parent.mkdir(parents=True, exist_ok=True)
            os.replace(p, dest)
            print(dest)


if __name__ == "__main__":
    main()
