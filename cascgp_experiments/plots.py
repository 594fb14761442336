"""Figures, tables and CSVs of the data-efficiency study, regenerated from ``results.json`` alone.

Reads only the JSON written by :func:`cascgp_experiments.study.run_study` (or ``cascgp sarcos``'s, whose figure,
CSV and claims are the SARCOS rows below; no data files, no models;
of ``cascgp`` only :mod:`cascgp.io`, no ``jaco_env`` or torch import) and writes into ``out``:

======================  =====================================================================
file                    content
======================  =====================================================================
fig_jaco_np.png         paper Fig. 3: NP inward/outward/standard + RBD, nRMSE vs seconds
fig_jaco_sp.png         paper Fig. 4: the same for the SP models
fig_jaco_np_df.png      the derivative-free NP models (not a paper figure)
fig_jaco_sp_df.png      the derivative-free SP models (not a paper figure)
fig_sarcos.png          paper Fig. 5: SARCOS NP models (if the JSON has a SARCOS block)
fig_iterations.png      paper run-time figure: L-BFGS iterations per joint (mean +- std)
fig_correlation.png     paper correlation figure: |Spearman| of states and torques
table1.md               paper Table I layout, measured, next to the paper's numbers
curves_jaco.csv         every curve point: model, T, joint; mean, std, median, quartiles
curves_sarcos.csv       the same for SARCOS
iterations.csv          iteration counts per model and joint
claims.md               which of the paper's claims hold here (:mod:`cascgp_experiments.claims`)
======================  =====================================================================

Command line: ``cascgp plots --json out/study/results.json --out DIR``.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Any

import numpy as np

from cascgp.io import atomic_write_text
from cascgp_experiments.claims import claims_markdown
from cascgp_experiments.common import RBD, STRUCT_ORDER, label, make_table, model_name, read_json, save_figure
from cascgp_experiments.pooled_stats import chain_first, standard_twin

COLORS = {"inward": "tab:blue", "outward": "tab:orange", "standard": "tab:green", RBD: "tab:gray"}


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _finish(fig: Any, path: Path) -> Path:
    """Lay out, write (80 dpi) and close a figure; returns ``path``."""
    fig.tight_layout()
    save_figure(fig, path, dpi=80)
    _plt().close(fig)
    return path


def _struct(m: str) -> str:
    return RBD if m == RBD else m.split("-")[1]


def curve_figure(block: dict[str, Any], models: list[str], title: str, path: Path) -> Path:
    """nRMSE vs seconds of data (log x), median over subsets with the interquartile range as
    error bars (mean +- std for blocks without medians), one panel per joint. A panel in which a cascade is its
    standard model by construction (its chain's first joint) says so in its title: the two curves coincide."""
    plt = _plt()
    N = int(block["dof"])
    ncol = 3 if N <= 6 else 4
    nrow = int(np.ceil(N / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.2 * nrow), squeeze=False)
    grid = np.asarray(block["grid_s"], float)
    for j in range(nrow * ncol):
        ax = axes[j // ncol][j % ncol]
        if j >= N:
            ax.axis("off")
            continue
        for m in models:
            if m not in block["models"]:
                continue
            v = block["models"][m]
            if "nrmse_median" in v:
                mu = np.asarray(v["nrmse_median"], float)[:, j]
                yerr = np.stack([mu - np.asarray(v["nrmse_q25"], float)[:, j],
                                 np.asarray(v["nrmse_q75"], float)[:, j] - mu])
            else:
                mu = np.asarray(v["nrmse_mean"], float)[:, j]
                yerr = np.asarray(v["nrmse_std"], float)[:, j]
            if m == RBD:
                ax.plot(grid, mu, "--", color=COLORS[RBD], label=label(m))
            else:
                ax.errorbar(grid, mu, yerr=yerr, marker="o", ms=3, capsize=2, color=COLORS[_struct(m)],
                            label=label(m))
        ax.set_xscale("log")
        same = [_struct(m) for m in models if m in block["models"] and chain_first(m, N) == j
                and standard_twin(m) in models and standard_twin(m) in block["models"]]
        ax.set_title(f"Joint {j + 1}" + "".join(f" ({s} = standard)" for s in same))
        ax.set_xlabel("seconds of training data")
        ax.set_ylabel("nRMSE")
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].legend(fontsize=7)
    fig.suptitle(title)
    return _finish(fig, path)


def iterations_figure(it: dict[str, Any], path: Path) -> Path:
    plt = _plt()
    models = list(it["models"])
    N = len(it["models"][models[0]]["n_iter_mean"])
    fig, ax = plt.subplots(figsize=(7, 3.5))
    w = 0.8 / len(models)
    for k, m in enumerate(models):
        mu = np.asarray(it["models"][m]["n_iter_mean"], float)
        sd = np.asarray(it["models"][m]["n_iter_std"], float)
        ax.bar(np.arange(N) + (k - (len(models) - 1) / 2) * w, mu, w, yerr=sd, capsize=2,
               color=COLORS.get(_struct(m)), label=label(m))
    ax.set_xticks(np.arange(N), [f"Joint {j + 1}" for j in range(N)])
    ax.set_ylabel("L-BFGS iterations (mean over starts)")
    ax.set_title(f"Iterations per joint, n = {it['n']}, {it['n_restarts']} restarts")
    ax.legend(fontsize=8)
    return _finish(fig, path)


def correlation_figure(c: dict[str, Any], path: Path) -> Path:
    plt = _plt()
    M = np.asarray(c["abs_spearman"], float)
    labels = c["labels"]
    fig, ax = plt.subplots(figsize=(7, 6))
    im = ax.imshow(M, vmin=0, vmax=1, cmap="viridis")
    ax.set_xticks(range(len(labels)), labels, rotation=90, fontsize=7)
    ax.set_yticks(range(len(labels)), labels, fontsize=7)
    fig.colorbar(im, ax=ax, label="|Spearman rho|")
    ax.set_title(f"|Spearman| of joint states and torques ({c.get('data', '')})", fontsize=9)
    return _finish(fig, path)


def _fmt(v: float | None) -> str:
    if v is None or not np.isfinite(v):
        return "-"
    return f"{v:.3f}".lstrip("0") if v < 1 else f"{v:.2f}"


def table_markdown(table: dict[str, Any], models: list[str], title: str,
                   marks: bool = True, shared: bool = False) -> str:
    """Table I layout: rows = models, columns = joint x interval. Best per category **bold**,
    within 5 % of the best *italic* (the paper's yellow / light yellow); ``shared``: a cascade's cell that is
    the standard model by construction gets a dagger."""
    rows = table["rows"]
    ivs = table["intervals"]
    N = len(next(iter(rows.values())))
    head = "| model | " + " | ".join(f"J{j + 1} {int(hi)}s" for j in range(N) for _, hi in ivs) + " |"
    sep = "|---|" + "---|" * (N * len(ivs))
    lines = [f"**{title}**", "", head, sep]
    for m in models:
        if m not in rows:
            continue
        cells = []
        for j in range(N):
            for k in range(len(ivs)):
                s = _fmt(rows[m][j][k])
                if marks and table.get("best", {}).get(m, [[False]])[j][k]:
                    s = f"**{s}**"
                elif marks and table.get("near", {}).get(m, [[False]])[j][k]:
                    s = f"*{s}*"
                if shared and j == chain_first(m, N):
                    s += " †"
                cells.append(s)
        lines.append(f"| {label(m)} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _table_legend(block: dict[str, Any]) -> str:
    """What the numbers of Table I are, its marks, and how the shared cells were made."""
    g = np.asarray(block["grid_s"], float)
    pts = "; ".join(f"{lo:g}-{hi:g} s: " + (", ".join(f"{t:g}" for t in inside) if inside.size else "none, '-'")
                    for lo, hi in ((1, 2), (4, 5), (9, 10))
                    for inside in [g[(g >= lo - 1e-9) & (g <= hi + 1e-9)]])
    sh = block.get("shared")
    how = ("fitted once, in the standard model's job, and shared (exactly equal)" if sh else
           "fitted separately in this run, not shared (largest difference from the standard model's per-subset "
           f"value there: {_shared_gap(block):.1e})")
    return (f"Each cell: nRMSE of the joint on the test rows; per grid point the **median over the "
            f"{block['n_subsets']} subsets**, then the **mean over the interval's grid points** ({pts} s of data). "
            f"**bold**: lowest in its category (NP or SP, derivative based or free); *italic*: within 5 % of it. "
            f"†: the standard model's GP by construction (the cascade's first joint in its chain direction takes "
            f"every joint's state and no torque), {how}; not counted in any comparison. "
            f"RBD: nominal model, not marked.\n")


def _shared_gap(block: dict[str, Any]) -> float:
    """Largest |cascade - standard| over subsets and grid points in the cells that are the same by construction."""
    gap = 0.0
    for m, v in block["models"].items():
        st = standard_twin(m)
        j = chain_first(m, np.asarray(v["nrmse_all"]).shape[2])
        if j is not None and st in block["models"]:
            a, b = np.asarray(v["nrmse_all"], float), np.asarray(block["models"][st]["nrmse_all"], float)
            gap = max(gap, float(np.abs(a[:, :, j] - b[:, :, j]).max()))
    return gap


def _table_order() -> list[str]:
    return [model_name(p, s, df) for df in (False, True) for p in ("np", "sp") for s in STRUCT_ORDER]


def _write_rows(path: Path, rows: list[list[Any]]) -> Path:
    """Write CSV rows atomically (the csv module's ``\\r\\n`` line ends)."""
    buf = io.StringIO(newline="")
    csv.writer(buf).writerows(rows)
    return atomic_write_text(path, buf.getvalue())


def write_csv(block: dict[str, Any], path: Path, dataset: str) -> Path:
    """Every curve point of a curves block: ``dataset, model, seconds, joint, nrmse_mean, nrmse_std, n_subsets,
    nrmse_median, nrmse_q25, nrmse_q75`` over the subsets (the figures and tables show the median and the
    interquartile range; the last three are empty for a results file that predates them)."""
    rows: list[list[Any]] = [["dataset", "model", "seconds", "joint", "nrmse_mean", "nrmse_std", "n_subsets",
                              "nrmse_median", "nrmse_q25", "nrmse_q75"]]
    for m, v in block["models"].items():
        mu, sd = np.asarray(v["nrmse_mean"], float), np.asarray(v["nrmse_std"], float)
        quart = [np.asarray(v[k], float) if k in v else None for k in ("nrmse_median", "nrmse_q25", "nrmse_q75")]
        for g, T in enumerate(block["grid_s"]):
            for j in range(mu.shape[1]):
                rows.append([dataset, m, T, j + 1, f"{mu[g, j]:.6f}", f"{sd[g, j]:.6f}", block["n_subsets"],
                             *("" if q is None else f"{q[g, j]:.6f}" for q in quart)])
    return _write_rows(path, rows)


def as_results(run: Any) -> dict[str, Any] | None:
    """A study's ``results.json`` as it is, ``cascgp sarcos``'s ``sarcos.json`` as its ``"sarcos"`` block, else
    ``None`` (neither)."""
    if not isinstance(run, dict):
        return None
    if {"jaco", "sarcos"} & set(run):
        return run
    if {"models", "grid_s", "n_subsets"} <= set(run):
        return {"sarcos": run}
    return None


def render(json_path: str | Path, out: str | Path) -> list[Path]:
    """Write every figure/table/CSV above from ``json_path`` (a study's ``results.json`` or ``cascgp sarcos``'s
    ``sarcos.json``) into ``out``; returns the paths."""
    res = as_results(read_json(json_path))
    if res is None:
        raise ValueError(f"{json_path}: expected a study's results.json or a sarcos.json (no 'jaco' or 'sarcos' "
                         f"results)")
    return render_results(res, out)


def render_results(res: dict[str, Any], out: str | Path, claims: str = "claims.md") -> list[Path]:
    """Write every figure/table/CSV above from the results dict ``res`` into ``out`` (the claims into the file
    ``claims``); returns the paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    jaco = res.get("jaco")
    if jaco:
        for p, df, name in (("np", False, "np"), ("sp", False, "sp"), ("np", True, "np_df"), ("sp", True, "sp_df")):
            ms = [model_name(p, s, df) for s in STRUCT_ORDER] + [RBD]
            if any(m in jaco["models"] for m in ms[:-1]):
                kind = "derivative-free" if df else "derivative-based"
                written.append(curve_figure(jaco, ms, f"Jaco (simulated): {p.upper()} models, {kind}",
                                            out / f"fig_jaco_{name}.png"))
        written.append(write_csv(jaco, out / "curves_jaco.csv", "jaco"))
        order = [m for m in _table_order() if m in jaco["table"]["rows"]] + [RBD]
        md = ["# Table I, measured (simulated Jaco)\n", _table_legend(jaco),
              table_markdown(jaco["table"], order, "Measured, cascades with the predicted neighbour torque "
                             "(mean over the interval's grid points of the per-point median over subsets)",
                             shared=True), "\n"]
        if "table_measured" in jaco:
            md += [table_markdown(jaco["table_measured"], order, "The same, cascades scored with the measured "
                                  "neighbour torque (standard models and RBD as above)", shared=True), "\n"]
        if "table_q25" in jaco:
            iqr = {m: [[f"{a:.3f}-{b:.3f}" if a is not None and b is not None else "-" for a, b in zip(ra, rb)]
                       for ra, rb in zip(jaco["table_q25"][m], jaco["table_q75"][m])] for m in jaco["table_q25"]}
            N = len(next(iter(iqr.values())))
            md.append("**Interquartile range over subsets (mean over the interval's grid points of the per-point "
                      "25th and 75th percentiles)**\n")
            md.append("| model | " + " | ".join(f"J{j + 1} {hi}s" for j in range(N) for hi in (2, 5, 10)) + " |")
            md.append("|---|" + "---|" * (3 * N))
            for m in order:
                if m in iqr:
                    md.append(f"| {label(m)} | " + " | ".join(c for row in iqr[m] for c in row) + " |")
            md.append("\n")
        a = jaco.get("audit")
        if a and a.get("n_gps"):
            md.append(f"**Equivalence audit**: {a['n_audited_fits']} of {a['n_fits']} grid fits "
                      f"({a['n_gps']} GPs) refitted with {jaco.get('n_restarts', '?')} cold starts run to "
                      f"convergence; NLL gap (protocol minus cold) <= {a['tol_nats']} nat for "
                      f"{100 * a['within_tol']:.1f} % of the GPs (median {a['gap_median']:+.3f}, 95th percentile "
                      f"{a['gap_q95']:+.3f}, max {a['gap_max']:+.3f} nats; better than cold by > 0.1 nat: "
                      f"{100 * a['better_than_cold']:.1f} %).\n")
        if "paper_table" in res:
            pt = make_table([1.5, 4.5, 9.5], {m: [[r[j][k] for j in range(len(r))] for k in range(3)]
                                              for m, r in res["paper_table"]["rows"].items()},
                            intervals=[(1, 2), (4, 5), (9, 10)])
            md.append(table_markdown(pt, _table_order(), "Paper (Table I), marks recomputed the same way"))
        atomic_write_text(out / "table1.md", "\n".join(md))
        written.append(out / "table1.md")
    if res.get("sarcos"):
        s = res["sarcos"]
        written.append(curve_figure(s, [model_name("np", st, False) for st in STRUCT_ORDER],
                                    f"SARCOS: NP models ({s['n_subsets']} subsets, de-duplicated IAS test rows)",
                                    out / "fig_sarcos.png"))
        written.append(write_csv(s, out / "curves_sarcos.csv", "sarcos"))
    if res.get("iterations"):
        it = res["iterations"]
        written.append(iterations_figure(it, out / "fig_iterations.png"))
        rows: list[list[Any]] = [["model", "joint", "input_dim", "n_iter_mean", "n_iter_std", "n_iter_per_start",
                                  "wall_s"]]
        for m, r in it["models"].items():
            for j in range(len(r["n_iter_mean"])):
                rows.append([m, j + 1, r["dim"][j], f"{r['n_iter_mean'][j]:.1f}", f"{r['n_iter_std'][j]:.1f}",
                             " ".join(map(str, r["n_iter"][j])), f"{r['wall_s'][j]:.2f}"])
        written.append(_write_rows(out / "iterations.csv", rows))
    if res.get("correlation"):
        written.append(correlation_figure(res["correlation"], out / "fig_correlation.png"))
    source = "sarcos.json" if set(res) == {"sarcos"} else "results.json"
    written.append(atomic_write_text(out / claims, claims_markdown(res, source)))
    return written
