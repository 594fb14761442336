r"""Stationary covariance functions of the scaled squared distance: one object per kernel.

Every kernel is a function of the *scaled* squared distance (automatic relevance determination, one
lengthscale :math:`\ell_k` per input) with unit signal variance; the GP code multiplies by :math:`s_f^2`:

.. math::

    r^2(\mathbf x, \mathbf x') = \sum_{k=1}^{d} \frac{(x_k - x'_k)^2}{\ell_k^2}.

* Matern 5/2 (``"matern52"``, the paper's kernel), with :math:`\rho = \sqrt{5 r^2}`:

  .. math::

      k = \left(1 + \rho + \tfrac13 \rho^2\right) e^{-\rho},
      \qquad \frac{\partial k}{\partial (r^2)} = -\tfrac56 \left(1 + \rho\right) e^{-\rho}.

* Matern 3/2 (``"matern32"``), with :math:`\rho = \sqrt{3 r^2}`: rougher functions (once differentiable):

  .. math::

      k = \left(1 + \rho\right) e^{-\rho},
      \qquad \frac{\partial k}{\partial (r^2)} = -\tfrac32 e^{-\rho}.

* Squared exponential (``"rbf"``):

  .. math::

      k = e^{-r^2/2}, \qquad \frac{\partial k}{\partial (r^2)} = -\tfrac12 e^{-r^2/2}.

All three derivatives are finite at :math:`r = 0`, so the lengthscale gradient needs no special case on the diagonal.

Each kernel object offers the formula in the forms its callers need, all written here once:

==============================  ================================================================================
method                          used by
==============================  ================================================================================
``value(r2)``                   NumPy reference (:class:`cascgp.gp.posterior.GPPosterior.predict`, tests)
``grad_r2(r2)``                 NumPy derivative (the mean's input gradient, cascade variance propagation)
``value_torch(r2)``             batched prediction and the final factors (:mod:`cascgp.gp.bank`)
``value_and_grad_(A,B,C)``      the NLL gradient (:func:`cascgp.gp.likelihood.nll_and_grad`): in place on
                                :math:`s\,r^2` (``s = r2_scale``), no temporaries
``value_scaled_np_(a)``         the single-query fast path (:mod:`cascgp.models.fastpath`): in place on
                                :math:`s\,r^2`, NumPy
``value_and_grad_scaled_np``    the fast path with variance (gated controller): value and derivative in
                                :math:`a = s\,r^2`
==============================  ================================================================================

``r2_scale`` :math:`s` is folded into the inputs (or distances) by the callers of the two in-place forms,
which saves one pass over the data: 5 for Matern 5/2 and 3 for Matern 3/2 (:math:`s r^2 = \rho^2`), 1/2 for the RBF
(:math:`s r^2` is the exponent; scaling by this power of two is exact in floating point).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np
import torch

__all__ = ["Kernel", "Matern52", "Matern32", "RBF", "KERNELS", "get_kernel", "check_kernel", "kernel_of_r2",
           "scaled_sqdist"]


class Kernel(ABC):
    """A unit-variance stationary kernel :math:`k(r^2)` (see the module docstring)."""

    name: str
    r2_scale: float

    @abstractmethod
    def value(self, r2: np.ndarray) -> np.ndarray:
        """:math:`k(r^2)` in NumPy float64; tiny negative round-off in ``r2`` is clipped to 0."""

    @abstractmethod
    def grad_r2(self, r2: np.ndarray) -> np.ndarray:
        r""":math:`\partial k / \partial (r^2)` in NumPy float64 (finite at :math:`r = 0`)."""

    @abstractmethod
    def value_torch(self, r2: torch.Tensor) -> torch.Tensor:
        """:math:`k(r^2)` in torch (no autograd bookkeeping needed)."""

    @abstractmethod
    def value_and_grad_(self, A: torch.Tensor, B: torch.Tensor, C: torch.Tensor) -> float:
        r"""In place: ``A`` holds :math:`s\,r^2` on entry and :math:`k` on exit; ``B`` receives ``u`` with
        :math:`\partial k / \partial (r^2) = c\,u`; ``C`` is scratch. Returns ``c``. No temporaries: fresh large
        tensors cost page faults that were measured to take longer than the arithmetic itself."""

    @abstractmethod
    def value_scaled_np_(self, a: np.ndarray) -> np.ndarray:
        r""":math:`k` from :math:`a = s\,r^2` (1-D NumPy), overwriting ``a``; returns ``a``."""

    @abstractmethod
    def value_and_grad_scaled_np(self, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r""":math:`\kappa(a) = k(a / s)` and :math:`d\kappa/da` from :math:`a = s\,r^2` (NumPy, new arrays)."""

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


class Matern52(Kernel):
    """Matern 5/2, the paper's kernel."""

    name = "matern52"
    r2_scale = 5.0
    _SQRT5 = math.sqrt(5.0)

    def value(self, r2: np.ndarray) -> np.ndarray:
        r2 = np.maximum(np.asarray(r2, dtype=np.float64), 0.0)
        sr = self._SQRT5 * np.sqrt(r2)
        return (1.0 + sr + (5.0 / 3.0) * r2) * np.exp(-sr)

    def grad_r2(self, r2: np.ndarray) -> np.ndarray:
        sr = self._SQRT5 * np.sqrt(np.maximum(np.asarray(r2, dtype=np.float64), 0.0))
        return (-5.0 / 6.0) * (1.0 + sr) * np.exp(-sr)

    def value_torch(self, r2: torch.Tensor) -> torch.Tensor:
        sr = torch.sqrt(r2).mul_(self._SQRT5)
        e = torch.exp(-sr)
        return sr.add_(1.0).add_(r2, alpha=5.0 / 3.0).mul_(e)

    def value_and_grad_(self, A: torch.Tensor, B: torch.Tensor, C: torch.Tensor) -> float:
        torch.sqrt(A, out=B)  # rho
        torch.neg(B, out=C).exp_()  # e^{-rho}
        B.add_(1.0).mul_(C)  # u = (1 + rho) e^{-rho}
        torch.addcmul(B, A, C, value=1.0 / 3.0, out=A)  # k = u + rho^2 e^{-rho} / 3
        return -5.0 / 6.0

    def value_and_grad_scaled_np(self, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        s = np.sqrt(a)  # rho
        e = np.exp(-s)
        return (1.0 + s + a / 3.0) * e, -(1.0 + s) * e / 6.0

    def value_scaled_np_(self, a: np.ndarray) -> np.ndarray:
        s = np.sqrt(a)  # rho
        e = np.exp(-s)
        a *= 1.0 / 3.0
        a += s
        a += 1.0
        a *= e
        return a


class Matern32(Kernel):
    """Matern 3/2."""

    name = "matern32"
    r2_scale = 3.0
    _SQRT3 = math.sqrt(3.0)

    def value(self, r2: np.ndarray) -> np.ndarray:
        sr = self._SQRT3 * np.sqrt(np.maximum(np.asarray(r2, dtype=np.float64), 0.0))
        return (1.0 + sr) * np.exp(-sr)

    def grad_r2(self, r2: np.ndarray) -> np.ndarray:
        sr = self._SQRT3 * np.sqrt(np.maximum(np.asarray(r2, dtype=np.float64), 0.0))
        return -1.5 * np.exp(-sr)

    def value_torch(self, r2: torch.Tensor) -> torch.Tensor:
        sr = torch.sqrt(r2).mul_(self._SQRT3)
        e = torch.exp(-sr)
        return sr.add_(1.0).mul_(e)

    def value_and_grad_(self, A: torch.Tensor, B: torch.Tensor, C: torch.Tensor) -> float:
        torch.sqrt(A, out=C)  # rho
        torch.neg(C, out=B).exp_()  # u = e^{-rho}
        C.add_(1.0)
        torch.mul(C, B, out=A)  # k = (1 + rho) e^{-rho}
        return -1.5

    def value_and_grad_scaled_np(self, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        s = np.sqrt(a)  # rho
        e = np.exp(-s)
        return (1.0 + s) * e, -0.5 * e

    def value_scaled_np_(self, a: np.ndarray) -> np.ndarray:
        np.sqrt(a, out=a)  # rho
        e = np.exp(-a)
        a += 1.0
        a *= e
        return a


class RBF(Kernel):
    """Squared exponential."""

    name = "rbf"
    r2_scale = 0.5

    def value(self, r2: np.ndarray) -> np.ndarray:
        r2 = np.maximum(np.asarray(r2, dtype=np.float64), 0.0)
        return np.exp(-0.5 * r2)

    def grad_r2(self, r2: np.ndarray) -> np.ndarray:
        return -0.5 * np.exp(-0.5 * np.maximum(np.asarray(r2, dtype=np.float64), 0.0))

    def value_torch(self, r2: torch.Tensor) -> torch.Tensor:
        return torch.exp(-0.5 * r2)

    def value_and_grad_(self, A: torch.Tensor, B: torch.Tensor, C: torch.Tensor) -> float:
        A.neg_().exp_()
        B.copy_(A)
        return -0.5

    def value_scaled_np_(self, a: np.ndarray) -> np.ndarray:
        np.negative(a, out=a)
        return np.exp(a, out=a)

    def value_and_grad_scaled_np(self, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        e = np.exp(-a)
        return e, -e


_REGISTRY: dict[str, Kernel] = {k.name: k for k in (Matern52(), Matern32(), RBF())}
#: Names of the kernels this module implements.
KERNELS: tuple[str, ...] = tuple(_REGISTRY)


def check_kernel(name: str) -> str:
    """Return ``name`` if it is a known kernel, otherwise raise ``ValueError`` naming the field ``kernel``."""
    if not isinstance(name, str) or name not in _REGISTRY:
        raise ValueError(f"kernel: expected one of {KERNELS}, got {name!r}")
    return name


def get_kernel(name: str) -> Kernel:
    """The kernel object called ``name`` (``ValueError`` naming ``kernel`` if unknown)."""
    return _REGISTRY[check_kernel(name)]


def kernel_of_r2(name: str, r2: np.ndarray) -> np.ndarray:
    """``get_kernel(name).value(r2)``: unit-variance kernel value in NumPy, values in (0, 1]."""
    return get_kernel(name).value(r2)


def scaled_sqdist(Z1: torch.Tensor, Z2: torch.Tensor | None = None) -> torch.Tensor:
    r"""Squared Euclidean distances between the rows of already scaled inputs.

    Computed as :math:`\|z_i\|^2 + \|z'_j\|^2 - 2 z_i^\top z'_j` with one matrix product (no ``(n, m, d)``
    tensor) and clamped at zero. With ``Z2 = None`` the distances of ``Z1`` to itself are returned with an
    exactly zero diagonal. Shapes: ``(..., n, d)``, ``(..., m, d)`` -> ``(..., n, m)``.
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
