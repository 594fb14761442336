"""The paper's claims, checked on the measured numbers of ``results.json`` (and, where the claim
is about Table I, on the paper's own Table I with the same test).

Each check computes a plain statistic from the table rows (``rows[model][joint][interval]``,
intervals 1-2 s, 4-5 s, 9-10 s) so the verdict is reproducible from the JSON alone. A cascade's cell that is the
standard model by construction (its chain's first joint) does not count as a cascade's win.

The verdicts rest on the pooled, Holm-corrected paired tests of :mod:`cascgp_experiments.pooled_stats` (primary);
the per-(joint, interval) sign tests (:func:`paired`) are secondary: with 10 subsets a cell needs 9 wins, and
their power is low (stated in the generated text, :func:`~cascgp_experiments.pooled_stats.sign_test_power`).
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from cascgp_experiments.common import PAPER_TABLE, RBD, TABLE_INTERVALS, label, make_table, model_name
from cascgp_experiments.pooled_stats import (JACO_FAMILIES, SARCOS_FAMILIES, Comparison, has_scores, identical_joints,
                                             pooled_markdown, scores, sign_test_power, subset_interval)

IV = ("1-2 s", "4-5 s", "9-10 s")


def _f(v) -> str:
    """3-decimal number, '-' for missing (None/NaN: no grid point in the interval)."""
    return "-" if v is None or not np.isfinite(v) else f"{v:.3f}"


def _a(rows: dict, m: str) -> np.ndarray:
    return np.asarray(rows[m], dtype=float)  # (N, 3)


def _cascades(rows: dict, p: str, df: bool) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) rows of the better cascade (inward or outward; a cell that is the standard model by construction
    left out) and of the standard model."""
    st = _a(rows, model_name(p, "standard", df))
    best = np.full(st.shape, np.inf)
    for c in ("inward", "outward"):
        m = model_name(p, c, df)
        v = _a(rows, m).copy()
        v[list(identical_joints(m, model_name(p, "standard", df), st.shape[0]))] = np.inf
        best = np.minimum(best, v)
    return best, st


def cascade_vs_standard(rows: dict, p: str, df: bool = False) -> np.ndarray:
    """Per interval: joints where the better cascade (inward or outward) beats the standard model."""
    best, st = _cascades(rows, p, df)
    return (best < st).sum(axis=0)


def rel_gain(rows: dict, p: str, df: bool = False) -> np.ndarray:
    """Per interval: mean over joints of (standard - best cascade) / standard."""
    best, st = _cascades(rows, p, df)
    return ((st - best) / st).mean(axis=0)


def inward_vs_outward(rows: dict, p: str, df: bool = False) -> np.ndarray:
    """(N, 3) bool: inward < outward."""
    return _a(rows, model_name(p, "inward", df)) < _a(rows, model_name(p, "outward", df))


def df_vs_db(rows: dict) -> np.ndarray:
    """Per interval: fraction of (variant, joint) cells where the -df model beats its db twin."""
    wins, total = np.zeros(3), 0
    for p in ("np", "sp"):
        for s in ("inward", "outward", "standard"):
            wins += (_a(rows, model_name(p, s, True)) < _a(rows, model_name(p, s, False))).sum(axis=0)
            total += _a(rows, model_name(p, s, False)).shape[0]
    return wins / total


def sign_test_p(wins: int, losses: int) -> float:
    """Two-sided exact sign test (binomial, p = 1/2) of ``wins`` against ``losses`` (ties dropped)."""
    from scipy.stats import binomtest

    n = wins + losses
    return 1.0 if n == 0 else float(binomtest(int(wins), n, 0.5).pvalue)


