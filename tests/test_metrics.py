"""nRMSE and RMSE."""

import numpy as np
import pytest

from cascgp.metrics import nrmse, rmse


def test_values():
    y = np.array([[0.0, 1.0], [2.0, 1.0], [4.0, 5.0]])
    p = y + np.array([[1.0, 0.0], [-1.0, 0.0], [1.0, 2.0]])
    np.testing.assert_allclose(rmse(p, y), [1.0, np.sqrt(4 / 3)])
    np.testing.assert_allclose(nrmse(p, y), [1.0 / 4, np.sqrt(4 / 3) / 4])
    assert nrmse(y, y).tolist() == [0.0, 0.0]
    assert rmse(p[:, 0], y[:, 0]).shape == (1,)


def test_errors():
    y = np.ones((5, 2))
    y[:, 0] = np.arange(5)
    with pytest.raises(ValueError, match="column 1 is constant"):
        nrmse(y, y)
    with pytest.raises(ValueError, match="pred"):
        rmse(np.zeros((5, 3)), y)
    p = y.copy()
    p[2, 0] = np.nan
    with pytest.raises(ValueError, match="pred.*row 2"):
        rmse(p, y)
    with pytest.raises(ValueError, match="at least one row"):
        rmse(np.zeros((0, 2)), np.zeros((0, 2)))


def test_interval_coverage_of_a_gaussian_sample_and_errors():
    from cascgp.metrics import interval_coverage

    rng = np.random.default_rng(0)
    y = rng.normal(size=(200_000, 2)) * np.array([1.0, 3.0])
    cov = interval_coverage(np.zeros_like(y), np.ones_like(y) * np.array([1.0, 9.0]), y)
    np.testing.assert_allclose(cov, 0.95, atol=0.003)
    assert interval_coverage(np.zeros((4, 1)), np.ones((4, 1)), np.array([[0.0], [1.95], [1.97], [-3.0]]))[0] == 0.5
    with pytest.raises(ValueError, match="var: negative"):
        interval_coverage(np.zeros(3), -np.ones(3), np.zeros(3))
    with pytest.raises(ValueError, match="level"):
        interval_coverage(np.zeros(3), np.ones(3), np.zeros(3), level=1.0)
