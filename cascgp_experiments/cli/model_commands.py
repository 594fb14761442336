"""``cascgp fit``, ``cascgp evaluate`` and ``cascgp predict``: the models of :mod:`cascgp.models` on logged data.

Usage::

    cascgp fit --data train.csv --urdf robot.urdf --model sp-inward --out model.npz
    cascgp evaluate --model model.npz --data test.csv --json scores.json
    cascgp predict --model model.npz --data states.csv --out predictions.csv

Logs are CSV files in the format of :mod:`cascgp.logs` (``t``, ``q1..qN``, ``tau1..tauN``; ``qd``/``qdd``
optional and computed when absent; ``tau`` optional for ``predict``) or ``.npz`` files of
:meth:`cascgp.data.DynamicsData.save`. Semi-parametric models (``sp-*``) need the robot's URDF
(:func:`cascgp.rbd.load_nominal`; its sidecar JSON is optional) and embed it in the model file, so ``evaluate``
and ``predict`` need no URDF. Non-parametric models (``np-*``) use none, and ``fit`` refuses ``--urdf`` for
them rather than ignore it.

A bad file or argument ends the command with exit status 2 and one line ``cascgp <command>: error: ...`` on
stderr (no traceback). Progress and notes go to stderr, results to stdout. This module only imports
:mod:`cascgp`.
"""

from __future__ import annotations

import argparse
import hashlib
import re
import sys
import textwrap
import threading
import time
import warnings
from contextlib import contextmanager
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from cascgp_experiments.cli import log_notes
from cascgp_experiments.cli.options import check_output, require_at_least, settings_error

_NRMSE_HELP = ("nRMSE of joint i = RMSE_i / (max_i - min_i): the root-mean-square error of the predicted torques "
               "divided by the range of the measured test torques of that joint (0 = perfect; predicting the "
               "test mean scores about std/range, typically 0.2-0.3)")


class _Fail(Exception):
    """An error reported as ``<prog>: error: <message>`` with exit status 2."""


def _run(prog: str, body: Callable[[], int | None]) -> int:
    """Run ``body``; expected failures (bad files, bad values) become one line on stderr and status 2."""
    try:
        with warnings.catch_warnings():  # warnings (e.g. "no sidecar JSON") as one note line each, when raised
            warnings.simplefilter("default")
            warnings.showwarning = lambda message, *args, **kwargs: log_notes.note(prog, f"note: {message}")
            status = body()
    except (_Fail, ValueError, OSError) as exc:
        msg = " ".join(str(exc).split())  # one line
        print(f"{prog}: error: {msg}", file=sys.stderr)
        return 2
    return int(status or 0)


def _parser(prog: str, description: str) -> argparse.ArgumentParser:
    # the raw formatter keeps the examples' lines; the description is wrapped here (it would print as one line)
    return argparse.ArgumentParser(prog=prog, description=textwrap.fill(description, 79),
                                   epilog="examples:\n" + __doc__.split("\n\n")[2],
                                   formatter_class=argparse.RawDescriptionHelpFormatter)


def _read(path: Path, require_tau: bool = True) -> Any:
    from cascgp.logs import read_log

    return read_log(path, require_tau=require_tau)


def _describe(prog: str, data: Any, path: Path) -> None:
    m = data.meta
    steps = log_notes.periods(data)
    period = f", median sample period {np.median(steps):.4g} s" if steps.size else ""
    log_notes.note(prog, f"read {data.n_samples} rows, {data.dof} joint(s), {len(data.segments)} segment(s)"
                         f"{period} from {path}")
    computed = [g for g in ("qd", "qdd") if m.get(f"{g}_source") == "computed"]
    if computed:
        how = "when the log was read" if path.suffix.lower() == ".npz" else "(no such columns)"
        log_notes.note(prog, f"computed {' and '.join(computed)} {how} with {m.get('derivative_filter')}")


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _load(path: Path) -> Any:
    from cascgp.models import load_model

    return load_model(path)


def _check_dof(model: Any, data: Any, path: Path) -> None:
    if data.dof != model.dof:
        raise _Fail(f"{path}: the log has {data.dof} joint(s), the model {model.name!r} has {model.dof}")


