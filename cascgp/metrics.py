"""Error metrics for torque predictions (paper: nRMSE = RMSE / range of the test targets)."""

from __future__ import annotations

import numpy as np
from scipy.stats import norm

__all__ = ["rmse", "nrmse", "interval_coverage", "std_scale_for_level"]


def _pair(pred: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    try:
        p = np.asarray(pred, dtype=np.float64)
        y = np.asarray(target, dtype=np.float64)
    except (TypeError, ValueError) as exc:  # text, ragged lists
        raise ValueError(f"pred/target: expected real (T, N) or (T,) arrays ({exc})") from None
    if p.ndim > 2 or y.ndim > 2:
        raise ValueError(f"pred/target: expected (T, N) or (T,) arrays, got shapes {p.shape} and {y.shape}")
    if p.ndim == 1:
        p = p[:, None]
    if y.ndim == 1:
        y = y[:, None]
    if p.ndim != 2 or p.shape != y.shape:
        raise ValueError(f"pred: expected the shape of target {np.shape(target)}, got {np.shape(pred)}")
    if p.shape[0] == 0:
        raise ValueError("target: expected at least one row, got 0")
    for name, a in (("pred", p), ("target", y)):
        bad = ~np.isfinite(a)
        if bad.any():
            r = int(np.flatnonzero(bad.any(axis=1))[0])
            raise ValueError(f"{name}: non-finite value at row {r}")
    return p, y


def rmse(pred: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Root-mean-square error per column (joint): ``sqrt(mean((pred - target)^2, axis=0))``.

    ``pred``, ``target``: (T, N) or (T,) -> (N,) (a 1-element array for (T,))."""
    p, y = _pair(pred, target)
    return np.sqrt(np.mean((p - y) ** 2, axis=0))


def nrmse(pred: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Normalised RMSE per joint: ``rmse / (max(target) - min(target))`` over the test rows.

    A joint whose test targets are constant (zero range) raises ``ValueError`` (the
    normalisation is undefined).

    Example:
        >>> import numpy as np
        >>> target = np.array([[0.0, 10.0], [1.0, 20.0], [2.0, 30.0]])
        >>> nrmse(target + [[0.2, 0.0]], target).round(3)       # 0.2 on a range of 2; exact on joint 2
        array([0.1, 0. ])
    """
    p, y = _pair(pred, target)
    rng = y.max(axis=0) - y.min(axis=0)
    if (rng <= 0).any():
        j = int(np.flatnonzero(rng <= 0)[0])
        raise ValueError(f"target: column {j} is constant (zero range); nRMSE is undefined")
    return np.sqrt(np.mean((p - y) ** 2, axis=0)) / rng


def _interval_inputs(mean: np.ndarray, var: np.ndarray, target: np.ndarray, level: float
                     ) -> tuple[np.ndarray, np.ndarray, float]:
    r"""Checked ``|target - mean|``, ``var`` (2-D) and the interval's :math:`z_{(1+\text{level})/2}`."""
    p, y = _pair(mean, target)
    v, _ = _pair(var, target)
    if (v < 0).any():
        raise ValueError("var: negative variance")
    if not 0.0 < level < 1.0:
        raise ValueError(f"level: expected a probability in (0, 1), got {level!r}")
    return np.abs(y - p), v, float(norm.ppf(0.5 + 0.5 * level))


def interval_coverage(mean: np.ndarray, var: np.ndarray, target: np.ndarray, level: float = 0.95) -> np.ndarray:
    r"""Fraction of targets inside the central Gaussian interval of probability ``level``, per joint:
    :math:`|y - \mu| \le z_{(1+\text{level})/2}\,\sqrt{v}` (1.96 standard deviations for 95 %).

    ``var`` must be the variance of a *measurement* (latent variance plus noise) to compare with measured
    targets. A calibrated model gives about ``level``. Shapes as :func:`rmse`; ``var`` >= 0."""
    err, v, z = _interval_inputs(mean, var, target, level)
    return np.mean(err <= z * np.sqrt(v), axis=0)


def std_scale_for_level(mean: np.ndarray, var: np.ndarray, target: np.ndarray, level: float = 0.95) -> np.ndarray:
    r"""Per joint, the factor :math:`c` on the predictive standard deviation that makes the central interval of
    probability ``level`` cover that fraction of ``target``: the ``level`` quantile of :math:`|y - \mu| / \sqrt{v}`
    (linear interpolation, so on ``n`` rows the coverage can fall short by up to :math:`1/n`) divided by
    :math:`z_{(1+\text{level})/2}`.

    :math:`c > 1`: the intervals are too narrow (overconfident); :math:`c < 1`: too wide. Fitted on held-out data
    and applied to new predictions (:math:`\sqrt{v} \to c \sqrt{v}`), it is the one-parameter recalibration of
    a Gaussian predictive distribution (a quantile fit; Kuleshov et al. 2018 fit the whole CDF). Shapes as
    :func:`interval_coverage`. A row with zero error counts as ratio 0; a zero variance with a non-zero error has
    no finite factor: ``ValueError`` naming ``var``."""
    err, v, z = _interval_inputs(mean, var, target, level)
    bad = (v == 0) & (err > 0)
    if bad.any():
        r, j = (int(i) for i in np.argwhere(bad)[0])
        raise ValueError(f"var: zero variance with a non-zero error (row {r}, column {j}): no finite std factor")
    ratio = np.divide(err, np.sqrt(v), out=np.zeros_like(err), where=err > 0)
    return np.quantile(ratio, level, axis=0) / z
