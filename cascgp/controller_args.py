"""The argument checks of :class:`cascgp.controller.FeedforwardController`: gains, times, measurements and the
reference, each refused with an error naming it. The tick calls them every time: each takes the usual case (a
float64 array of the right shape) first, at the cost of a few comparisons."""

from __future__ import annotations

import inspect
import math
from typing import Any, Callable

import numpy as np

from cascgp.data import F64 as _F64, as_real_array

__all__ = ["as_gain", "check_time", "check_finite_reference", "check_predict_one", "measured", "reference_at"]

Reference = Callable[[float], tuple[np.ndarray, np.ndarray, np.ndarray]]


def as_gain(value: float | np.ndarray, dof: int, name: str) -> np.ndarray:
    """``value`` (one number or one per joint) as a read-only (dof,) array of finite, non-negative gains."""
    try:  # TypeError for complex (a cast drops the imaginary part), boolean, text, None
        arr = as_real_array(name, value, f"one real number or {dof} of them (one per joint)")
    except TypeError:
        raise TypeError(f"{name} must be one real number or {dof} of them (one per joint), got {value!r}") from None
    try:
        gain = np.broadcast_to(arr, (dof,)).copy()
    except ValueError:
        raise ValueError(f"{name} must be one real number or {dof} of them (one per joint, as torque_limits), got "
                         f"shape {arr.shape}") from None
    if not np.all(np.isfinite(gain)) or np.any(gain < 0):
        raise ValueError(f"{name} must be finite and non-negative, got {value!r}")
    gain.setflags(write=False)  # changed only through the checked assignment
    return gain


def check_time(t: Any, finite: bool = True) -> float:
    """``t`` as a float; ``TypeError`` unless it is a real number, ``ValueError`` if it is beyond float64's range
    or, with ``finite``, not finite (a time in s: the reference cannot be evaluated at NaN or inf)."""
    if isinstance(t, (bool, np.bool_)) or not isinstance(t, (int, float, np.integer, np.floating)):
        raise TypeError(f"t: expected a real number (s), got {type(t).__name__}")
    try:
        f = float(t)
    except OverflowError:  # an int beyond float64's range
        raise ValueError(f"t: expected a time (s) within float64's range, got {t!r}") from None
    if finite and not math.isfinite(f):
        raise ValueError(f"t: expected a finite time (s), got {t!r}")
    return f


def check_finite_reference(q_d: np.ndarray, qd_d: np.ndarray, qdd_d: np.ndarray, t: float) -> None:
    """``ValueError`` naming the first of ``q_d``, ``qd_d``, ``qdd_d`` with a NaN or inf entry: a reference is the
    caller's computation, so a non-finite one is a bug to report, not a sensor fault to ride out."""
    for name, x in (("q_d", q_d), ("qd_d", qd_d), ("qdd_d", qdd_d)):
        bad = np.flatnonzero(~np.isfinite(x))
        if bad.size:
            raise ValueError(f"reference: {name} at t={t} must be finite; entries {bad.tolist()} are NaN or inf: "
                             f"{x.tolist()}")


def measured(name: str, x: Any, dof: int) -> np.ndarray:
    """A measurement as a float64 (dof,) array (the array itself when it is one); ``TypeError`` / ``ValueError``
    naming ``name`` otherwise. NaN and inf pass: a non-finite measurement is a sensor fault, not an error."""
    if type(x) is np.ndarray and x.dtype == _F64 and x.shape == (dof,):
        return x  # what the general form below returns for a float64 (N,) array
    try:
        a = np.asarray(x)
    except (TypeError, ValueError) as exc:  # ragged nested sequences
        raise TypeError(f"{name}: expected a real numeric array of shape ({dof},) ({exc})") from None
    if a.dtype.kind not in "fiu":
        raise TypeError(f"{name}: expected a real numeric array, got dtype {a.dtype}")
    if a.shape != (dof,):
        raise ValueError(f"{name}: expected shape ({dof},), got {a.shape}")
    return a.astype(float, copy=False)


def reference_at(reference: Reference, t: float, dof: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``reference(t)`` as three float64 (dof,) arrays ``(q_d, qd_d, qdd_d)``; ``TypeError`` / ``ValueError``
    naming ``reference`` and the part otherwise (finiteness is checked by the caller, where it matters)."""
    out = reference(t)
    if not isinstance(out, (tuple, list)) or len(out) != 3:
        raise ValueError("reference: expected reference(t) to return (q_d, qd_d, qdd_d)")
    a, b, c = out
    shape = (dof,)
    if (type(a) is np.ndarray and type(b) is np.ndarray and type(c) is np.ndarray and a.dtype == _F64
            and b.dtype == _F64 and c.dtype == _F64 and a.shape == shape and b.shape == shape and c.shape == shape):
        return a, b, c  # what the general form below returns for float64 (N,) arrays
    parts = []
    for nm, x in zip(("q_d", "qd_d", "qdd_d"), out):
        arr = np.asarray(x)
        if arr.dtype.kind not in "fiu":
            raise TypeError(f"reference: {nm} must be a real numeric array, got dtype {arr.dtype}")
        if arr.shape != shape:
            raise ValueError(f"reference: {nm} must have shape ({dof},), got {arr.shape}")
        parts.append(arr.astype(float, copy=False))
    return parts[0], parts[1], parts[2]


def check_predict_one(model: Any, method: str = "predict_one") -> None:
    """``TypeError`` naming ``model`` when its ``method`` (``predict_one``, or a variance gate's
    ``predict_one_var``) cannot take what the controller passes, ``(q, qd, qdd, q_hist=...)`` (a model without it
    fell back to the rigid-body torque on every tick, raising nothing)."""
    fn = getattr(model, method, None)
    if fn is None:
        return
    if not callable(fn):
        raise TypeError(f"model: {method} must be a method, got {type(fn).__name__} on {type(model).__name__}")
    try:
        sig = inspect.signature(fn)
        sig.bind(None, None, None, q_hist=None)
    except ValueError:  # no signature to read (a compiled function): trusted
        return
    except TypeError:
        raise TypeError(f"model: the controller calls {method}(q, qd, qdd, q_hist=...), and "
                        f"{type(model).__name__}.{method}{sig} cannot take that") from None
