"""Property-based fuzzing (hypothesis) of the learning library's inputs: DynamicsData fields and the file loaders.

Every case must end in a valid result or in a ``ValueError``/``TypeError`` whose message names the field or the
file: never another exception type, never a silent NaN. Issue 12; about 10 s in the default suite.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from cascgp.data import DynamicsData
from cascgp.gp import GPFitConfig
from cascgp.models import load_model, make_model
from tests.conftest import make_arm, sinusoid_data

# Derandomized in the suite (reproducible CI); FUZZ_EXAMPLES=500 explores fresh random cases.
SETTINGS = settings(max_examples=int(os.environ.get("FUZZ_EXAMPLES", 60)), deadline=None,
                    derandomize="FUZZ_EXAMPLES" not in os.environ,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])
FIELDS = ("q", "qd", "qdd", "tau", "t", "segment")

_values = st.sampled_from([0.0, 1.0, -2.5, 1e300, -1e300, np.nan, np.inf, -np.inf, 1e-300])
_weird = st.sampled_from(["text", None, [1, [2, 3]], {"a": 1}, 1 + 2j, object()])


@st.composite
def _field_value(draw, T: int, N: int, name: str):
    kind = draw(st.sampled_from(["ok", "shape", "value", "weird", "dtype"]))
    shape = (T,) if name in ("t", "segment") else (T, N)
    good = np.arange(T, dtype=float) * 0.1 if name == "t" else np.zeros(shape)
    if name == "segment":
        good = np.zeros(T, dtype=np.int64)
    if kind == "ok":
        return good
    if kind == "shape":
        return np.zeros(draw(st.sampled_from([(T + 1,), (T, N + 1), (0, N), (T, N, 1), ()])))
    if kind == "value":
        a = good.astype(float).copy()
        a.flat[draw(st.integers(0, a.size - 1))] = draw(_values)
        return a
    if kind == "dtype":
        return good.astype(draw(st.sampled_from([np.complex128, np.bool_, np.int8, "U3", object])))
    return draw(_weird)


@given(data=st.data())
@SETTINGS
def test_dynamics_data_accepts_or_names_the_field(data) -> None:
    T, N = data.draw(st.integers(1, 5)), data.draw(st.integers(1, 3))
    kw = {name: data.draw(_field_value(T, N, name), label=name) for name in FIELDS}
    try:
        d = DynamicsData(**kw)
    except (ValueError, TypeError) as exc:
        assert "DynamicsData." in str(exc), str(exc)
        return
    for name in ("q", "qd", "qdd", "tau", "t"):
        assert np.isfinite(getattr(d, name)).all()
        assert getattr(d, name).dtype == np.float64


@pytest.fixture(scope="module")
def saved(tmp_path_factory) -> dict[str, Path]:
    """A saved DynamicsData and a saved cascade model (small)."""
    folder = tmp_path_factory.mktemp("fuzz")
    arm = make_arm(2)
    data = sinusoid_data(arm, 3.0, 10.0, seed=0, noise=0.01)
    model = make_model("np-inward", 2, gp_config=GPFitConfig(n_restarts=1, max_iter=10)).fit(data)
    return {"data": data.save(folder / "data.npz"), "model": model.save(folder / "model.npz")}


def _load(kind: str, path: Path):
    return DynamicsData.load(path) if kind == "data" else load_model(path)


def _loads_or_names_the_file(kind: str, path: Path) -> None:
    try:
        obj = _load(kind, path)
    except ValueError as exc:
        assert str(path) in str(exc), str(exc)
        return
    _check_result(kind, obj)


def _check_result(kind: str, obj) -> None:
    if kind == "data":
        assert np.isfinite(obj.q).all() and np.isfinite(obj.tau).all()
    else:
        mean, var = obj.predict(np.zeros(2), np.zeros(2), np.zeros(2))
        assert np.isfinite(mean).all() and np.isfinite(var).all()


@pytest.mark.parametrize("kind", ["data", "model"])
@given(cut=st.floats(0.0, 1.0), flips=st.lists(st.integers(0, 10**9), max_size=3))
@SETTINGS
def test_truncated_or_bit_flipped_files_fail_naming_the_file(saved, tmp_path_factory, kind, cut, flips) -> None:
    raw = bytearray(saved[kind].read_bytes())
    raw = raw[: int(cut * len(raw))] if cut < 1.0 else raw
    for f in flips:
        if raw:
            raw[f % len(raw)] ^= 0xFF
    path = tmp_path_factory.mktemp("t") / f"{kind}.npz"
    path.write_bytes(bytes(raw))
    _loads_or_names_the_file(kind, path)


_junk = st.one_of(
    st.just(np.array("text")), st.just(np.zeros((2, 2))), st.just(np.array([np.nan, 1.0])),
    st.just(np.array(1e308)), st.just(np.zeros(0)), st.just(np.array(["a", "b"])), st.just(np.array(True)),
    st.just(np.array('{"name": "np-inward"}')), st.just(np.array("[1, 2]")), st.just(np.array("{}")),
    st.just(np.zeros((1, 5, 7))), st.just(np.array([1 + 1j])),
)


@pytest.mark.parametrize("kind", ["data", "model"])
@given(data=st.data())
@SETTINGS
def test_any_corrupted_or_missing_field_fails_naming_the_file(saved, tmp_path_factory, kind, data) -> None:
    z = dict(np.load(saved[kind]))
    key = data.draw(st.sampled_from(sorted(z)), label="field")
    if data.draw(st.booleans(), label="remove"):
        del z[key]
    else:
        z[key] = data.draw(_junk, label="value")
    path = tmp_path_factory.mktemp("c") / f"{kind}.npz"
    np.savez(path, **z)
    _loads_or_names_the_file(kind, path)


def test_foreign_and_odd_paths_fail_naming_the_file(tmp_path: Path) -> None:
    np.savez(tmp_path / "foreign.npz", a=np.zeros(3))
    (tmp_path / "dir.npz").mkdir()
    os.symlink(tmp_path / "nowhere", tmp_path / "dangling.npz")
    shutil.copy(tmp_path / "foreign.npz", tmp_path / "no_suffix")
    for name in ("foreign.npz", "dir.npz", "no_suffix"):
        for load in (DynamicsData.load, load_model):
            with pytest.raises(ValueError, match=name):
                load(tmp_path / name)
    for load in (DynamicsData.load, load_model):
        with pytest.raises(FileNotFoundError, match="dangling"):
            load(tmp_path / "dangling.npz")
