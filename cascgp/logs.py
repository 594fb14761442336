r"""Logged robot data as CSV: the one place where the log format is defined, read and checked.

A log is a text file with one header row and one row per sample, comma-separated (``csv`` dialect "excel",
surrounding blanks ignored; the decimal separator is ``.``). Rows are numbered as lines of the file: the header is
**row 1**, the first sample row 2; error messages use these numbers. Blank lines are skipped (they keep their row
numbers), and so is a spreadsheet's separator line ``sep=,`` before the header.

=====================  ========  ================================================================================
column                 needed    meaning
=====================  ========  ================================================================================
``t``                  yes       time (s), strictly increasing within a segment
``q1`` .. ``qN``       yes       joint positions (rad or m), joint 1 = the joint nearest the base
``tau1`` .. ``tauN``   yes [1]_  joint torques (N m) or forces (N)
``qd1`` .. ``qdN``     no        joint velocities; computed from ``q`` when the group is absent
``qdd1`` .. ``qddN``   no        joint accelerations; computed from ``qd`` when the group is absent
``segment``            no        integer id of a time-contiguous recording (non-decreasing; default all 0)
=====================  ========  ================================================================================

.. [1] optional for ``cascgp predict`` (``read_log(..., require_tau=False)``).

N is read from the header: every group present holds exactly the columns ``1..N`` (``q`` defines N), columns
may come in any order, names are case-sensitive. Any other column is an error (a misspelt ``qd_1`` would
otherwise be dropped silently); remove unneeded columns first. Every cell is a finite decimal number in ASCII
digits (a row of empty cells is refused; a blank line is skipped). In a log
without velocity columns (whose velocities are computed from ``q``) no joint position changes by more than
:math:`\pi` from one row to the next within a segment: no arm moves that far in one sample, and a continuous
joint's angle wrapped to :math:`[-\pi, \pi)` or :math:`[0, 2\pi)` would give spikes in the computed velocity and
a discontinuous GP input (unwrap it, e.g. :func:`numpy.unwrap`).

Missing derivatives
-------------------
Within each segment, :math:`\dot q` is the derivative of :math:`q` and :math:`\ddot q` the derivative of
:math:`\dot q` (the given or the computed one), both by the same filter, by default :data:`DEFAULT_SMOOTHING`
(Savitzky-Golay, window 7, polynomial order 2, :class:`cascgp.data.SavGol`): the derivative of a local quadratic
fitted by least squares to 7 samples, centred (no lag), at the segment's median sample period where its sampling
is uniform, and at the actual sample times where its periods vary by more than 5 % (dropped samples); segments
shorter than the window, and ``smoothing=None``, use central differences (:func:`numpy.gradient` on the times).
A segment needs 3 rows to compute both, 2 to compute one of them; a shorter one is refused with a
:class:`LogFormatError` naming its first row (it would get a zero derivative). The filter used is recorded in
``data.meta["derivative_filter"]`` and each group's origin in ``data.meta["qd_source"]`` / ``["qdd_source"]``
(``"column"`` or ``"computed"``). A median sample period above
:data:`SLOWEST_PERIOD_S` (0.5 s) gets a warning: ``t`` in milliseconds would make the computed velocities 1000
times too small.

Errors are :class:`LogFormatError` (a ``ValueError``) naming the file, the row and the column. Predictions are
written by :func:`write_predictions` (columns ``t``, ``segment`` for a log of several segments, ``tau1..tauN``
predicted means, ``var1..varN`` their variances in N² m²).
"""

from __future__ import annotations

import csv
import io
import math
import os
import re
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from cascgp.data import DynamicsData, SavGol, differentiate
from cascgp.derivatives import UNIFORM_TOLERANCE, is_uniform
from cascgp.io import atomic_write

__all__ = ["LogFormatError", "DEFAULT_SMOOTHING", "read_log", "write_log", "write_predictions", "differentiate",
           "filter_name"]

