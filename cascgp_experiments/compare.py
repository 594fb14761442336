"""Two runs of an experiment side by side: how far apart their numbers are.

Used to check a change that should leave the numbers alone, or change them only through the fit (round-off in the
optimiser's path). For the data-efficiency study (:func:`compare_results`): per data set the largest change of any
nRMSE (every subset, grid point and joint), how many changed by more than 1 %, the largest change of a Table I
cell, every pooled test whose verdict changed, and both runs' fit audits
(:func:`cascgp_experiments.curves.audit_summary`). For the task transfer (:func:`compare_transfer`): per controller,
attempt by attempt, how far the tracking RMSE and the marbles in the jar moved.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["compare_results", "format_comparison", "compare_transfer", "format_transfer_comparison"]


def _verdict(test: dict[str, Any], alpha: float = 0.05) -> str:
    if test["p_holm"] >= alpha:
        return "n.s."
    return "first better" if test["ratio"] < 1 else "first worse"


def compare_results(a: dict[str, Any], b: dict[str, Any]) -> dict[str, Any]:
    """Compare two ``results.json`` of :func:`cascgp_experiments.study.run_study` (``a`` the reference).

    Returns per data set (``"jaco"``, ``"sarcos"``, those in both): ``max_abs_nrmse_change``, ``rel_change``
    (median, 99th percentile, max of :math:`|b - a| / a` over every subset, grid point and joint),
    ``n_cells``, ``n_cells_over_1pct``, ``max_abs_table_change``, ``pooled`` (per family: ``n_tests``,
    ``max_abs_ratio_change``, ``changed_verdicts``) and ``audit`` (both runs' summaries, records left out).
    ``ValueError`` names a data set or model present in one run only.
    """
    out: dict[str, Any] = {}
    for blk in ("jaco", "sarcos"):
        if blk not in a or blk not in b:
            continue
        A, B = a[blk], b[blk]
        if set(A["models"]) != set(B["models"]):
            raise ValueError(f"{blk}: the runs have different models: {sorted(A['models'])} / {sorted(B['models'])}")
        diffs, rels = [], []
        for m in A["models"]:
            x, y = np.asarray(A["models"][m]["nrmse_all"], float), np.asarray(B["models"][m]["nrmse_all"], float)
            if x.shape != y.shape:
                raise ValueError(f"{blk} {m}: the runs have different subsets, grids or joints: scores of shape "
                                 f"{x.shape} / {y.shape} (subsets, grid points, joints)")
            diffs.append(float(np.abs(y - x).max()))
            rels.append((np.abs(y - x) / np.abs(x)).ravel())
        rel = np.concatenate(rels)
        res: dict[str, Any] = {
            "max_abs_nrmse_change": max(diffs),
            "rel_change": {"median": float(np.median(rel)), "p99": float(np.percentile(rel, 99)),
                           "max": float(rel.max())},
            "n_cells": int(rel.size), "n_cells_over_1pct": int((rel > 0.01).sum())}
        if "table" in A and "table" in B:
            ta = np.array(list(A["table"]["rows"].values()), float)
            tb = np.array(list(B["table"]["rows"].values()), float)
            res["max_abs_table_change"] = float(np.abs(tb - ta).max())
        res["pooled"] = {}
        for fam, tests_a in A.get("pooled", {}).items():
            tests_b = B["pooled"][fam]
            res["pooled"][fam] = {
                "n_tests": len(tests_a),
                "max_abs_ratio_change": max((abs(t["ratio"] - u["ratio"]) for t, u in zip(tests_a, tests_b)),
                                            default=0.0),
                "changed_verdicts": [{"a": t["a"], "b": t["b"], "interval": t["interval"], "before": _verdict(t),
                                      "after": _verdict(u)}
                                     for t, u in zip(tests_a, tests_b) if _verdict(t) != _verdict(u)]}
        res["audit"] = {k: {kk: v for kk, v in R["audit"].items() if kk != "records"}
                        for k, R in (("reference", A), ("other", B))}
        out[blk] = res
    return out


def format_comparison(c: dict[str, Any]) -> str:
    """A Markdown summary of :func:`compare_results`."""
    lines = []
    for blk, r in c.items():
        rel = r["rel_change"]
        lines.append(f"**{blk}**: largest nRMSE change {r['max_abs_nrmse_change']:.2e}; relative change median "
                     f"{rel['median']:.1e}, 99th percentile {rel['p99']:.1e}, largest {rel['max']:.1e}; "
                     f"{r['n_cells_over_1pct']} of {r['n_cells']} values changed by more than 1 %"
                     + (f"; largest Table I change {r['max_abs_table_change']:.4f}" if "max_abs_table_change" in r
                        else ""))
        for fam, p in r["pooled"].items():
            lines.append(f"- pooled tests, {fam}: {p['n_tests']} tests, largest ratio change "
                         f"{p['max_abs_ratio_change']:.4f}, verdicts changed: {len(p['changed_verdicts'])}"
                         + "".join(f"; {v['a']} vs {v['b']} {v['interval']}: {v['before']} -> {v['after']}"
                                   for v in p["changed_verdicts"]))
        for k, s in r["audit"].items():
            within, gap = s.get("within_tol", float("nan")), s.get("gap_max", float("nan"))
            lines.append(f"- fit audit ({k}): {s.get('n_gps')} GPs, within {s.get('tol_nats')} nat: {within:.3f}, "
                         f"largest gap {gap:.2f} nat")
        lines.append("")
    return "\n".join(lines)


def _attempt_key(a: dict[str, Any]) -> tuple[Any, ...]:
    return a["task"], a["task_attempt"], a["phase"]


def compare_transfer(a: dict[str, Any], b: dict[str, Any], pour: float = 0.5) -> dict[str, Any]:
    """Compare two ``results.json`` of the task transfer (``cascgp transfer``; ``a`` the reference), attempt by
    attempt.

    Returns per controller in both runs: ``n_attempts``; ``identical`` (every attempt's tracking RMSE and share of
    marbles in the jar equal); ``rmse_abs_change`` (median and max over the attempts of :math:`|b - a|`, rad);
    ``rmse_ratio`` (min and max of :math:`b / a`); ``in_jar_abs_change_max``; ``pour_flips``, the attempts that
    poured at least ``pour`` of the marbles in one run and less in the other; and ``mean_in_jar`` of both runs.
    ``ValueError`` names a controller present in one run only or one whose attempts (task, attempt, phase) differ.
    """
    A, B = a["controllers"], b["controllers"]
    if set(A) != set(B):
        raise ValueError(f"the runs have different controllers: {sorted(A)} / {sorted(B)}")
    out: dict[str, Any] = {}
    for name in A:
        xa, xb = A[name], B[name]
        if [_attempt_key(t) for t in xa] != [_attempt_key(t) for t in xb]:
            raise ValueError(f"{name}: the runs' attempts differ (task, attempt, phase)")
        ra = np.array([t["tracking_rmse"] for t in xa], float)
        rb = np.array([t["tracking_rmse"] for t in xb], float)
        ja = np.array([t["in_jar"] for t in xa], float)
        jb = np.array([t["in_jar"] for t in xb], float)
        d = np.abs(rb - ra)
        out[name] = {
            "n_attempts": len(xa),
            "identical": bool(np.array_equal(ra, rb) and np.array_equal(ja, jb)),
            "rmse_abs_change": {"median": float(np.median(d)), "max": float(d.max())},
            "rmse_ratio": {"min": float((rb / ra).min()), "max": float((rb / ra).max())},
            "in_jar_abs_change_max": float(np.abs(jb - ja).max()),
            "pour_flips": [{"task": t["task"], "task_attempt": t["task_attempt"], "phase": t["phase"],
                            "in_jar": [float(p), float(q)]}
                           for t, p, q in zip(xa, ja, jb) if (p >= pour) != (q >= pour)],
            "mean_in_jar": [float(ja.mean()), float(jb.mean())]}
    return out


def format_transfer_comparison(c: dict[str, Any]) -> str:
    """A Markdown table of :func:`compare_transfer`."""
    lines = ["| controller | attempts | identical | RMSE change, median / max (rad) | RMSE ratio, min-max | "
             "largest in-jar change | attempts poured (>= half) in one run only | mean in jar |",
             "|---|---|---|---|---|---|---|---|"]
    for name, r in c.items():
        ch, ra = r["rmse_abs_change"], r["rmse_ratio"]
        lines.append(f"| {name} | {r['n_attempts']} | {'yes' if r['identical'] else 'no'} | {ch['median']:.3f} / "
                     f"{ch['max']:.3f} | {ra['min']:.2f}-{ra['max']:.2f} | {r['in_jar_abs_change_max']:.2f} | "
                     f"{len(r['pour_flips'])} | {r['mean_in_jar'][0]:.2f} -> {r['mean_in_jar'][1]:.2f} |")
    return "\n".join(lines)
