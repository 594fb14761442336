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
    with pytest.raises(ValueError, match=r"expected \(T, N\) or \(T,\) arrays, got shapes \(2, 2, 2\)"):
        rmse(np.zeros((2, 2, 2)), np.zeros((2, 2, 2)))
    with pytest.raises(ValueError, match="pred/target: expected real"):
        nrmse([[1.0, 2.0], [1.0]], y)


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


def test_std_scale_for_level_closed_form_and_its_invariant():
    from cascgp.metrics import interval_coverage, std_scale_for_level

    rng = np.random.default_rng(3)
    y = rng.normal(size=(20000, 2)) * np.array([1.0, 3.0])  # true sds 1 and 3
    # predicted sd 1 on both joints: the factor must be the true sd (to sampling error of the 95 % quantile)
    c = std_scale_for_level(np.zeros_like(y), np.ones_like(y), y)
    np.testing.assert_allclose(c, [1.0, 3.0], rtol=0.03)
    # the definition: the level-quantile of |error|/sd over z (here exactly, one column of known errors)
    e = np.arange(1.0, 101.0)[:, None]
    assert std_scale_for_level(np.zeros_like(e), np.full_like(e, 4.0), e, 0.9)[0] == pytest.approx(
        np.quantile(e[:, 0] / 2.0, 0.9) / 1.6448536269514722)
    # invariant: the scaled intervals cover the level on the data the factor was fitted on
    cov = interval_coverage(np.zeros_like(y), c**2 * np.ones_like(y), y)
    np.testing.assert_allclose(cov, 0.95, atol=1e-3)
    # zero error with zero variance is covered (factor 0), not a NaN
    assert std_scale_for_level(np.zeros((3, 1)), np.zeros((3, 1)), np.zeros((3, 1)))[0] == 0.0
    with pytest.raises(ValueError, match="var"):
        std_scale_for_level(np.zeros(3), -np.ones(3), np.zeros(3))
    with pytest.raises(ValueError, match="var: zero variance with a non-zero error"):
        std_scale_for_level(np.zeros(3), np.array([1.0, 0.0, 1.0]), np.array([0.0, 0.5, 0.0]))
    with pytest.raises(ValueError, match="level"):
        std_scale_for_level(np.zeros(3), np.ones(3), np.zeros(3), level=1.0)
