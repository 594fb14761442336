r"""Where a fitted model's training data lie: each joint's range of positions, and the queries outside it.

Away from its training inputs a GP's mean returns to its prior mean, the mean of its training targets (for an NP
model the joint's mean torque in the training log; for an SP model the rigid-body torque plus the mean residual),
so a query far outside the positions a model was trained on is an extrapolation: a log recorded in degrees against
a model trained in radians, or a continuous joint logged in another range of turns. The GP sees the angle as
logged, :math:`q` and :math:`q + 2\pi` are two inputs to it even where the rigid-body torque is the same.

Every GP of a model holds its joints' positions in the columns :math:`3k` of its inputs (``(q, q̇, q̈)`` or
``(q, q(t - δ), q(t - 2δ))`` per state joint, :func:`cascgp.models.queries.state_cols`), so the range is read from
the fitted banks: no file format holds it separately.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["training_positions", "training_position_range", "fraction_outside", "fraction_in_training",
           "fraction_of_training_in", "training_overlap"]


def training_positions(model: Any) -> np.ndarray:
    """``(n, N)``: the joint positions of the model's ``n`` training rows (rad or m), in training order (every GP of
    a model is fitted on the same rows).

    Args:
        model: a fitted :class:`~cascgp.models.CascadedGPModel`.
    """
    model._require_fitted()
    out = np.full((model.n_train, model.dof), np.nan)
    inputs = {k: model.banks[k].training_data()[0] for k in {k for k, _ in model.where}}  # each bank copied once
    for j, (k, b) in enumerate(model.where):
        for i, s in enumerate(model.specs[j][0]):
            out[:, s] = inputs[k][b][:, 3 * i]
    return out


def training_position_range(model: Any) -> np.ndarray:
    """``(N, 2)``: the smallest and largest position of each joint in the model's training data (rad or m).

    Args:
        model: a fitted :class:`~cascgp.models.CascadedGPModel`.
    """
    q = training_positions(model)
    return np.stack([q.min(axis=0), q.max(axis=0)], axis=1)


def fraction_outside(model: Any, q: Any, margin: float = 0.1) -> np.ndarray:
    r"""``(N,)``: the fraction of the rows of ``q`` (T, N) outside each joint's training range widened by ``margin``
    times its width on each side, :math:`[l - m (h - l),\; h + m (h - l)]`. A joint that held one position in
    training counts 0: the GPs cannot depend on a constant input."""
    q = np.asarray(q, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != model.dof or q.shape[0] == 0:
        raise ValueError(f"q: expected shape (T, {model.dof}) with T >= 1, got {q.shape}")
    r = training_position_range(model)
    pad = margin * (r[:, 1] - r[:, 0])
    out = ((q < r[:, 0] - pad) | (q > r[:, 1] + pad)) & (r[:, 1] > r[:, 0])
    return np.asarray(out.mean(axis=0))


def fraction_in_training(model: Any, q: Any) -> float:
    """The fraction of the rows of ``q`` (T, N) whose positions are, bit for bit, those of one of the model's
    training rows: a "test" log that is (or holds) the training log. Positions of a real log repeat exactly in
    another log only by copying."""
    return training_overlap(model, q)[0]


def fraction_of_training_in(model: Any, q: Any) -> float:
    """The fraction of the model's distinct training positions that stand, bit for bit, among the rows of ``q``
    (T, N): a log that holds the training log, however many other rows it has (a model fitted on 300 of a log's
    14,000 rows, evaluated on that log, has all of its training rows there: 2 % of the log's rows)."""
    return training_overlap(model, q)[1]


def training_overlap(model: Any, q: Any) -> tuple[float, float]:
    """``(fraction_in_training, fraction_of_training_in)`` of ``q`` (T, N) in one pass over its rows."""
    q = _positions(model, q)
    train = {row.tobytes() for row in np.ascontiguousarray(training_positions(model))}
    rows = [row.tobytes() for row in q]
    return sum(r in train for r in rows) / len(rows), len(train.intersection(rows)) / len(train)


def _positions(model: Any, q: Any) -> np.ndarray:
    q = np.ascontiguousarray(q, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != model.dof or q.shape[0] == 0:
        raise ValueError(f"q: expected shape (T, {model.dof}) with T >= 1, got {q.shape}")
    return q