#: The derivative filter applied to logs without velocity or acceleration columns.
DEFAULT_SMOOTHING = SavGol(window=7, polyorder=2)
_GROUPS = ("q", "qd", "qdd", "tau")
_COLUMN = re.compile(r"^(q|qd|qdd|tau)([1-9][0-9]*)$")


class LogFormatError(ValueError):
    """A log file that does not follow the format of :mod:`cascgp.logs`; the message names file, row, column."""


def filter_name(smoothing: SavGol | None) -> str:
    """Human-readable name of a derivative filter, as recorded in ``meta["derivative_filter"]``."""
    if smoothing is None:
        return "central differences (numpy.gradient)"
    kind = "causal Savitzky-Golay" if smoothing.causal else "Savitzky-Golay"
    return f"{kind} (window={smoothing.window}, polyorder={smoothing.polyorder})"


# --------------------------------------------------------------------------- reading
def _span(group: str, lo: int, hi: int) -> str:
    """``q2`` or ``q2..q4``."""
    return f"{group}{lo}" if lo == hi else f"{group}{lo}..{group}{hi}"


def _header(path: Path, names: list[str], row: int, require_tau: bool
            ) -> tuple[int, dict[str, list[int] | None], int | None]:
    """N, the column indices of every group (``None`` for an absent group) and the index of ``segment``."""
    where = f"{path}: row {row} (header)"
    seen: dict[str, int] = {}
    groups: dict[str, dict[int, int]] = {g: {} for g in _GROUPS}
    seg_col = None
    for c, name in enumerate(names):
        if name in seen:
            raise LogFormatError(f"{where}, column {name!r}: appears twice (columns {seen[name] + 1} and {c + 1})")
        seen[name] = c
        m = _COLUMN.match(name)
        if m:
            groups[m[1]][int(m[2])] = c
        elif name == "segment":
            seg_col = c
        elif name != "t":
            sep = next((s for s in (";", "\t", "|") if s in name), None)
            hint = (f"; the columns are separated by {sep!r}, and a log's by commas" if sep is not None and
                    len(names) == 1 else "")
            raise LogFormatError(
                f"{where}, column {name!r} (column {c + 1}): unknown column; expected t, q1..qN, tau1..tauN and "
                f"optionally qd1..qdN, qdd1..qddN, segment (see cascgp.logs){hint}")
    if "t" not in seen:
        raise LogFormatError(f"{where}, column 't': missing required column (time in s)")
    if not groups["q"]:
        raise LogFormatError(f"{where}, column 'q1': missing required column(s) q1..qN (joint positions)")
    n = max(groups["q"])
    for g in _GROUPS:
        if not groups[g]:
            if g == "tau" and require_tau:
                raise LogFormatError(f"{where}, column 'tau1': missing required column(s) tau1..tau{n} "
                                     "(joint torques)")
            continue
        have = set(groups[g])
        gaps = [f"{g}{j}" for j in range(1, n + 1) if j not in have]
        extra = [f"{g}{j}" for j in sorted(have) if j > n]
        if gaps or extra:
            bad = (gaps or extra)[0]
            raise LogFormatError(
                f"{where}, column {bad!r}: joint count mismatch: the q columns give N = {n} joints, so {g} needs "
                f"exactly {g}1..{g}{n}; "
                + (f"missing {', '.join(gaps)}" if gaps else
                   f"unexpected {', '.join(extra)} (or is {_span('q', n + 1, max(have))} missing?)"))
    cols = {g: ([groups[g][j] for j in range(1, n + 1)] if groups[g] else None) for g in _GROUPS}
    return n, cols, seg_col


