"""Input checks shared by the environments and the reference controllers (clear errors naming the field)."""

from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np


def is_real_number(value) -> bool:
    """True for a real number (Python or NumPy int/float); False for bools, strings, complex, arrays."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def real_array(value, shape: tuple[int, ...], what: str, *, finite: bool = True) -> np.ndarray:
    """``value`` as a float64 array of ``shape`` (a copy); otherwise an error naming ``what``.

    ``TypeError`` for anything that is not real numbers (strings, bools, complex, None, ...: refused
    before any cast, so that e.g. an imaginary part is never silently dropped); ``ValueError`` for a
    wrong shape or, with ``finite``, a NaN/inf entry.
    """
    try:
        a = np.asarray(value)
    except (TypeError, ValueError) as exc:  # ragged nested sequences
        raise TypeError(f"{what} must be an array of real numbers, got {type(value).__name__}") from exc
    if a.dtype.kind == "O":
        if not all(is_real_number(x) for x in a.flat):
            raise TypeError(f"{what} must be an array of real numbers, got {value!r}")
    elif a.dtype.kind not in "iuf":
        raise TypeError(f"{what} must be an array of real numbers, got dtype {a.dtype} ({value!r})")
    if a.shape != shape:
        raise ValueError(f"{what} must have shape {shape}, got shape {a.shape}")
    a = a.astype(np.float64)
    if finite and not np.isfinite(a).all():
        bad = np.flatnonzero(~np.isfinite(a)).tolist()
        raise ValueError(f"{what} must be finite; entries {bad} are NaN or inf: {a.tolist()}")
    return a


def check_mass(value: Any, lo: float, hi: float, what: str) -> float:
    """``value`` as a float in [lo, hi] kg (TypeError / ValueError naming ``what`` otherwise).

    Only real numbers are accepted: a string such as ``"1.2"``, a bool or a complex number raises
    ``TypeError`` (``float()`` would silently accept the first two).
    """
    if not is_real_number(value):
        raise TypeError(f"{what} must be a real number (kg), got {type(value).__name__} {value!r}")
    v = float(value)
    if not math.isfinite(v) or not (lo <= v <= hi):
        raise ValueError(f"{what} must be in [{lo:.3f}, {hi:.3f}] kg, got {v!r}")
    return v
