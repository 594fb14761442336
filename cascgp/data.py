"""One record type for everything the inverse-dynamics models learn from.

:class:`DynamicsData` holds, per time step, the joint positions ``q``, velocities ``qd``,
accelerations ``qdd`` and torques ``tau`` of an N-DOF arm (each ``(T, N)``), the sample
times ``t`` and a ``segment`` id per row (time-contiguous pieces: episodes, recordings, ...),
plus JSON metadata.

================  ===========  ==========================================================
field             shape        meaning
================  ===========  ==========================================================
``q``             (T, N)       joint positions (rad)
``qd``            (T, N)       joint velocities (rad/s)
``qdd``           (T, N)       joint accelerations (rad/s^2)
``tau``           (T, N)       joint torques (N m)
``t``             (T,)         time (s), strictly increasing within a segment
``segment``       (T,)         int64 segment id, non-decreasing
``meta``          dict         JSON-serialisable: robot, source, payload_mass, ...
================  ===========  ==========================================================

Every instance is validated on construction (shapes, finite values, non-decreasing segment
ids, strictly increasing time within a segment); a violation raises ``ValueError`` whose
message names the field and the first bad row.  An empty record (``T = 0``) is refused.

Files are ``.npz`` archives (``numpy.savez``) written atomically (temporary file in the same
folder, then :func:`os.replace`) and re-validated on load.  Format version:
:data:`FORMAT_VERSION`.

(One record type with its validation, slicing and file format; the numerical differentiation of
:meth:`DynamicsData.from_measurements` is :mod:`cascgp.derivatives`.)
"""

from __future__ import annotations

import json
import math
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .checks import check_count, check_positive
from .derivatives import SavGol, as_savgol, differentiate
from .io import atomic_savez, check_format_header, read_npz

__all__ = ["DynamicsData", "SavGol", "FORMAT_VERSION", "differentiate"]

#: Version of the ``.npz`` layout written by :meth:`DynamicsData.save`.
FORMAT_VERSION = 1
_KIND = "cascgp.DynamicsData"
_ARRAY_FIELDS = ("q", "qd", "qdd", "tau")


# --------------------------------------------------------------------------- validation
#: The float64 dtype, for the control tick's ``x.dtype == F64`` tests of its float64 arrays (cheaper than
#: comparing with ``np.float64``, which builds a dtype each time).
F64 = np.dtype(np.float64)


def all_finite(x: np.ndarray) -> bool:
    """Whether every entry of the short 1-D float vector ``x`` is finite: ``np.isfinite(x).all()`` in about a
    fifth of its time for the few-entry vectors checked every control tick (a list of a few Python floats instead
    of a ufunc and a reduction). No floating-point warnings, whatever the entries."""
    return all(map(math.isfinite, x.tolist()))


def as_real_array(label: str, raw: object, shape: str) -> np.ndarray:
    """A float64 copy of ``raw``; ``TypeError`` naming ``label`` for complex, boolean, text or other
    non-numeric input (a cast would silently drop an imaginary part or turn flags into numbers)."""
    try:
        a0 = np.asarray(raw)
    except (TypeError, ValueError, RuntimeError) as exc:  # ragged nested lists; a torch tensor that requires grad
        raise TypeError(f"{label}: expected a numeric {shape} array ({exc})") from None
    if a0.dtype.kind not in "fiuO":
        raise TypeError(f"{label}: expected a real numeric {shape} array, got dtype {a0.dtype}")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", np.exceptions.ComplexWarning)
            return np.array(a0, dtype=np.float64, order="C", copy=True)
    except (TypeError, ValueError, np.exceptions.ComplexWarning) as exc:
        raise TypeError(f"{label}: expected a real numeric {shape} array ({exc})") from None


def _first_bad_row(mask: np.ndarray) -> int:
    return int(np.flatnonzero(mask)[0])


def _check_finite(name: str, a: np.ndarray) -> None:
    bad = ~np.isfinite(a)
    if bad.any():
        rows = bad.reshape(bad.shape[0], -1).any(axis=1) if bad.ndim > 1 else bad
        r = _first_bad_row(rows)
        col = ""
        if a.ndim > 1:
            col = f", column {int(np.flatnonzero(bad[r].ravel())[0])}"
        raise ValueError(f"DynamicsData.{name}: non-finite value (NaN or inf) at row {r}{col}")


