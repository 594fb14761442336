"""State features and input maps (DESIGN.md table)."""

import numpy as np
import pytest

from cascgp.data import DynamicsData
from cascgp.features import build_inputs, input_dim, input_spec, state_features


@pytest.mark.parametrize("N", [6, 7])
def test_dimensions_match_design(N):
    for i in range(1, N + 1):  # 1-based as in the paper
        j = i - 1
        assert input_dim("standard", j, N) == 3 * N
        assert input_dim("inward", j, N) == (3 * N if i == N else 3 * i + 1)
        # paper prints 3(N-i)+1; its vector has N-i+1 joints
        assert input_dim("outward", j, N) == (3 * N if i == 1 else 3 * (N - i + 1) + 1)
    S = np.random.default_rng(0).normal(size=(11, N, 3))
    tau = np.random.default_rng(1).normal(size=(11, N))
    for structure in ("standard", "inward", "outward"):
        X = build_inputs(S, tau, structure)
        assert [x.shape for x in X] == [(11, input_dim(structure, j, N)) for j in range(N)]


def test_input_spec_contents():
    assert input_spec("inward", 0, 6) == ((0,), 1)
    assert input_spec("inward", 4, 6) == ((0, 1, 2, 3, 4), 5)
    assert input_spec("inward", 5, 6) == (tuple(range(6)), None)
    assert input_spec("outward", 0, 6) == (tuple(range(6)), None)
    assert input_spec("outward", 1, 6) == ((1, 2, 3, 4, 5), 0)
    assert input_spec("outward", 5, 6) == ((5,), 4)
    assert input_spec("standard", 3, 6) == (tuple(range(6)), None)
    with pytest.raises(ValueError, match="structure"):
        input_spec("sideways", 0, 6)
    with pytest.raises(ValueError, match="joint"):
        input_spec("inward", 6, 6)
    with pytest.raises(ValueError, match="dof"):
        input_spec("inward", 0, 0)


def test_build_inputs_columns():
    T, N = 4, 3
    S = np.arange(T * N * 3, dtype=float).reshape(T, N, 3)
    tau = -np.arange(T * N, dtype=float).reshape(T, N) - 1
    X = build_inputs(S, tau, "inward")
    np.testing.assert_array_equal(X[0], np.c_[S[:, 0], tau[:, 1]])  # torque last
    np.testing.assert_array_equal(X[1], np.c_[S[:, 0], S[:, 1], tau[:, 2]])
    np.testing.assert_array_equal(X[2], S.reshape(T, -1))
    Xo = build_inputs(S, tau, "outward")
    np.testing.assert_array_equal(Xo[2], np.c_[S[:, 2], tau[:, 1]])
    with pytest.raises(ValueError, match="tau"):
        build_inputs(S, None, "inward")
    with pytest.raises(ValueError, match="S"):
        build_inputs(S[..., :2], tau, "inward")


def test_db_and_df_state_features():
    t = np.arange(30) * 0.05
    q = np.c_[t, 2 * t**2]
    d = DynamicsData(q=q, qd=q + 1, qdd=q + 2, tau=q, t=t)
    S, valid = state_features(d, "db")
    np.testing.assert_array_equal(S[:, 1], np.c_[q[:, 1], q[:, 1] + 1, q[:, 1] + 2])
    assert valid.all()
    S, valid = state_features(d, "df", delta=0.1)
    # delta = 2 samples: valid from row 4 on; history by interpolation equals shifted rows
    assert not valid[:4].any() and valid[4:].all()
    np.testing.assert_allclose(S[4:, :, 1], q[2:-2], atol=1e-12)
    np.testing.assert_allclose(S[4:, :, 2], q[:-4], atol=1e-12)
    assert np.isfinite(S).all()
    # delta between samples: linear interpolation
    S, valid = state_features(d, "df", delta=0.075)
    np.testing.assert_allclose(S[5:, 0, 1], t[5:] - 0.075, atol=1e-12)
    assert not valid[2] and valid[3]
    with pytest.raises(ValueError, match="kind"):
        state_features(d, "xx")
    with pytest.raises(ValueError, match="delta"):
        state_features(d, "df", delta=0.0)


def test_df_history_stays_in_segment():
    t = np.r_[np.arange(10), np.arange(10)] * 0.05
    seg = np.repeat([0, 1], 10)
    q = np.r_[np.zeros(10), np.ones(10)][:, None]
    d = DynamicsData(q=q, qd=q, qdd=q, tau=q, t=t, segment=seg)
    S, valid = state_features(d, "df", delta=0.05)
    assert valid.sum() == 16 and not valid[10] and not valid[11]
    np.testing.assert_array_equal(S[10:, 0, 1:], 1.0)  # never mixes segment 0's values
