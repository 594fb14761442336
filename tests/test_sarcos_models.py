"""NP-standard on real SARCOS data (IAS file), the split of issue 3:
train = every 5th training row (10 Hz), the first 300; test = the first 1,500 test rows that do
not also stand in the training set.  GPy (Matern 5/2 ARD, 2 restarts) reached a mean nRMSE of
0.0587 (per joint 0.033 0.056 0.067 0.026 0.032 0.155 0.041)."""

from __future__ import annotations

import numpy as np
import pytest

from cascgp.gp import GPFitConfig
from cascgp.metrics import nrmse
from cascgp.models import make_model
from cascgp.sarcos import load_ias


@pytest.fixture(scope="module")
def split(sarcos_dir):
    train, test = load_ias(sarcos_dir / "ias_sarcos_data.mat")  # test de-duplicated
    tr10 = train.subsample(10.0)
    return tr10, test.take(np.arange(1500))


def _score(tr, te, n, restarts):
    m = make_model("np-standard", 7, gp_config=GPFitConfig(n_restarts=restarts)).fit(tr.take(np.arange(n)))
    mean, var = m.predict_data(te)
    assert np.isfinite(mean).all() and np.isfinite(var).all()
    return nrmse(mean, te.tau)


def test_split_is_the_documented_one(split):
    tr, te = split
    assert tr.n_samples > 300 and te.n_samples == 1500
    assert te.meta["n_duplicates_removed"] == 2785


def test_np_standard_sarcos_small(split):
    """Fast sibling: n = 100, one restart."""
    tr, te = split
    e = _score(tr, te, 100, 1)
    assert e.mean() <= 0.15, e


@pytest.mark.slow
def test_np_standard_sarcos_300(split):
    """The issue's criterion: mean nRMSE over the 7 joints <= 0.06 (2 restarts, as GPy).
    13-39 s on the shared 2-core machine (one torch thread; about 9 s of CPU), hence slow; measured 0.0361 0.0657 0.0656
    0.0225 0.0314 0.1543 0.0360, mean 0.0588 (with the default 10 restarts: mean 0.0600)."""
    tr, te = split
    e = _score(tr, te, 300, 2)
    print("SARCOS np-standard n=300 nRMSE per joint:", np.round(e, 4), "mean", round(float(e.mean()), 4))
    assert e.mean() <= 0.06, e