def _rows(path: Path, names: list[str], reader: Any) -> tuple[np.ndarray, list[int]]:
    """All sample rows as a float array plus their row numbers; ``LogFormatError`` for ragged or bad cells."""
    values: list[list[float]] = []
    rownos: list[int] = []
    k = len(names)
    for cells in reader:
        r = reader.line_num
        if not cells or (len(cells) == 1 and not cells[0].strip()):  # a blank line (a row of empty cells is not)
            continue
        if len(cells) != k:
            lines = sum(c.rstrip("\n").count("\n") for c in cells)
            if lines:  # a quoted cell runs over line ends: a quote that is not closed
                raise LogFormatError(f"{path}: row {r - lines}: a quote (\") opened in this row is not closed")
            col = names[len(cells)] if len(cells) < k else names[-1]
            what = (f"column {col!r}: missing (the row has {len(cells)} cells, the header {k})" if len(cells) < k else
                    f"column {col!r}: {len(cells) - k} extra cell(s) after it (the row has {len(cells)} cells, "
                    f"the header {k})")
            raise LogFormatError(f"{path}: row {r}, {what}")
        try:
            row = [float(c) for c in cells]
        except ValueError:
            row = []
        # float() also takes '1_000' and digits of other scripts; a log's cells are ASCII decimal numbers
        line = "".join(cells)  # one test of the row's characters, not one per cell
        if len(row) != k or not all(map(math.isfinite, row)) or not line.isascii() or "_" in line:
            for c, cell in enumerate(cells):
                if not (cell.isascii() and "_" not in cell and _is_number(cell)):
                    got = repr(cell.strip()) if cell.isascii() else f"{cell!r} (characters that are not ASCII)"
                    if "," in cell and _is_number(cell.replace(",", ".")):
                        got += " (a decimal comma? a log's decimal separator is '.', with no thousands separator)"
                    raise LogFormatError(f"{path}: row {r}, column {names[c]!r}: expected a finite number, got {got}")
        values.append(row)
        rownos.append(r)
    if not values:
        raise LogFormatError(f"{path}: row {reader.line_num + 1}: no data rows after the header (at least one "
                             "sample is needed)")
    return np.array(values, dtype=np.float64), rownos


def _is_number(cell: str) -> bool:
    """Whether ``float`` reads ``cell`` as a finite number."""
    try:
        return math.isfinite(float(cell))
    except ValueError:
        return False


class _CsvRows:
    """``csv.reader`` over ``text`` (``line_num`` too) whose errors (a cell longer than the csv module's field limit,
    say) are ``LogFormatError``s naming the file and row."""

    def __init__(self, path: Path, text: str) -> None:
        self._path, self._reader = path, csv.reader(io.StringIO(text), skipinitialspace=True)

    @property
    def line_num(self) -> int:
        return self._reader.line_num

    def __iter__(self) -> "_CsvRows":
        return self

    def __next__(self) -> list[str]:
        try:
            return next(self._reader)
        except csv.Error as exc:
            raise LogFormatError(f"{self._path}: row {self._reader.line_num}: not a row of numbers ({exc})") from None


