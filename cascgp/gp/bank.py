r"""The GP bank: ``B`` independent exact GPs (one per output) fitted together in one batch.

:class:`GPBank` owns the fit driver (normalise, build the starts, optimise every start of every GP in one batch,
keep the best start per GP, cache the factors) and batched prediction. The pieces it drives live next to it:
:mod:`~cascgp.gp.likelihood` (NLL and gradient), :mod:`~cascgp.gp.memory` (the memory plan),
:mod:`~cascgp.gp.lbfgs` (batched optimiser), :mod:`~cascgp.gp.restarts` (starts and early stopping),
:mod:`~cascgp.gp.posterior` (factors, NumPy posterior), :mod:`~cascgp.gp.state` (save/load).

Normalisation
-------------
Inputs and targets are normalised per GP: :math:`\tilde x = (x - \mu_x) / \sigma_x` per column,
:math:`\tilde y = (y - \mu_y) / \sigma_y`. GPs with fewer inputs than the widest are padded with zero columns;
their lengthscales are masked (gradient zero, never moved, reported as ``inf`` scale). Input columns that are
constant in the training data are treated the same way (at prediction time their value is ignored).
With ``GPFitConfig.noise_floor_target`` (a noise-variance bound in target units, e.g. a sensor's) the noise floor
of GP ``b`` is ``max(noise_floor, noise_floor_target[b] / y_std[b]**2)`` in normalised units
(:meth:`GPFitConfig.floors`); it is recomputed from the config and ``y_std`` wherever it is used (fit, factors,
:meth:`GPBank.hyperparameters`, a loaded bank), so a saved bank keeps its floor.

Edge cases (documented behaviour)
---------------------------------
* Constant target ``y[b]`` (standard deviation <= 1e-12 x max(1, |mean|), for SI-like units; an input column too):
  not optimised, ``y_std = 1``, hyperparameters at the default start (variances in target units squared that say
  nothing of its scale), the posterior mean exactly the constant, ``fit_info[b]["constant_target"]`` True.
* NaN/inf, wrong shapes, ``n < 2``, unequal ``n``, bad kernel: ``ValueError``; not a list, or not real: ``TypeError``.
* A log hyperparameter driven beyond ±700 (an unneeded input's lengthscale, a noise variance far below its floor) is
  clipped to it, as a saved bank holds (``state.THETA_MAX``): at :math:`e^{\pm 700}` predictions are the limit's.
"""

from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import torch

from cascgp.checks import check_count
from cascgp.gp.checks import as_list, check_matrix, check_scale, check_vector, json_num
from cascgp.gp.config import GPFitConfig, noise_var
from cascgp.gp.kernels import get_kernel, scaled_sqdist
from cascgp.gp.lbfgs import LBFGSOptions, minimize_batched
from cascgp.gp.likelihood import DTYPE, fit_threads, nll_and_grad
from cascgp.gp.memory import plan_chunk
from cascgp.gp.posterior import ZCLIP, Factors, GPPosterior, compute_factors
from cascgp.gp.restarts import initial_thetas, make_pruner, warm_theta
from cascgp.gp.state import THETA_MAX, BankData, bank_from_state, bank_state

__all__ = ["GPBank", "SharedGPError"]


class SharedGPError(ValueError):
    """An entry of :meth:`GPBank.fit`'s ``shared`` that does not hold its GP fitted as this fit would fit it."""


