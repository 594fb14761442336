r"""Where the starts of a GP fit begin and when a start stops early.

Restarts and early stopping
---------------------------
``n_restarts`` starts per GP: start 0 is a data-driven default (lengthscales :math:`\sqrt{d}` on standardised
inputs, :math:`s_f^2 = 1`, noise from the residual of a linear least-squares fit), the others are random
perturbations of it (seeded by ``seed``); with ``init=`` a previous bank's hyperparameters (converted to the new
normalisation) replace start 0. The best start per GP is kept.

Default rule (``stall_window``, ``stall_tol``, ``catch_up_windows``): after every batched round, the *leader* of
each GP (the start with the lowest current NLL) always continues to L-BFGS convergence (``rel_tol``, the same test
as GPy's L-BFGS-B). Any other start stops (``reason="stalled"``) once its NLL decreased by at most
``max(stall_tol, gap / catch_up_windows)`` over its last ``stall_window`` iterations, ``gap`` being its distance
to the leader (default: 0.01 nat over 5 iterations, or a tenth of the gap). Why this is safe: a stopped start
could only matter if it would later drop below the leader's final NLL; a start that has plateaued, or that at its
current pace needs more than 10 windows to reach the leader's *current* value, almost never does. Evidence (rerun
with ``python -m scripts.fit_audit``; report in ``docs/bench/fit_audit.md``): on 78 GPs (SARCOS subsets
n = 100-300, synthetic n = 50-200) the default's best NLL was within 0.03 nat of 10 starts run to convergence on
all of them. Rules measured and rejected on that audit: keeping the 5 best starts after 10 iterations ("racing",
option ``race_at``/``race_keep``, off by default: lost up to 1.2 nats on 2 of 36 synthetic GPs) and a shorter
catch-up horizon (``catch_up_windows=2``: lost up to 1.6 nats). On SARCOS (n = 500, 6 GPs x 10 starts) the rule
cuts the evaluations from 6,156 to 3,098 (each start: 103 -> 52; ``docs/bench``).

Other options (off by default): ``screen_n`` optimises all starts on a random subset of ``screen_n`` points first
and continues the ``screen_keep`` best on the full data (all of them if ``screen_keep >= n_restarts``); measured
on SARCOS, the subset's ranking did not predict the full data's (up to 7.8 nats lost), hence off. ``drop_after``
stops a start that is more than ``drop_margin`` nats behind its GP's best after ``drop_after`` iterations.

"""

from __future__ import annotations

import math

import numpy as np

from cascgp.gp.config import GPFitConfig, noise_var
from cascgp.gp.lbfgs import MemberState
from cascgp.gp.state import BankData

__all__ = ["initial_thetas", "linear_noise", "warm_theta", "prune_rule", "make_pruner"]


def linear_noise(Xa: np.ndarray, yb: np.ndarray) -> float:
    """Data-driven initial noise: a tenth of the residual variance of a linear least-squares fit (clipped)."""
    n = yb.shape[0]
    A = np.hstack([Xa, np.ones((n, 1))])
    if A.shape[1] >= n:
        return 0.1
    coef, *_ = np.linalg.lstsq(A, yb, rcond=None)
    res = float(np.mean((yb - A @ coef) ** 2))
    return float(np.clip(0.1 * res, 1e-4, 0.5))


def initial_thetas(cfg: GPFitConfig, Xn: np.ndarray, yn: np.ndarray, mask: np.ndarray, const_y: np.ndarray,
                   rng: np.random.Generator) -> np.ndarray:
    r"""Log hyperparameters ``(B, n_restarts, D + 2)`` of every start of every GP on normalised data.

    Start 0 is the data-driven default (lengthscales :math:`\sqrt{d}`, :math:`s_f^2 = 1`, noise from
    :func:`linear_noise`); the others perturb it with draws from ``rng`` (in GP order, so the stream is the same
    whatever the GPs' dimensions). Inactive (masked) lengthscales are not touched here.
    """
    B, _, D = Xn.shape
    R = cfg.n_restarts
    theta0 = np.zeros((B, R, D + 2))
    d_eff = np.maximum(mask.sum(1), 1.0)
    for b in range(B):
        noise0 = linear_noise(Xn[b][:, mask[b] > 0], yn[b]) if not const_y[b] else 0.1
        base = np.concatenate([np.full(D, 0.5 * math.log(d_eff[b])), [0.0, math.log(max(noise0, 1e-6))]])
        theta0[b, :, :] = base
        if R > 1:
            theta0[b, 1:, :D] += rng.uniform(-cfg.init_spread, cfg.init_spread, size=(R - 1, D))
            theta0[b, 1:, D] += rng.uniform(-1.0, 0.5, size=R - 1)
            theta0[b, 1:, D + 1] = np.log(np.clip(noise0 * np.exp(rng.uniform(-2.5, 1.5, size=R - 1)), 1e-6, 1.0))
    return theta0