def paired(block: dict, a: str, b: str, intervals=TABLE_INTERVALS, a_scoring: str = "predicted",
           b_scoring: str = "predicted") -> dict[str, Any]:
    """Paired per-subset comparison of ``a`` against ``b`` (the secondary, per-cell test): per (joint, interval)
    the number of subsets where ``a`` has the lower nRMSE, where ``b`` has, and the sign-test p-value. Joints
    where the two are the same model by construction (``identical``) get 0 / 0 and p = 1 and are not counted
    by :func:`paired_verdict`."""
    N = scores(block, a, a_scoring).shape[2]
    same = identical_joints(a, b, N) if (a != b or a_scoring != b_scoring) else tuple(range(N))
    wins, losses, p = [], [], []
    for lo, hi in intervals:
        A, B = subset_interval(block, a, a_scoring, lo, hi), subset_interval(block, b, b_scoring, lo, hi)
        w, l_ = (A < B).sum(0), (A > B).sum(0)
        w[list(same)] = 0
        l_[list(same)] = 0
        wins.append(w.tolist())
        losses.append(l_.tolist())
        p.append([sign_test_p(int(x), int(y)) for x, y in zip(w, l_)])
    # transpose to [joint][interval]
    T = lambda x: np.asarray(x).T.tolist()  # noqa: E731
    return {"a": a, "b": b, "a_scoring": a_scoring, "b_scoring": b_scoring, "wins": T(wins), "losses": T(losses),
            "p": T(p), "identical": list(same), "n_subsets": int(scores(block, a, a_scoring).shape[0])}


def paired_verdict(cmp: dict, alpha: float = 0.05) -> tuple[int, int, int]:
    """(cells where a is significantly better, significantly worse, neither) at level ``alpha``; cells of
    joints that are the same model by construction (``cmp["identical"]``) are not counted."""
    w, l_, p = (np.asarray(cmp[k], float) for k in ("wins", "losses", "p"))
    keep = np.ones(w.shape[0], bool)
    keep[list(cmp.get("identical", []))] = False
    w, l_, p = w[keep], l_[keep], p[keep]
    better = int(((p < alpha) & (w > l_)).sum())
    worse = int(((p < alpha) & (w < l_)).sum())
    return better, worse, int(p.size - better - worse)


def _secondary_pairs() -> list[tuple[Comparison, str]]:
    """The per-cell comparisons, in the order of the pooled families."""
    out = []
    for fam in JACO_FAMILIES.values():
        for c in fam:
            what = f"{label(c.a)}{' (measured τ)' if c.a_scoring == 'measured' else ''} vs {label(c.b)}"
            out.append((c, what + (" (predicted τ)" if c.a == c.b else "")))
    return out


def paired_markdown(block: dict, title: str) -> list[str]:
    """Markdown lines of the per-cell (secondary) paired claim checks on one curves block (models present)."""
    S = int(block["n_subsets"])
    need = next((k for k in range(S + 1) if sign_test_p(k, S - k) < 0.05 and k > S / 2), None)
    L = [f"\n### Per-cell sign tests (secondary): {title}\n",
         f"Per (joint, interval): subsets where the first model has the lower interval-mean nRMSE "
         f"(wins/losses of {S}) and the two-sided sign-test p-value, not corrected for multiplicity. A cell counts "
         f"as significant at p < 0.05" + (f" (without ties: at least {need} wins of {S})" if need else "")
         + f". Power of that test with {S} subsets: {sign_test_power(S, 0.7):.2f} at a true 70 % win rate, "
         f"{sign_test_power(S, 0.8):.2f} at 80 %, {sign_test_power(S, 0.9):.2f} at 90 %. Cells where the two are "
         f"the same model by construction (the cascade's first joint in its chain direction, which takes every "
         f"joint's state and no torque, against the standard model or against itself) are shown as `=` and not "
         f"counted.\n"]
    for c, what in _secondary_pairs():
        if not (has_scores(block, c.a, c.a_scoring) and has_scores(block, c.b, c.b_scoring)):
            continue
        r = paired(block, c.a, c.b, a_scoring=c.a_scoring, b_scoring=c.b_scoring)
        bt, wo, ne = paired_verdict(r)
        cells = "; ".join(f"J{j + 1} " + ("=" if j in r["identical"] else " ".join(
            f"{r['wins'][j][k]}/{r['losses'][j][k]} (p={r['p'][j][k]:.2g})" for k in range(3)))
            for j in range(len(r["wins"])))
        L.append(f"- **{what}**: better in {bt}, worse in {wo}, no significant difference in {ne} of "
                 f"{bt + wo + ne} cells. {cells}.")
    return L


def _have(rows: dict, names: list[str]) -> bool:
    return all(n in rows for n in names)


def _present(rows: dict[str, Any]) -> np.ndarray:
    """Per interval: True where the table has numbers (a grid point in the interval), shape (3,)."""
    return np.isfinite(np.asarray(next(iter(rows.values())), float)).all(axis=0)


