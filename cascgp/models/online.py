r"""Learning inside an episode: new measured samples enter a fitted cascade at a bounded cost.

Between retrainings the hyperparameters are held; each joint's GP keeps its fitted training set (``n0`` points,
kernel matrix :math:`K_{00}`, weights :math:`\alpha_{fit} = K_{00}^{-1} y_0`) and gains a window of at most
``window`` recent samples (the oldest is dropped when it is full). With :math:`B = K_{w0} K_{00}^{-1}` (one row
:math:`b_i = K_{00}^{-1} k_{0i}` per window sample) the enlarged kernel matrix is inverted by blocks through the
window's Schur complement

.. math::

    S = K_{ww} + \sigma^2 I - B K_{0w}, \qquad
    \alpha_w = S^{-1} (y_w - K_{w0} \alpha_{fit}), \qquad \alpha_0 = \alpha_{fit} - B^\top \alpha_w,

and the latent variance at a query with kernel rows :math:`k_0, k_w` is the fitted set's plus
:math:`v^\top S^{-1} v`, :math:`v = k_w - B k_0`. The window's samples sit in ``window`` slots written in turn
(the slot of a new sample is that of the oldest once the window is full), and :math:`S^{-1}` is kept explicitly
and updated by rank-one terms: dropping slot :math:`o` is the Schur complement of :math:`(S^{-1})_{oo}`,
:math:`S^{-1} \leftarrow S^{-1} - t t^\top / t_o` with :math:`t = S^{-1} e_o`, and adding a sample with column
:math:`s` and diagonal :math:`c` is

.. math::

    g = S^{-1} s, \quad \delta = c - s^\top g, \quad
    S^{-1} \leftarrow \begin{pmatrix} S^{-1} + g g^\top / \delta & -g / \delta \\ -g^\top / \delta & 1 / \delta
    \end{pmatrix},

:math:`O(w^2)` instead of refactorising the block (:math:`O(w^3)`). Once every ``window`` samples :math:`S^{-1}` is
recomputed from :math:`S` (Cholesky factor and its inverse, LAPACK ``dpotrf``/``dpotri``), so that the rank-one
updates' round-off does not accumulate. A sample whose :math:`\delta` is not positive (the enlarged matrix would
not be positive definite) is refused. A sample then costs two triangular solves with the fitted factor
:math:`L_{00}` (:math:`L_{00}^{-1} k_0`, then :math:`b = L_{00}^{-\top} L_{00}^{-1} k_0`; :math:`O(n_0^2)`), two
products with :math:`B` (:math:`O(n_0 w)`) and the rank-one terms. Why by hand: an extension of a fixed factor is
not a library routine in NumPy/SciPy/torch, and refitting or refactorising the whole :math:`(n_0 + w)` matrix per
sample (:math:`O(n^3)`) would not fit between control ticks. With the ``fast`` extra (Numba) a sample runs
compiled (:mod:`cascgp.models.online_kernel`: the same steps and BLAS calls in two compiled calls, equal to
round-off); this module's NumPy form is the reference and runs without it.

The single-query paths (:meth:`~cascgp.models.CascadedGPModel.predict_one`, ``predict_one_var``) read the
enlarged sets: the fast path is rebuilt with room for the window (its rows ``n0 + slot``; empty slots carry zero
weight), and the variance adds the window term above. Each joint's input uses the *measured* neighbour torque and
its target is the measured torque (minus the RBD torque for SP models), exactly as in training.
Derivative-based (``db``) models only.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.linalg.blas import dsymv, dsyr, dtrsv
from scipy.linalg.lapack import dpotrf, dpotri

from cascgp.checks import check_count
from cascgp.gp.checks import check_scale
from cascgp.gp.kernels import get_kernel
from cascgp.gp.likelihood import blas_threads
from cascgp.gp.memory import physical_memory_bytes
from cascgp.models.fastkernel import JIT_WT, jit_enabled, jit_var, kernel_id, warn_dropped
from cascgp.models.fastpath import FastPath, FastVariance
from cascgp.models.queries import one_real, state_cols

__all__ = ["OnlineWindow", "check_supported"]

#: Position in the compiled sample's work arrays of the proposal's rows ``(c, delta)`` per joint.
_PSC = 11
#: Magnitudes below which a sample's values are finite and normalisable without checking each field.
_SMALL = 1e150


class _JointWindow:
    """Window of one joint's GP (normalised units): slots, :math:`B`, :math:`S` and :math:`S^{-1}`.

    :math:`S^{-1}` is Fortran-ordered with its lower triangle kept (what BLAS ``dsymv``/``dsyr`` read and
    write); ``S`` is kept in full (for the periodic recomputation). Besides :math:`B` the slots hold
    :math:`L_{w0} = K_{w0} L_{00}^{-\top}` (rows :math:`L_{00}^{-1} k_{0i}`, the better-conditioned form of the
    variance term: :math:`B k_0 = L_{w0} L_{00}^{-1} k_0`). Every array is allocated once and written in place,
    never replaced (the compiled sample and variance hold them)."""

    def __init__(self, P: Any, window: int) -> None:
        self.P = P
        n0, d = P.Z.shape
        self.kernel = get_kernel(P.kernel)
        self.noise = P.noise_var + P.jitter
        self.Lf = np.ascontiguousarray(P.L)
        self.U00 = self.Lf.T  # L00^T, Fortran-ordered: what BLAS reads without a copy
        y0 = P.L @ (P.L.T @ P.alpha)  # the normalised targets
        self.u0 = dtrsv(self.U00, y0, lower=0, trans=1)  # L00^-1 y0
        self.alpha_fit = np.ascontiguousarray(P.alpha, dtype=np.float64)
        self.Z2 = np.einsum("nd,nd->n", P.Z, P.Z)
        self.window = W = window
        self.Zw = np.zeros((W, d))  # slot inputs
        self.B = np.zeros((W, n0))  # slot rows b_i = K00^-1 k0_i
        self.Lw0 = np.zeros((W, n0))  # slot rows L00^-1 k0_i
        self.r = np.zeros(W)  # slot targets minus the fitted set's part, y_i - (L00^-1 k0_i) . u0
        self.S = np.zeros((W, W))
        self.Sinv = np.zeros((W, W), order="F")
        self.m = 0  # samples held
        self.n_in = 0  # samples ever committed: the next slot is n_in % W
        self.alpha0 = self.alpha_fit.copy()
        self.alphaw = np.zeros(W)

    def _without(self, o: int, x: np.ndarray, t: np.ndarray | None) -> np.ndarray:
        """:math:`S^{-1} x` with slot ``o`` left out (``t``: column ``o`` of :math:`S^{-1}` when it is held)."""
        y = dsymv(1.0, self.Sinv, x, lower=1)
        if t is not None:
            y -= t * (float(t @ x) / t[o])
        y[o] = 0.0
        return y

    def propose(self, z: np.ndarray, y: float) -> tuple:
        """Everything that adding the normalised input ``z`` and target ``y`` would change, new weights included,
        computed without changing anything. Raises ``LinAlgError`` (the window as it was) when the enlarged
        matrix would not be positive definite; :meth:`commit` applies it and cannot fail."""
        P, W = self.P, self.window
        o = self.n_in % W  # the slot of the new sample: that of the oldest when the window is full
        drop = self.m == W
        k0 = P.signal_var * self.kernel.value(self.Z2 - 2.0 * (P.Z @ z) + float(z @ z))  # |z - Z_k|^2 expanded
        row = dtrsv(self.U00, k0, lower=0, trans=1)  # L00^-1 k0
        b = dtrsv(self.U00, row, lower=0)  # L00^-T L00^-1 k0 (the factor is still in cache)
        s = np.zeros(W)
        h = W if drop else self.m  # slots held
        if h:
            s[:h] = P.signal_var * self.kernel.value(((z - self.Zw[:h]) ** 2).sum(1)) - self.B[:h] @ k0
            s[o] = 0.0
        c = P.signal_var + self.noise - float(row @ row)
        t = None
        if drop:
            t = self.Sinv[:, o].copy()
            t[:o] = self.Sinv[o, :o]  # the lower triangle holds row o left of the diagonal
        g = self._without(o, s, t)
        delta = c - float(s @ g)
        if not (delta > 0.0 and math.isfinite(delta) and np.isfinite(g).all() and np.isfinite(b).all()):
            raise np.linalg.LinAlgError(f"the window block is not positive definite (Schur complement {delta!r})")
        r = self.r.copy()
        r[o] = float(y) - float(row @ self.u0)
        hv = g.copy()
        hv[o] = -1.0  # S_new^-1 = (S^-1 without o) + hv hv^T / delta
        alphaw = self._without(o, r, t)
        alphaw += hv * (float(hv @ r) / delta)
        alpha0 = self.alpha_fit - alphaw @ self.B  # B's row o: the new sample's (below)
        alpha0 += alphaw[o] * (self.B[o] - b)
        return o, t, z, row, b, s, c, hv, delta, r, alphaw, alpha0

    def commit(self, proposal: tuple) -> None:
        """Apply a :meth:`propose` result: the new sample in its slot (the oldest dropped if full), new weights."""
        o, t, z, row, b, s, c, hv, delta, r, alphaw, alpha0 = proposal
        Sinv = self.Sinv
        if t is not None:
            Sinv = dsyr(-1.0 / t[o], t, lower=1, a=Sinv, overwrite_a=1)  # in place (Fortran-ordered)
            Sinv[o, :] = Sinv[:, o] = 0.0
        Sinv = dsyr(1.0 / delta, hv, lower=1, a=Sinv, overwrite_a=1)
        if Sinv is not self.Sinv:  # the window's arrays stay the same objects (the compiled paths hold them)
            self.Sinv[...] = Sinv
        self.S[o, :] = self.S[:, o] = s
        self.S[o, o] = c
        self.Zw[o], self.B[o], self.Lw0[o], self.r[:] = z, b, row, r
        self.m = min(self.m + 1, self.window)
        self.n_in += 1
        self.alphaw[:], self.alpha0[:] = alphaw, alpha0
        if self.n_in % self.window == 0:
            self._recompute()

    def _recompute(self) -> None:
        """:math:`S^{-1}` of the (full) window from :math:`S` (its factor's inverse) in place of the updated one,
        and the weights from it."""
        Lf, info = dpotrf(self.S, lower=1, clean=1)
        if info != 0:
            return  # the updated inverse stays (it passed its checks)
        Si, info = dpotri(Lf, lower=1)
        if info == 0 and np.isfinite(Si).all():
            self.Sinv[:] = Si
            self.alphaw[:] = dsymv(1.0, self.Sinv, self.r, lower=1)
            self.alpha0[:] = self.alpha_fit - self.alphaw @ self.B

    def extra_var(self, kap_w: np.ndarray, u: np.ndarray, scale: float) -> float:
        """Window term of the latent variance (torque units): ``kap_w`` the query's kernel row of the slots,
        ``u`` the fitted set's solve :math:`c L_{00}^{-1} k_0`, ``scale`` :math:`c = y_{std} s_f^2`."""
        if self.m == 0:
            return 0.0
        v = scale * kap_w - self.Lw0 @ u
        return float(v @ dsymv(1.0, self.Sinv, v, lower=1))


def check_supported(model: Any, window: int | None = None, name: str = "window") -> None:
    """``ValueError`` naming the model unless online samples can enter it: derivative-based features, and
    neighbour torques in training that were measured (online samples carry measured ones). With ``window``
    (samples, checked by the caller), also ``ValueError`` naming ``name`` unless the fitted model's window arrays
    fit in this machine's physical memory (a model without ``posteriors()`` is checked when its window opens)."""
    if model.feature_kind != "db":
        raise ValueError(f"online: model {model.name!r}: online updates support derivative-based models only")
    if getattr(model, "train_on_predicted", False) and model.structure != "standard":
        raise ValueError(f"online: model {model.name!r} was trained on predicted neighbour torques; online "
                         "samples carry measured ones, so they would not match its training inputs")
    if window is not None and callable(getattr(model, "posteriors", None)):
        _check_window_memory(window, model.posteriors(), name)


def _check_values(name: str, a: np.ndarray, not_finite: str) -> None:
    """``ValueError`` with the message ``not_finite`` for a NaN or inf entry of ``a``, or naming ``name`` when its
    values are too large to normalise (:func:`cascgp.gp.checks.check_scale`)."""
    if not np.isfinite(a).all():
        raise ValueError(not_finite)
    check_scale(np.stack([a, np.zeros(a.size)]), name)


def _check_window_memory(window: int, posts: list[Any], name: str = "window") -> None:
    """``ValueError`` naming ``name`` when the window's arrays (per joint two window x window matrices and the
    window's rows against the fitted set) would not fit in this machine's physical memory, instead of NumPy's
    ``MemoryError`` or the system's out-of-memory kill later, when the pages are written."""
    phys = physical_memory_bytes()
    if phys is None:  # not POSIX: no bound known
        return
    need = sum(8 * (2 * window * window + 3 * window * (P.Z.shape[0] + P.Z.shape[1])) for P in posts)
    if need > phys:
        raise ValueError(f"{name}: {window} samples per joint would need about {need / 1e9:.3g} GB, more than this "
                         f"machine's {phys / 1e9:.3g} GB of physical memory; choose a smaller window")


class OnlineWindow:
    """Online samples of every joint of a fitted derivative-based cascade (see the module docstring).

    Args:
        model: a fitted :class:`~cascgp.models.CascadedGPModel` (``db`` features).
        window: samples kept per joint (the oldest is dropped beyond it).
    """

    def __init__(self, model: Any, window: int) -> None:
        check_supported(model)
        self.window = check_count(window, "window")
        self.model = model
        posts = model.posteriors()
        _check_window_memory(self.window, posts)
        self.joints = [_JointWindow(P, self.window) for P in posts]
        self.fast = FastPath.build(posts, model.specs, model.order, capacity=self.window)
        self.n0 = posts[0].Z.shape[0]
        self.c = math.sqrt(self.fast.kernel.r2_scale)
        self.n_added = 0
        D = 3 * model.dof  # columns of the flattened states; the measured torques follow them
        self._cols = [np.concatenate([state_cols(np.arange(D)[None], sj)[0], [D + tj] if tj is not None else []])
                      .astype(np.intp) for sj, tj in model.specs]
        self._var: FastVariance | None = None
        self._tfrom = np.array([-1 if t is None else t for t in self.fast.torque_from], dtype=np.int64)
        self._gathered: dict[str, Any] | None = None
        self._jit = self._compiled_work()

    def _compiled_work(self) -> tuple | None:
        """Work arrays of the compiled sample (:mod:`cascgp.models.online_kernel`), which is compiled (or loaded
        from Numba's cache) and run once now on copies of the window, so that an episode's first sample does not
        pay for it; None when the NumPy path runs (no Numba, ``CASCGP_JIT=0``, a kernel without a compiled form,
        or a loop that fails to build)."""
        if kernel_id(self.fast.kernel.name) < 0 or not jit_enabled() or self.fast.jit is None:
            return None
        try:
            from cascgp.models import online_kernel
        except ImportError:
            return None
        except Exception as exc:  # noqa: BLE001 - e.g. Numba finds no writable cache location when it decorates
            warn_dropped("online sample", exc, stacklevel=5)
            return None
        N, W, n0 = len(self.joints), self.window, self.n0
        d = max(J.Zw.shape[1] for J in self.joints)
        work = (np.zeros((N, d)), *(np.zeros((N, n0)) for _ in range(4)), *(np.zeros((N, W)) for _ in range(6)),
                np.zeros((N, 2)), np.zeros(4, dtype=np.int32), np.zeros(2), np.zeros(3, dtype=np.uint8))
        x = [J.P.x_mean.copy() for J in self.joints]
        y = np.array([J.P.y_mean for J in self.joints])
        try:
            with blas_threads(1):
                consts = self._consts()
                if self._propose_compiled(online_kernel, work, x, y, consts) >= 0:
                    return None  # a window that refuses the trial sample: the NumPy path, untried
                self._commit_compiled(online_kernel, work, consts, copies=True)
        except Exception as exc:  # noqa: BLE001 - as for the control tick's loop: the NumPy path still works
            warn_dropped("online sample", exc, stacklevel=5)
            return None
        return work

    def _per_joint(self, get: Any) -> tuple:
        """``get(J)`` for every joint's window, as the tuple the compiled loops take."""
        return tuple(get(J) for J in self.joints)

    def _consts(self) -> np.ndarray:
        """Per joint: signal variance, noise (plus jitter), target mean and scale, the fast path's weight scale
        (:data:`~cascgp.models.online_kernel.CONSTS`), read at each sample as the NumPy path reads them."""
        return np.array([(J.P.signal_var, J.noise, J.P.y_mean, J.P.y_std, J.P.y_std * J.P.signal_var)
                         for J in self.joints])

    def _arrays(self) -> dict[str, Any]:
        """The per-joint arrays the compiled loops take, gathered once per window (they are written in place, never
        replaced). Not copied or pickled with the window (``__getstate__``): a copy's views of its own arrays are
        gathered again."""
        gathered = getattr(self, "_gathered", None)  # None also in a window pickled before it was kept
        if gathered is None:
            per = self._per_joint
            self._gathered = gathered = {
                "fitted": (per(lambda J: J.P.x_mean), per(lambda J: J.P.x_scale), per(lambda J: J.Lf),
                           per(lambda J: J.P.Z), per(lambda J: J.Z2), per(lambda J: J.u0), per(lambda J: J.alpha_fit)),
                **{nm: per(lambda J, nm=nm: getattr(J, nm)) for nm in ("Zw", "B", "Lw0", "S", "r", "alphaw",
                                                                     "alpha0")},
                "ST": per(lambda J: J.Sinv.T)}  # the memory of each Fortran-ordered inverse
        return gathered

    def __getstate__(self) -> dict[str, Any]:
        return {**self.__dict__, "_gathered": None}

    def _propose_compiled(self, kernels: Any, work: tuple, x_per_joint: Any, y: np.ndarray,
                          consts: np.ndarray) -> int:
        """:func:`~cascgp.models.online_kernel.propose` (``kernels``: that module; ``consts``: :meth:`_consts`) on
        this window: -1, or the joint that refuses."""
        f, J0, a = kernels.blas(), self.joints[0], self._arrays()
        xs = tuple(np.ascontiguousarray(x, dtype=np.float64) for x in x_per_joint)
        return kernels.propose(f["dtrsv"], f["dgemv"], f["dsymv"], kernel_id(self.fast.kernel.name),
                               self.fast.zclip / self.c, J0.m, J0.n_in, xs, np.asarray(y, np.float64), consts,
                               *a["fitted"], a["Zw"], a["B"], a["ST"], a["r"], *work)

    def _commit_compiled(self, kernels: Any, work: tuple, consts: np.ndarray, copies: bool = False) -> None:
        """:func:`~cascgp.models.online_kernel.commit` of the last proposal (``consts``: the proposal's;
        ``copies``: into copies of every array it writes, changing nothing: the build's trial run)."""
        fast, a = self.fast, self._arrays()
        cp = (lambda x: x.copy()) if copies else (lambda x: x)
        cpt = (lambda t: tuple(x.copy() for x in t)) if copies else (lambda t: t)
        Pz, Prow, Pb, Pa0, _, Ps, Pt, Phv, Pr, Paw, _, Psc, fi, fd, ch = work
        WT = fast.jit[JIT_WT] if fast.jit is not None else np.zeros((1, 1, 1))  # the compiled mean's copy of W
        kernels.commit(kernels.blas()["dsyr"], self.joints[0].m, self.joints[0].n_in, consts, self._tfrom,
                       self.c, *(cpt(a[nm]) for nm in ("Zw", "B", "Lw0", "S", "ST", "r", "alphaw", "alpha0")),
                       cp(fast.W), cp(fast.W2), cp(WT), fast.jit is not None, cp(fast.Zt), cp(fast.alpha), Pz, Prow,
                       Pb, Pa0, Ps, Pt, Phv, Pr, Paw, Psc, fi, fd, ch)

    def variance(self, base: FastVariance | None = None) -> FastVariance:
        """The variance path of the fitted sets plus this window (the window's term is read live at each
        query). ``base``: the fitted model's own (:meth:`~cascgp.models.CascadedGPModel.prepare_variance`),
        so that opening a window does not rebuild it."""
        if self._var is None:
            base = base if base is not None else FastVariance.build(self.model.posteriors())
            Lc = base.Lc
            if Lc is not None and self.fast.jit is not None:  # compile (or load) the loop with the window's term now
                N = len(self.joints)
                _, Lw, ST = self.compiled_var_terms()
                try:  # run as with samples held (the window's term is 0: its arrays are still zero or hold samples)
                    jit_var(self.fast.jit, Lc, base.scale, base.prior, np.zeros(self.fast.alpha.shape), np.zeros(N),
                            np.zeros(N), (1, Lw, ST))
                except Exception as exc:  # noqa: BLE001 - as for the sample: the per-joint path still works
                    warn_dropped("variance of the online window", exc, "the per-joint path")
                    Lc = None
            self._var = FastVariance(L=base.L, scale=base.scale, prior=base.prior, window=self, Lc=Lc)
        return self._var

    def compiled_var_terms(self) -> tuple[int, tuple, tuple]:
        """The window's variance term for the compiled loop (:func:`~cascgp.models.fastkernel.jit_var`): samples
        held, each joint's :math:`L_{w0}`, and the memory of each joint's Fortran-ordered :math:`S^{-1}`."""
        a = self._arrays()
        return self.joints[0].m, a["Lw0"], a["ST"]

    def extra_var(self, j: int, kap: np.ndarray, u: np.ndarray) -> float:
        """Hook of :meth:`FastVariance.mean_var`: the window term of joint ``j``."""
        J = self.joints[j]
        return J.extra_var(kap[self.n0:], u, J.P.y_std * J.P.signal_var)

    def add_measured(self, q: Any, qd: Any, qdd: Any, tau: Any) -> None:
        """Add one measured sample ``(q, qd, qdd, tau)``, each (N,)
        (:meth:`~cascgp.models.CascadedGPModel.add_sample`): each joint's input holds its states and the
        *measured* neighbour torque, its target the measured torque (minus the RBD torque for SP models), as in
        training. ``ValueError`` for a non-finite value, or one (or an SP target) too large to normalise, changing
        nothing."""
        model = self.model
        N = model.dof
        arr = {}
        for nm, v in (("q", q), ("qd", qd), ("qdd", qdd), ("tau", tau)):
            a = one_real(nm, v)
            if a.shape != (N,):
                raise ValueError(f"{nm}: expected a finite array of shape ({N},), got {a!r}")
            arr[nm] = a
        if not np.abs(np.stack(list(arr.values()))).max() < _SMALL:  # else one of the exact checks fails
            for nm, a in arr.items():
                _check_values(nm, a, f"{nm}: expected a finite array of shape ({N},), got {a!r}")
        S = model._states(arr["q"][None], arr["qd"][None], arr["qdd"][None], None).reshape(-1)
        target = arr["tau"] - (model._rbd_torque(arr["q"], arr["qd"], arr["qdd"]) if model.parametric == "sp"
                               else 0.0)
        if model.parametric == "sp" and not np.abs(target).max() < _SMALL:  # a huge velocity's rigid-body torque
            _check_values("tau (minus the rigid-body torque: the sample's target)", target,
                          f"tau: the sample's target (tau minus the rigid-body torque) is not finite: {target!r}")
        v = np.concatenate([S, arr["tau"]])  # each joint's input: its state columns, then the neighbour's torque
        self.add([v[c] for c in self._cols], target)

    def add(self, x_per_joint: list[np.ndarray], y: np.ndarray) -> None:
        """Add one sample: each joint's raw GP input (states, measured neighbour torque) and target. BLAS runs
        on one thread (its threads spun against the simulation: 30 ms instead of 0.3 ms per window factor).
        ``ValueError`` naming the argument for a wrong number of joints or input length, changing nothing."""
        N = len(self.joints)
        if len(x_per_joint) != N or np.shape(y) != (N,):
            raise ValueError(f"add: expected {N} joint inputs and targets of shape ({N},), got "
                             f"{len(x_per_joint)} inputs and targets of shape {np.shape(y)}")
        for j, (J, x) in enumerate(zip(self.joints, x_per_joint)):
            if np.shape(x) != (J.Zw.shape[1],):
                raise ValueError(f"add: x_per_joint[{j}]: expected shape ({J.Zw.shape[1]},), got {np.shape(x)}")
        with blas_threads(1):
            self._add(x_per_joint, y)

    def _add(self, x_per_joint: list[np.ndarray], y: np.ndarray) -> None:
        if self._jit is not None:
            from cascgp.models import online_kernel

            consts = self._consts()
            j = self._propose_compiled(online_kernel, self._jit, x_per_joint, y, consts)
            if j >= 0:
                schur = float(self._jit[_PSC][j, 1])
                raise np.linalg.LinAlgError(f"the window block is not positive definite (Schur complement {schur!r})")
            self._commit_compiled(online_kernel, self._jit, consts)
            for j, J in enumerate(self.joints):  # the counts, and the periodic recomputation (in NumPy)
                J.m = min(J.m + 1, self.window)
                J.n_in += 1
                if J.n_in % self.window == 0:
                    J._recompute()
                    scale = J.P.y_std * J.P.signal_var
                    np.multiply(J.alpha0, scale, out=self.fast.alpha[j, :self.n0])
                    np.multiply(J.alphaw, scale, out=self.fast.alpha[j, self.n0:])
            self.n_added += 1
            return
        fast, n0, c = self.fast, self.n0, self.c
        proposals = []  # every joint first: a joint that refuses the sample leaves all of them unchanged
        for j, (J, x) in enumerate(zip(self.joints, x_per_joint)):
            P = J.P
            z = np.where(np.isfinite(P.x_scale), (x - P.x_mean) / P.x_scale, 0.0)
            z = np.clip(z, -fast.zclip / c, fast.zclip / c)
            proposals.append(J.propose(z, (float(y[j]) - P.y_mean) / P.y_std))
        for j, (J, proposal) in enumerate(zip(self.joints, proposals)):
            P = J.P
            J.commit(proposal)
            o, z = proposal[0], proposal[2]
            ds = z.size - (fast.torque_from[j] is not None)
            Wo = np.zeros((1, fast.W.shape[2]))
            Wo[0, :ds] = c * z[:ds]
            fast.set_rows(j, n0 + o, Wo)
            if fast.torque_from[j] is not None:
                fast.Zt[j, n0 + o] = c * z[ds]
            scale = P.y_std * P.signal_var
            np.multiply(J.alpha0, scale, out=fast.alpha[j, :n0])
            np.multiply(J.alphaw, scale, out=fast.alpha[j, n0:])
        self.n_added += 1
