r"""Batched exact Gaussian-process regression (float64, torch) with hand-written analytic gradients.

Model (one GP per output ``b``, all independent)
------------------------------------------------
Inputs and targets are normalised per GP: :math:`\tilde x = (x - \mu_x) / \sigma_x` per column,
:math:`\tilde y = (y - \mu_y) / \sigma_y`. On the normalised data

.. math::

    \tilde y = f(\tilde x) + \varepsilon, \quad f \sim \mathcal{GP}(0, s_f^2\, k(r^2)), \quad
    \varepsilon \sim \mathcal N(0, s_n^2), \quad
    r^2 = \sum_k (\tilde x_k - \tilde x'_k)^2 / \ell_k^2

with a Matern 5/2 (default), Matern 3/2 or squared-exponential kernel :math:`k` (:mod:`cascgp.gp.kernels`). The
hyperparameters are optimised in log space,

.. math::

    \theta = (\log \ell_1, \dots, \log \ell_d, \log s_f^2, \log(s_n^2 - s_{n,\min}^2 - s_f^2 / \rho_{\max})),

so that :math:`s_f^2 = e^{\theta_{d+1}} > 0` and :math:`s_n^2 = s_{n,\min}^2 + s_f^2/\rho_{\max} + e^{\theta_{d+2}}`
(``noise_floor`` :math:`s_{n,\min}^2`, default 1e-6 in normalised units, keeps the noise away from exactly zero;
``snr_max`` :math:`\rho_{\max}`, default 1e6, bounds the signal-to-noise variance ratio, see "Conditioning" in
:mod:`cascgp.gp.likelihood`).

Where each part lives
---------------------

==============================  ===============================================================================
module                          owns
==============================  ===============================================================================
:mod:`cascgp.gp.kernels`        the kernels (one object each: NumPy, torch, in-place fit and fast-path forms)
:mod:`cascgp.gp.config`         :class:`GPFitConfig` (fit options, validated)
:mod:`cascgp.gp.likelihood`     NLL and analytic gradient of a batch (:func:`nll_and_grad`)
:mod:`cascgp.gp.memory`         a fit's memory, planned before it starts (:class:`FitMemoryError`)
:mod:`cascgp.gp.lbfgs`          batched L-BFGS, one optimiser state per start
:mod:`cascgp.gp.restarts`       where the starts begin and when a start stops early
:mod:`cascgp.gp.bank`           :class:`GPBank`: the fit driver and batched prediction
:mod:`cascgp.gp.posterior`      factors of a fitted bank and the NumPy :class:`GPPosterior`
:mod:`cascgp.gp.state`          the saved form of a bank
==============================  ===============================================================================

Batching
--------
All GPs x all restarts form one batch ``(B, n, n)``. GPs with fewer inputs than the widest are padded with zero
columns; their lengthscales are masked (gradient zero, never moved, reported as ``inf`` scale). Input columns that
are constant in the training data are treated the same way (they carry no information; at prediction time their
value is ignored). Each batch member runs its own L-BFGS (:mod:`cascgp.gp.lbfgs`) and leaves the batch when it stops.
"""

from cascgp.gp.bank import GPBank
from cascgp.gp.config import GPFitConfig
from cascgp.gp.likelihood import nll_and_grad
from cascgp.gp.memory import FitMemoryError, estimate_fit_bytes, plan_chunk
from cascgp.gp.posterior import GPPosterior
from cascgp.gp.state import STATE_VERSION

__all__ = ["GPFitConfig", "GPBank", "GPPosterior", "nll_and_grad", "estimate_fit_bytes", "plan_chunk", "FitMemoryError",
           "STATE_VERSION"]
