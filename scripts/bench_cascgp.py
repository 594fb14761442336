"""Benchmark: cascgp's batched GP fit against GPy and GPyTorch, side by side in one run.

Fits one Matern 5/2 ARD GP per output (``n`` samples; SARCOS: d = 18 inputs, q, qd, qdd of joints 1-6, 6 torques,
or with ``--outputs 7`` all 21 inputs and 7 torques; simulated Jaco 2: q, qd, qdd of its 6 joints, 6 torques) with
10 restarts per output, on the *same* standardised data, with

* :class:`cascgp.gp.GPBank` (all outputs x 10 starts in one batch; the settings in ``CONFIGS``);
* GPy (``GPRegression`` + ``Matern52(ARD=True)``, zero mean, ``optimize_restarts(10)``, its default L-BFGS-B);
* GPyTorch (``scripts/gpytorch_fit.py``: its exact-GP recipe, ``ConstantMean``, noise bounded below by 1e-4, one
  model per output; ``adam``: lr 0.1 for 150 iterations, ``lbfgs``: torch's L-BFGS with strong-Wolfe line search
  to convergence; 10 random restarts, the best final loss kept).

One table, one row per library/setting: fit time, its ratio to GPy's, the NLL gap to GPy per output and the test
nRMSE per output (``cascgp.metrics.nrmse`` on the held-out rows) with its median. The NLL gap is computed for every
library by one closed-form objective (:func:`scripts.gpytorch_fit.hyper_nll`) from its fitted
``(lengthscales, signal variance, noise variance)`` on the standardised training targets with **zero mean** (the
objective cascgp and GPy optimise; total nats including ``n/2 log 2 pi``). GPyTorch optimises a different objective
(with a learned constant mean ``c``): the JSON also holds every library's NLL with ``c`` profiled out (its
least-squares value, GPyTorch's objective) and GPyTorch's own final loss. Test predictions are each library's own
posterior mean (GPyTorch's with its ``c``).

Data (``--sarcos`` / ``--jaco``, else a smooth synthetic function; training rows from
:func:`cascgp_experiments.audit_suite.benchmark_data`): SARCOS training rows ``X_train[::5][:n]``, test rows all of
``X_test`` (``--n-test`` caps them); Jaco: ``--jaco DIR`` with ``jaco_{train,test}.npz`` or ``--jaco quick`` to
collect the quick preset into ``<out>/data``; ``n`` training rows evenly spaced over the recording, all test rows;
synthetic: the ``--n-test`` rows that follow the ``n`` training rows. Test inputs and targets are standardised
with the training rows' statistics. The JSON (``bench_cascgp.json``) records the command, versions, the git commit
and the load average. If ``cascgp.models`` is present it also measures the latency of one single-query prediction
of a 6-joint NP inward cascade (``predict_one``; ``--queries 0`` skips it). For every cascgp setting it also reports
evaluations per start, the cost of one NLL+gradient evaluation and its breakdown. ``--scaling`` instead measures
time per evaluation and peak memory against n. ``--fit-accuracy`` runs the controlled experiment of
``docs/studies/fit_accuracy.md`` instead (needs ``--sarcos``; collects the quick Jaco data).

Usage::

    python -m scripts.bench_cascgp --out out/bench --sarcos /work/shared/data/sarcos/ias_sarcos_data.mat --threads 1
    python -m scripts.bench_cascgp --out out/bench --sarcos ... --n 300 --outputs 7
    python -m scripts.bench_cascgp --out out/bench --jaco quick --configs default
    python -m scripts.bench_cascgp --out out/bench --skip-gpy --skip-gpytorch     # cascgp only
    python -m scripts.bench_cascgp --out out/bench --gpytorch adam                # one GPyTorch optimiser
    python -m scripts.bench_cascgp --out out/bench --scaling 250,500,1000,2000 --scaling-iter 2
    python -m scripts.bench_cascgp --out out/fit_accuracy --sarcos ... --fit-accuracy

GPy and GPyTorch are optional extras (``pip install -e '.[bench]'``); a missing one is skipped with a message.
Threads: torch uses ``--threads`` (default 1) for cascgp and GPyTorch; GPy's NumPy BLAS is limited to ``--threads``
as well (with threadpoolctl when installed; the script also sets ``OMP_NUM_THREADS``/``OPENBLAS_NUM_THREADS``
before NumPy is imported when they are unset).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import time
from pathlib import Path

if __name__ == "__main__":  # BLAS reads these when NumPy is first imported
    _t = next((a.split("=", 1)[1] for a in sys.argv if a.startswith("--threads=")), None)
    if _t is None and "--threads" in sys.argv[:-1]:
        _t = sys.argv[sys.argv.index("--threads") + 1]
    for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_v, _t or "1")

import numpy as np

from cascgp.io import write_json
from cascgp_experiments.audit_suite import benchmark_data as load_data


#: cascgp settings of the benchmark. "default" is ``GPFitConfig()`` as a new user gets it (every GP's leading start
#: runs to convergence; the other starts stop once they stall: less than 0.01 nat gained over 5 iterations, or
#: less than a tenth of their gap to the leader). "converge-all" runs all 10 starts to convergence (the library
#: default before the early-stopping rule; the equivalence audit's reference).
CONFIGS = {
    "default": {},
    "converge-all": {"stall_window": None},
}


@contextlib.contextmanager
def blas_threads(k: int):
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # optional
        yield
        return
    with threadpool_limits(limits=k, user_api="blas"):
        yield


def bench_cascgp(X: np.ndarray, Y: np.ndarray, restarts: int, threads: int, config_kw: dict) -> dict:
    import torch

    from cascgp.gp import GPBank, GPFitConfig

    import cascgp.gp.likelihood as gp_mod

    torch.set_num_threads(threads)
    cfg = GPFitConfig(kernel="matern52", n_restarts=restarts, **config_kw)
    gp_mod.PROFILE = {}
    try:
        with blas_threads(1):  # NumPy/SciPy in the optimiser loop are tiny; keep OpenBLAS threads from spinning
            t0 = time.perf_counter()
            bank = GPBank(cfg).fit([X] * Y.shape[1], [Y[:, j] for j in range(Y.shape[1])])
            dt = time.perf_counter() - t0
        prof = dict(gp_mod.PROFILE)
    finally:
        gp_mod.PROFILE = None
    members = max(int(prof.pop("members", 0)), 1)
    phases = {k: float(v) for k, v in prof.items()}
    phases["optimiser_and_rest"] = dt - sum(phases.values())
    return {
        "breakdown_s": phases,
        "breakdown_us_per_eval": {k: 1e6 * v / members for k, v in phases.items()},
        "ms_per_eval": 1e3 * dt / max(bank.fit_summary["n_eval"], 1),
        "evals_per_start": float(bank.fit_summary["n_eval"]) / (restarts * Y.shape[1]),
        "time_s": dt,
        "best_nll": [fi["best_nll"] for fi in bank.fit_info],
        "nll_per_restart": [fi["nll"] for fi in bank.fit_info],
        "n_iter": [fi["n_iter"] for fi in bank.fit_info],
        "n_eval": [fi["n_eval"] for fi in bank.fit_info],
        "reason": [fi["reason"] for fi in bank.fit_info],
        "best": [fi["best"] for fi in bank.fit_info],
        "jitter": [fi["jitter"] for fi in bank.fit_info],
        "total_evals": bank.fit_summary["n_eval"],
        "batch_rounds": bank.fit_summary["batch_rounds"],
        "config": {k: getattr(cfg, k) for k in cfg.__dataclass_fields__},
        "torch_threads": threads,
        "hyper": [_jsonable(bank.hyperparameters(b)) for b in range(Y.shape[1])],
        "bank": bank,  # popped before the JSON is written
    }


def bench_gpy(X: np.ndarray, Y: np.ndarray, restarts: int, threads: int, Xte: np.ndarray | None = None) -> dict:
    import GPy

    times, best, per, iters, hyper, pred = [], [], [], [], [], []
    with blas_threads(threads):
        for j in range(Y.shape[1]):
            np.random.seed(j)  # noqa: NPY002 - GPy draws its restarts from NumPy's global generator
            t0 = time.perf_counter()
            m = GPy.models.GPRegression(X, Y[:, j : j + 1], GPy.kern.Matern52(X.shape[1], ARD=True))
            m.optimize_restarts(num_restarts=restarts, verbose=False, robust=True)
            times.append(time.perf_counter() - t0)
            best.append(float(-m.log_likelihood()))
            runs = m.optimization_runs[-restarts:]
            per.append([float(r.f_opt) for r in runs])
            iters.append([int(getattr(r, "funct_eval", -1) or -1) for r in runs])
            hyper.append({"lengthscale": np.asarray(m.kern.lengthscale.values, float).copy(),
                          "signal_var": float(m.kern.variance.values[0]),
                          "noise_var": float(m.likelihood.variance.values[0]), "mean": 0.0})
            if Xte is not None:
                pred.append(np.asarray(m.predict(Xte)[0], float).reshape(-1))
    out = {"time_s": float(sum(times)), "time_per_output_s": times, "best_nll": best, "nll_per_restart": per,
           "n_eval": iters, "version": GPy.__version__, "hyper": [_jsonable(h) for h in hyper]}
    if Xte is not None:
        out["pred"] = np.stack(pred, 1)
    return out


def bench_gpytorch(X: np.ndarray, Y: np.ndarray, restarts: int, threads: int, optimizer: str,
                   Xte: np.ndarray | None, iters: int = 150, lr: float = 0.1) -> dict:
    """GPyTorch's recipe (:mod:`scripts.gpytorch_fit`), one model per output, timed as a whole."""
    import warnings

    import gpytorch
    import torch

    from scripts import gpytorch_fit as gf

    torch.set_num_threads(threads)
    fits, pred = [], []
    with warnings.catch_warnings(), blas_threads(threads):
        warnings.simplefilter("ignore")  # GPyTorch's NumericalWarning on every jitter retry
        t0 = time.perf_counter()
        for j in range(Y.shape[1]):
            fits.append(gf.fit_one(X, Y[:, j], optimizer=optimizer, restarts=restarts, iters=iters, lr=lr,
                                   output=j))
        dt = time.perf_counter() - t0
        if Xte is not None:
            pred = [gf.predict(f, Xte) for f in fits]
    out = {"time_s": dt, "time_per_output_s": [f["time_s"] for f in fits], "own_nll": [f["nll"] for f in fits],
           "nll_per_restart": [f["nll_per_restart"] for f in fits], "n_eval": [f["n_eval"] for f in fits],
           "hyper": [_jsonable(f["hyper"]) for f in fits], "version": gpytorch.__version__,
           "recipe": {"optimizer": optimizer, "restarts": restarts, "mean": "constant", "noise_lower_bound": 1e-4,
                      "dtype": "float64", **({"iters": iters, "lr": lr} if optimizer == "adam" else
                                             {"max_iter": 1000, "tolerance_grad": 1e-5, "tolerance_change": 1e-9})}}
    if Xte is not None:
        out["pred"] = np.stack(pred, 1)
    return out


