"""SARCOS loaders (skip when ../shared/data/sarcos is missing)."""

import numpy as np
import pytest

from cascgp.sarcos import IAS_TO_GPML_TORQUE, duplicate_rows, load_gpml, load_ias


def test_load_ias(sarcos_dir):
    tr, te = load_ias(sarcos_dir / "ias_sarcos_data.mat")
    assert (tr.n_samples, tr.dof) == (13922, 7)
    assert te.n_samples == 5569 - 2785 and te.meta["n_duplicates_removed"] == 2785
    assert tr.dt == pytest.approx(0.02) and te.dt == pytest.approx(0.04)
    # no remaining test row stands in the training set
    Xtr = np.c_[tr.q, tr.qd, tr.qdd]
    Xte = np.c_[te.q, te.qd, te.qdd]
    assert not duplicate_rows(Xte, Xtr).any()
    # recordings are concatenated: several segments, first one long
    assert 8 <= len(tr.segments) <= 40
    assert tr.segment_bounds()[0][1] > 1500
    # 10 Hz subsampling == every 5th row
    s = tr.subsample(10.0).first_seconds(30.0)
    assert s.n_samples == 300
    np.testing.assert_array_equal(s.q, tr.q[::5][:300])
    _, te_all = load_ias(sarcos_dir / "ias_sarcos_data.mat", dedup=False)
    assert te_all.n_samples == 5569
    tr3, _ = load_ias(sarcos_dir / "ias_sarcos_data.mat", torque_scale=IAS_TO_GPML_TORQUE)
    np.testing.assert_allclose(tr3.tau, 3 * tr.tau)
    assert tr3.meta["torque_units"] == "GPML" and tr.meta["torque_units"] == "IAS"


def test_load_gpml_units_match_ias(sarcos_dir):
    g = load_gpml(sarcos_dir / "sarcos_inv_test.mat")
    assert (g.n_samples, g.dof) == (4449, 7)
    tr, te = load_ias(sarcos_dir / "ias_sarcos_data.mat", dedup=False)
    # SOURCE.txt: one input row is shared by both files; GPML torques are 3x IAS's there
    Xg = np.c_[g.q, g.qd, g.qdd]
    for d in (tr, te):
        X = np.c_[d.q, d.qd, d.qdd]
        m = duplicate_rows(Xg, X, 6)
        if m.any():
            i = int(np.flatnonzero(m)[0])
            j = int(np.flatnonzero(duplicate_rows(X, Xg[i:i + 1], 6))[0])
            np.testing.assert_allclose(g.tau[i], IAS_TO_GPML_TORQUE * d.tau[j], rtol=1e-5, atol=1e-5)
            break
    else:
        pytest.fail("no shared row found between the GPML and IAS files")
    gi = load_gpml(sarcos_dir / "sarcos_inv_test.mat", torque_scale=1 / IAS_TO_GPML_TORQUE)
    assert gi.meta["torque_units"] == "IAS"


def test_loader_errors(tmp_path, sarcos_dir):
    with pytest.raises(FileNotFoundError):
        load_ias(tmp_path / "missing.mat")
    (tmp_path / "bad.mat").write_bytes(b"not a mat file at all" * 10)
    with pytest.raises(ValueError, match="bad.mat"):
        load_ias(tmp_path / "bad.mat")
    with pytest.raises(ValueError, match="missing variable.*GPML SARCOS matrix 'sarcos_inv_test'"):
        load_ias(sarcos_dir / "sarcos_inv_test.mat")
    with pytest.raises(ValueError, match="28"):
        load_gpml(sarcos_dir / "ias_sarcos_data.mat")
    with pytest.raises(ValueError, match="torque_scale"):
        load_ias(sarcos_dir / "ias_sarcos_data.mat", torque_scale=0)


