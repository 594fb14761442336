"""The derivative filters of cascgp.derivatives: the causal Savitzky-Golay filter uses past samples only, is exact
on polynomials of its degree, has the frequency response of its FIR coefficients (its phase error, i.e. its delay),
and a larger noise gain than the centred one; the centred filter is unchanged (scipy's savgol_filter)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import savgol_filter

from cascgp.data import DynamicsData
from cascgp.derivatives import SavGol, differentiate

DT = 0.01


def _signal(T: int = 200, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(T) * DT
    rng = np.random.default_rng(seed)
    return t, np.sin(np.outer(t, [2.0, 5.0])) + 0.01 * rng.standard_normal((T, 2))


def test_causal_filter_uses_no_future_sample() -> None:
    t, x = _signal()
    seg = np.zeros(len(t), dtype=np.int64)
    base = differentiate(t, x, seg, SavGol(7, 2, causal=True))
    for k in (0, 3, 6, 50, 199):
        y = x.copy()
        y[k:] += 1.0 + np.arange(len(t) - k)[:, None]  # change sample k and everything after it
        out = differentiate(t, y, seg, SavGol(7, 2, causal=True))
        np.testing.assert_array_equal(out[:k], base[:k])
        assert np.all(out[k:] != base[k:]) or k == 0


def test_causal_filter_is_exact_on_quadratics_and_equals_its_fir() -> None:
    t = np.arange(100) * DT
    x = np.stack([3 * t**2 - t + 1, -2 * t**2], axis=1)
    dx = np.stack([6 * t - 1, -4 * t], axis=1)
    seg = np.zeros(len(t), dtype=np.int64)
    out = differentiate(t, x, seg, SavGol(9, 2, causal=True))
    np.testing.assert_allclose(out[2:], dx[2:], rtol=1e-9, atol=1e-9)  # rows 2.. fit a quadratic (row 1: a line)
    assert np.all(out[0] == 0)
    c = SavGol(9, 2, causal=True).coefficients(DT)
    np.testing.assert_allclose(out[8:, 0], np.convolve(x[:, 0], c[::-1], mode="valid"), rtol=1e-12, atol=1e-9)


def test_causal_filter_phase_error_matches_its_frequency_response() -> None:
    """On a sinusoid the interior output is |H| sin(wt + phi) with H the FIR's response: the filter's delay."""
    w = 2 * np.pi * 3.0  # 3 Hz
    t = np.arange(400) * DT
    seg = np.zeros(len(t), dtype=np.int64)
    sg = SavGol(7, 2, causal=True)
    out = differentiate(t, np.sin(w * t)[:, None], seg, sg)[:, 0]
    c = sg.coefficients(DT)
    k = np.arange(len(c)) - (len(c) - 1)  # taps at t - w + 1 .. t
    H = np.sum(c * np.exp(1j * w * k * DT))
    expected = np.imag(H * np.exp(1j * w * t))
    np.testing.assert_allclose(out[10:], expected[10:], rtol=0, atol=1e-9)
    # a differentiator at low frequency (H -> i w); at 3 Hz the end-point fit already errs by about 10 % in gain
    w0 = 2 * np.pi * 0.2
    H0 = np.sum(c * np.exp(1j * w0 * k * DT))
    assert abs(H0 / (1j * w0) - 1) < 1e-3
    assert 0.02 < abs(H / (1j * w) - 1) < 0.3


def test_centred_filter_is_scipys_and_causal_is_noisier() -> None:
    t, x = _signal()
    seg = np.zeros(len(t), dtype=np.int64)
    np.testing.assert_allclose(differentiate(t, x, seg, SavGol(7, 2)),
                               savgol_filter(x, 7, 2, deriv=1, delta=DT, axis=0, mode="interp"), rtol=1e-9, atol=1e-9)
    assert SavGol(7, 2, causal=True).noise_gain(DT) > 3 * SavGol(7, 2).noise_gain(DT)


def test_from_measurements_with_causal_filter_records_it() -> None:
    t, x = _signal(50)
    data = DynamicsData.from_measurements(q=x, qd=x, tau=x, t=t, smoothing=SavGol(5, 2, causal=True))
    assert "causal Savitzky-Golay" in data.meta["qdd_source"]
    with pytest.raises(TypeError, match="SavGol.causal"):
        SavGol(5, 2, causal="yes")  # type: ignore[arg-type]


@pytest.mark.parametrize("kwargs, name", [({"window": 5.0}, "window"), ({"window": True}, "window"),
                                          ({"polyorder": 2.0}, "polyorder"), ({"window": "7"}, "window")])
def test_savgol_takes_integers_only(kwargs, name) -> None:
    """A float window (5.0) was accepted and failed later inside SciPy; it is refused by name."""
    with pytest.raises(TypeError, match=rf"^SavGol.{name}: expected an integer, got "):
        SavGol(**kwargs)
    assert SavGol(np.int64(9), np.int32(3)).window == 9


def test_centred_filter_fits_at_the_sample_times_where_samples_were_dropped() -> None:
    """A 100 Hz log with every tenth sample dropped: the uniform filter took each period for the median one and was
    off by a fifth of the amplitude; fitted at the sample times the derivative is within 0.3 %. Uniform sampling
    keeps SciPy's filter bit for bit, and the fit at the sample times equals it there to round-off."""
    from cascgp.derivatives import _local_polynomial_derivative, is_uniform

    t = (np.arange(3600) * DT)[np.arange(3600) % 10 != 9]
    x = np.stack([np.sin(2.0 * t), np.cos(3.0 * t)], axis=1)
    true = np.stack([2.0 * np.cos(2.0 * t), -3.0 * np.sin(3.0 * t)], axis=1)
    seg = np.zeros(len(t), dtype=np.int64)
    assert not is_uniform(t)
    err = np.abs(differentiate(t, x, seg, SavGol(7, 2)) - true).max(axis=0)
    assert (err < 0.003 * np.array([2.0, 3.0])).all(), err
    uniform_err = np.abs(savgol_filter(x, 7, 2, deriv=1, delta=DT, axis=0, mode="interp") - true).max(axis=0)
    assert (uniform_err > 0.1 * np.array([2.0, 3.0])).all(), uniform_err  # what the uniform filter gave
    tu, xu = _signal()
    assert is_uniform(tu)
    h = float(np.median(np.diff(tu)))
    np.testing.assert_array_equal(differentiate(tu, xu, np.zeros(len(tu), dtype=np.int64), SavGol(7, 2)),
                                  savgol_filter(xu, 7, 2, deriv=1, delta=h, axis=0, mode="interp"))
    np.testing.assert_allclose(_local_polynomial_derivative(tu, xu, 7, 2),
                               savgol_filter(xu, 7, 2, deriv=1, delta=DT, axis=0, mode="interp"), rtol=0, atol=1e-10)
    # a segment too short for the window keeps central differences at its times
    np.testing.assert_array_equal(differentiate(t[:5], x[:5], seg[:5], SavGol(7, 2)),
                                  np.gradient(x[:5], t[:5], axis=0, edge_order=1))


@pytest.mark.parametrize("window, polyorder", [(7, 6), (15, 10), (21, 12)])
def test_the_fit_at_the_sample_times_holds_at_high_orders_and_across_a_long_pause(window, polyorder) -> None:
    """Solved by the normal equations (inverting V^T V, which squares the condition number), the fit at the sample
    times was off by 16-81 % at orders 10-12 and a pause of 1e9 periods made V^T V singular (numpy's LinAlgError)."""
    from cascgp.derivatives import _local_polynomial_derivative

    t, x = _signal(400)
    ref = savgol_filter(x, window, polyorder, deriv=1, delta=DT, axis=0, mode="interp")
    np.testing.assert_allclose(_local_polynomial_derivative(t, x, window, polyorder), ref, rtol=0,
                               atol=1e-7 * np.abs(ref).max())
    paused = np.r_[t[:200], 1e7 + t[200:]]
    out = differentiate(paused, x, np.zeros(len(t), dtype=np.int64), SavGol(window, min(polyorder, 4)))
    assert np.isfinite(out).all()
