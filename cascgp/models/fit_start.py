r"""What a :class:`~cascgp.models.CascadedGPModel` fit starts from: a warm start (``init``) and a shared GP (``share``).

A cascade's first joint in its chain order (inward: joint :math:`N`, outward: joint 1) sees every joint's state and
no torque, the inputs of the standard model's GP of that joint, so with the same data and settings it *is* that
GP. :func:`shared_chain_first` lets a cascade take it from a fitted standard model instead of fitting it again: the
cascade's bank draws the same random starts as the standard's, and the GPs of a bank are optimised independently
(:meth:`cascgp.gp.GPBank.fit`, ``shared``), so the cascade's fit is the one it would have made alone, at 1/N less
optimisation. "The one" up to the last bit: torch's batched kernels may round a block of starts differently from
a smaller block (one gradient entry in its last bit, at one of 13 sizes tried), which the optimiser can carry
forward. In practice the fits compared were the same bits (the data-efficiency study's cascades: see the
performance page of the documentation).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from cascgp.gp import GPBank

if TYPE_CHECKING:
    from cascgp.models.cascade import CascadedGPModel

__all__ = ["warm_start_banks", "shared_chain_first"]


def warm_start_banks(model: CascadedGPModel, init: Any, sequential: bool) -> list[GPBank] | None:
    """The banks whose hyperparameters warm-start ``model``'s fit (``init`` of
    :meth:`~cascgp.models.CascadedGPModel.fit`), or ``None`` for a cold start; errors name ``init``."""
    from cascgp.models.cascade import CascadedGPModel

    if init is None:
        return None
    if isinstance(init, CascadedGPModel):
        if init.name != model.name or init.dof != model.dof or not init.fitted:
            raise ValueError(f"init: expected a fitted {model.name!r} model with dof={model.dof}, got {init!r}")
        if len(init.banks) != (model.dof if sequential else 1):
            return None  # layouts differ (train_on_predicted changed): cold start
        return list(init.banks)
    if isinstance(init, GPBank):
        if sequential:
            raise ValueError("init: a GPBank cannot warm-start a train_on_predicted cascade; pass a model")
        return [init]
    raise TypeError(f"init: expected a CascadedGPModel, a GPBank or None, got {type(init).__name__}")


def shared_chain_first(model: CascadedGPModel, share: Any, sequential: bool) -> dict[int, tuple[GPBank, int]] | None:
    """``shared`` of :meth:`cascgp.gp.GPBank.fit` for ``model``'s one-bank fit: its chain's first joint taken from
    the fitted standard model ``share`` (``share`` of :meth:`~cascgp.models.CascadedGPModel.fit`); ``None`` without
    one. The kind, DOF and layout are checked here, the data, settings and warm start by the bank; errors name
    ``share``."""
    from cascgp.models.cascade import CascadedGPModel

    if share is None:
        return None
    if model.structure == "standard":
        raise ValueError(f"share: only a cascade takes a GP from a standard model; {model.name!r} is one")
    twin = model.name.replace(model.structure, "standard")
    if not isinstance(share, CascadedGPModel) or share.name != twin or share.dof != model.dof or not share.fitted:
        raise ValueError(f"share: expected a fitted {twin!r} model with dof={model.dof}, got {share!r}")
    if sequential or len(share.banks) != 1:
        raise ValueError("share: a train_on_predicted cascade fits joint by joint and cannot take a GP from a "
                         "standard model's bank")
    j0 = model.order[0]
    return {j0: (share.banks[0], j0)}
