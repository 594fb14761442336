"""The ``cascgp`` dispatcher: Ctrl-C ends a command with one line (and, for the experiments, how to resume), and
``cascgp plots`` redraws the figures and claims of a study's ``results.json`` or of a ``sarcos.json``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import cascgp_experiments.cli as cli

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("command, resumes", [("study", True), ("fit", False)])
def test_ctrl_c_is_one_line_and_names_the_resume(command: str, resumes: bool, monkeypatch, capsys) -> None:
    module, func = cli.COMMANDS[command][0].split(":")

    def interrupted(argv, prog=None):
        raise KeyboardInterrupt

    monkeypatch.setattr(f"{module}.{func}", interrupted)
    assert cli.main([command, "--out", "x"]) == 130
    err = capsys.readouterr().err
    assert err.strip().startswith(f"cascgp {command}: interrupted") and "Traceback" not in err
    assert ("run the same command again to resume" in err) == resumes


def test_a_folder_that_cannot_be_written_during_a_run_is_one_line(monkeypatch, capsys) -> None:
    """A cache folder of --out made read-only ended a study with a PermissionError traceback."""
    module, func = cli.COMMANDS["study"][0].split(":")

    def refused(argv, prog=None):
        raise PermissionError(13, "Permission denied", "out/cache/jaco/x.json")

    monkeypatch.setattr(f"{module}.{func}", refused)
    assert cli.main(["study", "--out", "out"]) == 2
    err = capsys.readouterr().err
    assert err.strip() == "cascgp study: error: [Errno 13] Permission denied: 'out/cache/jaco/x.json'", err


def test_plots_redraws_a_sarcos_json(tmp_path: Path, capsys) -> None:
    """A ``cascgp sarcos`` run's ``sarcos.json`` (here the SARCOS block of the documented study run) gives the
    study's SARCOS figure, CSV and claims, and the files that ``cascgp sarcos`` writes are named as it names them
    (``sarcos_claims.md``, and ``sarcos_table.md``, which was missing)."""
    from cascgp_experiments.cli.sarcos import summary_table

    block = json.loads((REPO / "docs" / "results.json").read_text())["sarcos"]
    (tmp_path / "sarcos.json").write_text(json.dumps(block))
    cli.main(["plots", "--json", str(tmp_path / "sarcos.json"), "--out", str(tmp_path / "out")])
    out = tmp_path / "out"
    assert {p.name for p in out.iterdir()} == {"fig_sarcos.png", "curves_sarcos.csv", "sarcos_claims.md",
                                               "sarcos_table.md"}
    assert (out / "sarcos_table.md").read_text() == summary_table(block) + "\n"
    import csv

    with (out / "curves_sarcos.csv").open() as f:  # the figures' median and quartiles too, not only mean and std
        rows = list(csv.DictReader(f))
    assert len(rows) == len(block["models"]) * len(block["grid_s"]) * 7
    for row in rows[::37]:
        v, g, j = block["models"][row["model"]], block["grid_s"].index(float(row["seconds"])), int(row["joint"]) - 1
        for key in ("nrmse_median", "nrmse_q25", "nrmse_q75", "nrmse_mean"):
            assert float(row[key]) == pytest.approx(v[key][g][j], abs=1e-6)
    claims = (out / "sarcos_claims.md").read_text()
    assert "Outward beats inward on the last joint (7)" in claims and "Simulated Jaco" not in claims
    assert str(out / "fig_sarcos.png") in capsys.readouterr().out


def test_plots_refuses_a_json_of_something_else(tmp_path: Path, capsys) -> None:
    (tmp_path / "other.json").write_text(json.dumps({"config": {}, "controllers": {}}))
    with pytest.raises(SystemExit) as exc:
        cli.main(["plots", "--json", str(tmp_path / "other.json"), "--out", str(tmp_path / "out")])
    assert exc.value.code == 2
    assert "expected a study's results.json or a sarcos.json" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
    run = json.loads((REPO / "docs" / "results.json").read_text())  # a results file that lacks a key
    del run["jaco"]["grid_s"]
    (tmp_path / "cut.json").write_text(json.dumps(run))
    with pytest.raises(SystemExit) as exc:
        cli.main(["plots", "--json", str(tmp_path / "cut.json"), "--out", str(tmp_path / "out")])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "cut.json: not a complete study results file (missing entry 'grid_s')" in err and "Traceback" not in err
    assert not (tmp_path / "out").exists() and not [p for p in tmp_path.iterdir() if p.name.startswith("tmp")]
    del run["iterations"]["models"]  # the Jaco figures are drawn before the iterations': still nothing written
    run["jaco"]["grid_s"] = json.loads((REPO / "docs" / "results.json").read_text())["jaco"]["grid_s"]
    (tmp_path / "cut.json").write_text(json.dumps(run))
    with pytest.raises(SystemExit):
        cli.main(["plots", "--json", str(tmp_path / "cut.json"), "--out", str(tmp_path / "out")])
    assert "missing entry 'models'" in capsys.readouterr().err and not (tmp_path / "out").exists()


@pytest.mark.parametrize("edit", ["grid_str", "grid_short", "median_short", "no_rows"])
def test_plots_refuses_a_results_file_whose_entries_cannot_be_drawn(tmp_path: Path, capsys, edit: str) -> None:
    """A hand-edited entry of another type or length ended in a traceback (ValueError, StopIteration)."""
    run = json.loads((REPO / "docs" / "results.json").read_text())
    if edit == "grid_str":
        run["jaco"]["grid_s"] = "abc"
    elif edit == "grid_short":
        run["jaco"]["grid_s"] = run["jaco"]["grid_s"][:1]
    elif edit == "median_short":
        model = next(iter(run["jaco"]["models"].values()))
        model["nrmse_median"] = model["nrmse_median"][:2]
    else:
        run["paper_table"]["rows"] = {}
    (tmp_path / "edited.json").write_text(json.dumps(run))
    with pytest.raises(SystemExit) as exc:
        cli.main(["plots", "--json", str(tmp_path / "edited.json"), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "edited.json: not a complete study results file" in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_help_of_a_command_and_no_command(capsys) -> None:
    """'cascgp help fit' showed the list of commands, and 'cascgp' alone (an error, exit 2) printed it on stdout."""
    with pytest.raises(SystemExit) as exc:
        cli.main(["help", "fit"])
    assert exc.value.code == 0 and capsys.readouterr().out.startswith("usage: cascgp fit")
    assert cli.main([]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.startswith("usage: cascgp")
