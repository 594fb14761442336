"""Derivative-free (-df) models fitted on rows chosen from a longer record: their position history comes from the
whole record (``fit(..., q_hist=...)``, and ``cascgp fit`` under ``--max-samples`` / ``--rate-hz``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cascgp.features import history_from_data
from cascgp.gp import GPFitConfig
from cascgp.logs import write_log
from cascgp.models import load_model, make_model
from cascgp_experiments.cli.model_commands import fit_main
from tests.conftest import make_arm, sinusoid_data

FAST = GPFitConfig(n_restarts=1, max_iter=100)


def test_given_history_equals_the_history_of_the_data_itself() -> None:
    """fit(data, q_hist=history_from_data(data), rows without history NaN) is fit(data), bit for bit."""
    data = sinusoid_data(make_arm(2), 6.0, 20.0, seed=3, noise=0.01)
    q_hist, valid = history_from_data(data, 0.1)
    assert 0 < (~valid).sum() < data.n_samples  # some rows have no history: left out both ways
    q_hist[~valid] = np.nan
    a = make_model("np-inward-df", 2, gp_config=FAST).fit(data)
    b = make_model("np-inward-df", 2, gp_config=FAST).fit(data, q_hist=q_hist)
    assert a.n_train == b.n_train == int(valid.sum())
    np.testing.assert_array_equal(a.predict_data(data)[0], b.predict_data(data)[0])


def test_a_given_history_of_the_wrong_kind_is_refused_and_changes_nothing() -> None:
    data = sinusoid_data(make_arm(2), 4.0, 20.0, seed=4)
    q_hist = history_from_data(data, 0.1)[0]
    m = make_model("np-standard-df", 2, gp_config=FAST)
    for bad, kind, match in ((q_hist[1:], ValueError, r"q_hist: expected shape \(80, 2, 2\)"),
                             (q_hist[:, :1], ValueError, r"q_hist: expected shape"),
                             ("history", TypeError, "q_hist: expected a real numeric"),
                             (q_hist + 1j, TypeError, "q_hist: expected a real numeric")):
        with pytest.raises(kind, match=match):
            m.fit(data, q_hist=bad)
        assert not m.fitted
    with pytest.raises(ValueError, match="q_hist: model 'np-standard' is derivative-based"):
        make_model("np-standard", 2, gp_config=FAST).fit(data, q_hist=q_hist)
    nan = np.full_like(q_hist, np.nan)
    nan[:1] = q_hist[:1]
    with pytest.raises(ValueError, match="at least 2 usable training samples, got 1"):
        m.fit(data, q_hist=nan)
    assert not m.fitted


def test_row_indices_are_the_rows_thin_and_subsample_keep() -> None:
    data = sinusoid_data(make_arm(2), 5.0, 50.0, seed=5)
    for rows, kept in ((data.thin_rows(37), data.thin(37)), (data.subsample_rows(7.0), data.subsample(7.0))):
        np.testing.assert_array_equal(data.t[rows], kept.t)
        np.testing.assert_array_equal(data.q[rows], kept.q)
    np.testing.assert_array_equal(data.thin_rows(10_000), np.arange(data.n_samples))
    np.testing.assert_array_equal(data.thin_rows(3), [0, 124, 249])  # first, middle (124.5 rounds to even), last
    np.testing.assert_array_equal(data.subsample_rows(10.0), np.arange(0, 250, 5))  # 50 Hz -> every 5th row


@pytest.mark.parametrize("options", [["--max-samples", "60"], ["--rate-hz", "4"]])
def test_cli_fit_takes_the_history_from_the_whole_log(tmp_path: Path, options: list[str]) -> None:
    """Rows chosen 0.25-0.5 s apart (df_delta is 0.1 s): each training row's history columns are the log's
    positions interpolated at t - 0.1 s and t - 0.2 s from every row of the log, not from the rows kept."""
    log = sinusoid_data(make_arm(2), 15.0, 50.0, seed=6, noise=0.01)
    write_log(tmp_path / "train.csv", log)
    out = tmp_path / "m.npz"
    assert fit_main(["--data", str(tmp_path / "train.csv"), "--model", "np-standard-df", "--out", str(out),
                     "--restarts", "1", "--threads", "1", *options]) == 0
    X = load_model(out).banks[0].training_data()[0][0]  # the standard model's GP of joint 1 sees every joint
    rows = np.array([np.flatnonzero(np.all(np.abs(log.q - x) < 1e-12, axis=1))[0] for x in X[:, 0::3]])
    assert len(rows) >= 50 and np.all(np.diff(log.t[rows]) > 0.2)  # the rows kept lie far apart
    assert log.t[rows].min() >= 0.2 - 1e-9  # every row kept has 0.2 s of history within the log
    for m, cols in ((1, X[:, 1::3]), (2, X[:, 2::3])):
        ref = np.column_stack([np.interp(log.t[rows] - 0.1 * m, log.t, log.q[:, j]) for j in range(2)])
        np.testing.assert_allclose(cols, ref, rtol=0, atol=1e-12)
