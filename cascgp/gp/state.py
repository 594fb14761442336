"""What a fitted GP bank *is* (:class:`BankData`: training set, normalisation, hyperparameters) and its saved form.

:func:`bank_state` writes plain NumPy arrays and JSON strings (no pickle); :func:`bank_from_state` validates every
field and raises ``ValueError`` naming it (``state['theta']: expected shape ...``). Everything else about a
fitted bank (Cholesky factors, ``alpha``) is recomputed from this on load.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from cascgp.gp.config import GPFitConfig

__all__ = ["BankData", "STATE_VERSION", "bank_state", "bank_from_state"]

#: Version of the saved bank layout.
STATE_VERSION = 1
_FORMAT = "cascgp.GPBank"


@dataclass
class BankData:
    """Training set and normalisation of ``B`` GPs, padded to the widest input ``D`` (float64 NumPy).

    Attributes:
        dims: ``(B,)`` input dimension per GP.
        X: ``(B, n, D)`` raw inputs (zero padded); y: ``(B, n)`` raw targets.
        x_mean, x_std, mask: ``(B, D)`` input normalisation; ``mask`` is 1 for active columns, 0 for padding and
            constant columns.
        y_mean, y_std: ``(B,)`` target normalisation (``y_std = 1`` for a constant target).
        const_y: ``(B,)`` bool, constant target (the GP is not optimised).
        theta: ``(B, D + 2)`` log hyperparameters in normalised units.
    """

    dims: np.ndarray
    X: np.ndarray
    y: np.ndarray
    x_mean: np.ndarray
    x_std: np.ndarray
    mask: np.ndarray
    y_mean: np.ndarray
    y_std: np.ndarray
    const_y: np.ndarray
    theta: np.ndarray

    @classmethod
    def normalise(cls, Xs: list[np.ndarray], ys: list[np.ndarray], D: int) -> BankData:
        """Pad and normalise checked inputs (constant columns masked, constant targets flagged); ``theta`` is
        zero until the fit sets it."""
        B, n = len(Xs), Xs[0].shape[0]
        dims = np.array([a.shape[1] for a in Xs], dtype=np.int64)
        Xp = np.zeros((B, n, D))
        x_mean = np.zeros((B, D))
        x_std = np.ones((B, D))
        mask = np.zeros((B, D))
        y_arr = np.zeros((B, n))
        y_mean = np.zeros(B)
        y_std = np.ones(B)
        const_y = np.zeros(B, dtype=bool)
        for b in range(B):
            d = dims[b]
            Xp[b, :, :d] = Xs[b]
            mu = Xs[b].mean(0)
            sd = Xs[b].std(0)
            # constant: a spread within 1e-12 of max(1, |mean|), which assumes SI-like units (rad, N m): round-off
            # around 0 (q̈ differenced from a constant q̇) is no input, at the price of data in units below 1e-12
            active = sd > 1e-12 * np.maximum(1.0, np.abs(mu))
            x_mean[b, :d] = mu
            x_std[b, :d] = np.where(active, sd, 1.0)
            mask[b, :d] = active
            y_arr[b] = ys[b]
            y_mean[b] = ys[b].mean()
            s = ys[b].std()
            if s <= 1e-12 * max(1.0, abs(y_mean[b])):  # as the inputs' rule
                const_y[b] = True
            else:
                y_std[b] = s
        return cls(dims, Xp, y_arr, x_mean, x_std, mask, y_mean, y_std, const_y, np.zeros((B, D + 2)))

    def normalised(self) -> tuple[np.ndarray, np.ndarray]:
        """Normalised inputs ``(B, n, D)`` (masked columns zero) and targets ``(B, n)``."""
        Xn = (self.X - self.x_mean[:, None, :]) / self.x_std[:, None, :] * self.mask[:, None, :]
        yn = (self.y - self.y_mean[:, None]) / self.y_std[:, None]
        return Xn, yn


def bank_state(config: GPFitConfig, data: BankData, fit_info: list[dict[str, Any]]) -> dict[str, Any]:
    """The saved form of a fitted bank (plain arrays, JSON strings)."""
    return {
        "format": _FORMAT,
        "version": STATE_VERSION,
        "config_json": json.dumps(asdict(config)),
        "dims": data.dims.copy(),
        "X": data.X.copy(),
        "y": data.y.copy(),
        "x_mean": data.x_mean.copy(),
        "x_std": data.x_std.copy(),
        "mask": data.mask.copy(),
        "y_mean": data.y_mean.copy(),
        "y_std": data.y_std.copy(),
        "theta": data.theta.copy(),
        "constant_target": data.const_y.copy(),
        "fit_info_json": json.dumps(fit_info),
    }


#: Largest |log hyperparameter| a saved state may hold, and a fit gives (:class:`~cascgp.gp.bank.GPBank`, clipped):
#: exp() of 709.8 overflows float64, and exp(-745) is 0.
THETA_MAX = 700.0


def bank_from_state(d: dict[str, Any]) -> tuple[GPFitConfig, BankData, list[dict[str, Any]]]:
    """Validate a :func:`bank_state` dict; ``ValueError`` naming the first bad field."""
    if not isinstance(d, dict):
        raise ValueError(f"state: expected a dict, got {type(d).__name__}")
    required = ("format", "version", "config_json", "dims", "X", "y", "x_mean", "x_std", "mask", "y_mean",
                "y_std", "theta", "constant_target", "fit_info_json")
    for k in required:
        if k not in d:
            raise ValueError(f"state[{k!r}]: missing")
    for k in ("format", "version", "config_json", "fit_info_json"):
        if np.asarray(d[k]).shape != ():
            raise ValueError(f"state[{k!r}]: expected a scalar, got an array of shape {np.asarray(d[k]).shape}")
    if str(np.asarray(d["format"])) != _FORMAT:
        raise ValueError(f"state['format']: expected {_FORMAT!r}, got {d['format']!r}")
    if np.asarray(d["version"]).dtype.kind not in "iu" or int(np.asarray(d["version"])) != STATE_VERSION:
        raise ValueError(f"state['version']: expected {STATE_VERSION}, got {d['version']!r}")
    try:
        config = GPFitConfig.from_dict(json.loads(str(np.asarray(d["config_json"]))))
    except (json.JSONDecodeError, TypeError, ValueError) as e:
        raise ValueError(f"state['config_json']: not a valid GPFitConfig ({e})") from None
    dims = np.asarray(d["dims"])
    if dims.dtype.kind not in "iu":
        raise ValueError(f"state['dims']: expected integers, got dtype {dims.dtype}")
    if dims.ndim != 1 or dims.size == 0 or np.any(dims < 1):
        raise ValueError(f"state['dims']: expected a non-empty 1-D array of positive ints, got {dims!r}")
    B, D = dims.size, int(dims.max())
    if np.asarray(d["X"]).dtype.kind not in "fiu":
        raise ValueError(f"state['X']: expected real numbers, got dtype {np.asarray(d['X']).dtype}")
    Xp = np.asarray(d["X"], dtype=np.float64)
    if Xp.ndim != 3 or Xp.shape[0] != B or Xp.shape[2] != D or Xp.shape[1] < 2:
        raise ValueError(f"state['X']: expected shape ({B}, n>=2, {D}), got {Xp.shape}")
    n = Xp.shape[1]
    shapes = {"y": (B, n), "x_mean": (B, D), "x_std": (B, D), "mask": (B, D), "y_mean": (B,), "y_std": (B,),
              "theta": (B, D + 2), "constant_target": (B,)}
    arrs = {}
    for k, shp in shapes.items():
        a = np.asarray(d[k])
        if a.shape != shp:
            raise ValueError(f"state[{k!r}]: expected shape {shp}, got {a.shape}")
        if a.dtype.kind not in ("b" if k == "constant_target" else "fiu"):
            raise ValueError(f"state[{k!r}]: unexpected dtype {a.dtype}")
        if k != "constant_target":
            a = a.astype(np.float64)
            if not np.all(np.isfinite(a)):
                raise ValueError(f"state[{k!r}]: contains NaN or inf")
        arrs[k] = a
    if not np.all(np.isfinite(Xp)):
        raise ValueError("state['X']: contains NaN or inf")
    if np.abs(arrs["theta"]).max() > THETA_MAX:  # exp() of it overflows (or underflows to a zero lengthscale)
        raise ValueError(f"state['theta']: expected log hyperparameters within +-{THETA_MAX:g}, got "
                         f"{arrs['theta'].flat[np.abs(arrs['theta']).argmax()]:g}")
    try:
        fit_info = json.loads(str(np.asarray(d["fit_info_json"])))
    except json.JSONDecodeError as e:
        raise ValueError(f"state['fit_info_json']: not valid JSON ({e})") from None
    if not isinstance(fit_info, list) or len(fit_info) != B:
        raise ValueError(f"state['fit_info_json']: expected a list of {B} entries (one per GP)")
    data = BankData(dims=dims, X=Xp.copy(), y=arrs["y"].copy(), x_mean=arrs["x_mean"].copy(),
                    x_std=arrs["x_std"].copy(), mask=arrs["mask"].copy(), y_mean=arrs["y_mean"].copy(),
                    y_std=arrs["y_std"].copy(), const_y=arrs["constant_target"].astype(bool),
                    theta=arrs["theta"].copy())
    return config, data, fit_info
