"""The controlled experiment of ``docs/studies/fit_accuracy.md``: why GPyTorch's Adam recipe predicted some
outputs better than cascgp's default fit, arm by arm, and the protocol's decision rules.

Run through the fit benchmark's command line (its data loading, fits and scoring are shared)::

    python -m scripts.bench_cascgp --out out/fit_accuracy --sarcos PATH/ias_sarcos_data.mat --fit-accuracy
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

from cascgp.io import write_json
from scripts.bench_cascgp import _jsonable, bench_cascgp, load_split, score

#: The controlled experiment's data sets (docs/studies/fit_accuracy.md): name, n, outputs, Jaco ("quick") or SARCOS.
FIT_ACCURACY_SETS = (("D1 SARCOS n=300 7 outputs", 300, 7, None), ("D2 SARCOS n=500 6 outputs", 500, 6, None),
                     ("D3 Jaco quick n=500 6 outputs", 500, 6, "quick"))
#: The protocol's arms, in the order they run (A0 and G0 always run: the others are measured against them).
FIT_ACCURACY_ARMS = ("A0", "A-gls", "A-floor", "G0", "G0-in-cascgp", "G0-in-cascgp+c", "G-zero", "G-floor", "G-init",
                     "G0-polish")


def bank_with(bank, hypers: list[dict], means) -> object:
    """A copy of a fitted cascgp bank with other hyperparameters (``lengthscale``, ``signal_var``, ``noise_var`` in
    the units of the training data) and constant means ``means`` (per GP; cascgp's own is the sample mean):
    cascgp's predictor for another library's hyperparameters."""
    from cascgp.gp import GPBank
    from cascgp.gp.config import noise_var

    st = bank.state_dict()
    cfg = bank.config
    th = np.array(st["theta"], float).copy()
    D = th.shape[1] - 2
    floors = cfg.floors(st["y_std"])
    for b, h in enumerate(hypers):
        ys2 = float(st["y_std"][b]) ** 2
        ls = np.asarray(h["lengthscale"], float)
        d = ls.size
        act = st["mask"][b, :d] > 0
        th[b, :d] = np.where(act, np.log(np.where(act, ls, 1.0) / st["x_std"][b, :d]), th[b, :d])
        sf2n = float(h["signal_var"]) / ys2
        th[b, D] = np.log(sf2n)
        fl = noise_var(cfg, sf2n, 0.0, None if floors is None else float(floors[b]))
        th[b, D + 1] = np.log(max(float(h["noise_var"]) / ys2 - fl, 1e-300))
    st["theta"] = th
    st["y_mean"] = np.asarray(means, float).copy()
    return GPBank.from_state_dict(st)


def _cascgp_starts(X: np.ndarray, Y: np.ndarray) -> list[list[dict]]:
    """cascgp's 10 default starts per output (``initial_thetas`` of ``GPFitConfig()``) in data units."""
    from cascgp.gp import GPFitConfig
    from cascgp.gp.config import noise_var
    from cascgp.gp.restarts import initial_thetas
    from cascgp.gp.state import BankData

    cfg = GPFitConfig()
    B, d = Y.shape[1], X.shape[1]
    data = BankData.normalise([X] * B, [Y[:, j] for j in range(B)], d)
    Xn, yn = data.normalised()
    th = initial_thetas(cfg, Xn, yn, data.mask, data.const_y, np.random.default_rng(cfg.seed))
    out = []
    for b in range(B):
        ys2 = data.y_std[b] ** 2
        out.append([{"lengthscale": np.exp(t[:d]) * data.x_std[b], "signal_var": float(np.exp(t[d]) * ys2),
                     "noise_var": float(noise_var(cfg, float(np.exp(t[d])), float(np.exp(t[d + 1]))) * ys2),
                     "mean": 0.0} for t in th[b]])
    return out


def fit_accuracy_one(X: np.ndarray, Y: np.ndarray, Xte: np.ndarray, Yte: np.ndarray, threads: int,
                     arms_to_run: tuple[str, ...] = FIT_ACCURACY_ARMS) -> dict:
    """The protocol's arms on one data set (``arms_to_run``, A0 and G0 always): hyperparameters, NLLs, test
    nRMSE, time."""
    import warnings

    import torch

    from cascgp.gp import GPBank, GPFitConfig
    from scripts import gpytorch_fit as gf

    torch.set_num_threads(threads)
    B = Y.shape[1]
    cols = [Y[:, j] for j in range(B)]
    arms: dict[str, dict] = {}

    def add(name: str, hyper: list[dict], pred: np.ndarray, t: float, **extra) -> None:
        arms[name] = {"hyper": [_jsonable(h) for h in hyper], "time_s": t, **score(X, Y, hyper, pred, Yte), **extra}
        print(f"  {name:<16} median test nRMSE {arms[name]['test_nrmse_median']:.4f}, zero-mean NLL "
              f"{sum(arms[name]['nll_zero_mean']):.2f} (sum), {t:.1f} s", flush=True)

    def cascgp_arm(name: str, kw: dict):
        c = bench_cascgp(X, Y, 10, threads, kw)
        bank = c.pop("bank")
        add(name, c["hyper"], bank.predict([Xte] * B, return_var=False)[0], c["time_s"])
        return bank, c["hyper"]

    def gpt_arm(name: str, **kw) -> list[dict]:
        mean, lb = kw.get("mean", "constant"), kw.get("noise_lb", 1e-4)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t0 = time.perf_counter()
            fits = gf.fit_adam_batched(X, Y, **kw)
            dt = time.perf_counter() - t0
            pred = np.stack([gf.predict_with(X, Y[:, j], Xte, f["hyper"], mean, lb) for j, f in enumerate(fits)], 1)
        add(name, [f["hyper"] for f in fits], pred, dt, own_nll=[f["nll"] for f in fits],
            own_nll_per_restart=[f["nll_per_restart"] for f in fits])
        return [f["hyper"] for f in fits]

    run = set(arms_to_run) | {"A0", "G0"}
    bank0, h0 = cascgp_arm("A0", {})
    if "A-gls" in run:
        c_gls = [gf.gls_mean(X, Y[:, j], np.asarray(h["lengthscale"]), h["signal_var"], h["noise_var"])
                 for j, h in enumerate(h0)]
        add("A-gls", h0, bank_with(bank0, h0, c_gls).predict([Xte] * B, return_var=False)[0], 0.0, gls_mean=c_gls)
    if "A-floor" in run:
        cascgp_arm("A-floor", {"noise_floor": 1e-4})
    hg = gpt_arm("G0")
    cg = [h["mean"] for h in hg]
    if "G0-in-cascgp" in run:
        add("G0-in-cascgp", hg, bank_with(bank0, hg, np.zeros(B)).predict([Xte] * B, return_var=False)[0], 0.0)
    if "G0-in-cascgp+c" in run:
        add("G0-in-cascgp+c", hg, bank_with(bank0, hg, cg).predict([Xte] * B, return_var=False)[0], 0.0)
    if "G-zero" in run:
        gpt_arm("G-zero", mean="zero")
    if "G-floor" in run:
        gpt_arm("G-floor", noise_lb=1e-6)
    if "G-init" in run:
        gpt_arm("G-init", init=_cascgp_starts(X, Y))
    if "G0-polish" not in run:
        return arms
    t0 = time.perf_counter()
    pol = GPBank(GPFitConfig(n_restarts=1)).fit([X] * B, cols, init=bank_with(bank0, hg, bank0.state_dict()["y_mean"]))
    dt = time.perf_counter() - t0
    add("G0-polish", [pol.hyperparameters(b) for b in range(B)], pol.predict([Xte] * B, return_var=False)[0], dt,
        n_iter=[fi["n_iter"][0] for fi in pol.fit_info])
    return arms


def fit_accuracy_verdict(sets: dict[str, dict]) -> dict:
    """The protocol's decision rules applied to the measured arms (docs/studies/fit_accuracy.md)."""
    med = {k: {a: v["test_nrmse_median"] for a, v in arms.items()} for k, arms in sets.items()}
    out: dict = {"per_set": {}, "candidates": {}}
    for k, arms in sets.items():
        m = med[k]
        gap = m["A0"] - m["G0"]
        r: dict = {"gap_A0_minus_G0": gap, "G0_better": bool(gap > 0)}
        if gap > 0:  # each rule where its arm was run
            r["fraction_closed"] = {a: (m[a] - m["G0"]) / gap for a in ("G-zero", "G-floor", "G-init",
                                                                          "G0-in-cascgp", "G0-polish") if a in m}
            r["explains"] = {a: bool(r["fraction_closed"][a] >= 0.5) for a in ("G-zero", "G-floor", "G-init")
                             if a in m}
            if "G0-polish" in m:
                dnll = np.median(np.subtract(arms["G0-polish"]["nll_zero_mean"], arms["A0"]["nll_zero_mean"]))
                r["H2_polish_median_nll_minus_A0"] = float(dnll)
                r["H2_holds"] = bool(dnll <= 0.1 and abs(m["G0-polish"] - m["A0"]) <= 0.25 * gap)
            if "G0-in-cascgp" in m:
                r["H3_prediction_holds"] = bool(r["fraction_closed"]["G0-in-cascgp"] >= 0.5)
        lower = np.less(arms["G0"]["nll_zero_mean"], arms["A0"]["nll_zero_mean"])
        r["H1_G0_lower_nll_outputs"] = f"{int(lower.sum())}/{lower.size}"
        r["H1_holds"] = bool(lower.sum() > lower.size / 2)
        out["per_set"][k] = r
    for cand in ("A-floor", "A-gls"):
        if not all(cand in a for a in sets.values()):
            out["candidates"][cand] = {"adopt": False, "not_run_on": [k for k, a in sets.items() if cand not in a]}
            continue
        rel = {k: (med[k]["A0"] - med[k][cand]) / med[k]["A0"] for k in sets}
        better = sum(int(np.sum(np.less(a[cand]["test_nrmse"], a["A0"]["test_nrmse"]))) for a in sets.values())
        total = sum(len(a["A0"]["test_nrmse"]) for a in sets.values())
        # the rule needs all three data sets: a run of some of them cannot adopt a candidate
        out["candidates"][cand] = {"relative_improvement_of_median": rel, "outputs_better": f"{better}/{total}",
                                   "adopt": bool(len(sets) == len(FIT_ACCURACY_SETS)
                                                 and all(v >= 0.01 for v in rel.values()) and better >= 2 * total / 3)}
    return out


def run_fit_accuracy(args: argparse.Namespace, prov: dict) -> int:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    res: dict = {"provenance": prov, "protocol": "docs/studies/fit_accuracy.md", "sets": {}, "data": {}}
    chosen = set(args.fit_sets.split(","))
    for name, n, k, jaco in FIT_ACCURACY_SETS:
        if name.split()[0] not in chosen:
            continue
        X, Y, Xte, Yte, desc = load_split(n, None if jaco else args.sarcos, jaco, args.seed, k, None, out)
        print(f"{name}: {desc}", flush=True)
        res["data"][name] = desc
        res["sets"][name] = fit_accuracy_one(X, Y, Xte, Yte, args.threads,
                                             tuple(a for a in args.fit_arms.split(",") if a))
        write_json(out / "bench_cascgp_fit_accuracy.json", res)
    res["verdict"] = fit_accuracy_verdict(res["sets"])
    res["provenance"]["load_average_end"] = list(os.getloadavg())
    for name, arms in res["sets"].items():
        a0 = arms["A0"]
        print(f"\n{name}\n{'arm':<16} | {'median nRMSE':>12} | {'dNLL0 med':>9} | {'dNLLc med':>9} | nRMSE per output")
        for a, v in arms.items():
            d0 = np.median(np.subtract(v["nll_zero_mean"], a0["nll_zero_mean"]))
            dc = np.median(np.subtract(v["nll_const_mean"], a0["nll_const_mean"]))
            print(f"{a:<16} | {v['test_nrmse_median']:>12.4f} | {d0:>+9.2f} | {dc:>+9.2f} | "
                  + " ".join(f"{e:.4f}" for e in v["test_nrmse"]))
    print(json.dumps(res["verdict"], indent=1))
    write_json(out / "bench_cascgp_fit_accuracy.json", res)
    print(f"wrote {out / 'bench_cascgp_fit_accuracy.json'}")
    return 0
