"""Loaders for the SARCOS inverse-dynamics data (7-DOF anthropomorphic arm).

Two public formats:

* GPML (``sarcos_inv.mat`` / ``sarcos_inv_test.mat``, from the GPML book's data page,
  http://www.gaussianprocess.org/gpml/data/): one ``T x 28`` matrix; columns 1-7 positions, 8-14 velocities,
  15-21 accelerations, 22-28 torques.  :func:`load_gpml`.
* IAS (``ias_sarcos_data.mat``, :data:`IAS_SOURCE`; sha256 ``8f6eec5f...de17f3``, 4,147,276 bytes):
  ``X_train``/``X_test`` (``T x 21``: positions, velocities, accelerations) and ``Y_train``/``Y_test``
  (``T x 7`` torques).  :func:`load_ias`.  The study's SARCOS part reads this file.

Torque units: the IAS torques are one third of GPML's (for the one input row both files
share, GPML = 3 x IAS).  Every loader takes ``torque_scale``, a factor applied to the file's
torques: ``load_ias(..., torque_scale=IAS_TO_GPML_TORQUE)`` gives GPML units and
``load_gpml(..., torque_scale=1 / IAS_TO_GPML_TORQUE)`` gives IAS units.  The default (1.0)
keeps each file's own units; ``meta["torque_units"]`` says which.  nRMSE is unaffected.

Time and segments: the files hold no time stamps.  ``t = row / rate_hz`` with the nominal
50 Hz of the data set (``rate_hz``).  Rows are in time order but the recordings are
concatenated; a new segment starts wherever consecutive rows are not continuous: where the
position step disagrees with the velocities, ``max_j |dq_j - h * (qd_j(t) + qd_j(t+1)) / 2|``
(``h`` fitted by least squares over the file) exceeds ``jump_factor`` (default 20) times its
median.  (The velocities imply a step ``h`` that is not 1/50 s in either file (IAS train about
4 ms, GPML test about 0.11 s); ``t`` nonetheless uses ``rate_hz`` as documented for the data
set, so "10 Hz" means every 5th row.)

De-duplication: 2785 of the 5569 IAS test inputs also stand (to 8 decimals) in the IAS
training inputs.  ``load_ias(dedup=True)`` (default) drops those test rows; the kept rows keep
their original times (``t = original_row / rate_hz``) and segments, and
``meta["n_duplicates_removed"]`` records the count.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .checks import check_positive
from .data import DynamicsData

__all__ = ["IAS_SOURCE", "IAS_TO_GPML_TORQUE", "SARCOS_DOF", "SARCOS_RATE_HZ", "check_ias", "load_ias", "load_gpml",
           "duplicate_rows", "detect_segments"]

#: Where to get the IAS SARCOS file (``ias_sarcos_data.mat``): a public repository's copy, at the commit read here.
IAS_SOURCE = "https://github.com/hanyas/mimo/blob/b1c3331da98c/datasets/Sarcos/ias_sarcos_data.mat"
#: GPML torque = IAS torque * IAS_TO_GPML_TORQUE.
IAS_TO_GPML_TORQUE = 3.0
SARCOS_DOF = 7
#: Nominal sample rate of the SARCOS data set (Hz).
SARCOS_RATE_HZ = 50.0


def _file(path: str | os.PathLike) -> Path:
    """``path`` as a ``Path`` to an existing file: ``FileNotFoundError``, or ``ValueError`` for a folder."""
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{path}: is a folder; expected a MATLAB .mat file")
    if not path.is_file():
        raise FileNotFoundError(f"SARCOS file not found: {path}")
    return path


def _mat_error(path: Path, exc: Exception) -> ValueError:
    """The ``ValueError`` for a file SciPy cannot read, with what to do where that is known."""
    text = f"{type(exc).__name__}: {exc}"
    if isinstance(exc, NotImplementedError) and "v7.3" in str(exc):
        return ValueError(f"{path}: a MATLAB v7.3 (HDF5) file, which this reader does not read; save it again in "
                          f"MATLAB with save(..., '-v7') ({text})")
    return ValueError(f"{path}: not a readable MATLAB .mat file (damaged or truncated?): {text}")


def _loadmat(path: str | os.PathLike) -> dict:
    from scipy.io import loadmat

    path = _file(path)
    try:
        return loadmat(path)
    except Exception as exc:  # scipy raises several types for corrupt files
        raise _mat_error(path, exc) from exc


def _matrix(path: str | os.PathLike, d: dict, name: str) -> np.ndarray:
    """Variable ``name`` of a loaded file as float64: ``ValueError`` naming it unless real numbers, all finite."""
    a = np.asarray(d[name])
    if a.dtype.kind not in "fiu":
        raise ValueError(f"{path}: {name}: expected real numbers, got dtype {a.dtype}")
    a = a.astype(np.float64)
    bad = ~np.isfinite(a)
    if bad.any():
        row = int(np.flatnonzero(bad.any(axis=1))[0]) if a.ndim == 2 else 0
        raise ValueError(f"{path}: {name}: NaN or inf (first at row {row})")
    return a


#: The IAS file's variables and their number of columns.
_IAS_COLUMNS = {"X_train": 3 * 7, "Y_train": 7, "X_test": 3 * 7, "Y_test": 7}


def check_ias(path: str | os.PathLike) -> None:
    """Check that ``path`` is an IAS SARCOS file (``ias_sarcos_data.mat``): its variables' names and shapes, then
    its data (readable to the end, real and finite; about 50 ms), so that a command can refuse a wrong or damaged
    file before it runs anything.

    Raises:
        FileNotFoundError: no file at ``path``.
        ValueError: a folder, not a readable MATLAB file (or a damaged one), not the IAS variables and shapes
            (``X_train``/``X_test``: T x 21, ``Y_train``/``Y_test``: T x 7, as many rows as their ``X``), or
            values that are not finite real numbers; a GPML file (``sarcos_inv.mat``, one T x 28 matrix) is named
            as such, with :func:`load_gpml` as its loader.
    """
    _read_ias(path)


def _read_ias(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """The IAS file's four matrices as float64, checked as :func:`check_ias` says."""
    from scipy.io import whosmat

    path = _file(path)
    try:
        shapes = {name: shape for name, shape, _ in whosmat(path)}
    except Exception as exc:  # scipy raises several types for files that are not MATLAB's
        raise _mat_error(path, exc) from exc
    missing = [k for k in _IAS_COLUMNS if k not in shapes]
    if missing:
        gpml = [k for k, s in shapes.items() if len(s) == 2 and s[1] == 28]
        hint = (f"; it holds the GPML SARCOS matrix {gpml[0]!r} (T x 28), which cascgp.load_gpml reads" if gpml else
                "; it holds only some of them: truncated?" if len(missing) < len(_IAS_COLUMNS) else "")
        raise ValueError(f"{path}: missing variable(s) {missing} (expected the IAS SARCOS format, "
                         f"ias_sarcos_data.mat){hint}")
    for k, cols in _IAS_COLUMNS.items():
        shape = shapes[k]
        rows = shapes["X_" + k.split("_")[1]][0]
        if len(shape) != 2 or shape[1] != cols or shape[0] != rows:
            raise ValueError(f"{path}: {k}: expected shape ({rows}, {cols}), got {tuple(shape)} "
                             "(the IAS SARCOS format)")
    d = _loadmat(path)
    return {k: _matrix(path, d, k) for k in _IAS_COLUMNS}