# --------------------------------------------------------------------------- fit
def fit_main(argv: list[str] | None = None, prog: str | None = None) -> int:
    """``cascgp fit``: fit a model to a log and save it; returns the exit status."""
    from cascgp.gp import GPFitConfig  # cascgp.models imports it anyway
    from cascgp.models import MODEL_NAMES

    prog = prog or "cascgp fit"
    p = _parser(prog, "Fit one of the twelve cascaded-GP models to logged data and save it (.npz).")
    p.add_argument("--data", type=Path, required=True, help="training log (.csv in the cascgp.logs format, or .npz)")
    p.add_argument("--model", required=True, choices=MODEL_NAMES, metavar="NAME",
                   help="model name: " + ", ".join(MODEL_NAMES))
    p.add_argument("--urdf", type=Path, default=None,
                   help="the robot's URDF (sp-* models only; a sidecar JSON next to it is optional)")
    p.add_argument("--joints", default=None, metavar="NAME,...",
                   help="the URDF joints that are the log's q1..qN, in the order Pinocchio lists the URDF's "
                        "joints (depth first from the base, branches by joint name; an error prints it). Default: "
                        "every joint not in --lock. The others (a gripper's fingers, say) are locked, except a URDF "
                        "mimic joint of one of them, which moves with it. A continuous joint's q is its "
                        "angle (rad, any range)")
    p.add_argument("--lock", default=None, metavar="NAME=Q,...",
                   help="positions (rad or m; 0 is the URDF's zero) at which the joints not in --joints are locked "
                        "(default 0 each)")
    p.add_argument("--out", type=Path, required=True, help="model file to write (.npz; replaced atomically)")
    p.add_argument("--restarts", type=int, default=None,
                   help=f"optimiser starts per joint's GP (default: {GPFitConfig().n_restarts}, the library's "
                        "GPFitConfig.n_restarts)")
    p.add_argument("--max-samples", type=int, default=1000,
                   help="keep at most this many training rows, evenly spaced over the log (default 1000; exact "
                        "GPs cost O(n^3)); -df models take their position history from the whole log")
    p.add_argument("--rate-hz", type=float, default=None,
                   help="first subsample each segment to about this rate (Hz), after derivatives are computed")
    p.add_argument("--kernel", default=None,
                   help="covariance function of every GP: matern52 (the paper's; default), matern32 or rbf")
    p.add_argument("--threads", type=int, default=None,
                   help="torch/BLAS threads during the fit (default: the library's, one thread)")
    p.add_argument("--max-memory", type=float, default=None, metavar="GIB",
                   help="memory a fit may use (GiB; default: the library's, 2): a fit whose estimate is over it, or "
                        "over the machine's memory, is refused before it starts, saying how many rows fit")
    p.add_argument("--seed", type=int, default=0, help="seed of the optimiser's random starts (default 0)")
    a = p.parse_args(argv)
    require_at_least(p, a, 1, "restarts", "threads")
    require_at_least(p, a, 2, "max_samples")  # a GP needs two rows
    require_at_least(p, a, 0, "seed")
    try:
        _fit_config(a).for_fit()
    except ValueError as exc:  # --threads beyond a fit's bound, say
        settings_error(p, exc, {"threads": "--threads", "n_restarts": "--restarts", "seed": "--seed",
                                "kernel": "--kernel", "max_batch_bytes": "--max-memory"})
    if a.rate_hz is not None and not (np.isfinite(a.rate_hz) and a.rate_hz > 0):
        p.error(f"--rate-hz: expected a positive rate, got {a.rate_hz}")
    if a.model.startswith("sp-") and a.urdf is None:
        p.error(f"--urdf: the semi-parametric model {a.model!r} needs the robot's URDF (its rigid-body mean)")
    if a.model.startswith("np-") and a.urdf is not None:
        p.error(f"--urdf: the non-parametric model {a.model!r} uses no rigid-body model; drop --urdf or choose "
                f"{'sp' + a.model[2:]!r}")
    for opt in ("joints", "lock"):
        if getattr(a, opt) is not None and a.urdf is None:
            p.error(f"--{opt}: chooses joints of the URDF; it needs --urdf (an sp-* model)")
    a.joints = _parse_joints(p, a.joints)
    a.lock = _parse_lock(p, a.lock)
    check_output(p, a.out, "--out", "file", {"--data": a.data, "--urdf": a.urdf})  # before the fit (minutes)
    if a.out.suffix.lower() != ".npz":
        p.error(f"--out: expected a model file name ending in .npz, got {str(a.out)!r}")
    return _run(prog, lambda: _fit(a, prog, argv))