def _per_interval(values: Any, present: np.ndarray, fmt: Callable[[Any], str]) -> str:
    """``a/b/c`` over the three intervals, ``-`` for an interval without grid points."""
    return "/".join(fmt(v) if ok else "-" for v, ok in zip(values, present))


def _cells(won: np.ndarray, present: np.ndarray) -> str:
    """``k of n`` (joint, interval) cells, counting only the intervals with grid points."""
    won = won[:, present]
    return f"{int(won.sum())} of {won.size}"


def _missing_intervals(rows: dict[str, Any]) -> str:
    """A line naming the intervals without grid points ('' when every interval has some)."""
    gone = [iv for iv, ok in zip(IV, _present(rows)) if not ok]
    return (f"No grid point in {', '.join(gone)}: those intervals are `-` and not counted.\n" if gone else "")


def claims_markdown(res: dict[str, Any], source: str = "results.json") -> str:
    """Markdown list of claims with measured (and paper) statistics; ``source``: the JSON's name, for the title."""
    L = [f"# The paper's claims, checked (generated from {source})\n"]
    jaco = res.get("jaco")
    paper = PAPER_TABLE
    if res.get("meta", {}).get("complete") is False:
        L.append("**This run did not finish** (`meta.complete` is false): the parts it had not reached are missing. "
                 "Run its command again to complete it.\n")
    skipped = res.get("meta", {}).get("sarcos_skipped")
    if skipped:
        L.append(f"The SARCOS part was not run ({skipped}): the claims checked on SARCOS are missing.\n")
    if jaco:
        rows = jaco["table"]["rows"]
        N = len(next(iter(rows.values())))
        have = _present(rows)
        npdb = [model_name("np", s, False) for s in ("inward", "outward", "standard")]
        spdb = [model_name("sp", s, False) for s in ("inward", "outward", "standard")]
        L.append(f"Simulated Jaco, {jaco['n_subsets']} subsets; intervals {', '.join(IV)}.\n")
        L += [line for line in [_missing_intervals(rows)] if line]
        for p, ms in (("np", npdb), ("sp", spdb)):
            if _have(rows, ms):
                c, g = cascade_vs_standard(rows, p), rel_gain(rows, p)
                cp, gp = cascade_vs_standard(paper, p), rel_gain(paper, p)
                L.append(f"- **{p.upper()}: a cascade (inward or outward) beats the standard model** on "
                         f"{_per_interval(c, have, str)} of {N} joints ({', '.join(IV)}); mean relative gain "
                         f"{_per_interval(g, have, lambda x: f'{100 * x:+.0f}%')}. Paper: "
                         f"{'/'.join(map(str, cp))} of 6 joints, gain {'/'.join(f'{100 * x:+.0f}%' for x in gp)}.")
        if _have(rows, npdb):
            iw = inward_vs_outward(rows, "np")
            iwp = inward_vs_outward(paper, "np")
            L.append(f"- **NP: inward more accurate than outward**: inward wins {_cells(iw, have)} "
                     f"(joint, interval) cells (paper: {int(iwp.sum())} of {iwp.size}).")
            for j in (3, 5):
                if j < N:
                    L.append(f"- **Outward beats inward on joint {j + 1} (NP, DB)**: measured inward/outward "
                             + ", ".join(f"{IV[k]} {_f(rows[npdb[0]][j][k])}/{_f(rows[npdb[1]][j][k])}"
                                         for k in range(3))
                             + " (paper: " + ", ".join(f"{_f(paper[npdb[0]][j][k])}/{_f(paper[npdb[1]][j][k])}"
                                                     for k in range(3)) + ").")
        if _have(rows, npdb + spdb):
            L.append("- **SP below NP (the RBD mean helps)**: mean nRMSE over joints, standard models, NP/SP: "
                     + ", ".join(f"{IV[k]} {_f(np.mean(_a(rows, npdb[2])[:, k]))}/"
                                 f"{_f(np.mean(_a(rows, spdb[2])[:, k]))}" for k in range(3))
                     + " (paper: " + ", ".join(f"{_f(np.mean(_a(paper, npdb[2])[:, k]))}/"
                                               f"{_f(np.mean(_a(paper, spdb[2])[:, k]))}" for k in range(3)) + ").")
        if RBD in rows:
            L.append("- **RBD alone** (nominal model without the payload): nRMSE per joint "
                     + ", ".join(f"{_f(v[0])}" for v in rows[RBD]) + ".")
        all12 = [model_name(p, s, df) for df in (False, True) for p in ("np", "sp")
                 for s in ("inward", "outward", "standard")]
        if _have(rows, all12):
            f, fp = df_vs_db(rows), df_vs_db(paper)
            L.append(f"- **Derivative-free features help in the first seconds, not later**: the -df twin wins "
                     f"{_per_interval(f, have, lambda x: f'{100 * x:.0f}%')} of cells ({', '.join(IV)}); paper: "
                     f"{'/'.join(f'{100 * x:.0f}%' for x in fp)}.")
    if jaco and all("nrmse_all" in v for v in jaco["models"].values()):
        L += pooled_markdown(jaco, JACO_FAMILIES, "simulated Jaco")
        L += paired_markdown(jaco, "simulated Jaco")
    s = res.get("sarcos")
    if s and all(m in s["models"] for m in ("np-inward", "np-outward", "np-standard")):
        grid = s["grid_s"]
        ivs = [(1, 2), (4, 5), (9, 10)]
        t = make_table(grid, {m: v.get("nrmse_median", v["nrmse_mean"]) for m, v in s["models"].items()}, ivs)["rows"]
        N = len(t["np-standard"])
        c = cascade_vs_standard(t, "np")
        iw = inward_vs_outward(t, "np")
        have_s = _present(t)
        L.append(f"\nSARCOS ({s['n_subsets']} subsets, {s['n_test_rows']} de-duplicated test rows):\n")
        L += [line for line in [_missing_intervals(t)] if line]
        L.append(f"- **Cascade beats standard NP** on {_per_interval(c, have_s, str)} of {N} joints "
                 f"({', '.join(IV)}); inward beats outward in {_cells(iw, have_s)} cells.")
        L.append("- **Outward beats inward on the last joint (7)**: inward/outward "
                 + ", ".join(f"{IV[k]} {_f(t['np-inward'][N - 1][k])}/{_f(t['np-outward'][N - 1][k])}"
                             for k in range(3)) + ".")
        if all("nrmse_all" in v for v in s["models"].values()):
            L += pooled_markdown(s, SARCOS_FAMILIES, "SARCOS")
            L += paired_markdown(s, "SARCOS")
    it = res.get("iterations")
    if it:
        L.append(f"\nIterations (n = {it['n']}, {it['n_restarts']} restarts, mean over starts per joint):\n")
        for m, r in it["models"].items():
            L.append(f"- {m}: " + ", ".join(f"J{j + 1} {v:.0f} (d={d})" for j, (v, d) in
                                             enumerate(zip(r["n_iter_mean"], r["dim"])))
                     + f"; total {sum(r['n_iter_mean']):.0f}; fit wall time {sum(r['wall_s']):.1f} s.")
        dims = np.concatenate([np.asarray(r["dim"], float) for r in it["models"].values()])
        its = np.concatenate([np.asarray(r["n_iter_mean"], float) for r in it["models"].values()])
        if np.std(dims) > 0 and np.std(its) > 0:
            L.append(f"- **Fewer iterations for smaller feature sets**: Pearson correlation of input dimension and "
                     f"mean iterations over all GPs: {np.corrcoef(dims, its)[0, 1]:+.2f}.")
    c = res.get("correlation")
    if c:
        M = np.asarray(c["abs_spearman"], float)
        lab = c["labels"]
        n = len(lab) // 4
        if n >= 5:
            def states(j):
                return [lab.index(f"{k}{j + 1}") for k in ("q", "qd", "qdd")]
            t4, t5 = lab.index("tau4"), lab.index("tau5")
            L.append("\nCorrelation (|Spearman|, max over q, qd, qdd):\n")
            L.append(f"- tau4 with joint 4 states {M[t4, states(3)].max():.2f}, with joint 5 states "
                     f"{M[t4, states(4)].max():.2f}; tau5 with joint 5 states {M[t5, states(4)].max():.2f}, "
                     f"with joint 4 states {M[t5, states(3)].max():.2f}; |rho(tau4, tau5)| = {M[t4, t5]:.2f}.")
    return "\n".join(L) + "\n"