def detect_segments(q: np.ndarray, qd: np.ndarray, jump_factor: float = 20.0) -> np.ndarray:
    """Segment ids (T,) for rows in time order: a new segment starts after each
    discontinuity (see the module docstring)."""
    T = q.shape[0]
    seg = np.zeros(T, dtype=np.int64)
    if T < 3:
        return seg
    dq = np.diff(q, axis=0)
    v = 0.5 * (qd[1:] + qd[:-1])
    vv = float(np.vdot(v, v))
    h = float(np.vdot(dq, v)) / vv if vv > 0 else 0.0
    err = np.abs(dq - h * v).max(axis=1)
    med = float(np.median(err))
    if med <= 0:
        return seg
    breaks = err > jump_factor * med
    seg[1:] = np.cumsum(breaks)
    return seg


def duplicate_rows(X_test: np.ndarray, X_train: np.ndarray, decimals: int = 8) -> np.ndarray:
    """Boolean mask (len(X_test),): True where the test input row, rounded to ``decimals``,
    equals some training input row rounded the same way."""
    A = np.round(np.asarray(X_test, dtype=np.float64), decimals) + 0.0  # +0.0: no -0.0
    B = np.round(np.asarray(X_train, dtype=np.float64), decimals) + 0.0
    if A.ndim != 2 or B.ndim != 2 or A.shape[1] != B.shape[1]:
        raise ValueError(f"X_test/X_train: expected 2-D arrays with equal widths, got {A.shape}, {B.shape}")
    train = {r.tobytes() for r in B}
    return np.fromiter((r.tobytes() in train for r in A), dtype=bool, count=A.shape[0])


