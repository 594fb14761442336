"""The gate rules as functions (:func:`cascgp.gates.gate_weights`): each is its documented formula, with the
edge cases (no correction, no uncertainty, non-finite values) and the error paths."""

from __future__ import annotations

import numpy as np
import pytest

from cascgp.gates import gate_weights


def test_gate_weights_are_the_documented_rules() -> None:
    rng = np.random.default_rng(0)
    d, v = rng.normal(size=(5, 3)), rng.uniform(0.01, 2.0, size=(5, 3))
    np.testing.assert_allclose(gate_weights(d, v), d**2 / (d**2 + v))
    prior = np.array([1.0, 2.0, 4.0])
    np.testing.assert_allclose(gate_weights(d, v, "variance", prior), np.clip(1 - v / prior, 0, 1))
    power = np.maximum(d**2, prior)
    np.testing.assert_allclose(gate_weights(d, v, "floor", prior), power / (power + v))
    assert np.all(gate_weights(d, v, "floor", prior) >= gate_weights(d, v))  # never shrinks more than Wiener
    # The floor rule keeps at least half a correction wherever v <= prior, whatever the correction's size.
    assert np.all(gate_weights(1e-6 * d, prior * np.ones((5, 1)), "floor", prior) == 0.5)
    assert gate_weights(np.zeros(2), np.zeros(2), "floor", np.zeros(2)).tolist() == [1.0, 1.0]
    assert gate_weights(np.array([np.nan, np.inf]), np.ones(2), "floor", np.ones(2)).tolist() == [0.0, 0.0]
    # No correction and no uncertainty: the model (1); a non-finite weight: the nominal torque (0).
    assert gate_weights(np.zeros(2), np.zeros(2)).tolist() == [1.0, 1.0]
    assert gate_weights(np.array([np.inf, 1.0]), np.array([1.0, np.inf])).tolist() == [0.0, 0.0]
    # A negative variance (round-off, a user model) counts as 0: every weight stays within [0, 1].
    d2, neg = rng.normal(size=(5, 3)), -rng.uniform(0.01, 2.0, size=(5, 3))
    for rule in ("wiener", "floor", "variance"):
        w = gate_weights(d2, neg, rule, prior)
        assert np.all((0.0 <= w) & (w <= 1.0))
        np.testing.assert_array_equal(w, gate_weights(d2, np.zeros_like(neg), rule, prior))
        assert gate_weights(np.ones(2), np.array([-np.inf, np.nan]), rule, prior[:2]).tolist() == [0.0, 0.0]
    for rule in ("variance", "floor"):
        with pytest.raises(ValueError, match="prior"):
            gate_weights(d, v, rule)
    with pytest.raises(ValueError, match="rule"):
        gate_weights(d, v, "median")
