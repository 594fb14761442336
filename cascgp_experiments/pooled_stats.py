r"""The study's primary tests: paired comparisons pooled over joints, Holm-corrected within fixed families.

For models :math:`A` and :math:`B`, subset :math:`s` and an interval :math:`I` (1-2, 4-5 or 9-10 s of data), let
:math:`e^A_{sj}` be the mean nRMSE of joint :math:`j` over the grid points in :math:`I` of the curve trained on
subset :math:`s`. The pooled statistic of subset :math:`s` is the mean log ratio

.. math:: d_s = \frac{1}{|J|} \sum_{j \in J} \log \frac{e^A_{sj}}{e^B_{sj}},

over the joints :math:`J` where :math:`A` and :math:`B` are not the same model by construction
(:func:`identical_joints`). The test is the two-sided Wilcoxon signed-rank test of :math:`d_1 .. d_S`
(``scipy.stats.wilcoxon``, exact for these sizes); the reported ratio is the geometric mean
:math:`\exp(\bar d)` (below 1: :math:`A` has the lower error), with the subsets where :math:`d_s < 0`.

Each comparison at each interval is one test of a family (:data:`JACO_FAMILIES`, :data:`SARCOS_FAMILIES`, fixed
here before the runs they judge); p-values are Holm-adjusted within the family (:func:`holm`) and a comparison is
significant at adjusted :math:`p < 0.05`. With :math:`S` subsets and no ties the smallest two-sided exact
Wilcoxon p-value is :math:`2 / 2^S` (1/512 at :math:`S = 10`), so a family of :math:`m` tests can reject
anything only if :math:`m \cdot 2^{1-S} < 0.05`, i.e. :math:`m \le 25` at :math:`S = 10`: the families are kept small.

Same model by construction: a cascade's first joint in its chain direction (inward: joint :math:`N`; outward:
joint 1) takes every joint's state and no torque, as the standard model's GP does
(:func:`cascgp.features.input_spec`); and a cascade scored with the measured neighbour torque
(:mod:`cascgp.models.measured`) equals itself scored with the chained prediction on that joint. Such joints are
left out of :math:`d_s` and of the per-cell sign tests' counts.

Reads only the results JSON (numpy and scipy; no model or simulation import).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from cascgp_experiments.common import TABLE_INTERVALS, interval_mean, label

SCORINGS = ("predicted", "measured")
ALPHA = 0.05


class Comparison(NamedTuple):
    """``a`` (scored with ``a_scoring``) against ``b`` (``b_scoring``)."""

    a: str
    b: str
    a_scoring: str = "predicted"
    b_scoring: str = "predicted"


def _cvs(df: bool, scoring: str) -> tuple[Comparison, ...]:
    d = "-df" if df else ""
    return tuple(Comparison(f"{p}-{c}{d}", f"{p}-standard{d}", scoring) for p in ("np", "sp")
                 for c in ("inward", "outward"))


#: The Jaco families, fixed before the runs: name -> comparisons, each tested at the three Table I intervals.
JACO_FAMILIES: dict[str, tuple[Comparison, ...]] = {
    "cascade vs standard (predicted neighbour torque)": _cvs(False, "predicted"),
    "cascade vs standard (measured neighbour torque)": _cvs(False, "measured"),
    "cascade vs standard, derivative free (predicted neighbour torque)": _cvs(True, "predicted"),
    "NP inward vs outward": (Comparison("np-inward", "np-outward"),),
    "SP vs NP": tuple(Comparison(f"sp-{s}", f"np-{s}") for s in ("standard", "inward", "outward")),
    "derivative free vs derivative based": tuple(Comparison(f"{p}-{s}-df", f"{p}-{s}") for p in ("np", "sp")
                                                 for s in ("standard", "inward", "outward")),
    "scoring: measured vs predicted neighbour torque": tuple(
        Comparison(f"{p}-{c}", f"{p}-{c}", "measured", "predicted") for p in ("np", "sp")
        for c in ("inward", "outward")),
}

#: The SARCOS families (NP derivative based only).
SARCOS_FAMILIES: dict[str, tuple[Comparison, ...]] = {
    "cascade vs standard (predicted neighbour torque)": _cvs(False, "predicted")[:2],
    "cascade vs standard (measured neighbour torque)": _cvs(False, "measured")[:2],
    "NP inward vs outward": (Comparison("np-inward", "np-outward"),),
}


# --------------------------------------------------------------------------- construction
def chain_first(name: str, dof: int) -> int | None:
    """The joint (0-based) of cascade ``name`` that has no torque input (inward: ``dof - 1``, outward: 0);
    None for a standard model or the RBD baseline."""
    parts = name.split("-")
    if len(parts) < 2:
        return None
    return {"inward": dof - 1, "outward": 0}.get(parts[1])


def standard_twin(name: str) -> str:
    """The standard model of the same kind as ``name``: ``"sp-inward-df"`` -> ``"sp-standard-df"``."""
    parts = name.split("-")
    return "-".join([parts[0], "standard", *parts[2:]]) if len(parts) >= 2 else name


def identical_joints(a: str, b: str, dof: int) -> tuple[int, ...]:
    """Joints on which ``a`` and ``b`` are the same model by construction: a cascade and the standard model of
    the same kind (NP/SP, derivative based/free), or a cascade against itself under the other scoring."""
    pa, pb = a.split("-"), b.split("-")
    if len(pa) < 2 or len(pb) < 2 or pa[0] != pb[0] or (pa[-1] == "df") != (pb[-1] == "df"):
        return ()
    if a == b:
        j = chain_first(a, dof)
    elif "standard" in (pa[1], pb[1]):
        j = chain_first(b if pa[1] == "standard" else a, dof)
    else:
        return ()
    return () if j is None else (j,)


# --------------------------------------------------------------------------- scores
def scores(block: dict[str, Any], m: str, scoring: str = "predicted") -> np.ndarray:
    """(S, G, N) nRMSE of ``m``: ``"predicted"`` (chained neighbour torque) or ``"measured"``; a model without a
    torque input (standard, RBD) has one score for both."""
    if scoring not in SCORINGS:
        raise ValueError(f"scoring: expected one of {SCORINGS}, got {scoring!r}")
    v = block["models"][m]
    if scoring == "measured" and chain_first(m, 1) is not None:
        v = v["measured"]
    return np.asarray(v["nrmse_all"], float)


def has_scores(block: dict[str, Any], m: str, scoring: str = "predicted") -> bool:
    """Whether ``block`` holds ``m``'s per-subset scores under ``scoring``."""
    v = block.get("models", {}).get(m)
    if v is None or "nrmse_all" not in v:
        return False
    return scoring == "predicted" or chain_first(m, 1) is None or "nrmse_all" in v.get("measured", {})