def test_check_ias_checks_names_shapes_and_data(tmp_path) -> None:
    """``check_ias`` accepts a file with the IAS variables and shapes and names the variable and the expected
    shape otherwise; ``load_ias`` raises the same errors. A truncated file, whose names and shapes it read alone
    before, is refused too (``cascgp study`` ran the whole Jaco part, then failed at the SARCOS load)."""
    from scipy.io import savemat

    from cascgp.sarcos import check_ias

    good = {"X_train": np.zeros((3, 21)), "Y_train": np.zeros((3, 7)), "X_test": np.zeros((2, 21)),
            "Y_test": np.zeros((2, 7))}
    savemat(tmp_path / "ok.mat", good)
    check_ias(tmp_path / "ok.mat")
    for name, value, expected in (("X_train", np.zeros((3, 20)), r"X_train: expected shape \(3, 21\), got \(3, 20\)"),
                                  ("Y_test", np.zeros((3, 7)), r"Y_test: expected shape \(2, 7\), got \(3, 7\)")):
        savemat(tmp_path / "bad.mat", {**good, name: value})
        with pytest.raises(ValueError, match=expected):
            check_ias(tmp_path / "bad.mat")
        with pytest.raises(ValueError, match=expected):
            load_ias(tmp_path / "bad.mat")
    with pytest.raises(FileNotFoundError, match="missing.mat"):
        check_ias(tmp_path / "missing.mat")
    (tmp_path / "text.mat").write_text("t,q1\n")
    with pytest.raises(ValueError, match="text.mat: not a readable MATLAB .mat file"):
        check_ias(tmp_path / "text.mat")
    raw = (tmp_path / "ok.mat").read_bytes()
    for cut, match in ((10, r"cut.mat: not a readable MATLAB .mat file \(damaged or truncated\?\)"),
                       (len(raw) // 2, r"cut.mat: missing variable\(s\) .*: truncated\?")):
        (tmp_path / "cut.mat").write_bytes(raw[:-cut])
        with pytest.raises(ValueError, match=match):
            check_ias(tmp_path / "cut.mat")
    with pytest.raises(ValueError, match=r"is a folder; expected a MATLAB .mat file"):
        check_ias(tmp_path)
    with pytest.raises(ValueError, match=r"is a folder; expected a MATLAB .mat file"):
        load_gpml(tmp_path)



def test_load_gpml_names_what_the_file_holds_and_refuses_complex_values(tmp_path) -> None:
    """A GPML file of another shape said 'found []'; a complex matrix lost its imaginary part with a warning; a
    MATLAB v7.3 file got SciPy's advice to use h5py."""
    from scipy.io import savemat

    A = np.random.default_rng(1).normal(size=(6, 28))
    savemat(tmp_path / "t.mat", {"sarcos_inv": A.T})
    with pytest.raises(ValueError, match=r"found 0 among its variables \{'sarcos_inv': \(28, 6\)\}"):
        load_gpml(tmp_path / "t.mat")
    with pytest.raises(ValueError, match=r"variable 'x' not found; the file holds \{'sarcos_inv': \(28, 6\)\}"):
        load_gpml(tmp_path / "t.mat", variable="x")
    savemat(tmp_path / "c.mat", {"sarcos_inv": A + 1j})
    with pytest.raises(ValueError, match=r"c.mat: sarcos_inv: expected real numbers, got dtype complex128"):
        load_gpml(tmp_path / "c.mat")
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 HDF5 schema 1.00 ."
    (tmp_path / "h5.mat").write_bytes(header.ljust(116) + b"\0" * 8 + b"\x00\x02IM" + b"\0" * 512)
    with pytest.raises(ValueError, match=r"h5.mat: a MATLAB v7.3 \(HDF5\) file.*save\(\.\.\., '-v7'\)"):
        load_gpml(tmp_path / "h5.mat")


def test_a_bad_matrix_names_the_file_and_the_matrix(tmp_path) -> None:
    """A NaN in the training inputs, or a test split whose rows all stand in the training set: the file and the
    matrix are named (they were DynamicsData's messages alone). Tiny files: no SARCOS copy needed."""
    from scipy.io import savemat

    from cascgp.sarcos import check_ias

    rng = np.random.default_rng(0)
    X, Y = rng.normal(size=(4, 21)), rng.normal(size=(4, 7))
    bad = X.copy()
    bad[2, 5] = np.nan
    savemat(tmp_path / "nan.mat", {"X_train": bad, "Y_train": Y, "X_test": X, "Y_test": Y})
    for load in (load_ias, check_ias):  # check_ias read names and shapes only: a command ran, then failed at the load
        with pytest.raises(ValueError, match=r"nan.mat: X_train: NaN or inf \(first at row 2\)"):
            load(tmp_path / "nan.mat")
    savemat(tmp_path / "dup.mat", {"X_train": X, "Y_train": Y, "X_test": X[:2], "Y_test": Y[:2]})
    with pytest.raises(ValueError, match=r"dup.mat: X_test \(0 of 2 rows kept\): "):
        load_ias(tmp_path / "dup.mat")
    for kwargs in ({"jump_factor": -1.0}, {"jump_factor": np.nan}, {"rate_hz": None}):
        with pytest.raises(ValueError, match=next(iter(kwargs))):
            load_ias(tmp_path / "nan.mat", **kwargs)
    savemat(tmp_path / "ok.mat", {"X_train": X, "Y_train": Y, "X_test": X[:2] + 1.0, "Y_test": Y[:2]})
    assert len(load_ias(tmp_path / "ok.mat", jump_factor=np.inf)[0].segments) == 1  # inf: never split