def _jsonable(h: dict) -> dict:
    return {k: (np.asarray(v, float).tolist() if np.ndim(v) else float(v)) for k, v in h.items()}


def score(X: np.ndarray, Y: np.ndarray, hyper: list[dict], pred: np.ndarray | None, Yte: np.ndarray | None
          ) -> dict:
    """One library's fitted hyperparameters under the common objectives, and its test error."""
    from scripts.gpytorch_fit import hyper_nll

    nll0, nllc = [], []
    for j, h in enumerate(hyper):
        args = (X, Y[:, j], np.asarray(h["lengthscale"]), h["signal_var"], h["noise_var"])
        nll0.append(hyper_nll(*args, mean=0.0))
        nllc.append(hyper_nll(*args, mean=None))
    out: dict = {"nll_zero_mean": nll0, "nll_const_mean": nllc}
    if pred is not None and Yte is not None:
        from cascgp.metrics import nrmse

        e = nrmse(pred, Yte)
        out["test_nrmse"] = [float(v) for v in e]
        out["test_nrmse_median"] = float(np.median(e))
    return out


def load_split(n: int, sarcos: str | None, jaco: str | None, seed: int, outputs: int, n_test: int | None,
               out: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, str]:
    """Standardised training ``X, Y``, test ``Xte, Yte`` (with the training statistics) and a description."""
    if jaco:
        from cascgp_experiments.collect import study_data

        if jaco == "quick":
            tr, te = study_data(None, out, preset="quick")
            src = f"simulated Jaco 2, quick preset collected into {out / 'data'}"
        else:
            tr, te = study_data(jaco, out)
            src = f"simulated Jaco 2 from {jaco}"
        if tr.q.shape[0] < n:
            raise SystemExit(f"--n: the Jaco training set has only {tr.q.shape[0]} rows")
        rows = np.round(np.linspace(0, tr.q.shape[0] - 1, n)).astype(int)
        Xr = np.hstack([tr.q, tr.qd, tr.qdd])[rows]
        Yr = tr.tau[rows]
        Xt, Yt = np.hstack([te.q, te.qd, te.qdd]), te.tau
        desc = (f"{src}: train {n} rows evenly spaced over {tr.q.shape[0]}, q/qd/qdd of 6 joints, 6 torques; "
                f"test all {te.q.shape[0]} rows of jaco_test")
        if n_test is not None:
            Xt, Yt = Xt[:n_test], Yt[:n_test]
    elif sarcos:
        import scipy.io

        X, Y, desc = load_data(n, sarcos, seed, outputs)
        d = scipy.io.loadmat(sarcos)
        rows = np.arange(0, d["X_train"].shape[0], 5)[:n]
        cols = np.arange(21) if outputs == 7 else np.r_[0:6, 7:13, 14:20]
        Xr = np.asarray(d["X_train"], float)[rows][:, cols]
        Yr = np.asarray(d["Y_train"], float)[rows][:, :outputs]
        Xt = np.asarray(d["X_test"], float)[:, cols]
        Yt = np.asarray(d["Y_test"], float)[:, :outputs]
        if n_test is not None:
            Xt, Yt = Xt[:n_test], Yt[:n_test]
        desc += f"; test X_test rows 0-{Xt.shape[0] - 1}"
    else:
        m = 1000 if n_test is None else n_test
        Xa, Ya, _ = load_data(n + m, None, seed, outputs)
        Xr, Yr, Xt, Yt = Xa[:n], Ya[:n], Xa[n:], Ya[n:]
        desc = f"synthetic smooth inverse-dynamics-like function, n={n}; test: the {m} rows that follow"
    mx, sx, my, sy = Xr.mean(0), Xr.std(0), Yr.mean(0), Yr.std(0)
    X, Y = (Xr - mx) / sx, (Yr - my) / sy
    if sarcos and not jaco:  # the training rows must be benchmark_data's (unchanged benchmark)
        assert np.allclose(X, load_data(n, sarcos, seed, outputs)[0], atol=1e-12)
    return X, Y, (Xt - mx) / sx, (Yt - my) / sy, desc


