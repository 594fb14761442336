"""The log format of :mod:`cascgp.logs`: round trips, derivative filling, and errors that name file, row and column."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from tests.conftest import make_arm, sinusoid_data

from cascgp.data import DynamicsData, SavGol
from cascgp.logs import DEFAULT_SMOOTHING, LogFormatError, filter_name, read_log, write_log, write_predictions


@pytest.fixture(scope="module")
def data() -> DynamicsData:
    """3 joints, 50 Hz, two segments (the second starts later and elsewhere)."""
    arm = make_arm(3)
    a, b = sinusoid_data(arm, 4.0, 50.0, seed=1), sinusoid_data(arm, 3.0, 50.0, seed=2, noise=0.01)
    return DynamicsData.concat([a, b])


def write_columns(path: Path, data: DynamicsData, groups: tuple[str, ...]) -> Path:
    """A CSV holding ``t``, ``segment`` and only the given groups (as a logger without some signals would write it)."""
    cols = {"t": data.t, "segment": data.segment}
    for g in groups:
        cols.update({f"{g}{j + 1}": getattr(data, g)[:, j] for j in range(data.dof)})
    lines = [",".join(cols)] + [",".join(repr(float(cols[k][r])) for k in cols) for r in range(data.n_samples)]
    path.write_text("\n".join(lines) + "\n")
    return path


# --------------------------------------------------------------------------- round trips
def test_csv_round_trip_is_exact(tmp_path: Path, data: DynamicsData) -> None:
    path = write_log(tmp_path / "log.csv", data)
    header = path.read_text().splitlines()[0].split(",")
    assert header[:2] == ["t", "segment"] and header[-1] == "tau3" and len(header) == 2 + 4 * 3
    back = read_log(path)
    for name in ("q", "qd", "qdd", "tau", "t", "segment"):
        np.testing.assert_array_equal(getattr(back, name), getattr(data, name), err_msg=name)
    assert back.meta["qd_source"] == back.meta["qdd_source"] == "column"
    assert back.meta["derivative_filter"] is None and back.meta["has_tau"] and back.meta["source"] == str(path)
    assert not list(tmp_path.glob(".*.tmp"))  # atomic write left no temporary file


def test_npz_is_accepted(tmp_path: Path, data: DynamicsData) -> None:
    back = read_log(write_log(tmp_path / "log.npz", data))
    np.testing.assert_array_equal(back.tau, data.tau)
    np.testing.assert_array_equal(back.segment, data.segment)
    (tmp_path / "broken.npz").write_bytes(b"not a zip archive")
    with pytest.raises(LogFormatError, match=r"broken\.npz"):
        read_log(tmp_path / "broken.npz")


def test_column_order_blanks_and_blank_lines_do_not_matter(tmp_path: Path) -> None:
    path = tmp_path / "log.csv"
    path.write_text(" tau1 , q1 , t\n\n3.0, 1.0, 0.0\n4.0, 1.5, 0.1\n\n5.0, 2.0, 0.2\n")
    d = read_log(path, smoothing=None)
    np.testing.assert_array_equal(d.q[:, 0], [1.0, 1.5, 2.0])
    np.testing.assert_array_equal(d.tau[:, 0], [3.0, 4.0, 5.0])
    np.testing.assert_allclose(d.qd[:, 0], [5.0, 5.0, 5.0])
    assert d.meta["derivative_filter"] == filter_name(None)


def test_tau_is_optional_only_when_asked(tmp_path: Path, data: DynamicsData) -> None:
    path = write_columns(tmp_path / "states.csv", data, ("q",))
    with pytest.raises(LogFormatError, match=r"states\.csv: row 1 \(header\), column 'tau1': missing"):
        read_log(path)
    d = read_log(path, require_tau=False)
    assert d.meta["has_tau"] is False and not d.tau.any()


def test_a_log_without_torques_stays_one_when_saved_and_cannot_be_fitted(tmp_path: Path, data: DynamicsData) -> None:
    """A log read without torques (tau a zero placeholder) became a log of measured zero torques once saved: the .npz
    was fitted silently (the model predicted 0), and write_log wrote the placeholder as tau columns."""
    from cascgp.models import make_model

    states = read_log(write_columns(tmp_path / "states.csv", data, ("q",)), require_tau=False)
    states.save(tmp_path / "states.npz")
    with pytest.raises(LogFormatError, match=r"states\.npz: holds no measured torques"):
        read_log(tmp_path / "states.npz")
    assert read_log(tmp_path / "states.npz", require_tau=False).meta["has_tau"] is False
    write_log(tmp_path / "again.csv", states)
    assert "tau1" not in (tmp_path / "again.csv").read_text().splitlines()[0]
    with pytest.raises(LogFormatError, match=r"column 'tau1': missing"):
        read_log(tmp_path / "again.csv")
    np.testing.assert_array_equal(read_log(tmp_path / "again.csv", require_tau=False).q, states.q)
    with pytest.raises(ValueError, match=r"^data: holds no measured torques"):
        make_model("np-standard", states.dof).fit(states)


def test_write_predictions(tmp_path: Path) -> None:
    t, mean, var = np.arange(4) * 0.1, np.arange(8.0).reshape(4, 2), np.full((4, 2), 0.5)
    text = write_predictions(tmp_path / "p.csv", t, mean, var).read_text().splitlines()
    assert text[0] == "t,tau1,tau2,var1,var2" and len(text) == 5
    np.testing.assert_array_equal(np.array([r.split(",") for r in text[1:]], float), np.column_stack([t, mean, var]))
    with pytest.raises(ValueError, match="predictions"):
        write_predictions(tmp_path / "q.csv", t, mean, var[:2])
    assert not (tmp_path / "q.csv").exists()
    # several segments (times may restart in each): their ids, to match rows back; one segment: no column
    seg = np.array([0, 0, 3, 3])
    text = write_predictions(tmp_path / "s.csv", t, mean, var, seg).read_text().splitlines()
    assert text[0] == "t,segment,tau1,tau2,var1,var2"
    np.testing.assert_array_equal(np.array([r.split(",") for r in text[1:]], float)[:, 1], seg)
    assert write_predictions(tmp_path / "one.csv", t, mean, var, np.zeros(4)).read_text().startswith("t,tau1,")
    for bad in (np.array([0.5, 1, 1, 1]), np.array([0, 1, np.nan, 1]), np.zeros(3), np.array(["a"] * 4)):
        with pytest.raises(ValueError, match=r"^segment: expected integer ids of shape \(4,\)"):
            write_predictions(tmp_path / "bad.csv", t, mean, var, bad)
    assert not (tmp_path / "bad.csv").exists()


# --------------------------------------------------------------------------- derivatives
@pytest.mark.parametrize("given", [("q", "tau"), ("q", "qdd", "tau"), ("q", "qd", "tau")])
def test_missing_derivatives_are_filled(tmp_path: Path, data: DynamicsData, given: tuple[str, ...]) -> None:
    d = read_log(write_columns(tmp_path / "log.csv", data, given))
    for g in ("qd", "qdd"):
        assert d.meta[f"{g}_source"] == ("column" if g in given else "computed")
        if g in given:
            np.testing.assert_array_equal(getattr(d, g), getattr(data, g))
    assert d.meta["derivative_filter"] == filter_name(DEFAULT_SMOOTHING)
    inner = np.ones(d.n_samples, bool)  # away from the segment ends (the filter's half window)
    for lo, hi in d.segment_bounds():
        inner[lo:lo + 6] = inner[hi - 6:hi] = False
    for g, tol in (("qd", 1e-2), ("qdd", 2e-2)):  # max error relative to the signal's range (measured < 1 %)
        err = np.abs(getattr(d, g) - getattr(data, g))[inner].max(axis=0)
        assert np.all(err < tol * np.ptp(getattr(data, g), axis=0)), (g, err)


def test_derivatives_stay_within_segments(tmp_path: Path, data: DynamicsData) -> None:
    """The jump between segments must not leak into the derivative of either segment's rows."""
    both = read_log(write_columns(tmp_path / "log.csv", data, ("q", "tau")), smoothing=SavGol(5, 2))
    (lo, hi), (lo2, hi2) = data.segment_bounds()
    alone = read_log(write_columns(tmp_path / "one.csv", data.take(slice(lo2, hi2)), ("q", "tau")),
                     smoothing=SavGol(5, 2))
    np.testing.assert_allclose(both.qd[lo2:hi2], alone.qd, rtol=1e-12, atol=1e-12)
    assert "window=5" in both.meta["derivative_filter"]