def warm_theta(config: GPFitConfig, old: BankData, new: BankData, D: int,
               new_config: GPFitConfig | None = None) -> np.ndarray:
    r"""A fitted bank's hyperparameters (``config``, ``old``) expressed in the normalisation of ``new`` data of
    width ``D``: start 0 of a warm-started fit. Lengthscales of columns inactive in either set restart at
    :math:`\sqrt{d}`; the noise keeps its value in target units (raised to the new fit's floor if below it).
    ``new_config``: the new fit's config; its per-GP floors (``noise_floor_target``) are used when it has them,
    otherwise ``config``'s floor, as before that field existed."""
    B = old.theta.shape[0]
    old_fl = config.floors(old.y_std)
    new_fl = new_config.floors(new.y_std) if new_config is not None else None
    new_cfg = config if new_config is None or new_fl is None else new_config
    out = np.zeros((B, D + 2))
    Dold = old.theta.shape[1] - 2
    for b in range(B):
        d = int(old.dims[b])
        th = old.theta[b]
        ll = th[:d] + np.log(old.x_std[b, :d]) - np.log(new.x_std[b, :d])
        ll = np.where((old.mask[b, :d] > 0) & (new.mask[b, :d] > 0), ll, 0.5 * math.log(max(d, 1)))
        out[b, :d] = ll
        scale = math.log(old.y_std[b] ** 2) - math.log(new.y_std[b] ** 2)
        out[b, D] = th[Dold] + scale
        sn2 = noise_var(config, math.exp(th[Dold]), math.exp(th[Dold + 1]),
                        None if old_fl is None else float(old_fl[b])) * math.exp(scale)
        floor = noise_var(new_cfg, math.exp(out[b, D]), 0.0, None if new_fl is None else float(new_fl[b]))
        out[b, D + 1] = math.log(max(sn2 - floor, 1e-8))
    return out


def make_pruner(cfg: GPFitConfig, gp_of: np.ndarray, B: int):
    """The ``prune`` callback of :func:`~cascgp.gp.lbfgs.minimize_batched` applying :func:`prune_rule` to members
    of the GPs ``gp_of`` (``None`` when no early-stopping option is on)."""
    if cfg.drop_after is None and cfg.stall_window is None and cfg.race_at is None:
        return None
    raced = np.zeros(B, dtype=bool)

    def prune(states: list[MemberState], rnd: int) -> np.ndarray | None:
        return prune_rule(cfg, states, gp_of, B, raced)
    return prune


def prune_rule(cfg: GPFitConfig, states: list[MemberState], gp_of: np.ndarray, B: int,
                raced: np.ndarray) -> np.ndarray:
    """Which live starts to stop now (see "Restarts and early stopping" in the module docstring).

    The leader of a GP (lowest current NLL; ties: lowest member index; finished starts included) is never stopped
    here. ``raced`` (B,) marks GPs whose race has been held (updated in place). Sets ``reason`` of stopped starts.
    """
    f = np.array([s.f if math.isfinite(s.f) else math.inf for s in states])
    live = np.array([not s.done for s in states])
    it = np.array([s.n_iter for s in states])
    best = np.full(B, np.inf)
    np.minimum.at(best, gp_of, f)
    lead = np.full(B, -1)
    for m in np.argsort(f, kind="stable")[::-1]:
        lead[gp_of[m]] = m
    out = np.zeros(len(states), dtype=bool)
    reason = [""] * len(states)
    if cfg.drop_after is not None:
        hope = live & (it >= cfg.drop_after) & (f > best[gp_of] + cfg.drop_margin)
        for m in np.flatnonzero(hope):
            out[m], reason[m] = True, "dropped"
    if cfg.race_at is not None:
        for b in np.unique(gp_of):
            if raced[b]:
                continue
            mem = np.flatnonzero(gp_of == b)
            if np.all((it[mem] >= cfg.race_at) | ~live[mem]):
                raced[b] = True
                order = mem[np.argsort(f[mem], kind="stable")]
                for m in order[cfg.race_keep:]:
                    if live[m] and not out[m]:
                        out[m], reason[m] = True, "raced_out"
    if cfg.stall_window is not None:
        w = cfg.stall_window
        for m, s in enumerate(states):
            if live[m] and not out[m] and lead[gp_of[m]] != m and len(s.trace) > w:
                gain = s.trace[-1 - w] - s.trace[-1]
                gap = f[m] - best[gp_of[m]]
                if gain <= max(cfg.stall_tol, gap / cfg.catch_up_windows):
                    out[m], reason[m] = True, "stalled"
    for m in np.flatnonzero(out):
        states[m].reason = reason[m]
    return out
