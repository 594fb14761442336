"""DynamicsData: validation, files, selections, numerical differentiation."""

from __future__ import annotations

import numpy as np
import pytest

from cascgp.data import DynamicsData, SavGol


def _rec(T=20, N=3, seed=0, **kw):
    rng = np.random.default_rng(seed)
    d = dict(q=rng.normal(size=(T, N)), qd=rng.normal(size=(T, N)), qdd=rng.normal(size=(T, N)),
             tau=rng.normal(size=(T, N)), t=np.arange(T) * 0.02)
    d.update(kw)
    return d


def test_properties():
    d = DynamicsData(**_rec(T=50, N=4), meta={"robot": "x"})
    assert d.n_samples == 50 and d.dof == 4 and len(d) == 50
    assert d.dt == pytest.approx(0.02)
    assert d.duration == pytest.approx(1.0)
    assert d.segment.dtype == np.int64 and (d.segment == 0).all()
    assert not d.q.flags.writeable


@pytest.mark.parametrize("field", ["q", "qd", "qdd", "tau", "t"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nonfinite_names_field_and_row(field, bad):
    r = _rec()
    a = np.array(r[field], dtype=float)
    if a.ndim == 2:
        a[7, 1] = bad
    else:
        a[7] = bad
    r[field] = a
    with pytest.raises(ValueError, match=rf"DynamicsData\.{field}.*row 7"):
        DynamicsData(**r)


@pytest.mark.parametrize("field", ["qd", "qdd", "tau"])
def test_shape_mismatch_names_field(field):
    r = _rec()
    r[field] = r[field][:, :2]
    with pytest.raises(ValueError, match=rf"DynamicsData\.{field}.*shape"):
        DynamicsData(**r)


def test_bad_dims_and_t_shape():
    r = _rec()
    r["q"] = r["q"][:, 0]
    with pytest.raises(ValueError, match=r"DynamicsData\.q.*\(T, N\)"):
        DynamicsData(**r)
    r = _rec()
    r["t"] = r["t"][:-1]
    with pytest.raises(ValueError, match=r"DynamicsData\.t.*shape"):
        DynamicsData(**r)
    with pytest.raises(TypeError, match=r"DynamicsData\.q"):
        DynamicsData(**_rec(q=[["a", "b", "c"]] * 20))


def test_empty_rejected():
    with pytest.raises(ValueError, match="empty"):
        DynamicsData(**_rec(T=0))


def test_single_sample_allowed():
    d = DynamicsData(**_rec(T=1))
    assert d.n_samples == 1 and np.isnan(d.dt) and d.duration == 0.0


def test_time_must_increase_within_segment():
    r = _rec()
    t = r["t"].copy()
    t[5] = t[4]  # duplicated sample time
    with pytest.raises(ValueError, match=r"DynamicsData\.t.*row 5"):
        DynamicsData(**_rec(t=t))
    # ... but time may restart in a new segment
    seg = np.zeros(20, int)
    seg[10:] = 1
    t2 = np.concatenate([np.arange(10), np.arange(10)]) * 0.1
    d = DynamicsData(**_rec(t=t2, segment=seg))
    assert len(d.segments) == 2 and d.duration == pytest.approx(2.0)


def test_segment_must_be_nondecreasing():
    seg = np.zeros(20, int)
    seg[3] = 1
    with pytest.raises(ValueError, match=r"DynamicsData\.segment.*row 4"):
        DynamicsData(**_rec(segment=seg))
    with pytest.raises(TypeError, match=r"DynamicsData\.segment"):
        DynamicsData(**_rec(segment=np.full(20, 0.5)))
    for huge in (np.r_[np.zeros(19), 1e30], np.r_[np.zeros(19, np.uint64), np.uint64(2**64 - 1)]):
        with pytest.raises(ValueError, match=r"DynamicsData\.segment: expected ids within \+-2\*\*63"):
            DynamicsData(**_rec(segment=huge))


def test_meta_must_be_json(tmp_path):
    with pytest.raises(TypeError, match=r"DynamicsData\.meta"):
        DynamicsData(**_rec(), meta={"x": object()})
    d = DynamicsData(**_rec())
    d.meta["x"] = object()  # changed after construction: save names it, and writes nothing
    with pytest.raises(TypeError, match=r"DynamicsData\.meta: expected a JSON-serialisable dict"):
        d.save(tmp_path / "d.npz")
    assert list(tmp_path.iterdir()) == []


def test_save_load_roundtrip(tmp_path):
    seg = np.repeat([0, 1], 10)
    d = DynamicsData(**_rec(segment=seg), meta={"robot": "planar", "payload_mass": 0.8})
    p = d.save(tmp_path / "sub" / "d.npz")
    assert p.exists() and not [f for f in p.parent.iterdir() if f.name.endswith(".tmp")]
    e = DynamicsData.load(p)
    for f in ("q", "qd", "qdd", "tau", "t", "segment"):
        np.testing.assert_array_equal(getattr(e, f), getattr(d, f))
    assert e.meta == d.meta


def test_load_errors(tmp_path):
    d = DynamicsData(**_rec())
    p = d.save(tmp_path / "d.npz")
    raw = p.read_bytes()
    (tmp_path / "trunc.npz").write_bytes(raw[: len(raw) // 2])
    with pytest.raises(ValueError, match="trunc.npz.*corrupt or truncated"):
        DynamicsData.load(tmp_path / "trunc.npz")
    bad = bytearray(raw)
    i = raw.index(b"tau.npy") + 200  # inside tau's data
    bad[i] ^= 0xFF
    (tmp_path / "flip.npz").write_bytes(bytes(bad))
    with pytest.raises(ValueError, match="flip.npz"):
        DynamicsData.load(tmp_path / "flip.npz")
    with pytest.raises(FileNotFoundError):
        DynamicsData.load(tmp_path / "nope.npz")
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    with pytest.raises(ValueError, match="format_kind"):
        DynamicsData.load(tmp_path / "other.npz")
    z = dict(np.load(p))
    z["format_version"] = np.array(99)
    np.savez(tmp_path / "v99.npz", **z)
    with pytest.raises(ValueError, match="format_version.*99"):
        DynamicsData.load(tmp_path / "v99.npz")
    z = dict(np.load(p))
    del z["qdd"]
    np.savez(tmp_path / "miss.npz", **z)
    with pytest.raises(ValueError, match="missing.*qdd"):
        DynamicsData.load(tmp_path / "miss.npz")
    z = dict(np.load(p))
    z["tau"] = z["tau"].copy()
    z["tau"][4, 0] = np.nan
    np.savez(tmp_path / "nan.npz", **z)
    with pytest.raises(ValueError, match=r"nan.npz.*DynamicsData\.tau.*row 4"):
        DynamicsData.load(tmp_path / "nan.npz")


def test_split_subsample_first_seconds_concat():
    T = 100
    seg = np.repeat([0, 1], 50)
    t = np.concatenate([np.arange(50), np.arange(50)]) / 50.0
    d = DynamicsData(**_rec(T=T, t=t, segment=seg))
    parts = d.split(3)
    assert [p.n_samples for p in parts] == [34, 33, 33]
    np.testing.assert_array_equal(np.concatenate([p.q for p in parts]), d.q)
    with pytest.raises(ValueError, match="k"):
        d.split(0)
    with pytest.raises(ValueError, match="k"):
        d.split(101)
    s = d.subsample(10.0)
    assert s.n_samples == 20 and s.dt == pytest.approx(0.1)
    np.testing.assert_array_equal(s.q, np.concatenate([d.q[0:50:5], d.q[50:100:5]]))
    assert len(s.segments) == 2 and s.meta["subsampled_hz"] == 10.0
    assert d.subsample(1000.0).n_samples == T
    with pytest.raises(ValueError, match="rate_hz"):
        d.subsample(0)
    f = s.first_seconds(1.5)
    assert f.n_samples == 15  # 10 rows of segment 0 (1 s) + 5 of segment 1
    assert d.first_seconds(100).n_samples == T
    c = DynamicsData.concat([d, d])
    assert c.n_samples == 2 * T and len(c.segments) == 4
    with pytest.raises(ValueError, match="parts"):
        DynamicsData.concat([])
    with pytest.raises(ValueError, match="dof"):
        DynamicsData.concat([d, DynamicsData(**_rec(N=2))])


def test_take():
    d = DynamicsData(**_rec())
    assert d.take([0, 3, 5]).n_samples == 3
    with pytest.raises(ValueError, match=r"DynamicsData\.t"):
        d.take([5, 3])
    assert d.take([-1]).t[0] == d.t[-1]  # NumPy's negative indices
    for idx, exc, match in (([100], ValueError, "take: idx: row 100 is out of range for 20 rows"),
                            ([-21], ValueError, "row -21 is out of range"),
                            ([], ValueError, "take: idx: expected at least one row"),
                            (3, TypeError, "take: idx: expected a 1-D sequence"),
                            ([0.5], TypeError, "take: idx: expected integer indices")):
        with pytest.raises(exc, match=match):
            d.take(idx)


@pytest.mark.parametrize("qd", [np.ones((20, 3)) * (1 + 1j), np.full((20, 3), "a"), [[1.0, 2.0, 3.0], [1.0]]])
def test_from_measurements_refuses_what_the_constructor_refuses(qd):
    r = _rec()
    with pytest.raises(TypeError, match=r"DynamicsData\.qd: expected a (real )?numeric"):
        DynamicsData.from_measurements(r["t"], r["q"], qd, r["tau"])


@pytest.mark.parametrize("call, match", [
    (lambda d: d.subsample(None), r"subsample: rate_hz: expected a finite number > 0 \(Hz\), got None"),
    (lambda d: d.subsample("10"), "subsample: rate_hz"),
    (lambda d: d.subsample(np.array([10.0, 5.0])), "subsample: rate_hz"),
    (lambda d: d.first_seconds("1"), r"first_seconds: seconds: expected a finite number > 0 \(s\)"),
    (lambda d: d.thin(2.5), "thin: max_samples: expected an integer >= 2, got 2.5"),
    (lambda d: d.thin(None), "thin: max_samples"),
    (lambda d: d.subsample(np.array(-1.0)), "subsample: rate_hz"),
])
def test_scalar_arguments_name_themselves(call, match):
    with pytest.raises(ValueError, match=match):
        call(DynamicsData(**_rec()))


def test_a_zero_dimensional_array_is_a_number():
    d = DynamicsData(**_rec())
    assert d.subsample(np.array(10.0)).n_samples == d.subsample(10.0).n_samples


def test_from_measurements_central_differences():
    t = np.linspace(0, 2, 201)
    w = 3.0
    q = np.sin(w * t)[:, None] * [1.0, 2.0]
    qd = w * np.cos(w * t)[:, None] * [1.0, 2.0]
    qdd_true = -w**2 * np.sin(w * t)[:, None] * [1.0, 2.0]
    d = DynamicsData.from_measurements(t, q, qd, np.zeros_like(q))
    # interior: second-order central differences
    np.testing.assert_allclose(d.qdd[1:-1], qdd_true[1:-1], atol=w**4 * 0.01**2)
    # ends: one-sided first-order
    np.testing.assert_allclose(d.qdd[[0, -1]], qdd_true[[0, -1]], atol=w**3 * 0.01 * 2)
    np.testing.assert_allclose(d.qdd[1:-1], (qd[2:] - qd[:-2]) / (t[2:] - t[:-2])[:, None], rtol=1e-11)
    assert "central" in d.meta["qdd_source"]


def test_from_measurements_per_segment_and_smoothing():
    rng = np.random.default_rng(0)
    t = np.concatenate([np.arange(100), np.arange(100)]) * 0.01
    seg = np.repeat([0, 1], 100)
    qd = np.concatenate([t[:100], -t[100:]])[:, None]  # slope +1 then -1: a jump between segments
    d = DynamicsData.from_measurements(t, np.zeros_like(qd), qd, np.zeros_like(qd), segment=seg)
    np.testing.assert_allclose(d.qdd[:100], 1.0)
    np.testing.assert_allclose(d.qdd[100:], -1.0)
    # smoothing reduces differentiation noise
    tt = np.arange(400) * 0.01
    v = np.sin(tt)[:, None]
    noisy = v + 1e-3 * rng.standard_normal(v.shape)
    plain = DynamicsData.from_measurements(tt, v, noisy, v)
    sg = DynamicsData.from_measurements(tt, v, noisy, v, smoothing=SavGol(15, 2))
    true = np.cos(tt)[:, None]
    assert np.sqrt(np.mean((sg.qdd - true) ** 2)) < 0.3 * np.sqrt(np.mean((plain.qdd - true) ** 2))
    assert "Savitzky" in sg.meta["qdd_source"]
    with pytest.raises(ValueError, match="window"):
        SavGol(4)
    with pytest.raises(TypeError, match="smoothing"):
        DynamicsData.from_measurements(tt, v, v, v, smoothing="yes")
    with pytest.raises(ValueError, match=r"DynamicsData\.qd.*row 3"):
        bad = noisy.copy()
        bad[3] = np.nan
        DynamicsData.from_measurements(tt, v, bad, v)
    one = DynamicsData.from_measurements(tt[:1], v[:1], v[:1], v[:1])
    assert one.qdd[0, 0] == 0.0


def test_thin_keeps_evenly_spaced_rows_with_both_ends() -> None:
    T = 101
    t = np.arange(T) * 0.01
    q = np.c_[t, 2 * t]
    d = DynamicsData(q=q, qd=q, qdd=q, tau=q, t=t)
    thin = d.thin(11)
    np.testing.assert_array_equal(thin.t, t[::10])
    assert d.thin(T) is d and d.thin(500) is d
    with pytest.raises(ValueError, match="thin: max_samples"):
        d.thin(1)


def test_all_finite_equals_numpys_check_without_warnings() -> None:
    """The per-tick finiteness check (cascgp.data.all_finite) answers as np.isfinite(x).all() for every kind of
    entry, overflowing squares included, and raises no floating-point warning."""
    import warnings

    from cascgp.data import all_finite

    big, tiny = np.finfo(np.float64).max, np.finfo(np.float64).tiny
    cases = [np.zeros(0), np.zeros(19), np.array([1.0, -2.0]), np.array([big, -big]), np.array([tiny, 5e-324]),
             np.array([np.nan]), np.array([1.0, np.inf]), np.array([-np.inf, np.inf]), np.array([1e200, np.nan]),
             np.array([1.0, np.nan], dtype=np.float32), np.arange(10.0)[::3]]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for x in cases:
            assert all_finite(x) is bool(np.isfinite(x).all()), x