def _read_csv(path: Path, smoothing: SavGol | None, require_tau: bool) -> DynamicsData:
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        hint = ("; the SARCOS .mat files become logs with train, test = cascgp.load_ias(path) (the IAS file) or "
                "data = cascgp.load_gpml(path) (a GPML file), then .save('x.npz')" if path.suffix.lower() == ".mat"
                else "")
        raise LogFormatError(f"{path}: not a UTF-8 text file ({exc}); expected a CSV log or a .npz file of "
                             f"DynamicsData.save{hint}") from None
    reader = _CsvRows(path, text)
    header = next(reader, None)
    while header is not None and not any(c.strip() for c in header):  # leading blank lines
        header = next(reader, None)
    if header is None:
        raise LogFormatError(f"{path}: row 1: empty file; expected a header row with columns t, q1..qN, "
                             "tau1..tauN (see cascgp.logs)")
    names = [c.strip() for c in header]
    if names and names[0].lower().startswith("sep="):  # Excel's separator line, before the header
        if ",".join(header).strip().lower() != "sep=,":
            raise LogFormatError(f"{path}: row {reader.line_num}: a spreadsheet's separator line, "
                                 f"{','.join(header)!r}; expected sep=, (a log's columns are separated by commas)")
        header = next(reader, None)
        if header is None:
            raise LogFormatError(f"{path}: row {reader.line_num + 1}: expected a header row after the separator line "
                                 "sep=, with columns t, q1..qN, tau1..tauN (see cascgp.logs)")
        names = [c.strip() for c in header]
    n, cols, seg_col = _header(path, names, reader.line_num, require_tau)
    a, rownos = _rows(path, names, reader)
    t = a[:, names.index("t")]
    seg = np.zeros(len(t), dtype=np.int64)
    if seg_col is not None:
        raw = a[:, seg_col]
        bad = np.flatnonzero((raw != np.round(raw)) | (np.abs(raw) > 2.0**53))  # 2^53: exact in float64 and int64
        if bad.size:
            raise LogFormatError(f"{path}: row {rownos[bad[0]]}, column 'segment': expected an integer id (of at most "
                                 f"2^53 in magnitude), got {float(raw[bad[0]])!r}")
        seg = raw.astype(np.int64)
        dec = np.flatnonzero(np.diff(seg) < 0)
        if dec.size:
            r = dec[0] + 1
            raise LogFormatError(f"{path}: row {rownos[r]}, column 'segment': ids must be non-decreasing; "
                                 f"{seg[r]} follows {seg[r - 1]} (row {rownos[r - 1]})")
    back = np.flatnonzero((np.diff(seg) == 0) & (np.diff(t) <= 0))
    if back.size:
        r = back[0] + 1
        raise LogFormatError(f"{path}: row {rownos[r]}, column 't': time must be strictly increasing within a "
                             f"segment; t = {float(t[r])!r} does not come after t = {float(t[r - 1])!r} "
                             f"(row {rownos[r - 1]})")
    arr = {g: (None if cols[g] is None else a[:, cols[g]]) for g in _GROUPS}
    meta: dict = {"source": str(path), "format": "cascgp log CSV", "qd_source": "column", "qdd_source": "column",
                  "has_tau": arr["tau"] is not None, "derivative_filter": None}
    if arr["qd"] is None or arr["qdd"] is None:
        _check_segment_rows(path, seg, rownos, arr["qd"] is None, arr["qdd"] is None, seg_col is not None)
        _check_uniform(path, t, seg, smoothing)
        _check_seconds(path, t, seg)
        meta["derivative_filter"] = filter_name(smoothing)
        if smoothing is not None and np.min(np.diff(np.r_[0, np.flatnonzero(np.diff(seg)) + 1, len(t)])) \
                < smoothing.window:
            meta["derivative_filter"] += f"; central differences on segments shorter than {smoothing.window} rows"
    q, qd, qdd, tau = arr["q"], arr["qd"], arr["qdd"], arr["tau"]
    assert q is not None  # _header refuses a log without q1..qN
    with np.errstate(all="ignore"):  # a derivative that overflows is refused in _derivative, naming it
        if qd is None:  # rows with given velocities may be independent samples (a shuffled data set): not checked
            _check_no_wrap(path, q, seg, rownos)
            qd = _derivative(path, t, q, seg, smoothing, "velocities qd from q")
            meta["qd_source"] = "computed"
        if qdd is None:
            qdd = _derivative(path, t, qd, seg, smoothing, "accelerations qdd from qd")
            meta["qdd_source"] = "computed"
    if tau is None:
        tau = np.zeros_like(q)  # placeholder: meta["has_tau"] is False
    try:
        return DynamicsData(q=q, qd=qd, qdd=qdd, tau=tau, t=t, segment=seg, meta=meta)
    except (ValueError, TypeError) as exc:  # not expected after the checks above; still name the file
        raise LogFormatError(f"{path}: {exc}") from exc