def test_nonuniform_sampling_is_warned_about(tmp_path: Path) -> None:
    t = np.cumsum(np.r_[0.0, np.full(9, 0.02), np.full(10, 0.04)])
    path = tmp_path / "log.csv"
    path.write_text("t,q1,tau1\n" + "".join(f"{float(x)!r},{float(np.sin(x))!r},0.5\n" for x in t))
    with pytest.warns(UserWarning, match=r"log.csv: sample periods vary .*longest 0.04 s.*actual sample times.*"
                                          r"start a new segment"):
        read_log(path)
    with pytest.warns(UserWarning, match=r"causal.* takes every period for the median one"):  # not fitted at the times
        read_log(path, smoothing=SavGol(7, 2, causal=True))
    # two segments, each uniform at its own rate: no warning (the periods were pooled across segments)
    path.write_text("t,segment,q1,tau1\n" + "".join(f"{float(x)!r},{int(x > 0.19)},{float(np.sin(x))!r},0.5\n"
                                                     for x in t))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_log(path)


def test_a_time_column_in_milliseconds_is_warned_about_where_derivatives_are_computed(tmp_path: Path) -> None:
    """A 100 Hz log with t in ms (median period 10 "s") gets a warning naming the period; the same log in seconds,
    and the ms log with velocity columns (nothing computed from t), do not."""
    import warnings

    t_s = np.arange(50) * 0.01
    rows = [(float(x), float(np.sin(x)), float(np.cos(x)), 0.5) for x in t_s]
    ms, sec, ms_qd = tmp_path / "ms.csv", tmp_path / "s.csv", tmp_path / "ms_qd.csv"
    ms.write_text("t,q1,tau1\n" + "".join(f"{1000 * x!r},{q!r},{tau!r}\n" for x, q, _, tau in rows))
    sec.write_text("t,q1,tau1\n" + "".join(f"{x!r},{q!r},{tau!r}\n" for x, q, _, tau in rows))
    ms_qd.write_text("t,q1,qd1,qdd1,tau1\n" + "".join(f"{1000 * x!r},{q!r},{qd!r},0,{tau!r}\n"
                                                       for x, q, qd, tau in rows))
    with pytest.warns(UserWarning, match=r"ms.csv: the median sample period is 10 s \(0.1 Hz\); is column 't' in "
                                         "seconds"):
        read_log(ms)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_log(sec)
        read_log(ms_qd)


