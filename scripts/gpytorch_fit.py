"""GPyTorch's exact-GP recipe for the fit benchmark, and one closed-form NLL for every library's hyperparameters.

The recipe (GPyTorch's exact-GP regression tutorial, float64): ``ExactGP`` with ``ConstantMean`` (or ``ZeroMean``)
and ``ScaleKernel(MaternKernel(nu=2.5, ard_num_dims=d))``, ``GaussianLikelihood`` (default noise constraint
``GreaterThan(1e-4)``), loss ``-ExactMarginalLogLikelihood``; one model per output, optimised with

* ``adam``: ``torch.optim.Adam(lr=0.1)`` for a fixed number of iterations (150 by default), as most users run it;
* ``lbfgs``: ``torch.optim.LBFGS(lr=1, line_search_fn="strong_wolfe", history_size=10)`` to its own convergence
  (``tolerance_grad=1e-5``, ``tolerance_change=1e-9`` on the per-point loss, at most ``max_iter`` iterations).

Restarts (the random initialisation): restart 0 starts from GPyTorch's default initialisation (every raw parameter
0: lengthscales and output scale ``softplus(0) = 0.693``, noise ``1e-4 + 0.693``, constant 0); restarts ``r >= 1``
draw every raw parameter (raw lengthscales, raw output scale, raw noise) i.i.d. from N(0, 1) with a generator seeded
by ``seed * 1000 + 100 * output + r``; the constant starts at 0. ``init=`` replaces these by given starting points.
The restart with the lowest final loss (recomputed at its final parameters) is kept. A restart whose Cholesky fails
beyond GPyTorch's jitter retries ends with loss ``inf``.

All NLLs here are totals in nats on the data as given (``-mll * n``, including ``n/2 log 2 pi``).
:func:`hyper_nll` is the closed-form objective used to compare libraries: given ``(lengthscale, signal_var,
noise_var)`` and a constant mean ``c`` (0: cascgp's and GPy's objective on standardised targets), or ``c=None`` for
the constant-mean objective with ``c`` profiled out (its generalised-least-squares value, GPyTorch's optimum in c).
"""

from __future__ import annotations

import math
import time

import numpy as np

LOG2PI = math.log(2.0 * math.pi)


# ---------------------------------------------------------------------------------------------- closed form
def matern52(X1: np.ndarray, X2: np.ndarray, lengthscale: np.ndarray, signal_var: float) -> np.ndarray:
    """Matern 5/2 ARD kernel matrix ``s_f^2 (1 + sqrt5 r + 5 r^2 / 3) exp(-sqrt5 r)``."""
    A = X1 / lengthscale
    B = X2 / lengthscale
    r2 = np.maximum((A * A).sum(1)[:, None] + (B * B).sum(1)[None, :] - 2.0 * A @ B.T, 0.0)
    r = np.sqrt(r2)
    return signal_var * (1.0 + math.sqrt(5.0) * r + 5.0 / 3.0 * r2) * np.exp(-math.sqrt(5.0) * r)


def gls_mean(X: np.ndarray, y: np.ndarray, lengthscale: np.ndarray, signal_var: float, noise_var: float) -> float:
    """The constant ``c`` that maximises the marginal likelihood for fixed kernel hyperparameters:
    ``1' K^-1 y / 1' K^-1 1``."""
    K = matern52(X, X, lengthscale, signal_var) + noise_var * np.eye(X.shape[0])
    L = np.linalg.cholesky(K)
    one = np.ones(X.shape[0])
    a = np.linalg.solve(L, y)
    b = np.linalg.solve(L, one)
    return float(b @ a / (b @ b))


