"""SARCOS part of the data-efficiency study (the paper's Fig. 5).

Data: the IAS SARCOS file (``ias_sarcos_data.mat``, path argument), the real 7-DOF SARCOS arm.
Training: the IAS training rows subsampled to 10 Hz (every 5th row of the nominal 50 Hz, restarting
at each recording boundary that :mod:`cascgp.sarcos` detects: 2803 rows) and
split into 9 time-contiguous subsets of equal row counts (about 31 s each). Test: the IAS test
rows whose inputs do NOT also stand in the training rows (to 8 decimals: 2785 of 5569 are
removed, :func:`cascgp.sarcos.load_ias` with ``dedup=True``), all 2784 kept rows, not
subsampled. Models: NP standard, inward and outward (derivative based), as in the paper.

Usage::

    python -m scripts.sarcos_study --sarcos ../shared/data/sarcos/ias_sarcos_data.mat --out out/sarcos
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from scripts._study_common import DEFAULT_SARCOS, NP_DB, write_json
from scripts._study_curves import CurveSpec, default_workers, run_curves

SARCOS_FULL_GRID = (1.0, 1.5, 2.0, 3.0, 4.0, 4.5, 5.0, 7.0, 9.0, 9.5, 10.0, 14.0, 20.0, 30.0)
SARCOS_QUICK_GRID = (1.0, 2.0, 5.0, 10.0)
SARCOS_SMOKE_GRID = (1.0, 2.0)


def prepare_files(sarcos_path: str | Path, out: str | Path) -> tuple[Path, Path, dict[str, Any]]:
    """Write the IAS train / de-duplicated test sets as DynamicsData files under ``out``."""
    from cascgp.sarcos import load_ias

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    train, test = load_ias(sarcos_path, dedup=True)
    tr, te = out / "sarcos_train.npz", out / "sarcos_test.npz"
    train.save(tr)
    test.save(te)
    info = {"file": str(sarcos_path), "n_train_rows_file": train.n_samples,
            "n_test_rows_file": int(test.meta["n_rows_in_file"]),
            "n_test_duplicates_removed": int(test.meta["n_duplicates_removed"]),
            "n_test_rows": test.n_samples,
            "test_set": "IAS X_test/Y_test rows whose inputs do not stand in X_train (8 decimals)"}
    return tr, te, info


def run_sarcos(sarcos_path: str | Path, out: str | Path, *, grid=SARCOS_FULL_GRID, n_subsets: int = 9,
               n_restarts: int = 1, workers: int | None = None, seed: int = 0,
               gp_overrides: dict | None = None) -> dict[str, Any]:
    """The SARCOS block of the results JSON (curves of NP standard / inward / outward)."""
    t0 = time.perf_counter()
    out = Path(out)
    tr, te, info = prepare_files(sarcos_path, out / "data")
    spec = CurveSpec(train_path=str(tr), test_path=str(te), n_subsets=n_subsets, grid=list(grid),
                     train_hz=10.0, test_hz=None, split_by="rows", urdf=None, n_restarts=n_restarts,
                     seed=seed, gp_overrides=dict(gp_overrides or {}))
    block = run_curves(spec, list(NP_DB), workers=workers or default_workers(),
                       cache_dir=out / "cache" / "sarcos", desc="SARCOS fits")
    block.update(info)
    block["dof"] = 7
    block["wall_s_total"] = time.perf_counter() - t0
    return block


def main(argv: list[str] | None = None) -> None:
    from scripts._study_common import limit_threads

    ap = argparse.ArgumentParser(description="SARCOS NP standard/inward/outward data-efficiency curves")
    ap.add_argument("--sarcos", default=str(DEFAULT_SARCOS), help="path of ias_sarcos_data.mat")
    ap.add_argument("--out", required=True)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--restarts", type=int, default=1)
    ap.add_argument("--workers", type=int, default=None)
    a = ap.parse_args(argv)
    limit_threads(1)
    block = run_sarcos(a.sarcos, a.out, grid=SARCOS_QUICK_GRID if a.quick else SARCOS_FULL_GRID,
                       n_restarts=a.restarts, workers=a.workers)
    write_json(Path(a.out) / "sarcos.json", block)
    print(f"wrote {Path(a.out) / 'sarcos.json'}")


if __name__ == "__main__":
    main()