def _derivative(path: Path, t: np.ndarray, x: np.ndarray, seg: np.ndarray, smoothing: SavGol | None,
                what: str) -> np.ndarray:
    """``differentiate`` with a ``LogFormatError`` naming ``what`` where the result is not finite (time steps so
    small, 1e-300 s say, or values so large that a difference quotient overflows)."""
    try:
        out = differentiate(t, x, seg, smoothing)
    except ValueError as exc:  # SciPy's "array must not contain infs or NaNs" from a step that overflowed
        if "infs or NaNs" not in str(exc):
            raise
        out = np.full_like(x, np.nan)
    if not np.isfinite(out).all():
        d = np.diff(t)[np.diff(seg) == 0]
        raise LogFormatError(f"{path}: computing the {what} overflows (time steps as small as {d.min():.3g} s in "
                             f"column 't', values up to {np.abs(x).max():.3g}); t must be in seconds")
    return out


def _check_no_wrap(path: Path, q: np.ndarray, seg: np.ndarray, rownos: list[int]) -> None:
    """``LogFormatError`` at the first step of more than pi in a joint position within a segment (a wrapped angle)."""
    step = np.abs(np.diff(q, axis=0))
    jump = np.argwhere((step > math.pi) & (np.diff(seg) == 0)[:, None])
    if jump.size:
        r, j = int(jump[0, 0]) + 1, int(jump[0, 1])
        change = float(q[r, j] - q[r - 1, j])
        raise LogFormatError(f"{path}: row {rownos[r]}, column 'q{j + 1}': changes by {change:.4g} from row "
                             f"{rownos[r - 1]}, more than pi in one sample; a wrapped angle of a continuous joint? "
                             "Unwrap it (numpy.unwrap) or start a new segment there")


def _check_segment_rows(path: Path, seg: np.ndarray, rownos: list[int], no_qd: bool, no_qdd: bool,
                        has_segments: bool) -> None:
    """``LogFormatError`` naming the first segment too short for the derivatives to compute: q̇ and q̈ both from q
    need 3 rows per segment, one of them 2 (a one-row segment had velocity 0, a two-row one acceleration 0)."""
    need = 3 if no_qd and no_qdd else 2
    starts = np.r_[0, np.flatnonzero(np.diff(seg)) + 1]
    sizes = np.diff(np.r_[starts, len(seg)])
    short = np.flatnonzero(sizes < need)
    if short.size:
        lo, k = int(starts[short[0]]), int(sizes[short[0]])
        what = "qd and qdd from q" if need == 3 else "qd from q" if no_qd else "qdd from qd"
        cols = "qd1..qdN and qdd1..qddN" if need == 3 else "qd1..qdN" if no_qd else "qdd1..qddN"
        rows = f"{k} row{'s' if k > 1 else ''}"
        where = f"row {rownos[lo]}: segment {int(seg[lo])} has {rows}" if has_segments else f"the log has {rows}"
        raise LogFormatError(f"{path}: {where}; computing {what} needs at least {need} rows per segment: merge or "
                             f"drop it, or give the {cols} columns")


def _check_uniform(path: Path, t: np.ndarray, seg: np.ndarray, smoothing: SavGol | None) -> None:
    """Warn when a segment's sample periods vary by more than :data:`~cascgp.derivatives.UNIFORM_TOLERANCE` of its
    median (:func:`~cascgp.derivatives.is_uniform`): a centred filter then fits at the sample times, and a polynomial
    that spans a pause in logging is a poor one; a causal filter takes the median period."""
    if smoothing is None:
        return
    cuts = np.flatnonzero(np.diff(seg) != 0) + 1
    for lo, hi in zip(np.r_[0, cuts], np.r_[cuts, len(t)]):
        if not is_uniform(t[lo:hi]):
            d = np.diff(t[lo:hi])
            how = ("takes every period for the median one" if smoothing.causal else
                   "fits its polynomial at the actual sample times there, also across a pause")
            warnings.warn(f"{path}: sample periods vary by more than {UNIFORM_TOLERANCE:.0%} of their median within "
                          f"a segment ({np.median(d):.4g} s, longest {d.max():.4g} s); the {filter_name(smoothing)} "
                          f"derivative {how}: start a new segment (column 'segment') where logging paused",
                          stacklevel=3)
            return