def hyper_nll(X: np.ndarray, y: np.ndarray, lengthscale: np.ndarray, signal_var: float, noise_var: float,
              mean: float | None = 0.0) -> float:
    r"""Negative log marginal likelihood (total, nats) of a GP with Matern 5/2 ARD kernel and constant mean:
    :math:`\tfrac12 (y - c)^\top K^{-1} (y - c) + \tfrac12 \log|K| + \tfrac n2 \log 2\pi`,
    :math:`K = k(X, X) + s_n^2 I`. ``mean=0``: the zero-mean objective (cascgp's and GPy's on standardised
    targets); ``mean=None``: ``c`` profiled out (:func:`gls_mean`)."""
    X = np.asarray(X, float)
    y = np.asarray(y, float).reshape(-1)
    ls = np.asarray(lengthscale, float)
    c = gls_mean(X, y, ls, signal_var, noise_var) if mean is None else float(mean)
    K = matern52(X, X, ls, signal_var) + noise_var * np.eye(X.shape[0])
    L = np.linalg.cholesky(K)
    a = np.linalg.solve(L, y - c)
    return float(0.5 * a @ a + np.log(np.diag(L)).sum() + 0.5 * X.shape[0] * LOG2PI)


def predict_mean(X: np.ndarray, y: np.ndarray, Xq: np.ndarray, lengthscale: np.ndarray, signal_var: float,
                 noise_var: float, mean: float = 0.0) -> np.ndarray:
    """Posterior mean (NumPy reference): ``c + k(Xq, X) K^-1 (y - c)``."""
    K = matern52(X, X, lengthscale, signal_var) + noise_var * np.eye(X.shape[0])
    alpha = np.linalg.solve(K, y - mean)
    return mean + matern52(Xq, X, lengthscale, signal_var) @ alpha


# ---------------------------------------------------------------------------------------------- GPyTorch
def _model(X, y, mean: str, noise_lb: float, batch_shape=()):
    import gpytorch
    import torch

    bs = torch.Size(batch_shape)

    class ExactGPModel(gpytorch.models.ExactGP):
        def __init__(self, train_x, train_y, likelihood):
            super().__init__(train_x, train_y, likelihood)
            self.mean_module = (gpytorch.means.ConstantMean(batch_shape=bs) if mean == "constant"
                                else gpytorch.means.ZeroMean(batch_shape=bs))
            self.covar_module = gpytorch.kernels.ScaleKernel(
                gpytorch.kernels.MaternKernel(nu=2.5, ard_num_dims=train_x.shape[-1], batch_shape=bs),
                batch_shape=bs)

        def forward(self, x):
            return gpytorch.distributions.MultivariateNormal(self.mean_module(x), self.covar_module(x))

    lik = gpytorch.likelihoods.GaussianLikelihood(
        noise_constraint=gpytorch.constraints.GreaterThan(noise_lb), batch_shape=bs)
    return ExactGPModel(X, y, lik).double(), lik.double()


def _set_start(model, lik, start: dict | None, gen, r: int, noise_lb: float) -> None:
    """Restart ``r``'s starting point: ``start`` (``lengthscale``, ``signal_var``, ``noise_var``, ``mean``) if given,
    else GPyTorch's default (r = 0) or raw parameters ~ N(0, 1) (r >= 1)."""
    import torch

    kern = model.covar_module
    with torch.no_grad():
        for p in (kern.base_kernel.raw_lengthscale, kern.raw_outputscale, lik.noise_covar.raw_noise):
            p.zero_()
            if start is None and r > 0:
                p.copy_(torch.randn(p.shape, generator=gen, dtype=p.dtype))
        if hasattr(model.mean_module, "raw_constant"):
            model.mean_module.raw_constant.zero_()
        if start is not None:
            kern.base_kernel.lengthscale = torch.as_tensor(np.asarray(start["lengthscale"], float)).reshape(
                kern.base_kernel.lengthscale.shape)
            kern.outputscale = torch.as_tensor(float(start["signal_var"]))
            lik.noise = torch.as_tensor(max(float(start["noise_var"]), noise_lb * 1.001))
            if hasattr(model.mean_module, "raw_constant"):
                model.mean_module.constant = torch.as_tensor(float(start.get("mean", 0.0)))


def _hyper(model, lik) -> dict:
    kern = model.covar_module
    c = float(model.mean_module.constant.detach()) if hasattr(model.mean_module, "raw_constant") else 0.0
    return {"lengthscale": kern.base_kernel.lengthscale.detach().numpy().reshape(-1).copy(),
            "signal_var": float(kern.outputscale.detach()), "noise_var": float(lik.noise.detach().reshape(-1)[0]),
            "mean": c}