def _parse_joints(p: argparse.ArgumentParser, text: str | None) -> list[str] | None:
    """``--joints``: comma-separated joint names."""
    if text is None:
        return None
    names = [n.strip() for n in text.split(",")]
    if not all(names):
        p.error(f"--joints: expected joint names separated by commas, got {text!r}")
    return names


def _parse_lock(p: argparse.ArgumentParser, text: str | None) -> dict[str, float] | None:
    """``--lock``: ``NAME=Q`` pairs separated by commas."""
    if text is None:
        return None
    out: dict[str, float] = {}
    for item in text.split(","):
        name, eq, value = item.partition("=")
        try:
            q = float(value)
        except ValueError:
            q = float("nan")
        if not eq or not name.strip() or not np.isfinite(q):
            p.error(f"--lock: expected NAME=Q pairs (Q a finite position in rad or m) separated by commas, "
                    f"got {item!r}")
        if name.strip() in out:
            p.error(f"--lock: {name.strip()!r} is given twice")
        out[name.strip()] = q
    return out


def _as_options(msg: str) -> str:
    """A library error about its arguments ``joints=`` / ``locked=`` in the command's terms (``--joints``,
    ``--lock``)."""
    for arg, opt in (("joints", "--joints"), ("locked", "--lock")):
        if msg.startswith(f"{arg}: "):
            msg = opt + msg[len(arg):]
        msg = msg.replace(f"{arg}=", opt)
    return msg


def _command(prog: str, argv: list[str] | None) -> list[str]:
    """The command line that ran (for a file's provenance)."""
    return ["cascgp", *prog.split()[1:], *(sys.argv[2:] if argv is None else argv)]


def _log_record(path: Path, data: Any) -> dict[str, Any]:
    """A log's file, SHA-256, rows and derivative sources (for a file's provenance)."""
    return {"file": str(path), "sha256": _sha256(path), "n_rows": data.n_samples,
            **{k: data.meta.get(k) for k in ("qd_source", "qdd_source", "derivative_filter")}}


def _in_log_terms(msg: str, path: Path) -> str:
    """A library message about ``data.<field>`` (a 0-based column index) in a log's terms: the file, and the column
    by its name (``data.tau: ... (column 0): ...`` -> ``train.csv: column 'tau1': ...: ...``)."""
    m = re.match(r"data\.(q|qd|qdd|tau): (.*?) \(column (\d+)\)(.*)", msg, re.S)
    if m:
        return f"{path}: column '{m[1]}{int(m[3]) + 1}': {m[2]}{m[4]}"
    return f"{path}: {msg}" if msg.startswith("data") else msg


def _training_rows(prog: str, a: argparse.Namespace, model: Any, data: Any) -> tuple[Any, Any, bool]:
    """The rows to fit (``--rate-hz``, then ``--max-samples``), their ``-df`` history taken from the full log
    (``None`` for other models), and whether ``--max-samples`` thinned them; a note for each step."""
    from cascgp.features import history_from_data

    rows, q_hist = np.arange(data.n_samples), None
    if model.feature_kind == "df":  # before rows are chosen: chosen rows lie further apart than df_delta
        q_hist, valid = history_from_data(data, model.df_delta)
        if valid.sum() < 2:
            raise _Fail(f"{a.data}: fewer than 2 rows have the {2 * model.df_delta:g} s of history within their "
                        "segment that -df models need")
        if not valid.all():
            log_notes.note(prog, f"note: {int((~valid).sum())} row(s) lack {2 * model.df_delta:g} s of history "
                                 "within their segment and are left out (-df models)")
            rows = np.flatnonzero(valid)
            data = data.take(rows)
    if a.rate_hz is not None:
        n0 = data.n_samples
        keep = data.subsample_rows(a.rate_hz)
        if keep.size < 2:
            raise _Fail(f"--rate-hz {a.rate_hz:g} keeps {keep.size} of {n0} rows (the log's rate: "
                        f"{log_notes.log_rate(data)}); a fit needs at least 2: choose a higher rate")
        if keep.size < n0:
            data, rows = data.take(keep), rows[keep]  # the rows of data.subsample (its loop once)
            log_notes.note(prog, f"subsampled to {a.rate_hz:g} Hz: {data.n_samples} of {n0} rows")
        else:
            log_notes.note(prog, f"note: --rate-hz {a.rate_hz:g} keeps every row (the log's rate: "
                                 f"{log_notes.log_rate(data)}): all {n0} rows kept")
    thinned = data.n_samples > a.max_samples
    if thinned:
        n0 = data.n_samples
        keep = data.thin_rows(a.max_samples)
        data, rows = data.take(keep), rows[keep]
        log_notes.note(prog, f"thinned evenly to {data.n_samples} of {n0} rows (--max-samples)")
    return data, None if q_hist is None else q_hist[rows], thinned


