"""The paper's two analyses besides the curves: optimiser iteration counts and rank correlations.

Iteration counts per joint (the paper's run-time figure, :func:`iteration_counts`): for the NP
standard, inward and outward models, the GP of every joint is fitted on its own (one
:class:`cascgp.gp.GPBank` per joint, so that each fit's wall time is that joint's) on ``n`` (500)
training rows with ``n_restarts`` (10) starts. L-BFGS stops at max |gradient| <= 1e-5 or a relative
objective change <= 2e-9 (the paper's tolerances, :class:`GPFitConfig` defaults). Reported per
joint: the iteration count of every start, their mean and standard deviation, the evaluations, and
the wall time of the fit.

Spearman rank correlation of joint states and torques (the paper's correlation figure,
:func:`spearman_block`): the labels ``q1..qN, qd1..qdN, qdd1..qddN, tau1..tauN`` and the matrix of
absolute Spearman coefficients (:func:`scipy.stats.spearmanr`) over all rows; the command line is
``python -m scripts.correlation``.

The figures are made by :mod:`cascgp_experiments.plots` from the JSON.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from tqdm import tqdm

STRUCTURES = ("standard", "inward", "outward")


def iteration_counts(data, *, n: int = 500, n_restarts: int = 10, seed: int = 0,
                     structures: tuple[str, ...] = STRUCTURES) -> dict[str, Any]:
    """Fit the NP GPs of ``structures`` on the first ``n`` rows of ``data`` (DynamicsData, 10 Hz)."""
    from cascgp.features import build_inputs, input_dim, state_features
    from cascgp.gp import GPBank, GPFitConfig

    if data.n_samples < n:
        raise ValueError(f"n: {n} training rows requested but the data has {data.n_samples}")
    d = data.take(np.arange(n))
    S, _ = state_features(d, "db")
    N = d.dof
    out: dict[str, Any] = {"n": n, "n_restarts": n_restarts, "models": {}}
    bar = tqdm(total=len(structures) * N, desc=f"iteration counts (n={n}, {n_restarts} restarts)",
               unit="GP")
    for s in structures:
        X = build_inputs(S, d.tau, s)
        rec: dict[str, list] = {"n_iter": [], "n_eval": [], "wall_s": [], "best_nll": [], "dim": [],
                                "converged": [], "reason": []}
        for j in range(N):
            cfg = GPFitConfig(n_restarts=n_restarts, seed=seed + 7919 * j)
            t0 = time.perf_counter()
            bank = GPBank(cfg).fit([X[j]], [d.tau[:, j]])
            rec["wall_s"].append(time.perf_counter() - t0)
            info = bank.fit_info[0]
            rec["n_iter"].append(info["n_iter"])
            rec["n_eval"].append(info["n_eval"])
            rec["best_nll"].append(info["best_nll"])
            rec["converged"].append(info["converged"])
            rec["reason"].append(info["reason"])
            rec["dim"].append(input_dim(s, j, N))
            bar.update(1)
        it = np.asarray(rec["n_iter"], dtype=float)
        rec["n_iter_mean"] = it.mean(axis=1).tolist()
        rec["n_iter_std"] = it.std(axis=1).tolist()
        out["models"][f"np-{s}"] = rec
    bar.close()
    return out


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
