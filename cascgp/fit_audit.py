r"""Equivalence audit of the GP fit: does the (fast) default reach the optimum of a thorough search?

For every GP, the negative log marginal likelihood (NLL, normalised units, as in :mod:`cascgp.gp`) reached by a
fit with the configuration under test is compared with the best NLL of a *reference* fit of the same data:
``n_cold`` cold starts, each run to convergence (no stalling, racing, dropping or screening). The gap

.. math::

    \Delta_b = \mathcal L_b^{\text{config}} - \mathcal L_b^{\text{cold}} \quad (\text{nats; } < 0: \text{the config
    found a better optimum})

is reported per GP; the default configuration is meant to keep :math:`\Delta_b \le 0.1` on at least 95 % of GPs
(``scripts/fit_audit.py`` runs the audit on a suite of data sets and writes a report; ``tests/test_fit_audit.py``
runs it on small data).

Two entry points:

* :func:`audit_bank` fits both from raw data ``X, Y``.
* :func:`audit_model` audits an already fitted :class:`cascgp.models.CascadedGPModel` (or :class:`GPBank`):
  every GP is refitted on its own training data with ``n_cold`` cold starts and compared with the NLL the model
  holds. This is what the data-efficiency study calls after each of its fits.

The cold reference uses ``seed`` for its starts. With ``seed`` equal to the tested config's seed (both 0 by
default) the reference runs the *same* start points to convergence, so the gap isolates what the early-stopping
rules lose; pass another ``seed`` for an independent search.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import numpy as np

from cascgp.gp import GPBank, GPFitConfig
from cascgp.checks import check_count

__all__ = ["cold_config", "audit_bank", "audit_model", "summarise_gaps"]


def cold_config(config: GPFitConfig | None = None, *, n_cold: int = 10, seed: int = 0) -> GPFitConfig:
    """The reference configuration: ``config`` (default :class:`GPFitConfig`) with ``n_cold`` starts, every start
    run to convergence (``stall_window``, ``race_at``, ``drop_after`` and ``screen_n`` switched off)."""
    config = config or GPFitConfig()
    if not isinstance(config, GPFitConfig):
        raise TypeError(f"config: expected GPFitConfig or None, got {type(config).__name__}")
    return dataclasses.replace(config, n_restarts=check_count(n_cold, "n_cold"), seed=int(seed), stall_window=None,
                               race_at=None, drop_after=None, screen_n=None)


def summarise_gaps(gaps: np.ndarray, tol: float = 0.1) -> dict[str, Any]:
    """``n``, ``frac_within`` (share of gaps ``<= tol``), ``max_gap``, ``median_gap``, ``n_better`` (gap < -tol)."""
    g = np.asarray(gaps, dtype=float)
    return {"n": int(g.size), "tol": float(tol), "frac_within": float(np.mean(g <= tol)) if g.size else 1.0,
            "max_gap": float(g.max()) if g.size else 0.0, "median_gap": float(np.median(g)) if g.size else 0.0,
            "n_better": int(np.sum(g < -tol))}


def _as_lists(X: Any, Y: Any) -> tuple[list[np.ndarray], list[np.ndarray]]:
    Ya = Y if isinstance(Y, (list, tuple)) else None
    if Ya is None:
        Y = np.asarray(Y, dtype=np.float64)
        if Y.ndim == 1:
            Y = Y[:, None]
        if Y.ndim != 2:
            raise ValueError(f"Y: expected (n, B) targets or a list of (n,) vectors, got shape {Y.shape}")
        Ya = [Y[:, b] for b in range(Y.shape[1])]
    if isinstance(X, (list, tuple)):
        Xa = list(X)
    else:
        Xa = [np.asarray(X, dtype=np.float64)] * len(Ya)
    if len(Xa) != len(Ya):
        raise ValueError(f"X: expected one input array per GP ({len(Ya)}), got {len(Xa)}")
    return Xa, list(Ya)


def audit_bank(X: Any, Y: Any, config: GPFitConfig | None = None, *, n_cold: int = 10, seed: int = 0,
               tol: float = 0.1) -> dict[str, Any]:
    """Fit ``X, Y`` with ``config`` and with ``n_cold`` cold starts run to convergence; compare NLLs per GP.

    Args:
        X: inputs: one ``(n, d)`` array shared by all GPs, or a list of ``(n, d_b)`` arrays (one per GP).
        Y: targets: ``(n, B)`` (or ``(n,)``) array, or a list of ``(n,)`` vectors.
        config: the configuration under test (default :class:`GPFitConfig`, i.e. the library default).
        n_cold: starts of the reference fit.
        seed: seed of the reference's starts (see the module docstring).
        tol: the gap counted as "equivalent" in ``summary`` (nats).

    Returns:
        dict with ``gaps`` (B,) ``= default_nll - cold_nll`` (nats, normalised units), ``default_nll`` (B,),
        ``cold_nll`` (B,), ``summary`` (:func:`summarise_gaps`), ``default_time_s``, ``cold_time_s``,
        ``default_evals``, ``cold_evals`` (NLL+gradient evaluations, all GPs), ``config`` and ``cold_config``
        (dicts), and ``bank`` / ``cold_bank`` (the fitted :class:`GPBank` objects).
    """
    config = config or GPFitConfig()
    ref_cfg = cold_config(config, n_cold=n_cold, seed=seed)
    Xa, Ya = _as_lists(X, Y)
    t0 = time.perf_counter()
    bank = GPBank(config).fit(Xa, Ya)
    t1 = time.perf_counter()
    cold = GPBank(ref_cfg).fit(Xa, Ya)
    t2 = time.perf_counter()
    d_nll = np.array([fi["best_nll"] for fi in bank.fit_info])
    c_nll = np.array([fi["best_nll"] for fi in cold.fit_info])
    gaps = d_nll - c_nll
    return {"gaps": gaps, "default_nll": d_nll, "cold_nll": c_nll, "summary": summarise_gaps(gaps, tol),
            "default_time_s": t1 - t0, "cold_time_s": t2 - t1, "default_evals": int(bank.fit_summary["n_eval"]),
            "cold_evals": int(cold.fit_summary["n_eval"]), "config": dataclasses.asdict(config),
            "cold_config": dataclasses.asdict(ref_cfg), "bank": bank, "cold_bank": cold}


def _bank_training_data(bank: GPBank) -> tuple[list[np.ndarray], list[np.ndarray]]:
    return bank.training_data()


def audit_model(model: Any, *, n_cold: int = 10, seed: int = 0, tol: float = 0.1) -> dict[str, Any]:
    """Audit an already fitted model: refit each of its GPs with ``n_cold`` cold starts and compare NLLs.

    Args:
        model: a fitted :class:`cascgp.models.CascadedGPModel` (its ``banks``) or a fitted :class:`GPBank`.
        n_cold, seed, tol: as in :func:`audit_bank`; the reference uses the model's own ``GPFitConfig`` with the
            early-stopping rules switched off (:func:`cold_config`).

    Returns:
        dict with ``gaps`` (one per GP, in the model's joint order ``model.where`` for a model, bank order for a
        bank) ``= model_nll - cold_nll``, ``model_nll``, ``cold_nll``, ``summary``, ``cold_time_s``,
        ``cold_evals``.
    """
    if isinstance(model, GPBank):
        banks, where = [model], [(0, b) for b in range(model.n_gps)]
    elif hasattr(model, "banks") and hasattr(model, "where"):
        if not model.banks:
            raise ValueError("model: not fitted (no GP banks)")
        banks, where = list(model.banks), list(model.where)
    else:
        raise TypeError(f"model: expected a fitted CascadedGPModel or GPBank, got {type(model).__name__}")
    cold_by_bank: dict[int, np.ndarray] = {}
    t0 = time.perf_counter()
    evals = 0
    for k, bank in enumerate(banks):
        Xa, Ya = _bank_training_data(bank)
        cold = GPBank(cold_config(bank.config, n_cold=n_cold, seed=seed)).fit(Xa, Ya)
        cold_by_bank[k] = np.array([fi["best_nll"] for fi in cold.fit_info])
        evals += int(cold.fit_summary["n_eval"])
    m_nll = np.array([banks[k].fit_info[b]["best_nll"] for k, b in where])
    c_nll = np.array([cold_by_bank[k][b] for k, b in where])
    gaps = m_nll - c_nll
    return {"gaps": gaps, "model_nll": m_nll, "cold_nll": c_nll, "summary": summarise_gaps(gaps, tol),
            "cold_time_s": time.perf_counter() - t0, "cold_evals": evals}
