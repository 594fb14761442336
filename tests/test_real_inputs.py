"""Complex, boolean and text inputs are refused by name (TypeError), not cast: a cast drops an imaginary part or
turns flags into numbers, silently. Real inputs of any numeric dtype are accepted."""

from __future__ import annotations

import numpy as np
import pytest

import jaco_env
from cascgp.gp import GPBank, GPFitConfig
from cascgp.models import make_model
from cascgp.rbd import RigidBodyModel

X = np.random.default_rng(0).uniform(-1, 1, (12, 2))
Y = np.sin(X[:, 0])


@pytest.mark.parametrize("bad", [X + 1j, X > 0, X.astype(str)], ids=["complex", "bool", "text"])
def test_a_gp_bank_refuses_inputs_that_are_not_real(bad: np.ndarray) -> None:
    with pytest.raises(TypeError, match=r"X\[0\]: expected a real numeric \(n, d\) array"):
        GPBank(GPFitConfig(n_restarts=1)).fit([bad], [Y])
    bank = GPBank(GPFitConfig(n_restarts=1, max_iter=20)).fit([X.astype(np.float32)], [Y.tolist()])  # any real
    with pytest.raises(TypeError, match=r"y\[0\]: expected a real numeric \(12,\) array"):
        GPBank(GPFitConfig(n_restarts=1)).fit([X], [Y + 0j])
    with pytest.raises(TypeError, match=r"X\[0\]: expected a real numeric"):
        bank.predict([bad[:3]])


def test_the_rigid_body_model_refuses_states_that_are_not_real() -> None:
    rbd = RigidBodyModel.from_urdf(jaco_env.NOMINAL_URDF)
    z = np.zeros((2, 6))
    for bad in (z + 2j, z > 0):
        with pytest.raises(TypeError, match=r"qd: expected a real numeric \(6,\) or \(T, 6\) array"):
            rbd.inverse_dynamics(z, bad, z)
    np.testing.assert_array_equal(rbd.inverse_dynamics(z.tolist(), z.astype(np.float32), z.astype(int)),
                                  rbd.inverse_dynamics(z, z, z))


@pytest.mark.parametrize("bad", ["no", "False", 0, None])
def test_train_on_predicted_must_be_true_or_false(bad: object) -> None:
    with pytest.raises(TypeError, match="train_on_predicted: expected True or False"):
        make_model("np-inward", 2, train_on_predicted=bad)
    assert make_model("np-inward", 2, train_on_predicted=np.True_).train_on_predicted is True
