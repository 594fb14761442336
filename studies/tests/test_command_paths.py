"""The studies' commands refuse an output they cannot write, and calibration a --data folder without the data,
before any work: one error line naming the option, exit status 2, nothing written."""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest

COMMANDS = ["calibration", "lag_diagnosis", "quick_transfer_spread", "sensing_factorial", "gate_eval", "gate_rule",
            "learner_divergence"]


@pytest.mark.parametrize("command", COMMANDS)
def test_an_output_folder_that_is_a_file_is_refused(tmp_path: Path, capsys, command: str) -> None:
    (tmp_path / "file").write_text("x")
    with pytest.raises(SystemExit) as exc:
        importlib.import_module(f"studies.commands.{command}").main(["--out", str(tmp_path / "file")])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "Traceback" not in err
    assert err.strip().splitlines()[-1].endswith(f"error: --out: {tmp_path / 'file'} is a file; expected a folder "
                                                 "(created if missing)")
    assert [p.name for p in tmp_path.iterdir()] == ["file"]


def test_calibration_data_folder_without_the_data_is_refused(tmp_path: Path, capsys) -> None:
    from studies.commands.calibration import main

    with pytest.raises(SystemExit) as exc:
        main(["--out", str(tmp_path / "out"), "--data", str(tmp_path)])
    assert exc.value.code == 2 and "--data: " in capsys.readouterr().err and not (tmp_path / "out").exists()