#: A median sample period above this (s) is taken for a time column in other units than seconds: no arm's dynamics
#: are learned from samples 0.5 s apart, while milliseconds at 1 kHz or more read as periods of 1 s or more.
SLOWEST_PERIOD_S = 0.5


def _check_seconds(path: Path, t: np.ndarray, seg: np.ndarray) -> None:
    """Warn when the median sample period is above :data:`SLOWEST_PERIOD_S` (``t`` in milliseconds, say): the
    computed velocities and accelerations would be off by the unit's factor and its square."""
    d = np.diff(t)[np.diff(seg) == 0]
    if d.size and np.median(d) > SLOWEST_PERIOD_S:
        warnings.warn(f"{path}: the median sample period is {np.median(d):.4g} s ({1 / np.median(d):.3g} Hz); is "
                      "column 't' in seconds? Velocities and accelerations are computed from it (t in "
                      "milliseconds would make them 1000x and 10^6x too small)", stacklevel=3)


def read_log(path: str | os.PathLike, *, smoothing: SavGol | int | None = DEFAULT_SMOOTHING,
             require_tau: bool = True) -> DynamicsData:
    """Read a log: a CSV file in the format of the module docstring, or a ``.npz`` file of
    :meth:`cascgp.data.DynamicsData.save`.

    Args:
        path: ``.csv`` (any other suffix but ``.npz`` is read as CSV) or ``.npz``.
        smoothing: derivative filter for missing ``qd`` / ``qdd`` columns: a :class:`~cascgp.data.SavGol`, an odd
            ``int`` window (polynomial order 2) or ``None`` (central differences).
        require_tau: if ``False``, the ``tau`` columns may be absent: ``tau`` is then zero and
            ``meta["has_tau"]`` is ``False`` (for prediction only); if ``True``, such a log saved as ``.npz`` is
            refused too.

    Returns:
        The validated :class:`~cascgp.data.DynamicsData`; ``meta`` records ``source``, ``has_tau``,
        ``qd_source``, ``qdd_source`` and ``derivative_filter`` (``None`` when nothing was computed).

    Raises:
        FileNotFoundError: no such file.
        LogFormatError: anything else (message names the file, the row and the column).

    Example:
        >>> import numpy as np, pathlib, tempfile
        >>> t = np.arange(0.0, 1.0, 0.01)                       # a 1-joint log at 100 Hz: time, angle, torque
        >>> csv = pathlib.Path(tempfile.mkdtemp()) / "arm.csv"
        >>> np.savetxt(csv, np.column_stack([t, np.sin(t), 0.5 * np.sin(t)]), delimiter=",", header="t,q1,tau1",
        ...            comments="")
        >>> log = read_log(csv)                                 # qd and qdd are differentiated
        >>> log.n_samples, log.meta["qd_source"], bool(abs(log.qd[50, 0] - np.cos(0.5)) < 1e-3)
        (100, 'computed', True)
    """
    path = Path(path)
    if isinstance(smoothing, (int, np.integer)) and not isinstance(smoothing, bool):
        smoothing = SavGol(int(smoothing))
    if smoothing is not None and not isinstance(smoothing, SavGol):
        raise TypeError(f"smoothing: expected None, an odd int window or SavGol, got {smoothing!r}")
    if not path.exists():
        raise FileNotFoundError(f"log file not found: {path}")
    if not path.is_file():
        raise LogFormatError(f"{path}: not a file (expected a CSV or .npz log)")
    if path.suffix.lower() != ".npz":
        return _read_csv(path, smoothing, require_tau)
    try:
        data = DynamicsData.load(path)
    except ValueError as exc:
        raise LogFormatError(str(exc)) from exc
    if require_tau and data.meta.get("has_tau") is False:
        raise LogFormatError(f"{path}: holds no measured torques (its tau is the zero placeholder of a log read for "
                             "prediction, read_log(..., require_tau=False)); fitting and evaluating need tau1..tauN")
    meta = {**data.meta, "source": str(path), "format": "cascgp.DynamicsData .npz"}
    meta.setdefault("has_tau", True)
    meta.setdefault("derivative_filter", None)
    return DynamicsData(q=data.q, qd=data.qd, qdd=data.qdd, tau=data.tau, t=data.t, segment=data.segment, meta=meta)


