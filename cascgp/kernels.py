r"""Stationary covariance functions of the scaled squared distance.

Every kernel here is written as a function of the *scaled* squared distance

.. math::

    r^2(\mathbf x, \mathbf x') = \sum_{k=1}^{d} \frac{(x_k - x'_k)^2}{\ell_k^2}

(automatic relevance determination, one lengthscale :math:`\ell_k` per input) with unit signal variance;
the GP code multiplies by the signal variance :math:`s_f^2`.

* Matern 5/2 (``"matern52"``, the paper's kernel):

  .. math::

      k(r) = \left(1 + \sqrt5\, r + \tfrac53 r^2\right) e^{-\sqrt5\, r},
      \qquad \frac{\partial k}{\partial (r^2)} = -\tfrac56 \left(1 + \sqrt5\, r\right) e^{-\sqrt5\, r}.

* Squared exponential (``"rbf"``):

  .. math::

      k(r) = e^{-r^2/2}, \qquad \frac{\partial k}{\partial (r^2)} = -\tfrac12 e^{-r^2/2}.

Both derivatives with respect to :math:`r^2` are finite at :math:`r = 0`, so the lengthscale gradient needs no
special case on the diagonal. The torch functions are used by :mod:`cascgp.gp`; :func:`kernel_of_r2` is the
NumPy version for hand-written single-query prediction paths.
"""

from __future__ import annotations

import math

import numpy as np
import torch

__all__ = ["KERNELS", "check_kernel", "kernel_of_r2", "kernel_of_r2_torch", "kernel_and_grad_r2", "scaled_sqdist"]

#: Names of the kernels this module implements.
KERNELS: tuple[str, ...] = ("matern52", "rbf")

_SQRT5 = math.sqrt(5.0)


def check_kernel(name: str) -> str:
    """Return ``name`` if it is a known kernel, otherwise raise ``ValueError`` naming the field ``kernel``."""
    if not isinstance(name, str) or name not in KERNELS:
        raise ValueError(f"kernel: expected one of {KERNELS}, got {name!r}")
    return name


def kernel_of_r2(name: str, r2: np.ndarray) -> np.ndarray:
    """Unit-variance kernel value :math:`k(r^2)` in NumPy (float64).

    Args:
        name: ``"matern52"`` or ``"rbf"``.
        r2: scaled squared distances, any shape, non-negative (tiny negative round-off is clipped to 0).

    Returns:
        Array of the same shape as ``r2`` with values in (0, 1].
    """
    check_kernel(name)
    r2 = np.maximum(np.asarray(r2, dtype=np.float64), 0.0)
    if name == "rbf":
        return np.exp(-0.5 * r2)
    sr = _SQRT5 * np.sqrt(r2)
    return (1.0 + sr + (5.0 / 3.0) * r2) * np.exp(-sr)


def kernel_of_r2_torch(name: str, r2: torch.Tensor) -> torch.Tensor:
    """Torch version of :func:`kernel_of_r2` (no gradient bookkeeping needed)."""
    if name == "rbf":
        return torch.exp(-0.5 * r2)
    sr = torch.sqrt(r2).mul_(_SQRT5)
    e = torch.exp(-sr)
    return sr.add_(1.0).add_(r2, alpha=5.0 / 3.0).mul_(e)


def kernel_and_grad_r2(name: str, r2: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    r"""Kernel value :math:`k` and derivative :math:`\partial k / \partial (r^2)` (unit signal variance).

    Args:
        name: ``"matern52"`` or ``"rbf"``.
        r2: scaled squared distances (any shape, >= 0).

    Returns:
        ``(k, dk_dr2)``, both of the shape of ``r2``.
    """
    if name == "rbf":
        k = torch.exp(-0.5 * r2)
        return k, -0.5 * k
    sr = torch.sqrt(r2).mul_(_SQRT5)
    e = torch.exp(-sr)
    one_sr = sr.add_(1.0)  # 1 + sqrt5 r (in place: sr is not needed any more)
    dk = torch.mul(one_sr, e).mul_(-5.0 / 6.0)
    k = one_sr.add_(r2, alpha=5.0 / 3.0).mul_(e)
    return k, dk


def scaled_sqdist(Z1: torch.Tensor, Z2: torch.Tensor | None = None) -> torch.Tensor:
    r"""Squared Euclidean distances between the rows of already scaled inputs.

    Computed as :math:`\|z_i\|^2 + \|z'_j\|^2 - 2 z_i^\top z'_j` with one matrix product (no ``(n, m, d)``
    tensor) and clamped at zero. With ``Z2 = None`` the distances of ``Z1`` to itself are returned with an
    exactly zero diagonal.

    Args:
        Z1: ``(..., n, d)``.
        Z2: ``(..., m, d)`` or ``None``.

    Returns:
        ``(..., n, m)``.
    """
    s1 = (Z1 * Z1).sum(-1)
    if Z2 is None:
        r2 = torch.matmul(Z1, Z1.transpose(-1, -2)).mul_(-2.0)
        r2.add_(s1.unsqueeze(-1)).add_(s1.unsqueeze(-2)).clamp_min_(0.0)
        r2.diagonal(dim1=-2, dim2=-1).zero_()
        return r2
    s2 = (Z2 * Z2).sum(-1)
    r2 = torch.matmul(Z1, Z2.transpose(-1, -2)).mul_(-2.0)
    return r2.add_(s1.unsqueeze(-1)).add_(s2.unsqueeze(-2)).clamp_min_(0.0)