# --------------------------------------------------------------------------- errors
HEAD = "t,q1,q2,tau1,tau2"
CASES = {
    "missing column": ("t,q1,q2,tau1\n0,1,2,3\n", 1, "tau2", "missing tau2"),
    "missing t": ("q1,tau1\n1,2\n", 1, "t", "missing required column"),
    "missing q": ("t,tau1\n0,2\n", 1, "q1", "missing required column"),
    "unknown column": (HEAD + ",qd_1\n0,1,2,3,4,5\n", 1, "qd_1", "unknown column"),
    "duplicate column": ("t,q1,q1,tau1\n0,1,1,2\n", 1, "q1", "appears twice"),
    "N mismatch": (HEAD + ",tau3\n0,1,2,3,4,5\n", 1, "tau3", "N = 2"),
    "q column missing": ("t,q1,tau1,tau2,tau3\n0,1,2,3,4\n", 1, "tau2",
                         "unexpected tau2, tau3 (or is q2..q3 missing?)"),
    "partial group": (HEAD + ",qd2\n0,1,2,3,4,5\n", 1, "qd1", "missing qd1"),
    "ragged row (short)": (HEAD + "\n0,1,2,3,4\n0.1,1,2\n", 3, "tau1", "the row has 3 cells, the header 5"),
    "ragged row (long)": (HEAD + "\n0,1,2,3,4,5\n", 2, "tau2", "1 extra cell"),
    "non-numeric cell": (HEAD + "\n0,1,2,3,4\n0.1,1,two,3,4\n", 3, "q2", "got 'two'"),
    "empty cell": (HEAD + "\n0,1,,3,4\n", 2, "q2", "got ''"),
    # a row of empty cells (what pandas writes for a row of NaN) was skipped as a blank line
    "row of empty cells": (HEAD + "\n0,1,2,3,4\n,,,,\n0.2,1,2,3,4\n", 3, "t", "got ''"),
    # float() takes these; a log's cells are ASCII decimal numbers
    "underscore in a number": (HEAD + "\n0,1_000,2,3,4\n", 2, "q1", "got '1_000'"),
    "digits of another script": (HEAD + "\n0,1,\u0661\u0662,3,4\n", 2, "q2", "got '\u0661\u0662'"),
    "non-breaking space": (HEAD + "\n0,1,2,\u00a03,4\n", 2, "tau1", "got '\\xa03' (characters that are not ASCII)"),
    "quoted decimal comma": (HEAD + '\n0,1,"2,5",3,4\n', 2, "q2", "got '2,5' (a decimal comma? a log's decimal "
                                                                     "separator is '.', with no thousands separator)"),
    "separator line not a comma": ("sep=;\nt;q1;tau1\n0;1;2\n", 1, None, "a spreadsheet's separator line, 'sep=;'"),
    "separator line alone": ("sep=,\n", 2, None, "expected a header row after the separator line"),
    "NaN cell": (HEAD + "\n0,1,2,3,4\n0.1,1,2,nan,4\n", 3, "tau1", "got 'nan'"),
    "inf cell": (HEAD + "\n0,1,2,3,4\n0.1,1,2,3,-inf\n", 3, "tau2", "got '-inf'"),
    "t repeats": (HEAD + "\n0,1,2,3,4\n0.1,1,2,3,4\n0.1,1,2,3,4\n", 4, "t", "strictly increasing"),
    "t goes back": (HEAD + "\n0,1,2,3,4\n0.2,1,2,3,4\n\n0.1,1,2,3,4\n", 5, "t", "does not come after t = 0.2 (row 3)"),
    "segment not integer": ("t,segment,q1,tau1\n0,0.5,1,2\n", 2, "segment", "integer"),
    "segment goes back": ("t,segment,q1,tau1\n0,1,1,2\n0.1,0,1,2\n", 3, "segment", "non-decreasing"),
    "wrapped angle": (HEAD + "\n0,3.1,2,3,4\n\n0.1,-3.1,2,3,4\n0.2,-3.1,2,3,4\n", 4, "q1",
                      "changes by -6.2 from row 2, more than pi"),
    "empty file": ("", 1, None, "empty file"),
    "blank file": ("\n\n", 1, None, "empty file"),
    "no data rows": (HEAD + "\n", 2, None, "no data rows"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_errors_name_file_row_and_column(tmp_path: Path, case: str) -> None:
    text, row, column, what = CASES[case]
    path = tmp_path / "my log.csv"
    path.write_text(text)
    with pytest.raises(LogFormatError) as err:
        read_log(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}: row {row}"), msg
    assert column is None or f"column '{column}'" in msg, msg
    assert what in msg, msg
    assert isinstance(err.value, ValueError)


def test_a_spreadsheets_separator_line_sep_comma_is_skipped(tmp_path: Path) -> None:
    """Excel writes 'sep=,' before the header of a CSV it saves; it was an unknown column 'sep='."""
    body = HEAD + "\n0,1,2,3,4\n0.1,1.1,2,3,4\n0.2,1.2,2,3,4\n"
    plain, excel = tmp_path / "plain.csv", tmp_path / "excel.csv"
    plain.write_text(body)
    excel.write_text("sep=,\n" + body)
    a, b = read_log(plain), read_log(excel)
    for name in ("t", "q", "qd", "qdd", "tau"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    for line in ("SEP=,", '"sep=,"'):  # any case, quoted or not
        excel.write_text(line + "\n" + body)
        np.testing.assert_array_equal(read_log(excel).q, a.q)
    excel.write_text("sep=,\n" + HEAD + "\n0,1,2,3,x\n")
    with pytest.raises(LogFormatError, match=r"row 3, column 'tau2'"):  # rows are still the file's lines
        read_log(excel)


def test_a_jump_across_segments_or_unwrapped_is_accepted(tmp_path: Path) -> None:
    """The wrap check is per segment, only for logs whose velocities are computed, and an unwrapped continuous
    angle passes it."""
    path = tmp_path / "log.csv"
    rows = [f"{r / 10},{r // 3},{3.1 if r < 3 else -3.1},1\n" for r in range(6)]  # segments of 3 rows, +-3.1 rad
    path.write_text("t,segment,q1,tau1\n" + "".join(rows))
    assert read_log(path).n_samples == 6
    path.write_text("t,q1,qd1,qdd1,tau1\n0,3.1,0,0,1\n0.1,-3.1,0,0,1\n")  # independent samples
    assert read_log(path).n_samples == 2
    t = np.arange(0.0, 2.0, 0.01)
    angle = np.unwrap(np.angle(np.exp(1j * 8.0 * t)))  # 16 rad in 2 s, past +pi several times
    np.savetxt(path, np.column_stack([t, angle, np.zeros_like(t)]), delimiter=",", header="t,q1,tau1", comments="")
    np.testing.assert_allclose(read_log(path).qd[5:-5, 0], 8.0, rtol=1e-6)
    wrapped = np.angle(np.exp(1j * angle))
    np.savetxt(path, np.column_stack([t, wrapped, np.zeros_like(t)]), delimiter=",", header="t,q1,tau1", comments="")
    with pytest.raises(LogFormatError, match="a wrapped angle of a continuous joint"):
        read_log(path)


def test_a_segment_too_short_to_differentiate_is_refused(tmp_path: Path) -> None:
    """qd and qdd from q need 3 rows per segment, qdd from qd 2: a shorter segment is named (it had velocity 0,
    or acceleration 0); with every derivative given, any length reads."""
    path = tmp_path / "log.csv"
    rows = "0,0,1.0,2\n0.1,0,1.2,2\n0.2,0,1.4,2\n0.3,1,1.0,2\n0.4,1,1.1,2\n"
    path.write_text("t,segment,q1,tau1\n" + rows)
    with pytest.raises(LogFormatError, match=r"log.csv: row 5: segment 1 has 2 rows; computing qd and qdd from q "
                                             r"needs at least 3 rows per segment.*give the qd1..qdN and qdd1..qddN "
                                             r"columns"):
        read_log(path)
    path.write_text("t,segment,q1,qd1,tau1\n" + rows.replace(",2\n", ",0.5,2\n"))
    assert read_log(path).n_samples == 5  # qdd from qd: 2 rows are enough
    path.write_text("t,segment,q1,qdd1,tau1\n" + rows.replace(",2\n", ",0.5,2\n"))
    np.testing.assert_allclose(read_log(path, smoothing=None).qd[3:, 0], 1.0)  # qd from q: 2 rows too
    path.write_text("t,segment,q1,qdd1,tau1\n0,0,1,0.5,2\n0.1,0,1,0.5,2\n0.2,1,1,0.5,2\n")
    with pytest.raises(LogFormatError, match="row 4: segment 1 has 1 row; computing qd from q needs at least 2"):
        read_log(path)
    path.write_text("t,segment,q1,qd1,tau1\n0,0,1,0.5,2\n0.1,1,1,0.5,2\n0.2,1,1,0.5,2\n")
    with pytest.raises(LogFormatError, match="row 2: segment 0 has 1 row; computing qdd from qd needs at least 2"):
        read_log(path)
    path.write_text("t,q1,tau1\n0,1.0,2\n")
    with pytest.raises(LogFormatError, match="log.csv: the log has 1 row; computing qd and qdd"):
        read_log(path, require_tau=False)
    path.write_text("t,q1,qd1,qdd1\n0,1.0,0.5,0.1\n")
    assert read_log(path, require_tau=False).n_samples == 1


def test_segments_reset_time(tmp_path: Path) -> None:
    path = tmp_path / "log.csv"
    path.write_text("t,segment,q1,tau1\n0,0,1,2\n0.1,0,1,2\n0.2,0,1,2\n0,1,1,2\n0.1,1,1,2\n0.2,1,1,2\n")
    assert read_log(path, smoothing=None).segments.tolist() == [0, 1]


def test_other_failures(tmp_path: Path, data: DynamicsData) -> None:
    with pytest.raises(FileNotFoundError, match=re.escape(str(tmp_path / "none.csv"))):
        read_log(tmp_path / "none.csv")
    with pytest.raises(LogFormatError, match="not a file"):
        read_log(tmp_path)
    (tmp_path / "bin.csv").write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(LogFormatError, match=r"bin\.csv: not a UTF-8 text file") as exc:
        read_log(tmp_path / "bin.csv")
    assert "load_ias" not in str(exc.value)
    (tmp_path / "sarcos.mat").write_bytes(b"MATLAB 5.0 MAT-file\xff\xfe\x00")
    with pytest.raises(LogFormatError, match=r"sarcos\.mat: not a UTF-8 text file.*cascgp\.load_ias\(path\)"):
        read_log(tmp_path / "sarcos.mat")
    for sep in (";", "\t"):
        (tmp_path / "semi.csv").write_text(sep.join(["t", "q1", "tau1"]) + "\n" + sep.join("012") + "\n")
        with pytest.raises(LogFormatError, match=f"unknown column.*separated by {re.escape(repr(sep))}, and a "
                                                 "log's by commas"):
            read_log(tmp_path / "semi.csv")
    with pytest.raises(TypeError, match="smoothing"):
        read_log(tmp_path / "none.csv", smoothing="savgol")
    with pytest.raises(TypeError, match="data"):
        write_log(tmp_path / "x.csv", {"q": data.q})
    assert not (tmp_path / "x.csv").exists()


def test_csv_errors_of_the_csv_module_name_the_file_and_row(tmp_path: Path) -> None:
    """A cell longer than the csv module's field limit, and a quote that is not closed (which runs over every line
    after it), are LogFormatErrors naming the row where they start."""
    long = tmp_path / "long.csv"
    long.write_text("t,q1,tau1\n0,1,2\n0.1," + "1" * 200_000 + ",2\n0.2,1,2\n")
    with pytest.raises(LogFormatError, match=r"long\.csv: row 3: not a row of numbers \(field larger than field limit"):
        read_log(long)
    quote = tmp_path / "quote.csv"
    quote.write_text('t,q1,tau1\n0,1,2\n"0.1,1,2\n0.2,1,2\n0.3,1,2\n')
    with pytest.raises(LogFormatError, match=r'quote\.csv: row 3: a quote \(\"\) opened in this row is not closed'):
        read_log(quote)


def test_time_steps_too_small_and_segment_ids_too_large_are_named(tmp_path: Path) -> None:
    tiny = tmp_path / "tiny.csv"
    tiny.write_text("t,q1,tau1\n0,0.1,1\n5e-324,0.2,1\n1e-323,0.3,1\n1.5e-323,0.35,1\n")
    with pytest.raises(LogFormatError, match=r"tiny\.csv: computing the velocities qd from q overflows \(time steps "
                                             r"as small as 4.94e-324 s in column 't', values up to 0.35\)"):
        read_log(tiny)
    seg = tmp_path / "seg.csv"
    seg.write_text("t,segment,q1,tau1\n0,1e19,0.1,1\n0.1,1e19,0.2,1\n0.2,1e19,0.3,1\n")
    with pytest.raises(LogFormatError, match=r"seg\.csv: row 2, column 'segment': expected an integer id \(of at "
                                             r"most 2\^53 in magnitude\), got 1e\+19"):
        read_log(seg)
