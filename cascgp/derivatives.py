"""Numerical differentiation of sampled joint signals: the accelerations a learner gets from measured
velocities (:meth:`cascgp.data.DynamicsData.from_measurements`, :mod:`cascgp.logs`).

:class:`SavGol` is the Savitzky-Golay derivative, centred (offline, zero phase) or causal (what a controller
running online can compute); :func:`differentiate` applies it per time-contiguous segment.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["SavGol", "as_savgol", "differentiate", "UNIFORM_TOLERANCE", "is_uniform"]

#: Sample periods within this fraction of their median count as uniform sampling.
UNIFORM_TOLERANCE = 0.05


def is_uniform(t: np.ndarray) -> bool:
    """Whether the periods of the sample times ``t`` (one segment, ascending) are all within
    :data:`UNIFORM_TOLERANCE` of their median."""
    d = np.diff(t)
    return not d.size or bool(np.max(np.abs(d - np.median(d))) <= UNIFORM_TOLERANCE * np.median(d))


@dataclass(frozen=True)
class SavGol:
    r"""Savitzky-Golay smoothing for :meth:`cascgp.data.DynamicsData.from_measurements`.

    The acceleration is the first derivative of a local polynomial of degree ``polyorder``
    fitted by least squares to ``window`` consecutive velocity samples. A uniformly sampled segment uses its
    median period; one whose periods vary by more than :data:`UNIFORM_TOLERANCE` of the median (dropped samples,
    say) is fitted at the actual sample times (centred filter; :func:`differentiate`).

    ============  =====================================================================================
    ``causal``    the estimate at sample :math:`t`
    ============  =====================================================================================
    ``False``     centred (offline): the fit to samples :math:`t - w/2 \ldots t + w/2`, evaluated at
                  :math:`t` (:func:`scipy.signal.savgol_filter`, ``deriv=1``, ``mode="interp"``); zero
                  phase, but it needs :math:`\lfloor w/2 \rfloor` future samples. Segments shorter than
                  ``window`` fall back to central differences.
    ``True``      causal (what a controller running online can compute): the fit to the last
                  :math:`w` samples :math:`t - w + 1 \ldots t`, evaluated at the newest one
                  (``savgol_coeffs(..., pos=window - 1)``); exact for polynomials of degree
                  ``polyorder``, but with a larger noise gain and a phase error that grows with
                  frequency. The first rows of a segment use the fit to the rows available (degree
                  lowered to fit); the first row gets 0.
    ============  =====================================================================================
    """

    window: int = 7
    polyorder: int = 2
    causal: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.causal, (bool, np.bool_)):
            raise TypeError(f"SavGol.causal: expected a bool, got {type(self.causal).__name__} {self.causal!r}")
        for name in ("window", "polyorder"):
            v = getattr(self, name)
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
                raise TypeError(f"SavGol.{name}: expected an integer, got {type(v).__name__} {v!r}")
        if self.window < 3 or self.window % 2 == 0:
            raise ValueError(f"SavGol.window: expected an odd integer >= 3, got {self.window}")
        if not 1 <= self.polyorder < self.window:
            raise ValueError(
                f"SavGol.polyorder: expected 1 <= polyorder < window, got {self.polyorder}")

    def noise_gain(self, dt: float) -> float:
        r"""Variance gain of the differentiating filter for white noise on the velocities, in s⁻².

        In the interior of a segment the filter is a fixed linear combination
        :math:`\hat{\ddot q}_t = \sum_k c_k \dot q_{t+k}` (``scipy.signal.savgol_coeffs(window, polyorder,
        deriv=1, delta=dt)``), so independent velocity noise of variance :math:`\sigma^2_{\dot q}` gives the
        acceleration noise variance :math:`\sigma^2_{\ddot q} = \sigma^2_{\dot q} \sum_k c_k^2`; this returns
        :math:`\sum_k c_k^2`. (Window 9, order 2, ``dt`` = 0.01 s: :math:`c_k = k / (60\,dt)`, gain
        :math:`1 / (60\,dt^2)` = 166.7 s⁻².) The centre coefficient of a centred first-derivative filter is 0,
        so that acceleration noise is uncorrelated with the velocity noise of the same sample; a causal
        filter's newest coefficient is not, so its acceleration noise is correlated with that sample's. The
        ``window // 2`` samples at each end of a segment (``mode="interp"``) and the first ``window - 1`` rows
        of a causal filter use other, noisier coefficients; they are not covered.
        """
        if not np.isfinite(dt) or dt <= 0:
            raise ValueError(f"dt: expected a positive sample period (s), got {dt!r}")
        c = self.coefficients(float(dt))
        return float(np.sum(c * c))

    def coefficients(self, dt: float) -> np.ndarray:
        r"""The interior filter :math:`c_k`: :math:`\hat{\ddot q}_t = \sum_k c_k \dot q_{t-w+1+k}` (causal) or
        :math:`\sum_k c_k \dot q_{t-\lfloor w/2 \rfloor+k}` (centred), in s⁻¹ per sample."""
        from scipy.signal import savgol_coeffs

        pos = self.window - 1 if self.causal else None
        return savgol_coeffs(self.window, self.polyorder, deriv=1, delta=float(dt), pos=pos, use="dot")


def as_savgol(smoothing: Any) -> SavGol | None:
    """A ``smoothing`` argument as a filter: ``None``, a :class:`SavGol`, or an odd ``int`` window (polyorder 2);
    ``TypeError`` naming ``smoothing`` otherwise."""
    if isinstance(smoothing, (int, np.integer)) and not isinstance(smoothing, bool):
        return SavGol(int(smoothing))
    if smoothing is not None and not isinstance(smoothing, SavGol):
        raise TypeError(f"smoothing: expected None, an odd int window or SavGol, got {smoothing!r}")
    return smoothing


def differentiate(t: np.ndarray, x: np.ndarray, segment: np.ndarray, smoothing: SavGol | None) -> np.ndarray:
    r"""Time derivative of ``x`` (T, N) within each segment: the filter of
    :meth:`cascgp.data.DynamicsData.from_measurements` and of logs without derivative columns (:mod:`cascgp.logs`).

    With ``smoothing`` a segment of at least ``smoothing.window`` rows uses :func:`scipy.signal.savgol_filter`
    (``deriv=1``, ``delta`` = the segment's median period, ``mode="interp"``) where it is uniformly sampled
    (:func:`is_uniform`), and the same local polynomial fitted at the actual sample times where it is not
    (a log with dropped samples: the uniform filter took every period for the median one, and was off by a fifth
    with one sample in ten dropped); shorter segments and ``smoothing=None`` use :func:`numpy.gradient` on the
    sample times. A one-row segment gets 0. A causal ``smoothing`` (:class:`SavGol` with ``causal=True``) uses
    past rows only, in every segment, at the median period.
    """
    out = np.zeros_like(x, dtype=np.float64)
    cuts = np.flatnonzero(np.diff(segment) != 0) + 1
    for lo, hi in zip(np.r_[0, cuts], np.r_[cuts, len(t)]):
        if hi - lo < 2:
            continue
        ts = t[lo:hi]
        if smoothing is not None and smoothing.causal:
            out[lo:hi] = _causal_derivative(x[lo:hi], float(np.median(np.diff(ts))), smoothing)
        elif smoothing is not None and hi - lo >= smoothing.window and not is_uniform(ts):
            out[lo:hi] = _local_polynomial_derivative(ts, x[lo:hi], smoothing.window, smoothing.polyorder)
        elif smoothing is not None and hi - lo >= smoothing.window:
            from scipy.signal import savgol_filter

            h = float(np.median(np.diff(ts)))
            out[lo:hi] = savgol_filter(x[lo:hi], smoothing.window, smoothing.polyorder, deriv=1, delta=h, axis=0,
                                       mode="interp")
        else:
            out[lo:hi] = np.gradient(x[lo:hi], ts, axis=0, edge_order=1)
    return out


def _local_polynomial_derivative(t: np.ndarray, x: np.ndarray, window: int, polyorder: int) -> np.ndarray:
    """The centred Savitzky-Golay derivative of one segment ``x`` (T, N), T >= ``window``, at the sample times ``t``:
    at each row the slope of the polynomial of degree ``polyorder`` fitted by least squares to the ``window`` rows
    around it (the first or last ``window`` rows near the segment's ends, as ``savgol_filter``'s ``mode="interp"``).
    Written here because SciPy's filter takes one sample period; on uniform times it equals that filter to
    round-off."""
    T, h = len(t), window // 2
    idx = np.clip(np.arange(T) - h, 0, T - window)[:, None] + np.arange(window)  # (T, window): each row's rows
    tau = t[idx] - t[:, None]  # the window's times from the row's
    span = np.abs(tau).max(axis=1)  # > 0: times increase within a segment
    V = (tau / span[:, None])[:, :, None] ** np.arange(polyorder + 1)  # (T, window, polyorder + 1), entries in [-1, 1]
    # least squares by the pseudo-inverse (SVD: as well conditioned as the scaled Vandermonde matrix, whatever the
    # pause inside a window); the slope at tau = 0 is row 1 of pinv(V), over the window's span
    slope = np.linalg.pinv(V)[:, 1, :] / span[:, None]  # (T, window)
    return np.einsum("tw,twn->tn", slope, x[idx])


def _causal_derivative(x: np.ndarray, h: float, smoothing: SavGol) -> np.ndarray:
    """The causal Savitzky-Golay derivative of one segment ``x`` (T, N), T >= 2, sample period ``h``."""
    from numpy.lib.stride_tricks import sliding_window_view
    from scipy.signal import savgol_coeffs

    w, T = smoothing.window, len(x)
    out = np.zeros_like(x, dtype=np.float64)
    for m in range(2, min(w, T + 1)):  # row m - 1 sees the m rows 0 .. m - 1
        c = savgol_coeffs(m, min(smoothing.polyorder, m - 1), deriv=1, delta=h, pos=m - 1, use="dot")
        out[m - 1] = c @ x[:m]
    if T >= w:
        out[w - 1:] = sliding_window_view(x, w, axis=0) @ smoothing.coefficients(h)
    return out
