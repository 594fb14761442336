"""Spearman rank correlation of joint states and torques (the paper's correlation figure).

``spearman_block(data)`` returns the labels ``q1..qN, qd1..qdN, qdd1..qddN, tau1..tauN`` and the
matrix of absolute Spearman coefficients (:func:`scipy.stats.spearmanr`) over all rows.
The plot is made by :mod:`scripts.study_plots` from the JSON.

Usage::

    python -m scripts.correlation --data out/study/data/jaco_train.npz --out corr.json
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np


def spearman_block(data, max_rows: int | None = None) -> dict[str, Any]:
    """``{"labels": [...], "abs_spearman": (4N, 4N)}`` for a :class:`cascgp.data.DynamicsData`.

    ``max_rows``: use an evenly spaced subset of rows (rank correlation of long records is
    dominated by sorting; 10 Hz data is used in the study anyway)."""
    from scipy.stats import spearmanr

    n = data.dof
    M = np.concatenate([data.q, data.qd, data.qdd, data.tau], axis=1)
    if max_rows is not None and M.shape[0] > max_rows:
        M = M[np.linspace(0, M.shape[0] - 1, max_rows).astype(int)]
    rho = spearmanr(M).statistic
    labels = ([f"q{j + 1}" for j in range(n)] + [f"qd{j + 1}" for j in range(n)]
              + [f"qdd{j + 1}" for j in range(n)] + [f"tau{j + 1}" for j in range(n)])
    return {"labels": labels, "abs_spearman": np.abs(np.asarray(rho)), "n_rows": int(M.shape[0])}


def main(argv: list[str] | None = None) -> None:
    from cascgp.data import DynamicsData
    from scripts._study_common import write_json

    ap = argparse.ArgumentParser(description="Spearman correlation of joint states and torques")
    ap.add_argument("--data", required=True, help="DynamicsData .npz")
    ap.add_argument("--out", required=True, help="JSON file to write")
    ap.add_argument("--hz", type=float, default=10.0, help="subsample to this rate first")
    a = ap.parse_args(argv)
    d = DynamicsData.load(a.data).subsample(a.hz)
    write_json(a.out, spearman_block(d))


if __name__ == "__main__":
    main()
