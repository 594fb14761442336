"""Cost of the uncertainty-aware feedforward per control tick and of an online sample.

    python -m scripts.bench_online --out out/bench [--data out/study/data] [--n 500] [--window 150]

Fits the 6-joint SP inward cascade (default GP fit) on ``n`` rows of simulated Jaco 2 data (the study's
``jaco_train.npz`` at 10 Hz; without ``--data`` a collection preset is recorded: the quick one (36 s of training
motion, 360 rows) when it has ``n`` rows, else the full one (600 s, 6,000 rows)), then times on queries from the
held-out motions: ``predict_one`` (the paper's feedforward), ``predict_one_var`` (mean and propagated variance, what
the gated controller calls), ``add_sample`` (one online sample into every joint), and both single-query paths again
with a full online window; the six triangular solves of the variance alone and one read of the same factors'
triangles packed into one array (the memory floor of an exact variance at this n); one online sample's BLAS calls
alone, with SciPy's wrappers' overhead and (with the compiled sample) from one compiled call without it (the
floor of its memory traffic); and whole controller ticks
(:class:`cascgp.FeedforwardController`, PD plus feedforward): ungated, with the innovation gate (``gate=True``; RBD plus
``predict_one`` per tick) and its update per measured sample (``observe``: one more ``predict_one`` and RBD call),
and with each variance gate (RBD plus ``predict_one_var``); the innovation- and variance-gated ticks again one every
25 ms (``--paced-reps`` of them; the 40 Hz control period of a robot), the process idle in between (asleep: the core
may idle and the caches fill with other work) and busy-waiting (as a real-time loop on a dedicated core), and, as a
reference, a NumPy dot product of 0.3 MB back to back and paced the same way. Medians, 90th and 99th percentiles
over ``--reps`` calls, one thread; ``compiled`` says whether the compiled single-query loop ran
(:mod:`cascgp.models.fastkernel`: Numba installed, ``CASCGP_JIT`` not 0 or off). When it ran, the compiled online sample
and variance loop are also timed against their reference paths (NumPy sample, per-joint BLAS solves) on the same
model in alternating rounds. Prints tables and writes ``bench_online.json``.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path
from typing import Any, Callable

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402

from cascgp_experiments.cli.options import check_input, check_output  # noqa: E402
from scripts.provenance import git_commit  # noqa: E402


#: Training rows at 10 Hz of the quick collection preset (3 motions of 12 s).
QUICK_ROWS = 360


def _times(fn, args_list, reps: int, gap_s: float = 0.0, spin: bool = False) -> dict[str, float]:
    """Median, 90th and 99th percentile (us) of ``reps`` calls, ``gap_s`` before each (0: back to back) spent asleep
    or, with ``spin``, busy-waiting."""
    out = []
    for k in range(reps):
        a = args_list[k % len(args_list)]
        if gap_s and spin:
            end = time.perf_counter() + gap_s
            while time.perf_counter() < end:
                pass
        elif gap_s:
            time.sleep(gap_s)
        t0 = time.perf_counter()
        fn(*a)
        out.append(time.perf_counter() - t0)
    us = 1e6 * np.asarray(out)
    return {"median_us": float(np.median(us)), "p90_us": float(np.percentile(us, 90)),
            "p99_us": float(np.percentile(us, 99))}


def _sample_blas_calls(model: Any) -> Callable[[], None]:
    """One online sample's BLAS calls for every joint of the open (full) window, nothing else: the two triangular
    solves with the fitted factor, the two products with B, the two symmetric products and the two rank-one
    updates with the window's inverse (on a copy), through SciPy's wrappers (their call overhead included)."""
    from scipy.linalg.blas import dgemv, dsymv, dsyr, dtrsv

    rng = np.random.default_rng(0)
    joints = model._online.joints
    k0 = [np.abs(rng.standard_normal(J.U00.shape[0])) for J in joints]
    v = [rng.standard_normal(J.window) for J in joints]
    Sc = [J.Sinv.copy(order="F") for J in joints]

    def calls() -> None:
        for J, k, x, S in zip(joints, k0, v, Sc):
            row = dtrsv(J.U00, k, lower=0, trans=1)
            dtrsv(J.U00, row, lower=0)
            dgemv(1.0, J.B.T, k, trans=1)  # B @ k0 (B.T: the Fortran-ordered view BLAS reads without a copy)
            dgemv(1.0, J.B.T, x)  # x @ B
            dsymv(1.0, S, x, lower=1)
            dsymv(1.0, S, x, lower=1)
            dsyr(1e-12, x, lower=1, a=S, overwrite_a=1)
            dsyr(-1e-12, x, lower=1, a=S, overwrite_a=1)

    return calls


def _sample_blas_calls_compiled(model: Any) -> Callable[[], None] | None:
    """The same BLAS calls as :func:`_sample_blas_calls` made from one compiled call, as the compiled online sample
    makes them (:mod:`cascgp.models.online_kernel`'s helpers, on the window's own factor, ``B`` and a copy of its
    inverse): no wrapper overhead, so what is left is their memory traffic. None without the compiled sample."""
    win = model._online
    if win._jit is None:
        return None
    import numba

    from cascgp.models import online_kernel as ok

    @numba.njit(nogil=True)
    def calls(trsv: Any, gemv: Any, symv: Any, syr: Any, Lf: tuple, B: tuple, ST: tuple, k0: np.ndarray,
              work: np.ndarray, xw: np.ndarray, yw: np.ndarray, y0: np.ndarray, fi: np.ndarray, fd: np.ndarray,
              ch: np.ndarray) -> None:  # pragma: no cover - runs compiled
        for j in range(len(Lf)):
            n0, W = Lf[j].shape[0], B[j].shape[0]
            work[j, :] = k0[j]
            ok._trsv(trsv, 84, Lf[j], work[j], fi, ch)  # L00^-1 k0
            ok._trsv(trsv, 78, Lf[j], work[j], fi, ch)  # L00^-T (...)
            ok._gemv(gemv, 84, n0, W, B[j], k0[j], yw[j], fi, fd, ch)  # B @ k0
            ok._gemv(gemv, 78, n0, W, B[j], xw[j], y0[j], fi, fd, ch)  # x @ B
            ok._without(symv, 0, ST[j], xw[j], xw[j], False, yw[j], fi, fd, ch)
            ok._without(symv, 0, ST[j], xw[j], xw[j], False, yw[j], fi, fd, ch)
            ok._syr(syr, 1e-12, xw[j], ST[j], fi, fd, ch)
            ok._syr(syr, -1e-12, xw[j], ST[j], fi, fd, ch)

    f, a = ok.blas(), win._arrays()
    Lf, B = a["fitted"][2], a["B"]
    ST = tuple(x.copy() for x in a["ST"])
    N, n0, W = len(Lf), Lf[0].shape[0], B[0].shape[0]
    rng = np.random.default_rng(0)
    k0, xw = np.abs(rng.standard_normal((N, n0))), rng.standard_normal((N, W))
    args = (f["dtrsv"], f["dgemv"], f["dsymv"], f["dsyr"], Lf, B, ST, k0, np.zeros((N, n0)), xw, np.zeros((N, W)),
            np.zeros((N, n0)), np.zeros(4, dtype=np.int32), np.zeros(2), np.zeros(3, dtype=np.uint8))
    calls(*args)  # compile now
    return lambda: calls(*args)


#: Alternating rounds of :func:`_paths_side_by_side`.
PATH_ROUNDS = 10


def _paths_side_by_side(model: Any, q: list, samples: list) -> dict[str, dict[str, float]]:
    """The compiled online sample against the NumPy one, and the compiled variance loop (with the window's term,
    then without a window) against the per-joint BLAS path, on the same model in alternating rounds (the reference
    path is switched on by clearing the compiled path's handle, as a failed compile does; the window's full and in
    use)."""
    win, fv, fvo = model._online, model._fast_var_offline, model.prepare_variance()
    work, Lc = win._jit, fv.Lc
    pairs = {"add_sample (full window)": (model.add_sample, samples, 60,
                                          lambda on: setattr(win, "_jit", work if on else None)),
             "predict_one_var (online, full window)": (model.predict_one_var, q, 300,
                                                       lambda on: object.__setattr__(fvo, "Lc", Lc if on else None)),
             "predict_one_var (offline)": (model.predict_one_var, q, 300,
                                           lambda on: object.__setattr__(fv, "Lc", Lc if on else None))}
    out = {}
    for label, (fn, args, reps, use) in pairs.items():
        if (work if label.startswith("add") else Lc) is None:
            continue
        if label.endswith("(offline)"):
            model.stop_online()  # the offline variance path
        t = {True: [], False: []}
        for k in range(PATH_ROUNDS):
            for on in (True, False):
                use(on)
                t[on].append(_times(fn, args[k * reps % len(args):] + args, reps)["median_us"])
        use(True)
        ratio = float(np.median(np.array(t[True]) / np.array(t[False])))
        out[label] = {"compiled_us": float(np.median(t[True])), "reference_us": float(np.median(t[False])),
                      "ratio": ratio}
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--data", default=None, help="folder with jaco_train.npz and jaco_test.npz")
    ap.add_argument("--n", type=int, default=500, help="training rows (10 Hz)")
    ap.add_argument("--window", type=int, default=150, help="online window per joint")
    ap.add_argument("--reps", type=int, default=2000)
    ap.add_argument("--paced-reps", type=int, default=200,
                    help="ticks of the innovation- and variance-gated controllers timed again one every 25 ms (the "
                         "40 Hz control period), asleep and busy-waiting between them (0: skip)")
    a = ap.parse_args(argv)
    check_output(ap, a.out, "--out", "folder")
    check_input(ap, a.data, "--data", "folder", contains=("jaco_train.npz", "jaco_test.npz"))
    import torch

    torch.set_num_threads(1)
    from cascgp.io import write_json
    from cascgp.models import make_model
    from cascgp.rbd import load_nominal
    from cascgp_experiments.collect import nominal_urdf_for, study_data

    out = Path(a.out)
    train, test = study_data(a.data, out, preset="quick" if a.n <= QUICK_ROWS else "full")
    data = train.subsample(10.0)
    data = data.take(np.arange(min(a.n, data.n_samples)))
    rbd = load_nominal(nominal_urdf_for(train.meta))
    t0 = time.perf_counter()
    model = make_model("sp-inward", 6, rbd).fit(data)
    fit_s = time.perf_counter() - t0
    q = [(test.q[i], test.qd[i], test.qdd[i]) for i in range(0, test.n_samples, 7)]
    rows = {"predict_one (offline)": _times(model.predict_one, q, a.reps),
            "predict_one_var (offline)": _times(model.predict_one_var, q, a.reps)}
    # The variance's core and its memory floor: one triangular solve per joint (reads the lower half of each
    # (n, n) factor), and one pass over the same triangles packed into one array (the least memory traffic of any
    # exact O(n^2) read of them), both in the same run.
    from scipy.linalg.blas import dtrsv

    fv = model.prepare_variance()
    rhs = [np.random.default_rng(j).standard_normal(L.shape[0]) for j, L in enumerate(fv.L)]
    rows["six triangular solves alone (variance core)"] = _times(
        lambda: [dtrsv(L, b, lower=0, trans=1) for L, b in zip(fv.L, rhs)], [()], a.reps)
    packed = np.concatenate([L[np.triu_indices(L.shape[0])] for L in fv.L])
    rows[f"one read of the six factors' triangles ({packed.nbytes / 1e6:.1f} MB, memory floor)"] = _times(
        np.add.reduce, [(packed,)], a.reps)
    del packed
    import jaco_env
    from cascgp.controller import FeedforwardController

    ticks = [(0.0, x[0], x[1], lambda t, x=x: x) for x in q]
    gates = (("controller tick, ungated", False), ("controller tick, innovation gate", "innovation"),
             ("controller tick, wiener gate", "wiener"), ("controller tick, floor gate", "floor"),
             ("controller tick, variance gate", "variance"))
    for label, gate in gates:
        ctrl = FeedforwardController(model, jaco_env.DEFAULT_KP, jaco_env.DEFAULT_KD, jaco_env.robot.TORQUE_LIMITS,
                                     fallback=rbd, gate=gate, online_every=1)
        ctrl.start(None, {})
        rows[label + " (offline)"] = _times(ctrl, ticks, a.reps)
        if gate in ("innovation", "variance") and a.paced_reps:  # as on a robot: 25 ms between ticks
            rows[f"{label} (offline), one every 25 ms, idle between"] = _times(ctrl, ticks, a.paced_reps, 0.025)
            rows[f"{label} (offline), one every 25 ms, busy-waiting between"] = _times(
                ctrl, ticks, a.paced_reps, 0.025, spin=True)
        if gate == "innovation":
            innovation = ctrl
    if a.paced_reps:  # the same pacing on a call that is not ours: what the machine does to a cold working set
        x, y = np.random.default_rng(0).random((2, 20_000))
        label = "reference: one dot product of two 20,000-element vectors (0.3 MB)"
        rows[label] = _times(np.dot, [(x, y)], a.reps)
        rows[label + ", one every 25 ms, busy-waiting between"] = _times(np.dot, [(x, y)], a.paced_reps, 0.025,
                                                                        spin=True)
    measured = [(test.q[i], test.qd[i], test.tau[i], 0.025 * k) for k, i in enumerate(range(0, test.n_samples, 3))]
    rows["innovation update per sample (observe)"] = _times(innovation.observe, measured, a.reps)
    model.start_online(a.window)
    samples = [(test.q[i], test.qd[i], test.qdd[i], test.tau[i]) for i in range(0, test.n_samples, 10)]
    rows["add_sample (window filling and full)"] = _times(model.add_sample, samples, max(3 * a.window, 300))
    rows["add_sample's BLAS calls alone (full window, through SciPy's wrappers)"] = _times(
        _sample_blas_calls(model), [()], a.reps)
    compiled_calls = _sample_blas_calls_compiled(model)
    if compiled_calls is not None:
        rows["add_sample's BLAS calls alone (full window, from one compiled call)"] = _times(compiled_calls, [()],
                                                                                            a.reps)
    rows["predict_one (online, full window)"] = _times(model.predict_one, q, a.reps)
    rows["predict_one_var (online, full window)"] = _times(model.predict_one_var, q, a.reps)
    from cascgp.models.fastkernel import jit_enabled

    paths = _paths_side_by_side(model, q, samples) if jit_enabled() else {}

    res = {"n_train": model.n_train, "window": a.window, "fit_s": fit_s, "reps": a.reps, "rows": rows,
           "compiled": jit_enabled(), "compiled_vs_reference_side_by_side": paths,
           "control_period_us": 25_000.0, "command": "python -m scripts.bench_online " + " ".join(argv or []),
           "git_commit": git_commit(),
           "load_average_end": list(os.getloadavg()), "cpu_count": os.cpu_count()}
    write_json(out / "bench_online.json", res)
    print(f"SP inward, 6 joints, n = {model.n_train}, online window {a.window}, one thread, "
          f"compiled single-query loop: {'yes' if res['compiled'] else 'no'}")
    print("| call | median (us) | p90 (us) | p99 (us) |\n|---|---|---|---|")
    for k, v in rows.items():
        print(f"| {k} | {v['median_us']:.0f} | {v['p90_us']:.0f} | {v['p99_us']:.0f} |")
    if paths:
        print(f"\nThe compiled loops against their reference paths, side by side ({PATH_ROUNDS} alternating rounds, "
              "medians of the rounds' medians):")
        print("| call | compiled (us) | reference (us) | compiled / reference (median of the rounds' ratios) |")
        print("|---|---|---|---|")
        for k, v in paths.items():
            print(f"| {k} | {v['compiled_us']:.0f} | {v['reference_us']:.0f} | {v['ratio']:.2f} |")
    print(f"wrote {out / 'bench_online.json'}")


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
