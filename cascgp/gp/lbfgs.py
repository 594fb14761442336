r"""Batched L-BFGS: many independent minimisations whose objective is evaluated in one batch.

Why hand-written: ``torch.optim.LBFGS`` and ``scipy.optimize`` optimise *one* problem. Summing the negative
log marginal likelihoods of independent GPs into one problem makes a single optimiser need far more iterations
(measured, see DESIGN.md), and a Python loop over ``scipy`` calls cannot share one batched Cholesky. Here each
problem ("member") runs its own L-BFGS with its own history, step length, strong-Wolfe line search and stopping
test, written as a plain sequential generator that *yields* the point it wants evaluated. The driver
:func:`minimize_batched` collects the pending points of all live members, evaluates them in one call of the
batched objective, and sends each member its value and gradient. Members that have stopped leave the batch,
so the batch shrinks as problems converge.

The algorithm per member is the standard two-loop L-BFGS (Nocedal & Wright, Alg. 7.4/7.5) with the strong-Wolfe
line search of Nocedal & Wright Alg. 3.5/3.6 (cubic interpolation; the same scheme as ``torch.optim.LBFGS``),
stopping when

* ``max |g| <= grad_tol`` (``"grad_tol"``), or
* ``(f_prev - f) / max(|f_prev|, |f|, 1) <= rel_tol`` (``"rel_tol"``, SciPy L-BFGS-B's ``factr`` test), or
* the step became negligible (``"small_step"``), the line search failed (``"line_search"``),
  ``max_iter`` iterations were done (``"max_iter"``) or ``max_eval`` evaluations were used (``"max_eval"``).

The optimiser state is NumPy (parameter vectors are short); only the objective is batched.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator
from dataclasses import dataclass, field

import numpy as np

__all__ = ["LBFGSOptions", "MemberState", "minimize_batched", "lbfgs_member"]


@dataclass
class LBFGSOptions:
    """Options shared by all members.

    Attributes:
        history: number of stored correction pairs (L-BFGS memory ``m``).
        max_iter: maximum number of iterations (line searches) per member.
        max_eval: maximum number of objective evaluations per member (``None``: ``max_iter * 5 // 4``... any
            large number; default 2.5 x ``max_iter``).
        grad_tol: stop when the largest absolute gradient entry is at most this.
        rel_tol: stop when the relative decrease of the objective over one iteration is at most this.
        max_ls: maximum evaluations per line search.
        c1, c2: Wolfe constants (sufficient decrease, curvature).
        step_tol: stop when ``max |t d| <= step_tol``.
    """

    history: int = 10
    max_iter: int = 1000
    max_eval: int | None = None
    grad_tol: float = 1e-5
    rel_tol: float = 2e-9
    max_ls: int = 25
    c1: float = 1e-4
    c2: float = 0.9
    step_tol: float = 1e-12


@dataclass
class MemberState:
    """Live state of one member, updated by its generator (read by the driver and by prune callbacks).

    ``x, f, g`` is the best *accepted* iterate (the last one; L-BFGS is monotone).
    """

    x: np.ndarray
    f: float = math.inf
    g: np.ndarray | None = None
    n_iter: int = 0
    n_eval: int = 0
    reason: str = "running"
    done: bool = False
    trace: list[float] = field(default_factory=list)


def _cubic_min(x1: float, f1: float, g1: float, x2: float, f2: float, g2: float,
               bounds: tuple[float, float] | None = None) -> float:
    """Minimiser of the cubic interpolating (x1, f1, g1), (x2, f2, g2), clipped to ``bounds``."""
    lo, hi = bounds if bounds is not None else (min(x1, x2), max(x1, x2))
    if not all(math.isfinite(v) for v in (x1, f1, g1, x2, f2, g2)) or x1 == x2:
        return 0.5 * (lo + hi)
    d1 = g1 + g2 - 3.0 * (f1 - f2) / (x1 - x2)
    d2_sq = d1 * d1 - g1 * g2
    if d2_sq >= 0.0:
        d2 = math.sqrt(d2_sq)
        if x1 <= x2:
            den = g2 - g1 + 2.0 * d2
            pos = x2 - (x2 - x1) * ((g2 + d2 - d1) / den) if den != 0.0 else 0.5 * (lo + hi)
        else:
            den = g1 - g2 + 2.0 * d2
            pos = x1 - (x1 - x2) * ((g1 + d2 - d1) / den) if den != 0.0 else 0.5 * (lo + hi)
        if not math.isfinite(pos):
            return 0.5 * (lo + hi)
        return min(max(pos, lo), hi)
    return 0.5 * (lo + hi)


Evaluation = tuple[float, np.ndarray]


def _line_search(st: MemberState, opt: LBFGSOptions, x: np.ndarray, t: float, d: np.ndarray, f: float,
                 g: np.ndarray, gtd: float) -> Generator[np.ndarray, Evaluation, tuple[float, np.ndarray, float, bool]]:
    """Strong-Wolfe line search along ``d`` from ``x`` (generator form). Returns ``(f, g, t, ok)``."""
    d_norm = float(np.max(np.abs(d)))
    n_ls = 0

    def evaluate(tt: float) -> Generator[np.ndarray, Evaluation, Evaluation]:
        ff, gg = yield x + tt * d
        st.n_eval += 1
        return ff, gg

    f_new, g_new = yield from evaluate(t)
    n_ls += 1
    # Non-finite objective (e.g. a Cholesky that failed even with jitter): shrink the step first.
    while not math.isfinite(f_new) and n_ls < opt.max_ls:
        t *= 0.1
        f_new, g_new = yield from evaluate(t)
        n_ls += 1
    if not math.isfinite(f_new):
        return f, g, 0.0, False
    gtd_new = float(g_new @ d)
    t_prev, f_prev, g_prev, gtd_prev = 0.0, f, g, gtd
    done = False
    bracket: list[float]
    while n_ls < opt.max_ls:
        if f_new > f + opt.c1 * t * gtd or (n_ls > 1 and f_new >= f_prev):
            bracket, bf, bg, bgtd = [t_prev, t], [f_prev, f_new], [g_prev, g_new], [gtd_prev, gtd_new]
            break
        if abs(gtd_new) <= -opt.c2 * gtd:
            bracket, bf, bg, bgtd = [t], [f_new], [g_new], [gtd_new]
            done = True
            break
        if gtd_new >= 0:
            bracket, bf, bg, bgtd = [t_prev, t], [f_prev, f_new], [g_prev, g_new], [gtd_prev, gtd_new]
            break
        # extrapolate
        t_next = _cubic_min(t_prev, f_prev, gtd_prev, t, f_new, gtd_new,
                            bounds=(t + 0.01 * (t - t_prev), t * 10.0))
        t_prev, f_prev, g_prev, gtd_prev = t, f_new, g_new, gtd_new
        t = t_next
        f_new, g_new = yield from evaluate(t)
        n_ls += 1
        if not math.isfinite(f_new):
            bracket, bf, bg, bgtd = [t_prev, t], [f_prev, math.inf], [g_prev, g_new], [gtd_prev, math.nan]
            break
        gtd_new = float(g_new @ d)
    else:
        bracket, bf, bg, bgtd = [0.0, t], [f, f_new], [g, g_new], [gtd, gtd_new]

    # zoom
    insuf = False
    if len(bracket) == 1:
        low = 0
    else:
        low, high = (0, 1) if bf[0] <= bf[1] else (1, 0)
    while not done and n_ls < opt.max_ls:
        if abs(bracket[1] - bracket[0]) * d_norm < opt.step_tol:
            break
        t = _cubic_min(bracket[0], bf[0], bgtd[0], bracket[1], bf[1], bgtd[1])
        bmax, bmin = max(bracket), min(bracket)
        eps = 0.1 * (bmax - bmin)
        if min(bmax - t, t - bmin) < eps:
            if insuf or t >= bmax or t <= bmin:
                t = bmax - eps if abs(t - bmax) < abs(t - bmin) else bmin + eps
                insuf = False
            else:
                insuf = True
        else:
            insuf = False
        f_new, g_new = yield from evaluate(t)
        n_ls += 1
        gtd_new = float(g_new @ d) if math.isfinite(f_new) else math.nan
        if not math.isfinite(f_new) or f_new > f + opt.c1 * t * gtd or f_new >= bf[low]:
            bracket[high], bf[high], bg[high], bgtd[high] = (t, (f_new if math.isfinite(f_new) else math.inf), g_new,
                                                             gtd_new)
            low, high = (0, 1) if bf[0] <= bf[1] else (1, 0)
        else:
            if abs(gtd_new) <= -opt.c2 * gtd:
                done = True
            elif gtd_new * (bracket[high] - bracket[low]) >= 0:
                bracket[high], bf[high], bg[high], bgtd[high] = bracket[low], bf[low], bg[low], bgtd[low]
            bracket[low], bf[low], bg[low], bgtd[low] = t, f_new, g_new, gtd_new
    t, f_new, g_new = bracket[low], bf[low], bg[low]
    ok = math.isfinite(f_new) and f_new <= f
    if not ok:
        return f, g, 0.0, False
    return f_new, g_new, t, True


def lbfgs_member(st: MemberState, opt: LBFGSOptions) -> Generator[np.ndarray, Evaluation, MemberState]:
    """L-BFGS for one member as a generator: yields points, receives ``(f, g)``; returns the final state.

    ``st.x`` holds the start on entry; on exit ``st`` holds the final iterate, counters and ``reason``.
    """
    max_eval = opt.max_eval if opt.max_eval is not None else int(opt.max_iter * 2.5)
    x = np.array(st.x, dtype=np.float64)
    f, g = yield x
    st.n_eval += 1
    if not math.isfinite(f):
        st.f, st.g, st.reason, st.done = f, g, "nonfinite_start", True
        return st
    st.f, st.g = f, g
    st.trace.append(f)
    if np.max(np.abs(g)) <= opt.grad_tol:
        st.reason, st.done = "grad_tol", True
        return st
    S: list[np.ndarray] = []
    Y: list[np.ndarray] = []
    RHO: list[float] = []
    d = -g
    t = min(1.0, 1.0 / max(float(np.abs(g).sum()), 1e-300))
    while True:
        gtd = float(g @ d)
        if gtd > -1e-300 or not np.all(np.isfinite(d)):
            # not a descent direction (broken curvature information): restart from steepest descent
            S.clear(); Y.clear(); RHO.clear()  # noqa: E702
            d = -g
            gtd = float(g @ d)
            t = min(1.0, 1.0 / max(float(np.abs(g).sum()), 1e-300))
        f_old = f
        f_new, g_new, t, ok = yield from _line_search(st, opt, x, t, d, f, g, gtd)
        st.n_iter += 1
        if not ok:
            if S:  # retry once from steepest descent before giving up
                S.clear(); Y.clear(); RHO.clear()  # noqa: E702
                d = -g
                t = min(1.0, 1.0 / max(float(np.abs(g).sum()), 1e-300))
                if st.n_iter < opt.max_iter and st.n_eval < max_eval:
                    continue
            st.reason = "line_search"
            break
        s = t * d
        x = x + s
        y = g_new - g
        f, g = f_new, g_new
        st.x, st.f, st.g = x, f, g
        st.trace.append(f)
        if np.max(np.abs(g)) <= opt.grad_tol:
            st.reason = "grad_tol"
            break
        if (f_old - f) / max(abs(f_old), abs(f), 1.0) <= opt.rel_tol:
            st.reason = "rel_tol"
            break
        if np.max(np.abs(s)) <= opt.step_tol:
            st.reason = "small_step"
            break
        if st.n_iter >= opt.max_iter:
            st.reason = "max_iter"
            break
        if st.n_eval >= max_eval:
            st.reason = "max_eval"
            break
        ys = float(y @ s)
        if ys > 1e-10 * max(float(y @ y), 1e-300) ** 0.5 * max(float(s @ s), 1e-300) ** 0.5:
            if len(S) == opt.history:
                S.pop(0); Y.pop(0); RHO.pop(0)  # noqa: E702
            S.append(s); Y.append(y); RHO.append(1.0 / ys)  # noqa: E702
        # two-loop recursion
        q = -g
        al = [0.0] * len(S)
        for i in range(len(S) - 1, -1, -1):
            al[i] = RHO[i] * float(S[i] @ q)
            q = q - al[i] * Y[i]
        if S:
            q = q * (1.0 / (RHO[-1] * float(Y[-1] @ Y[-1])))
        for i in range(len(S)):
            be = RHO[i] * float(Y[i] @ q)
            q = q + (al[i] - be) * S[i]
        d = q
        t = 1.0
    st.done = True
    return st


def minimize_batched(
    fun: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
    x0: np.ndarray,
    options: LBFGSOptions | None = None,
    prune: Callable[[list[MemberState], int], np.ndarray | None] | None = None,
) -> list[MemberState]:
    """Minimise ``M`` independent problems, evaluating all pending points together.

    Args:
        fun: batched objective ``fun(X, idx) -> (f, G)``: ``X`` is ``(k, p)`` points of the members ``idx``
            (``(k,)`` int, indices into ``x0``); returns values ``(k,)`` (``inf``/``nan`` allowed for points where
            the objective is undefined) and gradients ``(k, p)``.
        x0: ``(M, p)`` starting points.
        options: :class:`LBFGSOptions`.
        prune: optional callback ``prune(states, round) -> bool mask (M,)`` called after every batched evaluation
            round; members with ``True`` are stopped now (``reason="dropped"``), keeping their last accepted
            iterate. A callback may set ``states[i].reason`` itself (e.g. ``"stalled"``) before returning.

    Returns:
        One :class:`MemberState` per member (final ``x``, ``f``, ``g``, ``n_iter``, ``n_eval``, ``reason``).
    """
    opt = options or LBFGSOptions()
    x0 = np.asarray(x0, dtype=np.float64)
    states = [MemberState(x=x0[i].copy()) for i in range(x0.shape[0])]
    gens: dict[int, Generator[np.ndarray, Evaluation, MemberState]] = {}
    pending: dict[int, np.ndarray] = {}
    for i, st in enumerate(states):
        gen = lbfgs_member(st, opt)
        gens[i] = gen
        pending[i] = next(gen)
    rnd = 0
    while pending:
        idx = np.fromiter(pending.keys(), dtype=np.int64, count=len(pending))
        X = np.stack([pending[i] for i in idx])
        fv, G = fun(X, idx)
        fv = np.asarray(fv, dtype=np.float64)
        G = np.asarray(G, dtype=np.float64)
        new_pending: dict[int, np.ndarray] = {}
        for k, i in enumerate(idx):
            fk = float(fv[k])
            if math.isnan(fk):
                fk = math.inf
            try:
                new_pending[int(i)] = gens[int(i)].send((fk, G[k]))
            except StopIteration:
                del gens[int(i)]
        pending = new_pending
        rnd += 1
        if prune is not None and pending:
            mask = prune(states, rnd)
            if mask is not None:
                for i in list(pending):
                    if mask[i]:
                        gens[i].close()
                        del gens[i], pending[i]
                        if states[i].reason == "running":  # prune may name its own reason
                            states[i].reason = "dropped"
                        states[i].done = True
    return states
