"""cascgp fit / evaluate refuse input that would give a wrong or meaningless result, with a message naming the
option, file or column, exit status 2 and no traceback; a fit too big for its memory says what fits, and a long fit
says that it is still running."""

from __future__ import annotations

from pathlib import Path

import pytest

from cascgp.data import DynamicsData
from cascgp.gp import GPFitConfig
from cascgp.logs import write_log
from cascgp.models import make_model
from cascgp_experiments.cli.model_commands import evaluate_main, fit_main
from tests.conftest import make_arm, sinusoid_data


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("bad_input")
    train = sinusoid_data(make_arm(2), 4.0, 50.0, seed=1, noise=0.01)
    write_log(root / "train.csv", train)
    make_model("np-standard", 2, gp_config=GPFitConfig(n_restarts=1, max_iter=50)).fit(train.thin(60)).save(
        root / "model.npz")
    return {"root": root, "train": root / "train.csv", "model": root / "model.npz"}


def _refused(main, argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    status = main(argv)
    err = capsys.readouterr().err
    assert status == 2 and "Traceback" not in err, err
    return err.strip().splitlines()[-1]


def test_evaluate_refuses_torques_whose_nrmse_overflows(files: dict[str, Path], capsys) -> None:
    test = sinusoid_data(make_arm(2), 2.0, 50.0, seed=2)
    tau = test.tau.copy()
    tau[5, 1] = 1e308  # finite, but its square is not
    write_log(files["root"] / "huge.csv", DynamicsData(q=test.q, qd=test.qd, qdd=test.qdd, tau=tau, t=test.t))
    out = files["root"] / "scores.json"
    err = _refused(evaluate_main, ["--model", str(files["model"]), "--data", str(files["root"] / "huge.csv"),
                                   "--json", str(out)], capsys)
    assert "huge.csv: column 'tau2': the nRMSE of np-standard overflows (torques up to 1e+308" in err
    assert not out.exists()


def test_fit_names_a_rate_that_keeps_too_few_rows_and_a_urdf_folder(files: dict[str, Path], capsys) -> None:
    err = _refused(fit_main, ["--data", str(files["train"]), "--model", "np-standard", "--rate-hz", "0.01",
                              "--out", str(files["root"] / "m.npz")], capsys)
    assert "--rate-hz 0.01 keeps 1 of 200 rows (the log's rate: about 50 Hz); a fit needs at least 2" in err, err
    err = _refused(fit_main, ["--data", str(files["train"]), "--model", "sp-standard", "--urdf", str(files["root"]),
                              "--out", str(files["root"] / "m.npz")], capsys)
    assert f"URDF {str(files['root'])!r}: not a file (a folder?)" in err, err
    assert not (files["root"] / "m.npz").exists()


def test_fit_accepts_a_model_file_name_in_capitals(files: dict[str, Path], capsys) -> None:
    out = files["root"] / "MODEL.NPZ"
    assert fit_main(["--data", str(files["train"]), "--model", "np-standard", "--restarts", "1",
                     "--max-samples", "40", "--out", str(out)]) == 0
    assert out.is_file() and not (files["root"] / "MODEL.NPZ.npz").exists()


def test_fit_names_a_torque_column_too_large_to_normalise(files: dict[str, Path], capsys) -> None:
    log = sinusoid_data(make_arm(2), 2.0, 50.0, seed=3)
    tau = log.tau * [1.0, 1e300]
    write_log(files["root"] / "big.csv", DynamicsData(q=log.q, qd=log.qd, qdd=log.qdd, tau=tau, t=log.t))
    err = _refused(fit_main, ["--data", str(files["root"] / "big.csv"), "--model", "np-standard", "--restarts", "1",
                              "--out", str(files["root"] / "big.npz")], capsys)
    assert "big.csv: column 'tau2': values too large to normalise: largest magnitude" in err, err


def test_fit_too_big_for_its_memory_says_how_many_rows_fit(files: dict[str, Path], capsys) -> None:
    """A fit over the memory limit was refused in the library's terms ('raise GPFitConfig.max_batch_bytes', which
    the command could not set): it now names --max-samples, the rows that fit and --max-memory, which sets the
    limit; a fit within the raised limit runs."""
    from cascgp.gp import estimate_fit_bytes

    out = files["root"] / "big.npz"
    limit_gib = 0.13  # 133 MiB: the estimate's 128 MiB of overhead and a few (n, n) matrices
    err = _refused(fit_main, ["--data", str(files["train"]), "--model", "np-standard", "--restarts", "1",
                              "--max-samples", "200", "--max-memory", str(limit_gib), "--out", str(out)], capsys)
    rows = int(err.split("at most ")[1].split(" rows")[0])
    # np-standard on 2 joints: 2 GPs of 6 inputs (q, qd, qdd of both joints), one start
    assert 0 < rows < 200 and estimate_fit_bytes(rows, 6, 2, 1) <= limit_gib * 2**30 < estimate_fit_bytes(
        rows + 1, 6, 2, 1)
    assert err.startswith("cascgp fit: error: --max-samples 200: fitting 200 rows needs about ") and \
        err.endswith(f"over --max-memory {limit_gib:g} GiB; at most {rows} rows fit within it: lower --max-samples "
                     "or raise --max-memory"), err
    assert not out.exists()
    assert fit_main(["--data", str(files["train"]), "--model", "np-standard", "--restarts", "1", "--max-samples",
                     str(rows), "--max-memory", str(limit_gib), "--out", str(out)]) == 0 and out.is_file()
    assert fit_main(["--data", str(files["train"]), "--model", "np-standard", "--restarts", "1", "--max-samples",
                     "40", "--max-memory", "1e300", "--out", str(out)]) == 0  # beyond any machine: no limit but its
    err = _refused(fit_main, ["--data", str(files["train"]), "--model", "np-standard", "--restarts", "1",
                              "--max-memory", "1e-10", "--out", str(out)], capsys)
    assert err.endswith("over --max-memory 1e-10 GiB; not even 2 rows fit within it: raise --max-memory"), err
    for bad in ("0", "-1", "nan"):
        with pytest.raises(SystemExit):
            fit_main(["--data", str(files["train"]), "--model", "np-standard", "--max-memory", bad, "--out",
                      str(out)])
        assert f"--max-memory: expected a positive number of GiB, got {float(bad)}" in capsys.readouterr().err


def test_a_long_fit_says_it_is_still_running(files: dict[str, Path], capsys, monkeypatch) -> None:
    """A fit was silent between 'fitting ...' and 'fitted in' (minutes at n = 4000): it now says every
    STILL_FITTING_EVERY_S seconds that it is still running, and stops saying so when it is done."""
    import time

    import cascgp_experiments.cli.model_commands as commands
    from cascgp.models.cascade import CascadedGPModel

    fit = CascadedGPModel.fit

    def slow_fit(self, *args, **kwargs):
        time.sleep(0.5)
        return fit(self, *args, **kwargs)

    monkeypatch.setattr(CascadedGPModel, "fit", slow_fit)
    monkeypatch.setattr(commands, "STILL_FITTING_EVERY_S", 0.1)
    out = files["root"] / "slow.npz"
    assert fit_main(["--data", str(files["train"]), "--model", "np-standard", "--restarts", "1", "--max-samples",
                     "40", "--out", str(out)]) == 0 and out.is_file()
    err = capsys.readouterr().err
    assert err.count("cascgp fit: still fitting (") >= 2, err
    assert err.index("still fitting") < err.index("fitted in")
    time.sleep(0.3)
    assert "still fitting" not in capsys.readouterr().err  # the notes ended with the fit