def _make(X: np.ndarray, Y: np.ndarray, rows: np.ndarray, *, rate_hz: float, jump_factor: float,
          torque_scale: float, meta: dict, name: str) -> DynamicsData:
    n = SARCOS_DOF
    if X.ndim != 2 or X.shape[1] != 3 * n:
        raise ValueError(f"{name}: expected {3 * n} input columns (q, qd, qdd of 7 joints), got shape {X.shape}")
    if Y.ndim != 2 or Y.shape != (X.shape[0], n):
        raise ValueError(f"{name}: expected torques of shape {(X.shape[0], n)}, got {Y.shape}")
    q, qd, qdd = X[:, :n], X[:, n:2 * n], X[:, 2 * n:]
    seg = detect_segments(q, qd, jump_factor)
    t = np.arange(X.shape[0], dtype=np.float64) / rate_hz
    sel = np.asarray(rows)
    _, seg_ids = np.unique(seg[sel], return_inverse=True)
    try:
        return DynamicsData(q=q[sel], qd=qd[sel], qdd=qdd[sel], tau=Y[sel] * torque_scale, t=t[sel],
                            segment=seg_ids.astype(np.int64), meta=meta)
    except ValueError as exc:  # a NaN, or no rows left: name the file and the matrix
        left = f" ({len(sel)} of {X.shape[0]} rows kept)" if len(sel) != X.shape[0] else ""
        raise ValueError(f"{meta.get('file', 'the SARCOS file')}: {name}{left}: {exc}") from None


def _check_common(rate_hz: float, torque_scale: float, jump_factor: float) -> None:
    check_positive(rate_hz, "rate_hz", "Hz")
    check_positive(torque_scale, "torque_scale")
    if isinstance(jump_factor, bool) or not isinstance(jump_factor, (int, float, np.integer, np.floating)) \
            or not jump_factor > 0:  # inf: never split
        raise ValueError(f"jump_factor: expected a number > 0 (inf: one segment), got {jump_factor!r}")


def _units(torque_scale: float, native: str) -> str:
    if torque_scale == 1.0:
        return native
    if native == "IAS" and np.isclose(torque_scale, IAS_TO_GPML_TORQUE):
        return "GPML"
    if native == "GPML" and np.isclose(torque_scale, 1.0 / IAS_TO_GPML_TORQUE):
        return "IAS"
    return f"{native} x {torque_scale:g}"


