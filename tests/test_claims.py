"""The claims' text (``claims.md``) from a results dict: what it says of a run that is not a full one."""

from __future__ import annotations

import re

import numpy as np

from cascgp_experiments.common import RBD, VARIANTS


def test_claims_with_intervals_without_grid_points() -> None:
    """A grid that ends at 2 s leaves the 4-5 s and 9-10 s intervals empty: they are '-' and not counted, and
    claims.md says so (it printed +nan% and counted cells that do not exist)."""
    from cascgp_experiments.claims import claims_markdown

    rng = np.random.default_rng(0)
    rows = {m: [[float(rng.uniform(0.1, 0.2)), float("nan"), float("nan")] for _ in range(6)]
            for m in list(VARIANTS) + [RBD]}
    md = claims_markdown({"jaco": {"table": {"rows": rows}, "n_subsets": 3, "models": {m: {} for m in rows}},
                          "meta": {"sarcos_skipped": "no SARCOS file given, or --no-sarcos", "complete": False}})
    assert "nan" not in md.lower()
    assert "No grid point in 4-5 s, 9-10 s" in md
    assert "The SARCOS part was not run (no SARCOS file given" in md
    assert "**This run did not finish**" in md  # a killed run's results.json says so
    assert "\n\n\n" not in md
    inward = re.search(r"inward wins (\d+) of (\d+) \(joint, interval\) cells", md)
    assert inward and int(inward[2]) == 6  # six joints, one interval
    gain = re.search(r"mean relative gain ([^.]*)\.", md)
    assert gain and gain[1].endswith("/-/-")
