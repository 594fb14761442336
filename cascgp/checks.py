"""Checks of settings shared by the library and the experiments: a bad value raises ``ValueError`` naming the field
and what was expected. Imports neither torch nor MuJoCo, so settings classes can use it at import time."""

from __future__ import annotations

import math
import numbers
from typing import Any, Literal, overload

import numpy as np

#: Most optimiser starts per GP a fit takes (the default is 10): a command line's 100000000 is refused at once
#: instead of failing in the fit's memory plan.
MAX_RESTARTS = 1000

__all__ = ["MAX_RESTARTS", "check_count", "check_positive", "check_real_vector"]


@overload
def check_count(v: Any, field_name: str, minimum: int = ..., optional: Literal[False] = ...) -> int: ...


@overload
def check_count(v: Any, field_name: str, minimum: int = ..., *, optional: bool) -> int | None: ...


def check_count(v: Any, field_name: str, minimum: int = 1, optional: bool = False) -> int | None:
    """``v`` as an ``int`` if it is an integer (Python or NumPy, not ``bool``) of at least ``minimum``, or ``None``
    when ``optional``; else ``ValueError`` naming ``field_name`` and what was expected."""
    if optional and v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < minimum:
        raise ValueError(f"{field_name}: expected {'None or ' if optional else ''}an integer >= {minimum}, got {v!r}")
    return int(v)


def check_positive(v: Any, field_name: str, unit: str = "", zero: bool = False) -> float:
    """``v`` as a ``float`` if it is a finite real number above 0 (or 0 itself, with ``zero``); else ``ValueError``
    naming ``field_name``. A 0-d NumPy array counts as its number."""
    if isinstance(v, np.ndarray) and v.ndim == 0 and v.dtype.kind in "fiu":
        v = v[()]
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(v) \
            or v < 0 or (v == 0 and not zero):
        raise ValueError(f"{field_name}: expected a finite number {'>=' if zero else '>'} 0"
                         f"{f' ({unit})' if unit else ''}, got {v!r}")
    return float(v)


def _is_real(v: Any) -> bool:
    """A real number (Python or NumPy, a 0-d array of one), not a bool or a string."""
    if isinstance(v, np.ndarray) and v.ndim == 0:
        return v.dtype.kind in "fiu"
    return isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_))


def check_real_vector(value: Any, field_name: str, n: int, per: str = "one value per joint") -> np.ndarray:
    """``value`` as ``n`` finite floats (one number is repeated); else ``ValueError`` naming ``field_name``. Strings
    and booleans (a JSON file's ``"30"`` or ``true``) are refused, not converted."""
    if isinstance(value, np.ndarray) and value.dtype.kind in "fiu":
        arr = value.astype(float)
    else:
        raw = np.asarray(value, dtype=object)
        if not all(_is_real(v) for v in raw.ravel()):
            raise ValueError(f"{field_name}: expected numbers, got {value!r}")
        arr = np.array([float(v) for v in raw.ravel()]).reshape(raw.shape)
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,):
        raise ValueError(f"{field_name} must have shape ({n},) ({per}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{field_name} must be finite, got {arr}")
    return arr
