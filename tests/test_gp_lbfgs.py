"""Batched L-BFGS (cascgp.gp.lbfgs): each member converges on its own, matches SciPy, stops and drops per member."""

from __future__ import annotations

import numpy as np
import scipy.optimize

from cascgp.gp.lbfgs import LBFGSOptions, minimize_batched


def rosen_batch(X: np.ndarray, idx: np.ndarray):
    f = np.array([scipy.optimize.rosen(x) for x in X])
    g = np.array([scipy.optimize.rosen_der(x) for x in X])
    return f, g


def test_members_converge_independently_to_scipy_minimum():
    rng = np.random.default_rng(0)
    x0 = rng.uniform(-1.5, 1.5, size=(5, 4))
    states = minimize_batched(rosen_batch, x0, LBFGSOptions(grad_tol=1e-8, rel_tol=0.0))
    for st in states:
        assert st.reason == "grad_tol"
        np.testing.assert_allclose(st.x, np.ones(4), atol=1e-6)
    # different members need different numbers of iterations (each stops on its own criterion)
    assert len({st.n_iter for st in states}) > 1


def test_quadratics_with_nonfinite_region_and_max_iter():
    A = np.diag([1.0, 100.0])

    def fun(X, idx):
        f = 0.5 * np.einsum("ki,ij,kj->k", X, A, X)
        f[np.abs(X).max(1) > 50] = np.inf  # undefined far away: the line search must back off
        return f, X @ A

    x0 = np.array([[10.0, 1.0], [1.0, 1.0]])
    states = minimize_batched(fun, x0, LBFGSOptions())
    for st in states:
        assert st.f < 1e-9 and st.reason in ("grad_tol", "rel_tol")
    capped = minimize_batched(fun, x0, LBFGSOptions(max_iter=2, grad_tol=0.0, rel_tol=0.0))
    assert all(st.n_iter == 2 and st.reason == "max_iter" for st in capped)


def test_prune_drops_members():
    x0 = np.array([[0.0, 0.0], [-1.2, 1.0], [2.0, 2.0]])
    states = minimize_batched(rosen_batch, x0, LBFGSOptions(),
                              prune=lambda sts, rnd: np.array([i == 2 and rnd >= 2 for i in range(3)]))
    assert states[2].reason == "dropped" and states[0].reason != "dropped"
    assert np.isfinite(states[2].f)