# --------------------------------------------------------------------------- writing
def _csv_bytes(columns: dict[str, np.ndarray]) -> bytes:
    names = list(columns)
    a = np.column_stack([np.asarray(columns[k], dtype=np.float64) for k in names])
    # repr: the shortest text that reads back as the same float (0.04, not %.17g's 0.040000000000000001)
    cells = a.astype(object)
    if "segment" in names:  # ids as integers
        cells[:, names.index("segment")] = a[:, names.index("segment")].astype(np.int64).tolist()
    rows = (",".join(map(repr, row)) for row in cells.tolist())
    return "\n".join([",".join(names), *rows, ""]).encode("utf-8")


def write_log(path: str | os.PathLike, data: DynamicsData) -> Path:
    """Write ``data`` atomically (:func:`cascgp.io.atomic_write`): ``.npz`` as :meth:`DynamicsData.save`,
    anything else as a CSV log with every column (``t``, ``segment`` when there is more than one segment,
    ``q``, ``qd``, ``qdd``, ``tau``; no ``tau`` for a log read without torques, ``meta["has_tau"]`` false), values
    printed to round-trip exactly (Python's shortest repr of each float)."""
    if not isinstance(data, DynamicsData):
        raise TypeError(f"data: expected DynamicsData, got {type(data).__name__}")
    path = Path(path)
    if path.suffix.lower() == ".npz":
        return data.save(path)
    cols: dict[str, np.ndarray] = {"t": data.t}
    if len(data.segments) > 1:
        assert data.segment is not None  # DynamicsData stores the ids (None is only a constructor argument)
        cols["segment"] = data.segment
    for g in _GROUPS:
        if g == "tau" and data.meta.get("has_tau") is False:  # a zero placeholder, not measured torques
            continue
        for j in range(data.dof):
            cols[f"{g}{j + 1}"] = getattr(data, g)[:, j]
    body = _csv_bytes(cols)
    return atomic_write(path, lambda f: f.write(body))


def write_predictions(path: str | os.PathLike, t: np.ndarray, mean: np.ndarray, var: np.ndarray,
                      segment: np.ndarray | None = None) -> Path:
    """Write predictions atomically as CSV: ``t``, ``segment`` (the log's segment ids, when ``segment`` holds more
    than one: times may restart in each segment), ``tau1..tauN`` (predicted mean torques, N m) and ``var1..varN``
    (their variances, N² m²), one row per query."""
    t = np.asarray(t, dtype=np.float64)
    mean, var = np.asarray(mean, dtype=np.float64), np.asarray(var, dtype=np.float64)
    if mean.ndim != 2 or var.shape != mean.shape or t.shape != (mean.shape[0],):
        raise ValueError(f"predictions: expected t (T,), mean and var (T, N); got t {t.shape}, mean {mean.shape}, "
                         f"var {var.shape}")
    seg = None if segment is None else np.asarray(segment)
    if seg is not None and (seg.shape != t.shape or seg.dtype.kind not in "iuf"
                            or not np.isfinite(seg.astype(np.float64)).all() or (seg != np.round(seg)).any()):
        raise ValueError(f"segment: expected integer ids of shape {t.shape}, got {seg.dtype} {seg.shape}")
    cols = {"t": t, **({"segment": seg} if seg is not None and len(np.unique(seg)) > 1 else {}),
            **{f"tau{j + 1}": mean[:, j] for j in range(mean.shape[1])},
            **{f"var{j + 1}": var[:, j] for j in range(mean.shape[1])}}
    body = _csv_bytes(cols)
    return atomic_write(path, lambda f: f.write(body))