def subset_interval(block: dict[str, Any], m: str, scoring: str, lo: float, hi: float) -> np.ndarray:
    """(S, N): per subset, the mean nRMSE of ``m`` over the grid points in ``[lo, hi]``."""
    return interval_mean(block["grid_s"], scores(block, m, scoring).transpose(1, 0, 2), lo, hi)


# --------------------------------------------------------------------------- tests
def pooled_log_ratio(A: np.ndarray, B: np.ndarray, exclude: tuple[int, ...] = ()) -> np.ndarray:
    """(S,): per subset (row) the mean over the joints (columns) not in ``exclude`` of ``log(A / B)``."""
    A, B = np.asarray(A, float), np.asarray(B, float)
    keep = [j for j in range(A.shape[1]) if j not in exclude]
    return np.log(A[:, keep] / B[:, keep]).mean(axis=1)


def wilcoxon_p(d: np.ndarray) -> float:
    """Two-sided Wilcoxon signed-rank p-value of ``d`` against 0 (1 when every ``d`` is 0)."""
    from scipy.stats import wilcoxon

    d = np.asarray(d, float)
    if not np.any(d != 0):
        return 1.0
    return float(wilcoxon(d).pvalue)


def pooled_test(d: np.ndarray) -> dict[str, Any]:
    """Summary of the per-subset statistics ``d``: geometric-mean ratio, wins (``d < 0``), losses, p."""
    d = np.asarray(d, float)
    return {"ratio": float(np.exp(d.mean())), "wins": int((d < 0).sum()), "losses": int((d > 0).sum()),
            "n": int(d.size), "p": wilcoxon_p(d), "d": d.tolist()}


def holm(p: Any) -> np.ndarray:
    r"""Holm's step-down adjusted p-values: with :math:`p_{(1)} \le .. \le p_{(m)}`,
    :math:`\tilde p_{(i)} = \max_{k \le i} \min(1, (m - k + 1)\, p_{(k)})`; rejecting :math:`\tilde p < \alpha`
    controls the family-wise error at :math:`\alpha`."""
    p = np.asarray(p, float)
    m = p.size
    order = np.argsort(p, kind="stable")
    adj = np.minimum(1.0, np.maximum.accumulate((m - np.arange(m)) * p[order]))
    out = np.empty(m)
    out[order] = adj
    return out