def provenance(argv: list[str] | None) -> dict:
    """Command, versions, git commit and load average of this run."""
    import platform

    import scipy
    import torch

    import cascgp
    from scripts.provenance import git

    vers = {"python": platform.python_version(), "numpy": np.__version__, "scipy": scipy.__version__,
            "torch": torch.__version__, "cascgp": getattr(cascgp, "__version__", "?")}
    for mod in ("GPy", "gpytorch", "linear_operator"):
        try:
            vers[mod] = __import__(mod).__version__
        except ImportError:
            vers[mod] = None

    dirty = git("status", "--porcelain", "--", ":/scripts/bench_cascgp.py", ":/scripts/bench_scaling.py",
                 ":/scripts/fit_accuracy.py", ":/scripts/gpytorch_fit.py", ":/cascgp")
    return {"command": "python -m scripts.bench_cascgp " + " ".join(sys.argv[1:] if argv is None else argv),
            "versions": vers, "git_commit": git("rev-parse", "HEAD"),
            "git_dirty_relevant_files": None if dirty is None else dirty.splitlines(),
            "load_average_start": list(os.getloadavg()), "cpu_count": os.cpu_count(),
            "started_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}


def bench_cascade(X: np.ndarray, Y: np.ndarray, n_queries: int) -> dict | None:
    """Median latency of one single-query 6-joint NP inward cascade prediction (needs cascgp.models)."""
    try:
        from cascgp import models
        from cascgp.data import DynamicsData
    except ImportError:
        return None
    import torch

    from cascgp.gp import GPFitConfig

    torch.set_num_threads(1)
    n = X.shape[0]
    q, qd, qdd = X[:, 0:6], X[:, 6:12], X[:, 12:18]
    t = np.arange(n) * 0.1
    data = DynamicsData(q=q, qd=qd, qdd=qdd, tau=Y.copy(), t=t, segment=np.zeros(n, dtype=np.int64),
                        meta={"source": "bench"})
    model = models.make_model("np-inward", 6, gp_config=GPFitConfig(n_restarts=1, max_iter=50))
    model.fit(data)
    for i in range(min(n, 20)):  # warm-up, not timed
        model.predict_one(q[i], qd[i], qdd[i])
    lat = []
    for i in range(n_queries):
        k = i % n
        t0 = time.perf_counter_ns()
        model.predict_one(q[k], qd[k], qdd[k])
        lat.append(time.perf_counter_ns() - t0)
    lat = np.array(lat) / 1e3
    return {"median_us": float(np.median(lat)), "p90_us": float(np.percentile(lat, 90)), "n_queries": len(lat)}


def main(argv: list[str] | None = None) -> int:
    from scripts.bench_scaling import scaling, scaling_one  # these import this module
    from scripts.fit_accuracy import FIT_ACCURACY_ARMS, run_fit_accuracy

    from cascgp_experiments.cli.options import check_input, check_output, check_sarcos_file

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, help="output directory (bench_cascgp.json is written there)")
    ap.add_argument("--n", type=int, default=500)
    ap.add_argument("--restarts", type=int, default=10)
    ap.add_argument("--threads", type=int, default=1,
                    help="torch / BLAS threads for both libraries (default 1: on a shared 2-core box two OpenMP "
                         "threads spin against other processes and were measured 16x slower per evaluation)")
    ap.add_argument("--sarcos", default=None, help="path of ias_sarcos_data.mat (default: synthetic data)")
    ap.add_argument("--jaco", default=None,
                    help="simulated Jaco 2 data instead: a folder with jaco_train.npz/jaco_test.npz, or 'quick' to "
                         "collect the quick preset into <out>/data")
    ap.add_argument("--n-test", type=int, default=None,
                    help="held-out rows (default: all of the test split; synthetic data: 1000)")
    ap.add_argument("--skip-gpy", action="store_true")
    ap.add_argument("--skip-gpytorch", action="store_true")
    ap.add_argument("--gpytorch", default="adam,lbfgs", help="GPyTorch optimisers to run, of adam,lbfgs")
    ap.add_argument("--adam-iters", type=int, default=150, help="Adam iterations per GPyTorch restart")
    ap.add_argument("--adam-lr", type=float, default=0.1)
    ap.add_argument("--fit-accuracy", action="store_true",
                    help="run the controlled experiment of docs/studies/fit_accuracy.md instead (needs --sarcos)")
    ap.add_argument("--fit-sets", default="D1,D2,D3",
                    help="--fit-accuracy: the protocol's data sets to run, of D1,D2,D3 (default: all; the verdict "
                         "then covers only those run)")
    ap.add_argument("--fit-arms", default=",".join(FIT_ACCURACY_ARMS),
                    help="--fit-accuracy: the arms to run (A0 and G0, the references, always run; default: all)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--queries", type=int, default=2000, help="single queries for the cascade latency")
    ap.add_argument("--configs", default=",".join(CONFIGS),
                    help=f"comma-separated cascgp settings to run, of {list(CONFIGS)} (default: all)")
    ap.add_argument("--outputs", type=int, default=6, choices=(6, 7),
                    help="SARCOS outputs: 6 (joints 1-6, 18 inputs) or 7 (all joints, 21 inputs)")
    ap.add_argument("--scaling", default=None,
                    help="comma-separated n values: instead of the GPy comparison, measure per-evaluation time and "
                         "peak memory of the default fit at each n (each in a fresh process), e.g. 500,1000,2000")
    ap.add_argument("--scaling-one", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--scaling-iter", type=int, default=3, help="L-BFGS iterations per start in --scaling runs")
    args = ap.parse_args(argv)
    if args.scaling_one is not None:
        return scaling_one(args)
    check_output(ap, args.out, "--out", "folder")
    if args.sarcos:
        check_sarcos_file(ap, args.sarcos)
    if args.jaco and args.jaco != "quick":
        check_input(ap, args.jaco, "--jaco", "folder", contains=("jaco_train.npz", "jaco_test.npz"))
    if args.scaling is not None:
        return scaling(args)
    if args.fit_accuracy:
        sets = [x for x in args.fit_sets.split(",") if x]
        if not sets or any(x not in ("D1", "D2", "D3") for x in sets):
            ap.error(f"--fit-sets: expected some of D1,D2,D3 separated by commas, got {args.fit_sets!r}")
        bad = [x for x in args.fit_arms.split(",") if x and x not in FIT_ACCURACY_ARMS]
        if bad:
            ap.error(f"--fit-arms: unknown arm(s) {bad}; expected some of {','.join(FIT_ACCURACY_ARMS)}")
        if not args.sarcos and any(x != "D3" for x in sets):
            ap.error("--fit-accuracy needs --sarcos for D1 and D2")
        return run_fit_accuracy(args, provenance(argv))
    names = [c for c in args.configs.split(",") if c]
    unknown = [c for c in names if c not in CONFIGS]
    if unknown or not names:
        ap.error(f"--configs: unknown setting(s) {unknown}; expected some of {list(CONFIGS)}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    prov = provenance(argv)
    X, Y, Xte, Yte, desc = load_split(args.n, args.sarcos, args.jaco, args.seed, args.outputs, args.n_test, out)
    B = Y.shape[1]
    print(f"data: {desc}; X {X.shape}, Y {Y.shape}, test {Xte.shape[0]} rows; {os.cpu_count()} CPUs, "
          f"threads={args.threads}, load average {prov['load_average_start'][0]:.2f}", flush=True)
    res: dict = {"provenance": prov, "data": desc, "n": args.n, "n_test": int(Xte.shape[0]), "d": X.shape[1],
                 "outputs": B, "restarts": args.restarts,
                 "configs": {name: CONFIGS[name] for name in names}, "cascgp": {}, "gpytorch": {},
                 "nll_objective": "zero mean on the standardised training targets (cascgp's and GPy's), closed "
                                  "form from each library's fitted hyperparameters; nll_const_mean: the constant "
                                  "mean profiled out (GPyTorch's objective)"}
    rows: dict[str, dict] = {}
    for name in names:
        res["cascgp"][name] = c = bench_cascgp(X, Y, args.restarts, args.threads, CONFIGS[name])
        bank = c.pop("bank")
        pred = bank.predict([Xte] * B, return_var=False)[0]
        c.update(score(X, Y, c["hyper"], pred, Yte))
        rows[f"cascgp {name}"] = c
        print(f"cascgp fit ({name}): {c['time_s']:.2f} s, {c['total_evals']} NLL+grad evaluations "
              f"({c['evals_per_start']:.1f} per start, {c['ms_per_eval']:.2f} ms each) in {c['batch_rounds']} "
              "batched rounds; per evaluation: " + ", ".join(
                  f"{k} {v:.0f} us" for k, v in c["breakdown_us_per_eval"].items()), flush=True)
    if not args.skip_gpy:
        try:
            g = bench_gpy(X, Y, args.restarts, args.threads, Xte)
        except ImportError:
            print("GPy is not installed (pip install -e '.[bench]'); skipping it", file=sys.stderr)
        else:
            g.update(score(X, Y, g["hyper"], g.pop("pred"), Yte))
            res["gpy"] = rows["GPy"] = g
            print(f"GPy fit: {g['time_s']:.2f} s", flush=True)
    if not args.skip_gpytorch:
        for opt in [o for o in args.gpytorch.split(",") if o]:
            try:
                t = bench_gpytorch(X, Y, args.restarts, args.threads, opt, Xte, args.adam_iters, args.adam_lr)
            except ImportError:
                print("GPyTorch is not installed (pip install -e '.[bench]'); skipping it", file=sys.stderr)
                break
            t.update(score(X, Y, t["hyper"], t.pop("pred"), Yte))
            res["gpytorch"][opt] = rows[f"GPyTorch {opt}"] = t
            print(f"GPyTorch fit ({opt}): {t['time_s']:.2f} s", flush=True)
    if args.queries > 0:
        X6, Y6 = (X, Y) if X.shape[1] == 18 else load_data(args.n, args.sarcos, args.seed, 6)[:2]
        res["cascade"] = bench_cascade(X6, Y6, args.queries)
    else:
        res["cascade"] = None
    res["provenance"]["load_average_end"] = list(os.getloadavg())
    res["table"] = print_table(rows, B)
    g = res.get("gpy")
    tg = {k: v["time_s"] for k, v in res["gpytorch"].items()}
    res["summary"] = {}
    for name in names:
        c = res["cascgp"][name]
        summ: dict = {"time_s": c["time_s"], "test_nrmse_median": c["test_nrmse_median"]}
        line = f"fit time ({name}): cascgp {c['time_s']:.2f} s"
        if g:
            summ["speedup_vs_gpy"] = g["time_s"] / c["time_s"]
            summ["max_nll_gap_vs_gpy"] = float(max(a - b for a, b in zip(c["nll_zero_mean"], g["nll_zero_mean"])))
            line += (f", {summ['speedup_vs_gpy']:.1f}x GPy's speed; worst NLL gap (cascgp - GPy) "
                     f"{summ['max_nll_gap_vs_gpy']:+.3f} nats")
        for k, v in tg.items():
            summ[f"speedup_vs_gpytorch_{k}"] = v / c["time_s"]
            line += f", {v / c['time_s']:.1f}x GPyTorch {k}'s"
        others = [r["test_nrmse_median"] for lab, r in rows.items() if not lab.startswith("cascgp")]
        if others:
            best_other = min(others)
            summ["best_other_test_nrmse_median"] = best_other
            summ["test_error_at_least_as_good"] = bool(c["test_nrmse_median"] <= best_other)
            line += (f"; median test nRMSE {c['test_nrmse_median']:.4f} vs the best other library's "
                     f"{best_other:.4f}")
        if g and tg:
            summ["meets_target"] = bool(summ["speedup_vs_gpy"] >= 30 and summ.get("test_error_at_least_as_good")
                                        and all(v > c["time_s"] for v in tg.values()))
        res["summary"][name] = summ
        print(line)
    if res["cascade"] is None:
        print("cascade latency: skipped (--queries 0) or cascgp.models not available")
    else:
        print(f"single-query 6-joint NP inward cascade: median {res['cascade']['median_us']:.1f} us, "
              f"p90 {res['cascade']['p90_us']:.1f} us")
    write_json(out / "bench_cascgp.json", res)
    print(f"wrote {out / 'bench_cascgp.json'}")
    return 0


def print_table(rows: dict[str, dict], B: int) -> list[str]:
    """Print (and return) the table: per library/setting fit time, time relative to GPy, NLL gap to GPy per
    output (zero-mean objective), test nRMSE per output and its median."""
    ref = rows.get("GPy")
    hdr = (f"{'library / setting':<20} | {'fit s':>8} | {'GPy s /':>7} | "
           + " ".join(f"{'gap' + str(j + 1):>7}" for j in range(B)) + " | "
           + " ".join(f"{'nRMSE' + str(j + 1):>7}" for j in range(B)) + f" | {'median':>7}")
    lines = [hdr, "-" * len(hdr)]
    for lab, r in rows.items():
        ratio = f"{ref['time_s'] / r['time_s']:>7.1f}" if ref else f"{'-':>7}"
        gaps = " ".join(f"{a - b:>+7.2f}" if ref else f"{'-':>7}"
                        for a, b in zip(r["nll_zero_mean"], ref["nll_zero_mean"] if ref else r["nll_zero_mean"]))
        errs = " ".join(f"{v:>7.4f}" for v in r["test_nrmse"])
        lines.append(f"{lab:<20} | {r['time_s']:>8.2f} | {ratio} | {gaps} | {errs} | {r['test_nrmse_median']:>7.4f}")
    lines.append("gap: NLL (nats) of the row's hyperparameters minus GPy's, both on the zero-mean objective of the "
                 "standardised training targets (cascgp's and GPy's; GPyTorch optimised a constant-mean one). "
                 "nRMSE: held-out RMSE / range per output.")
    print("\n".join(lines), flush=True)
    return lines


if __name__ == "__main__":
    raise SystemExit(main())
