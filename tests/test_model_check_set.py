"""The check set of a model file: :func:`cascgp.models.load_model` recomputes the predictions stored at save time,
at random states and at training states, and refuses a file that does not reproduce them."""

from __future__ import annotations

import numpy as np
import pytest

from cascgp.data import DynamicsData
from cascgp.gp import GPFitConfig
from cascgp.models import load_model, make_model

FAST = GPFitConfig(n_restarts=1, max_iter=200)


@pytest.mark.parametrize("name", ["np-standard", "np-inward-df", "np-outward"])
def test_load_refuses_a_changed_model_trained_far_from_the_unit_box(name, tmp_path):
    """The stored check queries were random states in [-1, 1] only: a model trained on states elsewhere predicted
    its prior there, and a file with a changed hyperparameter loaded silently. The check now also queries training
    states."""
    t = np.arange(300) * 0.02
    q = 25.0 + 5.0 * np.stack([np.sin(t), np.sin(1.3 * t + 1.0)], axis=1)
    qd = 5.0 * np.stack([np.cos(t), 1.3 * np.cos(1.3 * t + 1.0)], axis=1)
    qdd = -5.0 * np.stack([np.sin(t), 1.69 * np.sin(1.3 * t + 1.0)], axis=1)
    tau = np.stack([np.sin(4.0 * q[:, 0]) + 0.1 * qd[:, 1], np.cos(q[:, 1]) + 0.05 * qdd[:, 0]], axis=1)
    model = make_model(name, 2, gp_config=FAST).fit(DynamicsData(q=q, qd=qd, qdd=qdd, tau=tau, t=t))
    p = tmp_path / "far.npz"
    model.save(p)
    loaded = load_model(p)
    np.testing.assert_array_equal(loaded.predict(q[:7], qd[:7], qdd[:7], model_hist(model, q[:7], qd[:7]))[0],
                                  model.predict(q[:7], qd[:7], qdd[:7], model_hist(model, q[:7], qd[:7]))[0])
    # a variance at a training row is the prior's minus nearly all of it: its round-off scales with the prior
    # variance (a rerun of README's tour, every buffer row twice, moved one by 5.7e-5 of itself and was refused)
    prior = np.array([post.signal_var * post.y_std**2 for post in model.posteriors()])
    z = dict(np.load(p))
    assert (z["check/var"][-1] < 1e-2 * prior).all()  # the last check row is a training row
    for rel, loads in ((1e-7, True), (1e-4, False)):
        z = dict(np.load(p))
        z["check/var"][-1] += rel * prior
        np.savez(tmp_path / "var.npz", **z)
        if loads:
            load_model(tmp_path / "var.npz")
        else:
            with pytest.raises(ValueError, match="does not reproduce its stored check predictions"):
                load_model(tmp_path / "var.npz")
    for b in range(2):  # one log-lengthscale of one GP, +0.1
        z = dict(np.load(p))
        z["bank0/theta"][b, 0] += 0.1
        np.savez(tmp_path / "changed.npz", **z)
        with pytest.raises(ValueError, match="does not reproduce its stored check predictions"):
            load_model(tmp_path / "changed.npz")


def model_hist(model, q, qd):
    """``q_hist`` of a derivative-free model (None for a derivative-based one), from q and qd."""
    return np.stack([q - 0.1 * qd, q - 0.2 * qd], axis=1) if model.feature_kind == "df" else None