@dataclass
class _Objective:
    """The batched objective handed to :func:`minimize_batched`: evaluates the NLL of the members ``idx`` (each
    the start of GP ``gp_of[idx]``) and counts the evaluations, rounds and largest jitter per GP."""

    cfg: GPFitConfig
    X: torch.Tensor
    y: torch.Tensor
    mask: torch.Tensor
    chunk: int
    max_jit: np.ndarray
    floor_gp: np.ndarray | None = None  # per-GP noise floors (normalised), None: cfg.noise_floor
    n_eval: int = 0
    rounds: int = 0
    stage_evals: dict[str, int] = field(default_factory=lambda: {"screen": 0, "full": 0})

    def bind(self, X: torch.Tensor, y: torch.Tensor, gp_of: np.ndarray, stage: str):
        def fun(Th: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            cfg, gsel = self.cfg, torch.as_tensor(gp_of[idx])
            floor = cfg.noise_floor if self.floor_gp is None else self.floor_gp[gp_of[idx]]
            f, g, jit = nll_and_grad(torch.as_tensor(Th, dtype=DTYPE), X[gsel], y[gsel], self.mask[gsel],
                                     cfg.kernel, floor, cfg.jitter_max, chunk=self.chunk, snr_max=cfg.snr_max)
            assert g is not None  # need_grad (the default) returns the gradient
            np.maximum.at(self.max_jit, gp_of[idx], jit.numpy())
            self.n_eval += len(idx)
            self.stage_evals[stage] += len(idx)
            self.rounds += 1
            return f.numpy(), g.numpy()
        return fun


def _settings_of(config: GPFitConfig, b: int) -> tuple[GPFitConfig, Any]:
    """What decides GP ``b``'s fit besides its data and place in the bank: the settings, its own noise floor."""
    t = config.noise_floor_target
    return replace(config, noise_floor_target=None), (t[b] if isinstance(t, tuple) and b < len(t) else t)


@dataclass
class _StartRecord:
    """Per GP and start: final NLL, iterations, evaluations, stop reason, subset NLL when screened."""

    nll: np.ndarray
    n_iter: np.ndarray
    n_eval: np.ndarray
    reason: list[list[str]]
    screen_nll: np.ndarray

    @classmethod
    def empty(cls, B: int, R: int) -> _StartRecord:
        return cls(np.full((B, R), np.nan), np.zeros((B, R), dtype=np.int64), np.zeros((B, R), dtype=np.int64),
                   [["not_run"] * R for _ in range(B)], np.full((B, R), np.nan))


class GPBank:
    """``B`` independent exact GPs (one per output), fitted together in one batch.

    Example::

        bank = GPBank(GPFitConfig(n_restarts=10)).fit([X0, X1], [y0, y1])
        mean, var = bank.predict([Xq0, Xq1])        # (m, 2), (m, 2) in target units
        post = bank.posterior(0)                     # NumPy factors for a single-query fast path

    Attributes:
        config: the :class:`GPFitConfig`.
        fit_info: per GP a dict (JSON-serialisable): ``nll`` (final NLL per start in normalised units; for a
            dropped start its last NLL, for a start screened out or not run ``None``), ``n_iter``, ``n_eval``,
            ``reason`` (per start: ``grad_tol``, ``rel_tol``, ``stalled``, ``dropped``, ``screened_out``, ...),
            ``best`` (index of the kept start), ``best_nll`` (normalised units; add ``n * log(y_std)`` for target
            units), ``converged`` (reason of the kept start), ``jitter`` (in the final factor, normalised units),
            ``max_jitter_fit`` (largest jitter met during the fit), ``constant_target``, ``warm_start`` (start 0
            came from ``init``), ``screen_nll`` (subset NLL per start when screening was used), ``shared`` (taken
            from another bank: ``shared`` of :meth:`fit`).
        fit_summary: totals of the last fit (``time_s``, ``n_eval``, ``batch_rounds``).
    """

    def __init__(self, config: GPFitConfig | None = None) -> None:
        if config is not None and not isinstance(config, GPFitConfig):
            raise TypeError(f"config: expected GPFitConfig or None, got {type(config).__name__}")
        self.config = config or GPFitConfig()
        self.fit_info: list[dict[str, Any]] = []
        self.fit_summary: dict[str, Any] = {}
        self._data: BankData | None = None
        self._factors: Factors | None = None

    # ------------------------------------------------------------------ properties
    @property
    def fitted(self) -> bool:
        return self._factors is not None

    @property
    def n_gps(self) -> int:
        return int(self._require_fitted().dims.shape[0])

    @property
    def dims(self) -> tuple[int, ...]:
        """Input dimension of each GP."""
        return tuple(int(d) for d in self._require_fitted().dims)

    @property
    def theta(self) -> np.ndarray:
        """Log hyperparameters ``(B, D + 2)`` in normalised units (see :mod:`cascgp.gp`); a copy."""
        return self._require_fitted().theta.copy()

    @property
    def n_train(self) -> int:
        return int(self._require_fitted().X.shape[1])

    def training_data(self) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Copies of the training inputs ``(n, d_b)`` and targets ``(n,)`` of every GP, as given to :meth:`fit`."""
        s = self._require_fitted()
        return ([s.X[b, :, : s.dims[b]].copy() for b in range(len(s.dims))],
                [s.y[b].copy() for b in range(len(s.dims))])

    def hyperparameters(self, b: int) -> dict[str, np.ndarray | float]:
        """Hyperparameters of GP ``b`` in *original* units: ``lengthscale`` (d,) (``inf`` for ignored columns),
        ``signal_var``, ``noise_var`` (target units squared)."""
        s = self._require_fitted()
        b = self._check_b(b)
        d = int(s.dims[b])
        th = s.theta[b]
        ls = np.where(s.mask[b, :d] > 0, np.exp(th[:d]) * s.x_std[b, :d], np.inf)
        ys2 = s.y_std[b] ** 2
        floors = self.config.floors(s.y_std)
        return {
            "lengthscale": ls,
            "signal_var": float(np.exp(th[-2]) * ys2),
            "noise_var": float(noise_var(self.config, math.exp(th[-2]), math.exp(th[-1]),
                                         None if floors is None else float(floors[b])) * ys2),
        }

    def _require_fitted(self) -> BankData:
        if self._data is None or self._factors is None:
            raise RuntimeError("GPBank: not fitted; call fit() or from_state_dict() first")
        return self._data

    def _check_b(self, b: int) -> int:
        B = self._require_fitted().dims.shape[0]
        if not isinstance(b, (int, np.integer)) or not 0 <= int(b) < B:
            raise ValueError(f"b: expected an integer in [0, {B}), got {b!r}")
        return int(b)

    # ------------------------------------------------------------------ fit
    def fit(self, X: list[np.ndarray], y: list[np.ndarray], init: GPBank | None = None, *,
            shared: dict[int, tuple[GPBank, int]] | None = None) -> GPBank:
        """Normalise, optimise all GPs x all starts in one batch, keep the best start, cache the factors.

        Args:
            X: per GP ``(n, d_b)`` inputs (the same ``n`` for all GPs, ``d_b`` may differ).
            y: per GP ``(n,)`` targets.
            init: a fitted bank with the same number of GPs and input dimensions; its hyperparameters (converted
                to this data's normalisation) are used as start 0 of every GP.
            shared: ``{b: (bank, b)}``: GP ``b`` was fitted already, as GP ``b`` of another fitted ``bank`` with
                as many GPs, of the same width, with the same settings, on the same inputs and targets (all
                checked) and from the same warm start (the caller's to ensure), so with the random starts this
                fit draws for it; it takes that GP's hyperparameters and ``fit_info`` (with ``"shared": True``)
                instead of being fitted again. The other GPs draw their starts as without ``shared`` and the GPs
                of a batch are optimised independently, so each GP ends where a fit without ``shared`` puts it,
                up to the rounding of torch's batched kernels, which can differ in the last bit for a batch of
                another size (the same bits in practice; see :mod:`cascgp.models.fit_start`).

        Returns:
            ``self``.

        The fit runs with ``config.threads`` torch and BLAS threads (one by default) and restores the caller's
        thread settings afterwards (:func:`cascgp.gp.likelihood.fit_threads`).
        """
        try:
            self.config = self.config.for_fit()  # a checked copy: a field may have been set after construction
        except (TypeError, ValueError) as exc:
            raise type(exc)(f"config.{exc}") from None
        with fit_threads(self.config.threads):
            return self._fit(X, y, init, shared)

    @staticmethod
    def _checked_inputs(X: Any, y: Any, init: GPBank | None) -> tuple[list[np.ndarray], list[np.ndarray]]:
        X = as_list(X, "X")
        y = as_list(y, "y")
        if len(X) != len(y):
            raise ValueError(f"y: expected {len(X)} target vectors (one per GP in X), got {len(y)}")
        X0 = check_matrix(X[0], "X[0]")
        n = X0.shape[0]
        if n < 2:
            raise ValueError(f"X[0]: a GP needs at least 2 training samples, got n={n}")
        Xs = [X0] + [check_matrix(X[b], f"X[{b}]", n=n) for b in range(1, len(X))]
        ys = [check_vector(y[b], f"y[{b}]", n) for b in range(len(y))]
        for b in range(len(Xs)):
            check_scale(Xs[b], f"X[{b}]")
            check_scale(ys[b], f"y[{b}]")
        if init is not None:
            dims = tuple(a.shape[1] for a in Xs)
            if not isinstance(init, GPBank) or not init.fitted:
                raise ValueError("init: expected a fitted GPBank or None")
            if init.dims != dims:
                raise ValueError(f"init: input dimensions {init.dims} do not match X's {dims}")
        return Xs, ys

    def _checked_shared(self, shared: Any, Xs: list[np.ndarray], ys: list[np.ndarray], warm: bool
                        ) -> dict[int, tuple[BankData, dict[str, Any]]]:
        """``shared`` of :meth:`fit` as ``{b: (the other bank's data, a copy of its fit_info[b])}``; ``SharedGPError``
        naming the entry that does not hold GP ``b`` fitted as this fit would fit it."""
        if shared is None:
            return {}
        if not isinstance(shared, dict):
            raise TypeError(f"shared: expected a dict {{GP: (GPBank, GP)}} or None, got {type(shared).__name__}")
        out: dict[int, tuple[BankData, dict[str, Any]]] = {}
        for b, entry in shared.items():
            if isinstance(b, bool) or not isinstance(b, (int, np.integer)) or not 0 <= int(b) < len(Xs):
                raise ValueError(f"shared: key {b!r} is not a GP of this fit (expected an integer in [0, {len(Xs)}))")
            where = f"shared[{int(b)}]"
            if not (isinstance(entry, tuple) and len(entry) == 2 and isinstance(entry[0], GPBank)
                    and entry[0].fitted):
                raise SharedGPError(f"{where}: expected (a fitted GPBank, the index of its GP), got {entry!r}")
            src, c = entry
            sd = src._require_fitted()
            width = max(a.shape[1] for a in Xs)
            if (isinstance(c, bool) or not isinstance(c, (int, np.integer)) or int(c) != int(b)
                    or src.n_gps != len(Xs) or sd.X.shape[2] != width):
                raise SharedGPError(f"{where}: expected GP {int(b)} of a bank of {len(Xs)} GPs and width {width} (so "
                                     f"that it drew the same random starts), got GP {c!r} of a bank of {src.n_gps} GPs "
                                     f"and width {sd.X.shape[2]}")
            c = int(c)
            if src.fit_info[c].get("warm_start") != warm:
                raise SharedGPError(f"{where}: GP {c} was fitted {'without' if warm else 'with'} a warm start, this "
                                     f"fit {'has' if warm else 'has none'}")
            if _settings_of(src.config, c) != _settings_of(self.config, c):
                raise SharedGPError(f"{where}: GP {c} was fitted with other settings ({src.config}) than this fit's "
                                     f"({self.config})")
            d = int(sd.dims[c])
            if (Xs[b].shape != (sd.X.shape[1], d) or not np.array_equal(sd.X[c, :, :d], Xs[b])
                    or not np.array_equal(sd.y[c], ys[b])):
                raise SharedGPError(f"{where}: GP {c} was fitted on other inputs or targets than X[{int(b)}], "
                                     f"y[{int(b)}]")
            out[c] = (sd, copy.deepcopy(src.fit_info[c]))
        return out

    def _fit(self, X: list[np.ndarray], y: list[np.ndarray], init: GPBank | None,
             shared: dict[int, tuple[GPBank, int]] | None = None) -> GPBank:
        t0 = time.perf_counter()
        cfg = self.config
        Xs, ys = self._checked_inputs(X, y, init)
        taken = self._checked_shared(shared, Xs, ys, init is not None)
        B, n, D = len(Xs), Xs[0].shape[0], max(a.shape[1] for a in Xs)
        chunk = plan_chunk(cfg, n, D, B)  # memory guard: before any large allocation
        data = BankData.normalise(Xs, ys, D)
        floor_gp = cfg.floors(data.y_std)  # None unless noise_floor_target is set
        Xn, yn = data.normalised()

        rng = np.random.default_rng(cfg.seed)
        R = cfg.n_restarts
        theta0 = initial_thetas(cfg, Xn, yn, data.mask, data.const_y, rng)
        warm = init is not None
        if init is not None:
            theta0[:, 0, :] = warm_theta(init.config, init._require_fitted(), data, D, new_config=cfg)
        theta0[:, :, :D] *= data.mask[:, None, :]  # inactive lengthscales fixed at 0 (unused)

        obj = _Objective(cfg, torch.as_tensor(Xn, dtype=DTYPE), torch.as_tensor(yn, dtype=DTYPE),
                         torch.as_tensor(data.mask, dtype=DTYPE), chunk, np.zeros(B), floor_gp)
        rec = _StartRecord.empty(B, R)
        final_theta = theta0[:, 0, :].copy()
        opt_gps = np.flatnonzero(~data.const_y & ~np.isin(np.arange(B), list(taken)))
        if opt_gps.size:
            self._optimise(obj, theta0, opt_gps, warm, rng, rec, final_theta)
        for g, (sd, _) in taken.items():  # the same data and width, so the same normalisation and layout
            final_theta[g] = sd.theta[g]
        best_r = np.zeros(B, dtype=np.int64)
        for b in opt_gps:
            best_r[b] = int(np.argmin(np.where(np.isfinite(rec.nll[b]), rec.nll[b], np.inf)))

        data.theta = np.clip(final_theta, -THETA_MAX, THETA_MAX)  # what a saved bank holds (docstring); a warm
        factors = self._set_data(data)  # start's shifted lengthscales too (a constant target is not optimised)
        self.fit_info = [{
            "nll": [json_num(v) for v in rec.nll[b]],
            "n_iter": [int(v) for v in rec.n_iter[b]],
            "n_eval": [int(v) for v in rec.n_eval[b]],
            "reason": list(rec.reason[b]),
            "best": int(best_r[b]),
            "best_nll": float(factors.nll[b]),
            "converged": "constant_target" if data.const_y[b] else rec.reason[b][int(best_r[b])],
            "jitter": float(factors.jitter[b]),
            "max_jitter_fit": float(obj.max_jit[b]),
            "constant_target": bool(data.const_y[b]),
            "warm_start": warm,
            "screen_nll": [json_num(v) for v in rec.screen_nll[b]],
            "shared": False,
        } for b in range(B)]
        for g, (_, info) in taken.items():
            self.fit_info[g] = {**info, "best_nll": float(factors.nll[g]), "shared": True}
        self.fit_summary = {"time_s": time.perf_counter() - t0, "n_eval": int(obj.n_eval),
                            "batch_rounds": obj.rounds, "n_eval_screen": obj.stage_evals["screen"],
                            "n_eval_full": obj.stage_evals["full"]}
        return self

    def _optimise(self, obj: _Objective, theta0: np.ndarray, opt_gps: np.ndarray, warm: bool,
                  rng: np.random.Generator, rec: _StartRecord, final_theta: np.ndarray) -> None:
        """Run every start of the GPs ``opt_gps`` (after optional screening); fill ``rec`` and write the best
        start's hyperparameters of each GP into ``final_theta``."""
        cfg = self.config
        B, R = theta0.shape[:2]
        n = obj.X.shape[1]
        member_gp = np.repeat(opt_gps, R)
        member_start = np.tile(np.arange(R), opt_gps.size)
        x0 = theta0[member_gp, member_start]
        gp_of, starts, start_idx = member_gp, x0, member_start
        pre_iter = np.zeros(len(gp_of), dtype=np.int64)
        pre_eval = np.zeros(len(gp_of), dtype=np.int64)
        if cfg.screen_n is not None and n > cfg.screen_n:
            keep, starts, pre_iter, pre_eval = self._screen(obj, x0, member_gp, member_start, opt_gps, warm, rng,
                                                            rec)
            gp_of, start_idx = member_gp[keep], member_start[keep]
        opts = LBFGSOptions(history=cfg.history, max_iter=cfg.max_iter, grad_tol=cfg.grad_tol, rel_tol=cfg.rel_tol)
        states = minimize_batched(obj.bind(obj.X, obj.y, gp_of, "full"), starts, opts, make_pruner(cfg, gp_of, B))
        for k, st in enumerate(states):
            b, r = int(gp_of[k]), int(start_idx[k])
            rec.nll[b, r] = st.f
            rec.n_iter[b, r] = st.n_iter + pre_iter[k]
            rec.n_eval[b, r] = st.n_eval + pre_eval[k]
            rec.reason[b][r] = st.reason
        for b in opt_gps:
            r = int(np.argmin(np.where(np.isfinite(rec.nll[b]), rec.nll[b], np.inf)))
            k = int(np.flatnonzero((gp_of == b) & (start_idx == r))[0])
            final_theta[b] = states[k].x

    def _screen(self, obj: _Objective, x0: np.ndarray, member_gp: np.ndarray, member_start: np.ndarray,
                opt_gps: np.ndarray, warm: bool, rng: np.random.Generator, rec: _StartRecord
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Optimise every start on a random subset of ``screen_n`` points; the ``screen_keep`` best per GP (and a
        warm start) continue. Returns the kept members, their starting points and the iterations/evaluations
        already spent."""
        cfg = self.config
        B = rec.nll.shape[0]
        n = obj.X.shape[1]
        sub = np.sort(rng.choice(n, size=cfg.screen_n, replace=False))
        sopts = LBFGSOptions(history=cfg.history, max_iter=cfg.screen_max_iter, grad_tol=cfg.grad_tol,
                             rel_tol=cfg.screen_rel_tol)
        fun = obj.bind(obj.X[:, sub].clone(), obj.y[:, sub].clone(), member_gp, "screen")
        sst = minimize_batched(fun, x0, sopts, make_pruner(cfg, member_gp, B))
        sf = np.array([s.f for s in sst])
        keep: list[int] = []
        for b in opt_gps:
            mem = np.flatnonzero(member_gp == b)
            rec.screen_nll[b, member_start[mem]] = sf[mem]
            chosen = list(mem[np.argsort(sf[mem], kind="stable")][: cfg.screen_keep])
            if warm:  # the warm start always continues
                w = mem[member_start[mem] == 0]
                if w.size and w[0] not in chosen:
                    chosen.append(int(w[0]))
            for m in mem:
                if m not in chosen:
                    rec.reason[b][member_start[m]] = "screened_out"
                    rec.n_iter[b, member_start[m]] = sst[m].n_iter
                    rec.n_eval[b, member_start[m]] = sst[m].n_eval
            keep.extend(sorted(int(c) for c in chosen))
        kept = np.array(keep, dtype=np.int64)
        starts = np.stack([sst[m].x if np.isfinite(sst[m].f) else x0[m] for m in kept])
        return (kept, starts, np.array([sst[m].n_iter for m in kept]), np.array([sst[m].n_eval for m in kept]))

    def _set_data(self, data: BankData) -> Factors:
        """Adopt ``data`` (training set, normalisation, hyperparameters) and compute its factors (returned)."""
        Xn, yn = data.normalised()
        self._factors = compute_factors(self.config, Xn, yn, data.mask, data.theta, self.config.floors(data.y_std))
        self._data = data
        return self._factors

    # ------------------------------------------------------------------ prediction
    def predict(self, X: list[np.ndarray], return_var: bool = True,
                chunk: int = 4096) -> tuple[np.ndarray, np.ndarray | None]:
        """Posterior mean and latent variance of every GP.

        Args:
            X: per GP ``(m, d_b)`` query inputs (the same ``m`` for every GP).
            return_var: also return the variance of the latent function (no noise).
            chunk: queries per batched block, an integer >= 1 (memory bound: ``B * chunk * n`` floats).

        Returns:
            ``mean (m, B)`` and ``var (m, B)`` (or ``None``) in original target units.
        """
        s = self._require_fitted()
        f = self._factors
        assert f is not None  # _require_fitted checks it
        X, chunk, B = as_list(X, "X"), check_count(chunk, "chunk"), self.n_gps
        if len(X) != B:
            raise ValueError(f"X: expected {B} query arrays (one per GP), got {len(X)}")
        Q0 = check_matrix(X[0], "X[0]", d=int(s.dims[0]))
        m = Q0.shape[0]
        Qs = [Q0] + [check_matrix(X[b], f"X[{b}]", d=int(s.dims[b]), n=m) for b in range(1, B)]
        D = s.X.shape[2]
        Q = np.zeros((B, m, D))
        for b in range(B):
            Q[b, :, : s.dims[b]] = Qs[b]
        Qn = torch.as_tensor((Q - s.x_mean[:, None, :]) / s.x_std[:, None, :], dtype=DTYPE)
        kern = get_kernel(self.config.kernel)
        means, vars_ = [], []
        for c in range(0, max(m, 1), chunk):
            Zq = (Qn[:, c : c + chunk] * f.inv_l[:, None, :]).clamp_(-ZCLIP, ZCLIP)  # finite for finite input
            Ks = kern.value_torch(scaled_sqdist(Zq, f.Z)) * f.sf2[:, None, None]
            means.append(torch.matmul(Ks, f.alpha.unsqueeze(-1)).squeeze(-1))
            if return_var:
                V = torch.linalg.solve_triangular(f.L, Ks.transpose(-1, -2), upper=False)
                vars_.append((f.sf2[:, None] - (V * V).sum(-2)).clamp_min_(0.0))
        mean = torch.cat(means, 1).numpy().T * s.y_std[None, :] + s.y_mean[None, :]
        if not return_var:
            return np.ascontiguousarray(mean), None
        var = torch.cat(vars_, 1).numpy().T * (s.y_std[None, :] ** 2)
        return np.ascontiguousarray(mean), np.ascontiguousarray(var)

    def posterior(self, b: int) -> GPPosterior:
        """NumPy factors of GP ``b`` (see :class:`GPPosterior`)."""
        s = self._require_fitted()
        f = self._factors
        assert f is not None  # _require_fitted checks it
        b = self._check_b(b)
        d = int(s.dims[b])
        act = s.mask[b, :d] > 0
        with np.errstate(over="ignore"):  # a lengthscale beyond float range: the column is irrelevant (z = 0)
            x_scale = np.where(act, s.x_std[b, :d] * np.exp(s.theta[b, :d]), np.inf)
        return GPPosterior(
            kernel=self.config.kernel,
            x_mean=s.x_mean[b, :d].copy(),
            x_scale=x_scale,
            Z=f.Z[b, :, :d].numpy().copy(),
            alpha=f.alpha[b].numpy().copy(),
            L=f.L[b].numpy().copy(),
            signal_var=float(f.sf2[b]),
            noise_var=float(f.sn2[b]),
            y_mean=float(s.y_mean[b]),
            y_std=float(s.y_std[b]),
            jitter=float(f.jitter[b]),
        )

    # ------------------------------------------------------------------ persistence
    def state_dict(self) -> dict[str, Any]:
        """Plain NumPy arrays and scalars that reproduce the fitted bank exactly (see :meth:`from_state_dict`)."""
        return bank_state(self.config, self._require_fitted(), self.fit_info)

    @classmethod
    def from_state_dict(cls, d: dict[str, Any]) -> GPBank:
        """Rebuild a fitted bank from :meth:`state_dict` output (the Cholesky factors are recomputed)."""
        config, data, fit_info = bank_from_state(d)
        bank = cls(config)
        bank._set_data(data)
        bank.fit_info = fit_info
        return bank
