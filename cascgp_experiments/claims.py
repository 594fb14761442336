"""The paper's claims, checked on the measured numbers of ``results.json`` (and, where the claim
is about Table I, on the paper's own Table I with the same test).

Each check computes a plain statistic from the table rows (``rows[model][joint][interval]``,
intervals 1-2 s, 4-5 s, 9-10 s) so the verdict is reproducible from the JSON alone.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cascgp_experiments.common import PAPER_TABLE, RBD, interval_mean, make_table, model_name

IV = ("1-2 s", "4-5 s", "9-10 s")


def _f(v) -> str:
    """3-decimal number, '-' for missing (None/NaN: no grid point in the interval)."""
    return "-" if v is None or not np.isfinite(v) else f"{v:.3f}"


def _a(rows: dict, m: str) -> np.ndarray:
    return np.asarray(rows[m], dtype=float)  # (N, 3)


def cascade_vs_standard(rows: dict, p: str, df: bool = False) -> np.ndarray:
    """Per interval: joints where the better cascade (inward or outward) beats the standard model."""
    ci = _a(rows, model_name(p, "inward", df))
    co = _a(rows, model_name(p, "outward", df))
    st = _a(rows, model_name(p, "standard", df))
    return (np.minimum(ci, co) < st).sum(axis=0)


def rel_gain(rows: dict, p: str, df: bool = False) -> np.ndarray:
    """Per interval: mean over joints of (standard - best cascade) / standard."""
    ci = _a(rows, model_name(p, "inward", df))
    co = _a(rows, model_name(p, "outward", df))
    st = _a(rows, model_name(p, "standard", df))
    return ((st - np.minimum(ci, co)) / st).mean(axis=0)


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


def subset_interval_means(block: dict, m: str, lo: float, hi: float) -> np.ndarray:
    """(S, N): per subset, the mean nRMSE of model ``m`` over the grid points in ``[lo, hi]``."""
    a = np.asarray(block["models"][m]["nrmse_all"], float)  # (S, G, N)
    return interval_mean(block["grid_s"], a.transpose(1, 0, 2), lo, hi)


def paired(block: dict, a: str, b: str, intervals=((1, 2), (4, 5), (9, 10))) -> dict[str, Any]:
    """Paired per-subset comparison of ``a`` against ``b``: per (joint, interval) the number of
    subsets where ``a`` has the lower nRMSE, where ``b`` has, and the sign-test p-value."""
    wins, losses, p = [], [], []
    for lo, hi in intervals:
        A, B = subset_interval_means(block, a, lo, hi), subset_interval_means(block, b, lo, hi)
        w, l_ = (A < B).sum(0), (A > B).sum(0)
        wins.append(w.tolist())
        losses.append(l_.tolist())
        p.append([sign_test_p(int(x), int(y)) for x, y in zip(w, l_)])
    # transpose to [joint][interval]
    T = lambda x: np.asarray(x).T.tolist()  # noqa: E731
    return {"a": a, "b": b, "wins": T(wins), "losses": T(losses), "p": T(p),
            "n_subsets": int(np.asarray(block["models"][a]["nrmse_all"]).shape[0])}


def paired_verdict(cmp: dict, alpha: float = 0.05) -> tuple[int, int, int]:
    """(cells where a is significantly better, significantly worse, neither) at level ``alpha``."""
    w, l_, p = (np.asarray(cmp[k], float) for k in ("wins", "losses", "p"))
    better = int(((p < alpha) & (w > l_)).sum())
    worse = int(((p < alpha) & (w < l_)).sum())
    return better, worse, int(p.size - better - worse)


def paired_markdown(block: dict, title: str) -> list[str]:
    """Markdown lines of the paired claim checks on one curves block (models present only)."""
    S = int(block["n_subsets"])
    need = next((k for k in range(S + 1) if sign_test_p(k, S - k) < 0.05 and k > S / 2), None)
    L = [f"\n### Paired per-subset comparisons: {title}\n",
         f"Per (joint, interval): subsets where the first model has the lower interval-mean nRMSE "
         f"(wins/losses of {S}) and the two-sided sign-test p-value. A cell counts as significant at "
         f"p < 0.05" + (f" (without ties: at least {need} wins of {S})" if need else "") + ".\n"]
    ms = block["models"]
    pairs = []
    for p in ("np", "sp"):
        for df in (False, True):
            st = model_name(p, "standard", df)
            for c in ("inward", "outward"):
                pairs.append((model_name(p, c, df), st, f"{p.upper()}{'-DF' if df else ''}: {c} vs standard"))
        pairs.append((model_name(p, "inward", False), model_name(p, "outward", False),
                      f"{p.upper()}: inward vs outward"))
    for s_ in ("inward", "outward", "standard"):
        pairs.append((model_name("sp", s_, False), model_name("np", s_, False), f"{s_}: SP vs NP"))
    for s_ in ("inward", "outward", "standard"):
        for p in ("np", "sp"):
            pairs.append((model_name(p, s_, True), model_name(p, s_, False), f"{p.upper()} {s_}: DF vs DB"))
    for a, b, what in pairs:
        if a not in ms or b not in ms:
            continue
        c = paired(block, a, b)
        bt, wo, ne = paired_verdict(c)
        cells = "; ".join(f"J{j + 1} " + " ".join(f"{c['wins'][j][k]}/{c['losses'][j][k]} (p={c['p'][j][k]:.2g})"
                                                 for k in range(3)) for j in range(len(c["wins"])))
        L.append(f"- **{what}**: better in {bt}, worse in {wo}, no significant difference in {ne} of "
                 f"{bt + wo + ne} cells. {cells}.")
    L.append("\nSame model by construction (not evidence either way): NP-Outward J1 = NP and NP-Inward J{N} = NP "
             "(joint 1's outward GP and the last joint's inward GP take the standard GP's inputs: every joint's "
             "state, no torque); likewise for SP and -DF. Such pairs differ only through the optimiser's random "
             "starts (ties where they found the same optimum).\n"
             .replace("{N}", str(len(next(iter(ms.values()))["nrmse_all"][0][0]))))
    return L


def _have(rows: dict, names: list[str]) -> bool:
    return all(n in rows for n in names)


def claims_markdown(res: dict[str, Any]) -> str:
    """Markdown list of claims with measured (and paper) statistics."""
    L = ["# The paper's claims, checked (generated from results.json)\n"]
    jaco = res.get("jaco")
    paper = PAPER_TABLE
    if jaco:
        rows = jaco["table"]["rows"]
        N = len(next(iter(rows.values())))
        npdb = [model_name("np", s, False) for s in ("inward", "outward", "standard")]
        spdb = [model_name("sp", s, False) for s in ("inward", "outward", "standard")]
        L.append(f"Simulated Jaco, {jaco['n_subsets']} subsets; intervals {', '.join(IV)}.\n")
        for p, ms in (("np", npdb), ("sp", spdb)):
            if _have(rows, ms):
                c, g = cascade_vs_standard(rows, p), rel_gain(rows, p)
                cp, gp = cascade_vs_standard(paper, p), rel_gain(paper, p)
                L.append(f"- **{p.upper()}: a cascade (inward or outward) beats the standard model** on "
                         f"{'/'.join(map(str, c))} of {N} joints ({', '.join(IV)}); mean relative gain "
                         f"{'/'.join(f'{100 * x:+.0f}%' for x in g)}. Paper: {'/'.join(map(str, cp))} of 6 joints, "
                         f"gain {'/'.join(f'{100 * x:+.0f}%' for x in gp)}.")
        if _have(rows, npdb):
            iw = inward_vs_outward(rows, "np")
            iwp = inward_vs_outward(paper, "np")
            L.append(f"- **NP: inward more accurate than outward**: inward wins {int(iw.sum())} of {iw.size} "
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
                     f"{'/'.join(f'{100 * x:.0f}%' for x in f)} of cells ({', '.join(IV)}); paper: "
                     f"{'/'.join(f'{100 * x:.0f}%' for x in fp)}.")
    if jaco and all("nrmse_all" in v for v in jaco["models"].values()):
        L += paired_markdown(jaco, "simulated Jaco")
    s = res.get("sarcos")
    if s and all(m in s["models"] for m in ("np-inward", "np-outward", "np-standard")):
        grid = s["grid_s"]
        ivs = [(1, 2), (4, 5), (9, 10)]
        t = make_table(grid, {m: v.get("nrmse_median", v["nrmse_mean"]) for m, v in s["models"].items()}, ivs)["rows"]
        N = len(t["np-standard"])
        c = cascade_vs_standard(t, "np")
        iw = inward_vs_outward(t, "np")
        L.append(f"\nSARCOS ({s['n_subsets']} subsets, {s['n_test_rows']} de-duplicated test rows):\n")
        L.append(f"- **Cascade beats standard NP** on {'/'.join(map(str, c))} of {N} joints ({', '.join(IV)}); "
                 f"inward beats outward in {int(iw.sum())} of {iw.size} cells.")
        L.append("- **Outward beats inward on the last joint (7)**: inward/outward "
                 + ", ".join(f"{IV[k]} {_f(t['np-inward'][N - 1][k])}/{_f(t['np-outward'][N - 1][k])}"
                             for k in range(3)) + ".")
        if all("nrmse_all" in v for v in s["models"].values()):
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
