"""Hyperparameter-optimisation settings of :class:`cascgp.gp.GPBank` (:class:`GPFitConfig`), validated on
construction; :meth:`GPFitConfig.from_dict` reads the ``asdict`` form stored in model files."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from cascgp.checks import MAX_RESTARTS, check_count, check_positive
from cascgp.gp.kernels import check_kernel

__all__ = ["GPFitConfig", "INIT_SPREAD_MAX", "MAX_THREADS", "check_target_floor", "noise_var"]


#: Values of fields added after the first saved format, for configs saved without them (old behaviour).
_LEGACY_DEFAULTS: dict[str, Any] = {"snr_max": None, "stall_window": None}
#: The largest ``init_spread`` a fit takes (log units): a lengthscale scaled by e^20 (5e8) or more makes a start's
#: kernel numerically constant on standardised inputs (1 or 0 off the diagonal in float64), so such a start cannot
#: move, and far larger spreads overflow. Checked when a fit starts, not when a config is made, so that model files
#: saved with a larger value still load (the spread plays no part in prediction).
INIT_SPREAD_MAX = 20.0
#: The most ``threads`` a fit accepts: a bound on a typo (torch's ``set_num_threads`` takes a C ``int``, and
#: OpenMP starts a worker per thread), far above the cores of one machine. Checked when a fit starts, as
#: ``INIT_SPREAD_MAX``, so that a saved config loads whatever it holds.
MAX_THREADS = 1024


@dataclass
class GPFitConfig:
    r"""Hyperparameter optimisation settings.

    Attributes:
        kernel: ``"matern52"`` (paper), ``"matern32"`` or ``"rbf"`` (:mod:`cascgp.gp.kernels`).
        n_restarts: starts per GP (1 to 1000); the best is kept.
        max_iter: L-BFGS iterations per start.
        grad_tol: stop when max |dNLL/dtheta| <= grad_tol.
        rel_tol: stop when the relative NLL decrease of one iteration <= rel_tol (SciPy's ``factr`` test).
        seed: seed of the random starts and of the screening subset.
        history: L-BFGS memory.
        noise_floor: lower bound of the noise variance in normalised units.
        noise_floor_target: lower bound of the noise variance in *target* units squared (N² m² for torques), e.g.
            a sensor's known noise variance: a measured target cannot be less noisy than its sensor. A number for
            every GP of the bank, or a sequence with one value per GP; ``None`` (default): no such bound, the fit
            is exactly the one without this field. See :meth:`floors` for the conversion.
        jitter_max: largest jitter (relative to the mean diagonal of K) tried when a Cholesky fails.
        init_spread: half-width (in log units) of the random perturbation of the log lengthscales; a fit refuses more
            than ``INIT_SPREAD_MAX`` (20).
        drop_after: drop hopeless starts after this many iterations (``None``: never drop).
        drop_margin: a start is hopeless when its NLL exceeds the best of its GP by more than this (nats).
        screen_n: if set and ``n > screen_n``, first optimise all starts on ``screen_n`` random training points.
        screen_keep: starts per GP that continue on the full data after screening.
        screen_max_iter: iteration cap of the screening stage.
        screen_rel_tol: relative-change tolerance of the screening stage.
        stall_window: iterations over which a non-leading start's progress is measured (``None``: every start runs
            to convergence, the behaviour before the early-stopping rule).
        stall_tol: a non-leading start that gained at most this (nats) over ``stall_window`` iterations stops.
        catch_up_windows: ... or that gained less than ``gap / catch_up_windows`` (``gap``: its NLL minus the
            leader's), i.e. would need more than this many windows to reach the leader at its current pace.
        race_at: if set, after every start of a GP has done ``race_at`` iterations only the ``race_keep`` best
            continue (off by default: the audit showed lost optima).
        race_keep: starts kept by ``race_at``.
        snr_max: bound of the signal-to-noise variance ratio, :math:`s_n^2 \ge s_f^2 / \mathrm{snr\_max}`
            (``None``: no bound); keeps :math:`\operatorname{cond}(K) \le 1 + n\,\mathrm{snr\_max}`.
        max_batch_bytes: memory limit of a fit (bytes); the evaluation is chunked to stay within it, and a fit that
            cannot (:func:`~cascgp.gp.memory.estimate_fit_bytes` with one start at a time), or that needs more
            than the machine's memory at the least, is refused with :class:`~cascgp.gp.memory.FitMemoryError`.
        threads: threads of torch's intra-op pool *and* of the BLAS/LAPACK library while :meth:`GPBank.fit` runs;
            both are restored afterwards (:func:`cascgp.gp.likelihood.fit_threads`). The rule: **one thread**
            (default). A fit's work is many small, cache-sized pieces (one ``(n, n)`` kernel block and one
            Cholesky factor per GP and start, :math:`n \lesssim 2000`), on which a second thread gains little and
            idle-spinning OpenMP/OpenBLAS workers cost much when the cores are shared (SARCOS, n = 300, 7 outputs,
            ``python -m scripts.bench_fit_threads``: on 2 quiet cores torch's default two threads took 0.85x the
            one-thread time, beside one busy process 2.7x); parallelism across fits belongs to processes
            (``--workers``), and ``threads=2`` suits a dedicated machine. ``None`` leaves the caller's settings
            untouched; an integer ``k`` from 1 to :data:`MAX_THREADS` uses ``k`` threads. Another thread count sums
            in another order: the NLL and predictions agree to round-off, but where the NLL is flat (a lengthscale
            of an input that does not matter) the optimiser can stop elsewhere, with the same predictions to about
            1e-3 of the target's scale.
    """

    kernel: str = "matern52"
    n_restarts: int = 10
    max_iter: int = 1000
    grad_tol: float = 1e-5
    rel_tol: float = 2e-9
    seed: int = 0
    history: int = 10
    noise_floor: float = 1e-6
    jitter_max: float = 1e-2
    init_spread: float = 1.0
    drop_after: int | None = None
    drop_margin: float = 20.0
    stall_window: int | None = 5
    stall_tol: float = 0.01
    catch_up_windows: float = 10.0
    race_at: int | None = None
    race_keep: int = 5
    snr_max: float | None = 1e6
    max_batch_bytes: int = 2 * 1024**3
    screen_n: int | None = None
    screen_keep: int = 2
    screen_max_iter: int = 200
    screen_rel_tol: float = 1e-6
    noise_floor_target: float | tuple[float, ...] | None = None
    threads: int | None = 1

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> GPFitConfig:
        """Config from a saved ``asdict`` (unknown keys ignored). Fields missing from a save that predates them take
        the value that reproduces the old behaviour (``snr_max=None``, ``stall_window=None``), so that a loaded
        model predicts as when it was saved (to round-off: the factors are recomputed)."""
        if not isinstance(d, dict):
            raise TypeError(f"config: expected a dict, got {type(d).__name__}")
        names = {f.name for f in fields(cls)}
        kw = {k: v for k, v in d.items() if k in names}
        for k, v in _LEGACY_DEFAULTS.items():
            kw.setdefault(k, v)
        return cls(**kw)

    def __post_init__(self) -> None:
        check_kernel(self.kernel)
        for name in ("n_restarts", "max_iter", "history", "screen_keep", "screen_max_iter", "race_keep",
                     "max_batch_bytes"):
            check_count(getattr(self, name), name)
        for name in ("grad_tol", "rel_tol", "noise_floor", "jitter_max", "init_spread", "drop_margin", "stall_tol",
                     "screen_rel_tol"):
            setattr(self, name, check_positive(getattr(self, name), name, zero=True))  # a Python float (JSON)
        for name in ("drop_after", "stall_window", "race_at", "threads"):
            check_count(getattr(self, name), name, optional=True)
        check_count(self.seed, "seed", minimum=0)  # NumPy's generators take seeds >= 0
        if self.n_restarts > MAX_RESTARTS:
            raise ValueError(f"n_restarts: expected at most {MAX_RESTARTS} starts per GP, got {self.n_restarts}")
        if self.snr_max is not None and (isinstance(self.snr_max, bool) or not isinstance(self.snr_max, (int, float))
                                         or not math.isfinite(self.snr_max) or self.snr_max <= 0):
            raise ValueError(f"snr_max: expected None or a finite number > 0, got {self.snr_max!r}")
        if isinstance(self.catch_up_windows, bool) or not isinstance(self.catch_up_windows, (int, float)) \
                or not self.catch_up_windows > 0:
            raise ValueError(f"catch_up_windows: expected a number > 0, got {self.catch_up_windows!r}")
        check_count(self.screen_n, "screen_n", minimum=2, optional=True)
        self.noise_floor_target = check_target_floor(self.noise_floor_target, "noise_floor_target")

    def for_fit(self) -> GPFitConfig:
        """A copy checked again (a field may have been set after construction), and for a fit: ``init_spread`` at
        most ``INIT_SPREAD_MAX`` and ``threads`` at most :data:`MAX_THREADS`; ``ValueError`` naming the field."""
        config = replace(self)
        if config.init_spread > INIT_SPREAD_MAX:
            raise ValueError(f"init_spread: expected at most {INIT_SPREAD_MAX} (log units) for a fit, got "
                             f"{config.init_spread!r}")
        if config.threads is not None and config.threads > MAX_THREADS:
            raise ValueError(f"threads: expected at most {MAX_THREADS}, got {config.threads!r}")
        return config

    def floors(self, y_std: np.ndarray) -> np.ndarray | None:
        r"""Per-GP noise-variance floor in normalised units, ``(B,)``, or ``None`` without ``noise_floor_target``.

        A GP's targets are normalised as :math:`\tilde y = (y - \mu_y) / \sigma_y`, so a noise variance
        :math:`v` in target units is :math:`v / \sigma_y^2` in normalised units. With the bound
        :math:`v_{\min,b}` (``noise_floor_target``, target units squared) the floor of GP ``b`` is

        .. math:: s_{n,\min,b}^2 = \max\big(\mathrm{noise\_floor},\; v_{\min,b} / \sigma_{y,b}^2\big),

        which replaces ``noise_floor`` in :func:`noise_var` (the fitted noise is
        :math:`s_{n,\min,b}^2 + s_f^2/\mathrm{snr\_max} + e^{\theta_{d+2}} \ge s_{n,\min,b}^2`, so the noise
        variance in target units is at least :math:`v_{\min,b}`). ``ValueError`` naming ``noise_floor_target``
        when a per-GP sequence does not have one value per GP.
        """
        if self.noise_floor_target is None:
            return None
        ys = np.asarray(y_std, dtype=np.float64).reshape(-1)
        t = self.noise_floor_target
        if isinstance(t, tuple) and len(t) != ys.size:
            raise ValueError(f"noise_floor_target: expected one value per GP ({ys.size}), got {len(t)}")
        return np.maximum(float(self.noise_floor), np.asarray(t, dtype=np.float64) / ys**2)


def check_target_floor(v: Any, name: str) -> float | tuple[float, ...] | None:
    """``None``, a finite number >= 0 (as ``float``) or a non-empty 1-D sequence of them (as a tuple of floats);
    anything else is a ``ValueError`` naming ``name``."""
    if v is None:
        return None
    if isinstance(v, (bool, np.bool_)):
        raise ValueError(f"{name}: expected None, a finite number >= 0 or a 1-D sequence of them, got {v!r}")
    if isinstance(v, (int, float, np.integer, np.floating)):
        if not math.isfinite(float(v)) or v < 0:
            raise ValueError(f"{name}: expected a finite number >= 0 (variance, target units squared), got {v!r}")
        return float(v)
    if isinstance(v, (list, tuple, np.ndarray)):
        a = np.asarray(v)
        if a.ndim != 1 or a.size == 0 or a.dtype.kind not in "iuf":
            raise ValueError(f"{name}: expected a non-empty 1-D sequence of numbers (one per GP), got shape "
                             f"{a.shape} and dtype {a.dtype}")
        if not np.isfinite(a).all() or (a < 0).any():
            raise ValueError(f"{name}: expected finite values >= 0 (variances, target units squared), got {a.tolist()}")
        return tuple(float(x) for x in a)
    raise ValueError(f"{name}: expected None, a finite number >= 0 or a 1-D sequence of them, got "
                     f"{type(v).__name__}")


def noise_var(cfg: GPFitConfig, sf2: float, e: float, floor: float | None = None) -> float:
    r"""Noise variance (normalised units) from :math:`s_f^2` and :math:`e^{\theta_{d+2}}`:
    :math:`s_n^2 = s_{n,\min}^2 + s_f^2 / \mathrm{snr\_max} + e^{\theta_{d+2}}`, where :math:`s_{n,\min}^2`
    is ``floor`` (the GP's entry of :meth:`GPFitConfig.floors`) or, when ``None``, ``cfg.noise_floor``."""
    return (cfg.noise_floor if floor is None else floor) + (sf2 / cfg.snr_max if cfg.snr_max is not None else 0.0) + e