def fit_one(X: np.ndarray, y: np.ndarray, *, optimizer: str = "adam", restarts: int = 10, iters: int = 150,
            lr: float = 0.1, max_iter: int = 1000, seed: int = 0, output: int = 0, mean: str = "constant",
            noise_lb: float = 1e-4, init: list[dict] | None = None) -> dict:
    """Fit one output with ``restarts`` starts (see the module docstring); keep the lowest final loss.

    Returns ``hyper`` (``lengthscale``, ``signal_var``, ``noise_var``, ``mean``; units of the data as given),
    ``nll`` (the kept restart's total NLL under its own objective), ``nll_per_restart``, ``n_eval`` per restart,
    ``time_s`` and ``model``/``likelihood`` (the kept state loaded, for :func:`predict`)."""
    import gpytorch
    import torch

    if optimizer not in ("adam", "lbfgs"):
        raise ValueError(f"optimizer: expected 'adam' or 'lbfgs', got {optimizer!r}")
    t0 = time.perf_counter()
    Xt = torch.as_tensor(np.asarray(X, float))
    yt = torch.as_tensor(np.asarray(y, float).reshape(-1))
    n = Xt.shape[0]
    model, lik = _model(Xt, yt, mean, noise_lb)
    mll = gpytorch.mlls.ExactMarginalLogLikelihood(lik, model)
    finals, evals, best, best_state = [], [], math.inf, None
    for r in range(restarts):
        gen = torch.Generator().manual_seed(seed * 1000 + 100 * output + r)
        _set_start(model, lik, None if init is None else init[r], gen, r, noise_lb)
        model.train()
        lik.train()
        count = [0]
        try:
            if optimizer == "adam":
                opt = torch.optim.Adam(model.parameters(), lr=lr)
                for _ in range(iters):
                    opt.zero_grad()
                    loss = -mll(model(Xt), yt)
                    loss.backward()
                    opt.step()
                    count[0] += 1
            else:
                opt = torch.optim.LBFGS(model.parameters(), lr=1.0, max_iter=max_iter, history_size=10,
                                        line_search_fn="strong_wolfe", tolerance_grad=1e-5, tolerance_change=1e-9)

                def closure(opt=opt, count=count):
                    opt.zero_grad()
                    loss = -mll(model(Xt), yt)
                    loss.backward()
                    count[0] += 1
                    return loss
                opt.step(closure)
            with torch.no_grad():
                f = float(-mll(model(Xt), yt)) * n
        except Exception:  # NotPSDError and friends: this restart failed  # noqa: BLE001
            f = math.inf
        if not math.isfinite(f):
            f = math.inf
        finals.append(f)
        evals.append(count[0])
        if f < best:
            best = f
            best_state = {k: v.clone() for k, v in model.state_dict().items()}
    if best_state is not None:
        model.load_state_dict(best_state)
    model.eval()
    lik.eval()
    return {"hyper": _hyper(model, lik), "nll": best, "nll_per_restart": finals, "n_eval": evals,
            "time_s": time.perf_counter() - t0, "model": model, "likelihood": lik}


def predict(fit: dict, Xq: np.ndarray) -> np.ndarray:
    """Posterior mean of a :func:`fit_one` result at ``Xq`` (GPyTorch's own predictor)."""
    import gpytorch
    import torch

    with torch.no_grad(), gpytorch.settings.fast_pred_var(False):
        return fit["model"](torch.as_tensor(np.asarray(Xq, float))).mean.numpy().copy()


def predict_with(X: np.ndarray, y: np.ndarray, Xq: np.ndarray, hyper: dict, mean: str = "constant",
                 noise_lb: float = 1e-4) -> np.ndarray:
    """GPyTorch's posterior mean at ``Xq`` of a model on ``(X, y)`` with the hyperparameters ``hyper`` (as returned
    in ``fit["hyper"]``), without any optimisation."""
    import torch

    model, lik = _model(torch.as_tensor(np.asarray(X, float)), torch.as_tensor(np.asarray(y, float).reshape(-1)),
                        mean, noise_lb)
    _set_start(model, lik, hyper, None, 0, noise_lb)
    model.eval()
    lik.eval()
    return predict({"model": model}, Xq)