@dataclass(frozen=True, eq=False)
class DynamicsData:
    """Samples of an N-DOF arm's inverse dynamics (see the module docstring for the table).

    Arrays are stored as C-contiguous float64 (``segment`` as int64) copies.

    Example:
        >>> import numpy as np
        >>> t = np.arange(0.0, 2.0, 0.01)                      # 2 s at 100 Hz, one 2-joint motion
        >>> q = np.stack([np.sin(t), np.cos(t)], axis=1)
        >>> data = DynamicsData(q=q, qd=np.gradient(q, t, axis=0), qdd=-q, tau=-q, t=t)
        >>> data.n_samples, data.dof, round(data.duration, 2)
        (200, 2, 2.0)
        >>> data.first_seconds(1.0).subsample(10.0).n_samples   # the first second, thinned to 10 Hz
        10
    """

    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray
    t: np.ndarray
    segment: np.ndarray | None = None
    meta: dict = field(default_factory=dict)

    @property
    def _ids(self) -> np.ndarray:
        """``segment`` as :meth:`__post_init__` stores it (``None`` is only ever a constructor argument)."""
        assert self.segment is not None
        return self.segment

    # ------------------------------------------------------------------ construction
    def __post_init__(self) -> None:
        arrays: dict[str, np.ndarray] = {}
        for name in _ARRAY_FIELDS:
            a = as_real_array(f"DynamicsData.{name}", getattr(self, name), "(T, N)")
            if a.ndim != 2:
                raise ValueError(f"DynamicsData.{name}: expected shape (T, N), got {a.shape}")
            arrays[name] = a
        shape = arrays["q"].shape
        for name in _ARRAY_FIELDS[1:]:
            if arrays[name].shape != shape:
                raise ValueError(
                    f"DynamicsData.{name}: expected shape {shape} (the shape of q), "
                    f"got {arrays[name].shape}")
        T, N = shape
        if T == 0:
            raise ValueError("DynamicsData.q: empty data set (T = 0 rows); at least one sample is needed")
        if N == 0:
            raise ValueError("DynamicsData.q: expected at least one joint (N >= 1), got N = 0")
        t = as_real_array("DynamicsData.t", self.t, "(T,)")
        if t.shape != (T,):
            raise ValueError(f"DynamicsData.t: expected shape ({T},), got {t.shape}")
        if self.segment is None:
            seg = np.zeros(T, dtype=np.int64)
        else:
            seg_raw = np.asarray(self.segment)
            if seg_raw.shape != (T,):
                raise ValueError(f"DynamicsData.segment: expected shape ({T},), got {seg_raw.shape}")
            if seg_raw.dtype.kind not in "iub":
                if seg_raw.dtype.kind == "f" and np.all(np.isfinite(seg_raw)) and np.all(
                        seg_raw == np.round(seg_raw)):
                    pass
                else:
                    raise TypeError(
                        f"DynamicsData.segment: expected integer ids, got dtype {seg_raw.dtype}")
            if seg_raw.dtype.kind in "uf" and seg_raw.size and not np.abs(seg_raw).max() < 2.0**63:
                big = seg_raw[~(np.abs(seg_raw) < 2.0**63)][0]
                raise ValueError(f"DynamicsData.segment: expected ids within +-2**63, got {big!r}")
            seg = np.array(seg_raw, dtype=np.int64, order="C", copy=True)
        for name in _ARRAY_FIELDS:
            _check_finite(name, arrays[name])
        _check_finite("t", t)
        if T > 1:
            dseg = np.diff(seg)
            if (dseg < 0).any():
                r = _first_bad_row(dseg < 0) + 1
                raise ValueError(
                    f"DynamicsData.segment: ids must be non-decreasing; row {r} has id {seg[r]} "
                    f"after {seg[r - 1]}")
            same = dseg == 0
            bad = same & (np.diff(t) <= 0)
            if bad.any():
                r = _first_bad_row(bad) + 1
                raise ValueError(
                    f"DynamicsData.t: time must be strictly increasing within a segment; row {r} "
                    f"(t = {float(t[r])!r}) does not come after row {r - 1} (t = {float(t[r - 1])!r}) "
                    f"in segment {seg[r]}")
        if self.meta is not None and not isinstance(self.meta, dict):
            raise TypeError(f"DynamicsData.meta: expected a dict, got {type(self.meta).__name__}")
        meta = dict(self.meta) if self.meta is not None else {}
        try:
            meta = json.loads(json.dumps(meta))
        except (TypeError, ValueError) as exc:
            raise TypeError(f"DynamicsData.meta: expected a JSON-serialisable dict ({exc})") from None
        for name, a in arrays.items():
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        t.setflags(write=False)
        seg.setflags(write=False)
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "segment", seg)
        object.__setattr__(self, "meta", meta)

    # ------------------------------------------------------------------ properties
    @property
    def n_samples(self) -> int:
        """Number of rows T."""
        return int(self.q.shape[0])

    @property
    def dof(self) -> int:
        """Number of joints N."""
        return int(self.q.shape[1])

    @property
    def dt(self) -> float:
        """Median sample period (s) over consecutive rows of the same segment; ``nan`` if no
        segment has two rows."""
        d = self._within_segment_diffs()
        return float(np.median(d)) if d.size else float("nan")

    @property
    def duration(self) -> float:
        """Seconds of data: the sum over segments of ``t_last - t_first + dt`` (for regular
        sampling this is ``n_samples * dt``).  Segments of one row count ``dt`` (0 if ``dt``
        is undefined)."""
        dt = self.dt
        dt = 0.0 if not np.isfinite(dt) else dt
        total = 0.0
        for lo, hi in self.segment_bounds():
            total += float(self.t[hi - 1] - self.t[lo]) + dt
        return total

    @property
    def segments(self) -> np.ndarray:
        """The distinct segment ids in order."""
        return np.unique(self._ids)

    def segment_bounds(self) -> list[tuple[int, int]]:
        """``[(start, stop), ...]`` row ranges of the segments, in order."""
        if self.n_samples == 0:
            return []
        cuts = np.flatnonzero(np.diff(self._ids) != 0) + 1
        starts = np.concatenate([[0], cuts])
        stops = np.concatenate([cuts, [self.n_samples]])
        return [(int(a), int(b)) for a, b in zip(starts, stops)]

    def _within_segment_diffs(self) -> np.ndarray:
        if self.n_samples < 2:
            return np.zeros(0)
        same = np.diff(self._ids) == 0
        return np.diff(self.t)[same]

    def __len__(self) -> int:
        return self.n_samples

    def __repr__(self) -> str:
        return (f"DynamicsData(n_samples={self.n_samples}, dof={self.dof}, dt={self.dt:.4g}, "
                f"segments={len(self.segments)}, meta={self.meta})")

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_measurements(cls, t: np.ndarray, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, *,
                          smoothing: SavGol | int | None = None, meta: dict | None = None,
                          segment: np.ndarray | None = None) -> "DynamicsData":
        """Build a record from measured ``q``, ``qd`` and ``tau``, with ``qdd`` by numerical
        differentiation of ``qd`` with respect to ``t``.

        Without smoothing (``smoothing=None``) the derivative is taken within each segment by
        :func:`numpy.gradient` with the sample times as coordinates: second-order central
        differences in the interior (exact for non-uniform spacing of a quadratic) and
        first-order one-sided differences at the segment's ends.  A segment of a single row
        gets ``qdd = 0``.

        ``smoothing=SavGol(window, polyorder)`` (or an odd ``int`` window, polyorder 2) uses a
        Savitzky-Golay differentiating filter instead (see :class:`SavGol`): less noise, a
        little more bias on fast motions; no phase lag when centred (the default), past rows only
        with ``SavGol(..., causal=True)``.
        """
        smoothing = as_savgol(smoothing)
        qd_a = as_real_array("DynamicsData.qd", qd, "(T, N)")  # complex, text or ragged input refused by name
        # Build once without qdd to get all shape/finite/time checks with the usual messages.
        probe = cls(q=q, qd=qd_a, qdd=np.zeros_like(qd_a), tau=tau, t=t, segment=segment,
                    meta=meta or {})
        qdd = differentiate(probe.t, probe.qd, probe._ids, smoothing)
        meta2 = dict(probe.meta)
        meta2.setdefault("qdd_source", "numerical differentiation of qd" + (
            f" ({'causal ' if smoothing.causal else ''}Savitzky-Golay window={smoothing.window}, "
            f"polyorder={smoothing.polyorder})"
            if smoothing is not None else " (central differences)"))
        return cls(q=probe.q, qd=probe.qd, qdd=qdd, tau=probe.tau, t=probe.t,
                   segment=probe.segment, meta=meta2)

    @classmethod
    def concat(cls, parts: Sequence["DynamicsData"], meta: dict | None = None) -> "DynamicsData":
        """Stack records row-wise.  Segment ids are renumbered so that segments of different
        parts never merge (part k's segments come after part k-1's).  ``meta`` defaults to
        the first part's meta if all parts share it, else ``{"concat_of": [metas]}``."""
        parts = list(parts)
        if not parts:
            raise ValueError("DynamicsData.concat: parts: expected at least one DynamicsData, got none")
        for i, p in enumerate(parts):
            if not isinstance(p, DynamicsData):
                raise TypeError(f"DynamicsData.concat: parts[{i}]: expected DynamicsData, got {type(p).__name__}")
            if p.dof != parts[0].dof:
                raise ValueError(
                    f"DynamicsData.concat: parts[{i}]: dof {p.dof} differs from parts[0]'s {parts[0].dof}")
        segs, offset = [], 0
        for p in parts:
            _, inv = np.unique(p._ids, return_inverse=True)
            segs.append(inv.astype(np.int64) + offset)
            offset += int(inv.max()) + 1
        if meta is None:
            metas = [p.meta for p in parts]
            meta = metas[0] if all(m == metas[0] for m in metas) else {"concat_of": metas}
        return cls(q=np.concatenate([p.q for p in parts]), qd=np.concatenate([p.qd for p in parts]),
                   qdd=np.concatenate([p.qdd for p in parts]),
                   tau=np.concatenate([p.tau for p in parts]), t=np.concatenate([p.t for p in parts]),
                   segment=np.concatenate(segs), meta=meta)

    # ------------------------------------------------------------------ selections
    def take(self, idx: np.ndarray | slice | Sequence[int]) -> "DynamicsData":
        """Rows ``idx`` (indices, boolean mask or slice), in the order given.  The result is
        validated like any record: indices must keep segments non-decreasing and time
        increasing within a segment (sort them first)."""
        if isinstance(idx, slice):
            sel: Any = idx
        else:
            sel = np.asarray(idx)
            if sel.ndim != 1:
                raise TypeError(f"take: idx: expected a 1-D sequence of indices, a boolean mask or a slice, got "
                                f"{type(idx).__name__} of shape {sel.shape}")
            if sel.size == 0:
                raise ValueError("take: idx: expected at least one row, got none")
            if sel.dtype == bool:
                if sel.shape != (self.n_samples,):
                    raise ValueError(f"take: idx: boolean mask of shape ({self.n_samples},) expected, got {sel.shape}")
            elif sel.dtype.kind not in "iu":
                raise TypeError(f"take: idx: expected integer indices, a boolean mask or a slice, got {sel.dtype}")
            elif sel.min() < -self.n_samples or sel.max() >= self.n_samples:
                bad = sel[(sel < -self.n_samples) | (sel >= self.n_samples)][0]
                raise ValueError(f"take: idx: row {bad} is out of range for {self.n_samples} rows")
        return DynamicsData(q=self.q[sel], qd=self.qd[sel], qdd=self.qdd[sel], tau=self.tau[sel],
                            t=self.t[sel], segment=self._ids[sel], meta=self.meta)

    def thin(self, max_samples: int) -> "DynamicsData":
        """At most ``max_samples`` rows, evenly spaced over all rows (first and last kept); ``self`` if it has no
        more. The rows of :meth:`thin_rows`."""
        rows = self.thin_rows(max_samples)
        return self if rows.size == self.n_samples else self.take(rows)

    def thin_rows(self, max_samples: int) -> np.ndarray:
        """The indices of the rows :meth:`thin` keeps (every row if there are at most ``max_samples``): row
        ``round(k (T - 1) / (max_samples - 1))`` for ``k = 0 .. max_samples - 1``, duplicates dropped."""
        max_samples = check_count(max_samples, "thin: max_samples", 2)
        if self.n_samples <= max_samples:
            return np.arange(self.n_samples)
        return np.unique(np.linspace(0, self.n_samples - 1, max_samples).round().astype(np.int64))

    def subsample(self, rate_hz: float) -> "DynamicsData":
        """Keep rows at (about) ``rate_hz`` within each segment: the first row of a segment,
        then every row at least ``1/rate_hz`` after the last kept one (with a tolerance of a
        quarter sample period).  For regular 50 Hz data and 10 Hz this keeps every 5th row.
        A rate at or above the data rate keeps every row.  Segments are kept. The rows of
        :meth:`subsample_rows`; ``meta["subsampled_hz"]`` records the rate."""
        out = self.take(self.subsample_rows(rate_hz))
        meta = dict(out.meta)
        meta["subsampled_hz"] = float(rate_hz)
        return DynamicsData(q=out.q, qd=out.qd, qdd=out.qdd, tau=out.tau, t=out.t,
                            segment=out.segment, meta=meta)

    def subsample_rows(self, rate_hz: float) -> np.ndarray:
        """The indices of the rows :meth:`subsample` keeps."""
        rate_hz = check_positive(rate_hz, "subsample: rate_hz", "Hz")
        period = 1.0 / rate_hz
        dt = self.dt
        tol = 0.25 * dt if np.isfinite(dt) else 0.0
        keep = np.zeros(self.n_samples, dtype=bool)
        for lo, hi in self.segment_bounds():
            last = None
            for r in range(lo, hi):
                if last is None or self.t[r] >= last + period - tol:
                    keep[r] = True
                    last = self.t[r]
        return np.flatnonzero(keep)

    def split(self, k: int) -> list["DynamicsData"]:
        """Split into ``k`` time-contiguous subsets of (nearly) equal row counts, in order
        (``numpy.array_split`` over the rows; a segment may straddle two subsets)."""
        if not isinstance(k, (int, np.integer)) or k < 1:
            raise ValueError(f"split: k: expected a positive integer, got {k!r}")
        if k > self.n_samples:
            raise ValueError(f"split: k: {k} subsets requested but only {self.n_samples} rows")
        return [self.take(ix) for ix in np.array_split(np.arange(self.n_samples), int(k))]

    def first_seconds(self, seconds: float) -> "DynamicsData":
        """The leading rows covering ``seconds`` of data, counted as in :attr:`duration`
        (segment after segment): row r is kept when the data time elapsed before it is below
        ``seconds``.  At 10 Hz, ``first_seconds(30)`` keeps 300 rows."""
        seconds = check_positive(seconds, "first_seconds: seconds", "s")
        dt = self.dt
        dt = 0.0 if not np.isfinite(dt) else dt
        elapsed = np.empty(self.n_samples)
        base = 0.0
        for lo, hi in self.segment_bounds():
            elapsed[lo:hi] = base + (self.t[lo:hi] - self.t[lo])
            base += float(self.t[hi - 1] - self.t[lo]) + dt
        keep = elapsed < seconds - 1e-9 * max(1.0, abs(seconds))
        return self.take(keep)

    # ------------------------------------------------------------------ files
    def save(self, path: str | os.PathLike, *, exclusive: bool = False) -> Path:
        """Write an ``.npz`` archive atomically (see :func:`cascgp.io.atomic_savez`); returns the path.
        ``exclusive=True`` raises ``FileExistsError`` instead of replacing an existing file."""
        try:
            meta_json = json.dumps(self.meta)
        except (TypeError, ValueError) as exc:  # meta changed after construction
            raise TypeError(f"DynamicsData.meta: expected a JSON-serialisable dict ({exc})") from None
        return atomic_savez(path, exclusive=exclusive, arrays={
            "format_kind": np.array(_KIND), "format_version": np.array(FORMAT_VERSION),
            "q": self.q, "qd": self.qd, "qdd": self.qdd, "tau": self.tau, "t": self.t,
            "segment": self._ids, "meta_json": np.array(meta_json),
        })

    @classmethod
    def load(cls, path: str | os.PathLike) -> "DynamicsData":
        """Read and validate a file written by :meth:`save`.  A missing file raises
        ``FileNotFoundError``; a corrupt/truncated archive, a missing field, another format
        version or invalid contents raise ``ValueError`` naming the file and the field."""
        z = read_npz(path, "DynamicsData")
        check_format_header(z, path, _KIND, FORMAT_VERSION)
        missing = [k for k in (*_ARRAY_FIELDS, "t", "segment", "meta_json") if k not in z]
        if missing:
            raise ValueError(f"{path}: missing field(s) {missing}")
        try:
            meta = json.loads(str(z["meta_json"]))
        except ValueError as exc:
            raise ValueError(f"{path}: meta_json: not valid JSON ({exc})") from exc
        try:
            return cls(q=z["q"], qd=z["qd"], qdd=z["qdd"], tau=z["tau"], t=z["t"],
                       segment=z["segment"], meta=meta)
        except (ValueError, TypeError) as exc:
            raise ValueError(f"{path}: {exc}") from exc
