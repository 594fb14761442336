"""Input checks of the GP bank: every bad input raises an error naming the field (``X[1]``, ``y[0]``, ...)."""

from __future__ import annotations

from typing import Any

import numpy as np

from cascgp.data import as_real_array

__all__ = ["as_list", "real_array", "check_matrix", "check_vector", "check_scale", "json_num"]


def json_num(v: float) -> float | None:
    """JSON-friendly float: ``None`` for NaN (a start that was not run or not screened)."""
    return None if not np.isfinite(v) and np.isnan(v) else float(v)


def as_list(v: Any, field_name: str) -> list[np.ndarray]:
    if isinstance(v, np.ndarray):
        raise TypeError(f"{field_name}: expected a list of arrays (one per GP), got a single ndarray")
    if not isinstance(v, (list, tuple)) or len(v) == 0:
        raise ValueError(f"{field_name}: expected a non-empty list of arrays (one per GP), got {type(v).__name__}")
    return list(v)


def real_array(a: Any, field_name: str, shape: str) -> np.ndarray:
    """``a`` as float64; ``TypeError`` naming the field for complex, boolean, text or other non-numeric input (a
    cast would drop an imaginary part or turn flags into numbers)."""
    if type(a) is np.ndarray and a.dtype == np.float64:  # not a subclass (a masked array's NaN would pass)
        return a
    return as_real_array(field_name, a, shape)


def check_matrix(a: Any, field_name: str, d: int | None = None, n: int | None = None) -> np.ndarray:
    a = real_array(a, field_name, "(n, d)")
    if a.ndim != 2:
        raise ValueError(f"{field_name}: expected a 2-D array (n, d), got shape {a.shape}")
    if a.shape[1] < 1:
        raise ValueError(f"{field_name}: expected at least one input column, got shape {a.shape}")
    if d is not None and a.shape[1] != d:
        raise ValueError(f"{field_name}: expected {d} columns, got shape {a.shape}")
    if n is not None and a.shape[0] != n:
        raise ValueError(f"{field_name}: expected {n} rows (the same n for every GP), got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        row = int(np.argwhere(~np.isfinite(a))[0, 0])
        raise ValueError(f"{field_name}: contains NaN or inf (first at row {row})")
    return a


def check_vector(a: Any, field_name: str, n: int) -> np.ndarray:
    a = real_array(a, field_name, f"({n},)")
    if a.ndim != 1 or a.shape[0] != n:
        raise ValueError(f"{field_name}: expected shape ({n},), got {a.shape}")
    if not np.all(np.isfinite(a)):
        row = int(np.argwhere(~np.isfinite(a))[0, 0])
        raise ValueError(f"{field_name}: contains NaN or inf (first at row {row})")
    return a


def check_scale(a: np.ndarray, field_name: str) -> None:
    """``ValueError`` naming the field when finite values are too large to normalise: their standard deviation
    overflows (|values| beyond ~1e154), which would turn every prediction into NaN."""
    with np.errstate(over="ignore", invalid="ignore"):
        sd = np.asarray(a.std(0))
    bad = ~np.isfinite(sd)
    if bad.any():
        col = int(np.flatnonzero(bad.ravel())[0]) if a.ndim > 1 else None
        where = f" (column {col})" if col is not None else ""
        raise ValueError(f"{field_name}: values too large to normalise{where}: largest magnitude "
                         f"{float(np.abs(a).max()):.3g}, whose square overflows float64")