def _fit_config(a: argparse.Namespace) -> Any:
    """The fit's ``GPFitConfig`` from ``--seed``, ``--restarts``, ``--kernel``, ``--threads`` and ``--max-memory``
    (``ValueError`` naming a field)."""
    from cascgp.gp import GPFitConfig

    kw: dict[str, Any] = {"seed": a.seed}
    for option, field in (("restarts", "n_restarts"), ("kernel", "kernel"), ("threads", "threads")):
        if getattr(a, option) is not None:
            kw[field] = getattr(a, option)
    if a.max_memory is not None:
        if not (np.isfinite(a.max_memory) and a.max_memory > 0):
            raise ValueError(f"max_batch_bytes: expected a positive number of GiB, got {a.max_memory}")
        kw["max_batch_bytes"] = max(1, int(min(a.max_memory, 2.0**32) * 2**30))  # 4 EiB: beyond any machine
    return GPFitConfig(**kw)


def _fit(a: argparse.Namespace, prog: str, argv: list[str] | None) -> int:
    from cascgp.gp import FitMemoryError
    from cascgp.models import make_model
    from cascgp.rbd import load_nominal

    data = _read(a.data)
    _describe(prog, data, a.data)
    provenance: dict[str, Any] = {"command": _command(prog, argv), "data": _log_record(a.data, data), "urdf": None}
    rbd = None
    if a.urdf is not None:
        try:
            with warnings.catch_warnings(record=True) as said:  # each a note, in the command's terms
                warnings.simplefilter("always")
                rbd = load_nominal(a.urdf, joints=a.joints, locked=a.lock)
        except ValueError as exc:
            raise _Fail(_as_options(str(exc))) from None
        for w in said:
            log_notes.note(prog, f"note: {_as_options(str(w.message))}")
        provenance["urdf"] = {"file": str(a.urdf), "sha256": _sha256(a.urdf)}
        if rbd.dof != data.dof:
            more = ("; name the log's joints with --joints, or lock the others with --lock NAME=Q,..."
                    if rbd.dof > data.dof else "")
            what = "the rigid-body model" if rbd.locked or rbd.coupled else "the URDF"
            raise _Fail(f"{a.urdf}: {what} has {rbd.dof} joints ({', '.join(rbd.joint_names)}), the log "
                        f"{a.data} has {data.dof}{more}")
        locked = "".join(f"; {n} locked at {q:g}" for n, q in rbd.locked.items())
        locked += "".join(f"; {n} moves with {j} ({m:g} x {j} + {o:g})" for n, (j, m, o) in rbd.coupled.items())
        log_notes.note(prog, f"rigid-body model: {a.urdf} ({rbd.dof} joints: {', '.join(rbd.joint_names)}{locked})")
        log_notes.limits_note(prog, rbd, data)
        log_notes.torque_note(prog, rbd, data)
    cfg = _fit_config(a)
    model = make_model(a.model, data.dof, rbd, gp_config=cfg)
    data, q_hist, thinned = _training_rows(prog, a, model, data)
    log_notes.few_rows_note(prog, model, data, thinned)
    log_notes.note(prog, f"fitting {a.model}: {data.dof} GPs on {data.n_samples} rows, {cfg.n_restarts} start(s) "
                         "each ...")
    t0 = time.perf_counter()
    try:
        with _still_fitting(prog):
            model.fit(data, q_hist=q_hist)
    except FitMemoryError as exc:  # in the command's terms: which options to change, and to what
        if exc.machine:
            raise _Fail(f"--max-samples {a.max_samples}: fitting {exc.n} rows needs at least "
                        f"{exc.need / 2**20:.0f} MiB, more than this machine's memory ({exc.limit / 2**30:.1f} GiB); "
                        f"at most {exc.max_n} rows could fit in it: lower --max-samples") from None
        what = (f"at most {exc.max_n} rows fit within it: lower --max-samples or raise --max-memory"
                if exc.max_n >= 2 else "not even 2 rows fit within it: raise --max-memory")
        raise _Fail(f"--max-samples {a.max_samples}: fitting {exc.n} rows needs about {exc.need / 2**20:.0f} MiB "
                    f"(a high estimate), over --max-memory "
                    f"{exc.limit / 2**30 if a.max_memory is None else a.max_memory:g} GiB; {what}") from None
    except ValueError as exc:  # about the log's values: in its terms
        raise _Fail(_in_log_terms(str(exc), a.data)) from None
    log_notes.note(prog, f"fitted in {time.perf_counter() - t0:.1f} s")
    provenance["data"]["n_used"] = data.n_samples  # after --rate-hz and --max-samples
    model.save(a.out, provenance=provenance)
    print(f"saved {a.model} ({data.dof} joints, n_train={model.n_train}) to {a.out}")
    return 0