def load_ias(path: str | os.PathLike, *, dedup: bool = True, torque_scale: float = 1.0,
             rate_hz: float = SARCOS_RATE_HZ, jump_factor: float = 20.0
             ) -> tuple[DynamicsData, DynamicsData]:
    """Load ``ias_sarcos_data.mat`` -> ``(train, test)``.

    ``path``: the file. ``dedup``: drop the test rows whose inputs also stand in the training set (to 8
    decimals).  ``torque_scale``: factor on the file's torques (``IAS_TO_GPML_TORQUE`` for
    GPML units).  ``rate_hz``: the rate that gives the rows their times (``t = row / rate_hz``);
    ``jump_factor``: where the position step disagrees with the velocities by more than this times its median, a
    new segment starts (``inf``: one segment). See the module docstring for time, segments and units.
    """
    _check_common(rate_hz, torque_scale, jump_factor)
    d = _read_ias(path)
    X_tr, Y_tr, X_te, Y_te = d["X_train"], d["Y_train"], d["X_test"], d["Y_test"]
    units = _units(torque_scale, "IAS")
    base = {"robot": "SARCOS", "source": "IAS ias_sarcos_data.mat", "file": str(path),
            "torque_units": units, "torque_scale": float(torque_scale), "rate_hz": float(rate_hz)}
    train = _make(X_tr, Y_tr, np.arange(X_tr.shape[0]), rate_hz=rate_hz, jump_factor=jump_factor,
                  torque_scale=torque_scale, meta={**base, "split": "train"}, name="X_train")
    if dedup:
        dup = duplicate_rows(X_te, X_tr, 8)
        rows = np.flatnonzero(~dup)
    else:
        dup = np.zeros(X_te.shape[0], bool)
        rows = np.arange(X_te.shape[0])
    test = _make(X_te, Y_te, rows, rate_hz=rate_hz, jump_factor=jump_factor,
                 torque_scale=torque_scale,
                 meta={**base, "split": "test", "dedup": bool(dedup),
                       "n_duplicates_removed": int(dup.sum()), "n_rows_in_file": int(X_te.shape[0])},
                 name="X_test")
    return train, test


def load_gpml(path: str | os.PathLike, *, torque_scale: float = 1.0, rate_hz: float = SARCOS_RATE_HZ,
              jump_factor: float = 20.0, variable: str | None = None) -> DynamicsData:
    """Load a GPML-format file (``sarcos_inv.mat`` or ``sarcos_inv_test.mat``; the one ``T x 28``
    matrix, or ``variable``).  ``torque_scale=1/IAS_TO_GPML_TORQUE`` gives IAS units; ``rate_hz`` and
    ``jump_factor``: as for :func:`load_ias`."""
    _check_common(rate_hz, torque_scale, jump_factor)
    d = _loadmat(path)
    found = {k: np.shape(v) for k, v in d.items() if not k.startswith("__")}
    if variable is None:
        cands = [k for k, v in d.items() if not k.startswith("__") and isinstance(v, np.ndarray)
                 and v.ndim == 2 and v.shape[1] == 28]
        if len(cands) != 1:
            raise ValueError(f"{path}: expected exactly one T x 28 matrix (GPML SARCOS format), found "
                             f"{len(cands)} among its variables {found}")
        variable = cands[0]
    if variable not in d:
        raise ValueError(f"{path}: variable {variable!r} not found; the file holds {found}")
    A = _matrix(path, d, variable)
    if A.ndim != 2 or A.shape[1] != 28:
        raise ValueError(f"{path}: {variable}: expected shape (T, 28), got {A.shape}")
    meta = {"robot": "SARCOS", "source": f"GPML {Path(path).name}", "file": str(path),
            "torque_units": _units(torque_scale, "GPML"), "torque_scale": float(torque_scale),
            "rate_hz": float(rate_hz)}
    return _make(A[:, :21], A[:, 21:], np.arange(A.shape[0]), rate_hz=rate_hz,
                 jump_factor=jump_factor, torque_scale=torque_scale, meta=meta, name=variable)
