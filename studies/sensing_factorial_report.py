"""The sensing factorial study's report from its JSON alone: a Markdown page and one figure (effect per arm).

``python -m studies.commands.sensing_factorial --report out/sensing_factorial/factorial.json`` renders them again
(``--slim PATH``: also writes the results without the curve summaries, as kept in the documentation).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from cascgp_experiments.common import TABLE_INTERVALS


def _p(x: float) -> str:
    return f"{x:.4f}" if x >= 1e-4 else f"{x:.1e}"


def _effect_rows(res: dict[str, Any], scoring: str) -> list[str]:
    rows = ["| arm | P | " + " | ".join(f"{lo:g}-{hi:g} s" for lo, hi in TABLE_INTERVALS) + " |",
            "|---|---|" + "---|" * len(TABLE_INTERVALS)]
    for arm in res["meta"]["arms"]:
        for p in ("np", "sp"):
            cells = []
            for lo, hi in TABLE_INTERVALS:
                s = res["effects"][f"{arm}|{p}|{lo:g}-{hi:g}"][scoring]
                cells.append(f"{s['ratio']:.3f} [{s['q25']:.3f}, {s['q75']:.3f}] ({s['wins']}/{s['n']})")
            rows.append(f"| {arm} | {p.upper()} | " + " | ".join(cells) + " |")
    return rows


def markdown(res: dict[str, Any]) -> str:
    """The report: effects per arm (both scorings, per direction), the two primary families with their verdicts,
    the secondary intervals' unadjusted p-values, and the run's provenance."""
    m = res["meta"]
    lines = [f"# Sensing factorial: results{' (--quick: no verdicts)' if m['quick'] else ''}", "",
             f"Command: `{m['command']}`. Protocol: `{m['protocol']}` (commit `{m['protocol_commit']}`); code "
             f"commit `{m['code_commit']}`. {m['n_subsets']} subsets, grid {m['grid_s']} s, {m['n_restarts']} "
             f"starts per fit; wall time {m['wall_s']:.0f} s; load average {m['loadavg_start']} -> "
             f"{m['loadavg_end']}.", "",
             "Effect ratio exp(mean over subsets of e) of cascades (inward and outward, the joints where they differ "
             "from the standard model) against the standard model; [interquartile range over subsets]; (subsets with "
             "e < 0, cascades better). Below 1: cascades better.", "",
             "## Scored with the chained predicted neighbour torque (primary)", "", *_effect_rows(res, "predicted"),
             "", "## Scored with the measured neighbour torque (secondary)", "", *_effect_rows(res, "measured"), "",
             "## Per direction at 1-2 s (predicted; secondary)", "", "| arm | P | inward | outward |",
             "|---|---|---|---|"]
    for arm in m["arms"]:
        for p in ("np", "sp"):
            d = res["effects"][f"{arm}|{p}|1-2"]["per_direction"]
            lines.append(f"| {arm} | {p.upper()} | " + " | ".join(
                f"{d[c]['ratio']:.3f} ({d[c]['wins']}/{d[c]['n']})" for c in ("inward", "outward")) + " |")
    if "verdicts" in res:
        v = res["verdicts"]
        lines += ["", "## Primary family 1: does a factor change the effect? (1-2 s, Holm over 12 tests)", "",
                  "| arm | P | ratio of ratios (arm / ideal) | median difference of e | p | p (Holm) | verdict |",
                  "|---|---|---|---|---|---|---|"]
        lines += [f"| {t['arm']} | {t['param'].upper()} | {t['ratio_of_ratios']:.3f} | {t['median_diff']:+.3f} | "
                  f"{_p(t['p'])} | {_p(t['p_holm'])} | {t['verdict']} |" for t in v["factor_changes_effect"]]
        lines += ["", "## Primary family 2: do cascades beat the standard model under the arm? (1-2 s, Holm over 14 "
                  "tests)", "", "| arm | P | ratio | p | p (Holm) | verdict |", "|---|---|---|---|---|---|"]
        lines += [f"| {t['arm']} | {t['param'].upper()} | {t['ratio']:.3f} | {_p(t['p'])} | {_p(t['p_holm'])} | "
                  f"{t['verdict']} |" for t in v["cascades_beat_standard"]]
        for key, sec in res.get("secondary", {}).items():
            lines += ["", f"## Secondary, {key} s (unadjusted p-values, no verdicts)", "",
                      "| arm | P | ratio | p (vs 1) | ratio of ratios (arm / ideal) | p (vs ideal) |",
                      "|---|---|---|---|---|---|"]
            ch = {(t["arm"], t["param"]): t for t in sec["factor_changes_effect"]}
            for t in sec["cascades_beat_standard"]:
                c = ch.get((t["arm"], t["param"]))
                rest = f"{c['ratio_of_ratios']:.3f} | {_p(c['p'])}" if c else "- | -"
                lines.append(f"| {t['arm']} | {t['param'].upper()} | {t['ratio']:.3f} | {_p(t['p'])} | {rest} |")
    return "\n".join(lines) + "\n"


def slim(res: dict[str, Any]) -> dict[str, Any]:
    """The results without the curve summaries and job statistics: provenance, effects, verdicts and, per arm, its
    collection options and every per-subset score (``nrmse_all``, both scorings) from which the rest follows."""
    arms = {}
    for arm, a in res["arms"].items():
        c = a["curves"]
        models = {m: {"nrmse_all": v["nrmse_all"], **({"measured": {"nrmse_all": v["measured"]["nrmse_all"]}}
                                                      if "measured" in v else {})} for m, v in c["models"].items()}
        arms[arm] = {k: v for k, v in a.items() if k != "curves"} | {
            "curves": {"grid_s": c["grid_s"], "n_subsets": c["n_subsets"], "n_test_rows": c["n_test_rows"],
                       "shared": c.get("shared", []), "wall_s": c["wall_s"], "models": models}}
    return {k: v for k, v in res.items() if k != "arms"} | {"arms": arms}


def figure(res: dict[str, Any], path: str | Path) -> Path:
    """One figure: per interval, the effect ratio per arm for NP and SP with its interquartile range."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import ScalarFormatter

    from cascgp_experiments.common import save_figure

    arms = list(res["meta"]["arms"])
    fig, axes = plt.subplots(1, len(TABLE_INTERVALS), figsize=(4.2 * len(TABLE_INTERVALS), 3.8), sharey=True)
    for ax, (lo, hi) in zip(axes, TABLE_INTERVALS):
        for k, (p, colour) in enumerate((("np", "tab:blue"), ("sp", "tab:orange"))):
            xs, ys, lo_err, hi_err = [], [], [], []
            for i, arm in enumerate(arms):
                s = res["effects"][f"{arm}|{p}|{lo:g}-{hi:g}"]["predicted"]
                xs.append(i + (k - 0.5) * 0.25)
                ys.append(s["ratio"])
                lo_err.append(max(s["ratio"] - s["q25"], 0.0))
                hi_err.append(max(s["q75"] - s["ratio"], 0.0))
            ax.errorbar(xs, ys, yerr=[lo_err, hi_err], fmt="o", color=colour, capsize=3, label=p.upper())
        ax.axhline(1.0, color="0.4", lw=0.8, ls="--")
        ax.set_xticks(range(len(arms)), arms, rotation=45, ha="right")
        ax.set_title(f"{lo:g}-{hi:g} s of data")
        ax.set_yscale("log")
        ax.yaxis.set_major_formatter(ScalarFormatter())
        ax.yaxis.set_minor_formatter(ScalarFormatter())
    axes[0].set_ylabel("nRMSE ratio, cascades / standard\n(mean over subsets; bars: IQR)")
    axes[0].legend(loc="best")
    fig.tight_layout()
    out = save_figure(fig, path, dpi=120)
    plt.close(fig)
    return out