#: Seconds between the notes that a long fit is still running (an exact GP's time grows as n^3: minutes at n = 4000).
STILL_FITTING_EVERY_S = 30.0


@contextmanager
def _still_fitting(prog: str) -> Iterator[None]:
    """While the block runs, a note every :data:`STILL_FITTING_EVERY_S` seconds that the fit is still running."""
    done, t0 = threading.Event(), time.perf_counter()

    def tell() -> None:
        while not done.wait(STILL_FITTING_EVERY_S):
            log_notes.note(prog, f"still fitting ({time.perf_counter() - t0:.0f} s so far)")

    threading.Thread(target=tell, name="still-fitting", daemon=True).start()
    try:
        yield
    finally:
        done.set()


# --------------------------------------------------------------------------- evaluate
def evaluate_main(argv: list[str] | None = None, prog: str | None = None) -> int:
    """``cascgp evaluate``: per-joint nRMSE of a saved model (and of its rigid-body model) on a log."""
    prog = prog or "cascgp evaluate"
    p = _parser(prog, "Per-joint nRMSE of a saved model on a log with measured torques, and of the model's "
                      "nominal rigid-body model (sp-* models). " + _NRMSE_HELP + ".")
    p.add_argument("--model", type=Path, required=True, help="model file written by 'cascgp fit'")
    p.add_argument("--data", type=Path, required=True, help="test log with tau1..tauN (.csv or .npz)")
    p.add_argument("--json", type=Path, default=None,
                   help="also write the scores with provenance (cascgp version, command, files, SHA-256) as JSON")
    a = p.parse_args(argv)
    check_output(p, a.json, "--json", "file", {"--model": a.model, "--data": a.data})
    return _run(prog, lambda: _evaluate(a, prog, argv))