def sign_test_power(n: int, rate: float, alpha: float = ALPHA) -> float:
    """Power of the two-sided exact sign test at level ``alpha`` with ``n`` untied pairs when one model wins each
    pair with probability ``rate``: the probability of a win count in the test's rejection region."""
    from scipy.stats import binom, binomtest

    region = [k for k in range(n + 1) if binomtest(k, n, 0.5).pvalue < alpha]
    return float(sum(binom.pmf(k, n, rate) for k in region))


def run_family(block: dict[str, Any], family: tuple[Comparison, ...],
               intervals=TABLE_INTERVALS) -> list[dict[str, Any]]:
    """Every comparison of ``family`` that ``block`` has scores for, at every interval with grid points:
    :func:`pooled_test` plus ``p_holm`` (Holm over the rows returned: the whole family in a full run; the part
    that a reduced run has) and the excluded joints."""
    rows: list[dict[str, Any]] = []
    for c in family:
        if not (has_scores(block, c.a, c.a_scoring) and has_scores(block, c.b, c.b_scoring)):
            continue
        N = scores(block, c.a, c.a_scoring).shape[2]
        excl = identical_joints(c.a, c.b, N)
        g = np.asarray(block["grid_s"], float)
        for lo, hi in intervals:
            if not np.any((g >= lo - 1e-9) & (g <= hi + 1e-9)):
                continue  # no grid point in the interval (reduced grids)
            A = subset_interval(block, c.a, c.a_scoring, lo, hi)
            B = subset_interval(block, c.b, c.b_scoring, lo, hi)
            rows.append({**c._asdict(), "interval": [lo, hi], "excluded_joints": list(excl),
                         **pooled_test(pooled_log_ratio(A, B, excl))})
    for r, q in zip(rows, holm([r["p"] for r in rows]) if rows else []):
        r["p_holm"] = float(q)
    return rows


def pooled_block(block: dict[str, Any], families: dict[str, tuple[Comparison, ...]]) -> dict[str, list[dict]]:
    """:func:`run_family` for each family that has at least one comparison in ``block``."""
    out = {name: run_family(block, fam) for name, fam in families.items()}
    return {k: v for k, v in out.items() if v}


def _name(m: str, scoring: str) -> str:
    return label(m) + (" (measured τ)" if scoring == "measured" else "")


def pooled_markdown(block: dict[str, Any], families: dict[str, tuple[Comparison, ...]], title: str) -> list[str]:
    """Markdown of the pooled, Holm-corrected tests of ``block`` (one table per family)."""
    S = int(block["n_subsets"])
    L = [f"\n### Pooled paired tests (primary): {title}\n",
         f"Per subset, the mean over joints of log(nRMSE first / nRMSE second), each nRMSE the mean over the "
         f"interval's grid points, leaving out the joints where the two are the same model by construction; "
         f"ratio = exp(mean over the {S} subsets) (below 1: the first is better); won = subsets where the first "
         f"is better; two-sided Wilcoxon signed-rank p over the subsets, Holm-adjusted within each family "
         f"(fixed in `cascgp_experiments/pooled_stats.py`); significant at adjusted p < {ALPHA}. "
         f"The smallest attainable p with {S} subsets is {2 / 2 ** S:.4f}.\n"]
    for name, rows in pooled_block(block, families).items():
        L += [f"\n**{name}** ({len(rows)} tests)\n", "| first | second | interval | left out | ratio | won | "
              "Wilcoxon p | Holm p | verdict |", "|---|---|---|---|---|---|---|---|---|"]
        for r in rows:
            v = "n.s." if not r["p_holm"] < ALPHA else ("first better" if r["ratio"] < 1 else "first worse")
            out = ", ".join(f"J{j + 1}" for j in r["excluded_joints"]) or "-"
            L.append(f"| {_name(r['a'], r['a_scoring'])} | {_name(r['b'], r['b_scoring'])} | "
                     f"{r['interval'][0]:g}-{r['interval'][1]:g} s | {out} | {r['ratio']:.3f} | "
                     f"{r['wins']}/{r['n']} | {r['p']:.3g} | {r['p_holm']:.3g} | {v} |")
    return L