def fit_adam_batched(X: np.ndarray, Y: np.ndarray, *, restarts: int = 10, iters: int = 150, lr: float = 0.1,
                     seed: int = 0, mean: str = "constant", noise_lb: float = 1e-4,
                     init: list[list[dict]] | None = None) -> list[dict]:
    """The ``adam`` recipe for every output and restart at once, as one batched model (batch ``outputs x
    restarts``). Adam's update is element-wise and the loss is the sum of independent per-member losses, so each
    member follows the same path as its separate run (same starts: the generators of :func:`fit_one`) up to
    round-off. ``init[j][r]``: starting point of output ``j``, restart ``r``. Returns per output a dict like
    :func:`fit_one`'s without ``model`` (``hyper``, ``nll``, ``nll_per_restart``); predict with
    :func:`predict_with`."""
    import gpytorch
    import torch

    Xt = torch.as_tensor(np.asarray(X, float))
    n, d = Xt.shape
    B = Y.shape[1]
    M = B * restarts
    Yt = torch.as_tensor(np.repeat(np.asarray(Y, float).T, restarts, axis=0))  # (M, n), member m = j * R + r
    Xb = Xt.expand(M, n, d)
    model, lik = _model(Xb, Yt, mean, noise_lb, batch_shape=(M,))
    kern = model.covar_module
    with torch.no_grad():
        for p in (kern.base_kernel.raw_lengthscale, kern.raw_outputscale, lik.noise_covar.raw_noise):
            p.zero_()
        if hasattr(model.mean_module, "raw_constant"):
            model.mean_module.raw_constant.zero_()
        ls = kern.base_kernel.lengthscale.detach().clone()  # (M, 1, d)
        sf = kern.outputscale.detach().clone()
        sn = lik.noise.detach().clone().reshape(M)
        for j in range(B):
            for r in range(restarts):
                m = j * restarts + r
                if init is not None:
                    s = init[j][r]
                    ls[m, 0] = torch.as_tensor(np.asarray(s["lengthscale"], float))
                    sf[m] = float(s["signal_var"])
                    sn[m] = max(float(s["noise_var"]), noise_lb * 1.001)
                elif r > 0:
                    gen = torch.Generator().manual_seed(seed * 1000 + 100 * j + r)
                    raw_l = torch.randn((1, d), generator=gen, dtype=torch.float64)
                    raw_s = torch.randn((), generator=gen, dtype=torch.float64)
                    raw_n = torch.randn((1,), generator=gen, dtype=torch.float64)
                    ls[m] = torch.nn.functional.softplus(raw_l)
                    sf[m] = torch.nn.functional.softplus(raw_s)
                    sn[m] = noise_lb + torch.nn.functional.softplus(raw_n)[0]
        kern.base_kernel.lengthscale = ls
        kern.outputscale = sf
        lik.noise = sn.reshape(lik.noise.shape)
    mll = gpytorch.mlls.ExactMarginalLogLikelihood(lik, model)
    model.train()
    lik.train()
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    for _ in range(iters):
        opt.zero_grad()
        loss = -mll(model(Xb), Yt).sum()
        loss.backward()
        opt.step()
    with torch.no_grad():
        final = (-mll(model(Xb), Yt) * n).numpy()
    final = np.where(np.isfinite(final), final, np.inf)
    out = []
    lsn = kern.base_kernel.lengthscale.detach().numpy()
    sfn = kern.outputscale.detach().numpy()
    snn = lik.noise.detach().numpy().reshape(M)
    cn = (model.mean_module.constant.detach().numpy().reshape(M) if hasattr(model.mean_module, "raw_constant")
          else np.zeros(M))
    for j in range(B):
        fr = final[j * restarts:(j + 1) * restarts]
        m = j * restarts + int(np.argmin(fr))
        h = {"lengthscale": lsn[m, 0].copy(), "signal_var": float(sfn[m]), "noise_var": float(snn[m]),
             "mean": float(cn[m])}
        out.append({"hyper": h, "nll": float(fr.min()), "nll_per_restart": [float(v) for v in fr]})
    return out