def _evaluate(a: argparse.Namespace, prog: str, argv: list[str] | None) -> int:
    from cascgp import __version__
    from cascgp.features import history_from_data
    from cascgp.io import write_json
    from cascgp.metrics import nrmse
    from cascgp.models.io import saved_config

    model = _load(a.model)
    data = _read(a.data)
    _describe(prog, data, a.data)
    _check_dof(model, data, a.data)
    mean, _ = model.predict_data(data, return_var=False)
    rows = np.ones(data.n_samples, dtype=bool)
    if model.feature_kind == "df":  # rows without 2 * df_delta of history are not scored
        rows = history_from_data(data, model.df_delta)[1]
        if rows.sum() < 2:
            raise _Fail(f"{a.data}: fewer than 2 rows have the {2 * model.df_delta:g} s of history the -df model "
                        "needs")
    notes = [n for n in (log_notes.limits_note(prog, model.rbd, data), log_notes.torque_note(prog, model.rbd, data),
                         log_notes.coverage_note(prog, model, data), log_notes.in_sample_note(prog, model, data)) if n]
    tau = data.tau[rows]
    flat = [j for j in range(model.dof) if np.ptp(tau[:, j]) == 0]
    if flat:
        raise _Fail(f"{a.data}: column 'tau{flat[0] + 1}' is constant ({tau[0, flat[0]]:g}) over the "
                    f"{int(rows.sum())} rows scored; nRMSE (RMSE over the torque's range) is undefined: evaluate on a "
                    "log in which every joint's torque varies")
    with np.errstate(over="ignore", invalid="ignore"):  # a square that overflows: refused below
        scores = {model.name: nrmse(mean[rows], tau)}
        if model.rbd is not None:
            scores["nominal (rigid body)"] = nrmse(model.rbd.inverse_dynamics(data.q[rows], data.qd[rows],
                                                                              data.qdd[rows]), tau)
    for name, s in scores.items():
        if not np.isfinite(s).all():
            j = int(np.flatnonzero(~np.isfinite(s))[0])
            raise _Fail(f"{a.data}: column 'tau{j + 1}': the nRMSE of {name} overflows (torques up to "
                        f"{np.abs(tau[:, j]).max():.3g}, predictions up to {np.abs(mean[rows, j]).max():.3g}); "
                        "torques must be in N m (N for a prismatic joint)")
    nominal = scores.get("nominal (rigid body)")
    names = list(scores)
    width = max(12, *map(len, names))
    left = "" if rows.all() else (f" ({int((~rows).sum())} row(s) without {2 * model.df_delta:g} s of history "
                                  "left out)")
    print(f"nRMSE = RMSE / (max - min) of the test torques, {int(rows.sum())} rows of {a.data}{left}")
    print("joint  " + "  ".join(f"{n:>{width}}" for n in names))
    for j in range(model.dof):
        print(f"{j + 1:>5}  " + "  ".join(f"{scores[n][j]:>{width}.4f}" for n in names))
    print(f"{'mean':>5}  " + "  ".join(f"{scores[n].mean():>{width}.4f}" for n in names))
    if a.json is not None:
        saved = saved_config(a.model)  # the config JSON alone: the version and provenance it was saved with
        write_json(a.json, {
            "cascgp_version": __version__,
            "command": _command(prog, argv),
            "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "metric": _NRMSE_HELP,
            "model": {"file": str(a.model), "sha256": _sha256(a.model), "name": model.name, "dof": model.dof,
                      "n_train": model.n_train, "saved_by": saved.get("cascgp_version"),
                      "trained_on": saved.get("provenance")},  # what cascgp fit recorded (None: not recorded)
            "data": {**_log_record(a.data, data), "n_scored": int(rows.sum())},
            "nrmse": {"model": scores[model.name].tolist(),
                      "nominal": None if nominal is None else nominal.tolist()},
            "mean_nrmse": {"model": float(scores[model.name].mean()),
                           "nominal": None if nominal is None else float(nominal.mean())},
            "notes": notes,  # what the command noted about the log (in-sample rows, positions far outside)
        })
        log_notes.note(prog, f"wrote {a.json}")
    return 0


# --------------------------------------------------------------------------- predict
def predict_main(argv: list[str] | None = None, prog: str | None = None) -> int:
    """``cascgp predict``: a saved model's torque predictions for the states of a log, as CSV."""
    prog = prog or "cascgp predict"
    p = _parser(prog, "Predict joint torques for the states of a log and write them as CSV: t, tau1..tauN "
                      "(predicted mean, N m), var1..varN (latent variance of each prediction, N^2 m^2). The log's "
                      "tau columns are optional here.")
    p.add_argument("--model", type=Path, required=True, help="model file written by 'cascgp fit'")
    p.add_argument("--data", type=Path, required=True, help="log of states: t, q1..qN (qd, qdd, tau optional)")
    p.add_argument("--out", type=Path, required=True, help="CSV file to write (replaced atomically)")
    a = p.parse_args(argv)
    check_output(p, a.out, "--out", "file", {"--model": a.model, "--data": a.data})
    return _run(prog, lambda: _predict(a, prog))


def _predict(a: argparse.Namespace, prog: str) -> int:
    from cascgp.features import history_from_data
    from cascgp.logs import write_predictions

    model = _load(a.model)
    data = _read(a.data, require_tau=False)
    _describe(prog, data, a.data)
    _check_dof(model, data, a.data)
    mean, var = model.predict_data(data)
    log_notes.limits_note(prog, model.rbd, data)
    log_notes.coverage_note(prog, model, data)
    if model.feature_kind == "df":
        short = int((~history_from_data(data, model.df_delta)[1]).sum())
        if short:
            log_notes.note(prog, f"note: {short} row(s) lack {2 * model.df_delta:g} s of history within their segment; "
                        "their predictions use the segment's first position for the missing history")
    write_predictions(a.out, data.t, mean, var, data.segment)
    print(f"wrote {data.n_samples} predictions of {model.name} to {a.out}")
    return 0
