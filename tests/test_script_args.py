"""The benchmark and research scripts refuse a bad path up front: one ``error:`` line naming the option, exit status
2, no traceback and nothing written (several used to fail with a traceback, some after minutes of work)."""

from __future__ import annotations

import importlib
import json
from pathlib import Path

import numpy as np
import pytest


@pytest.fixture()
def paths(tmp_path: Path) -> dict[str, Path]:
    (tmp_path / "file").write_text("not a folder\n")
    (tmp_path / "empty").mkdir()
    (tmp_path / "other.json").write_text(json.dumps({"a": 1}))
    return {"missing": tmp_path / "nope" / "x", "file": tmp_path / "file", "empty": tmp_path / "empty",
            "other_json": tmp_path / "other.json", "out": tmp_path / "out", "root": tmp_path}


# (script, arguments with {placeholders} from the fixture, the option named in the error, a phrase of it)
CASES = [
    ("bench_cascgp", "--out {out} --sarcos {missing}", "--sarcos", "file not found"),
    ("bench_cascgp", "--out {out} --jaco {empty}", "--jaco", "has no jaco_train.npz"),
    ("bench_cascgp", "--out {file}", "--out", "is a file"),
    ("bench_fit_threads", "--out {out} --sarcos {file}", "--sarcos", "not a readable MATLAB"),
    ("bench_online", "--out {out} --data {missing}", "--data", "folder not found"),
    ("bench_online", "--out {out} --data {file}", "--data", "is a file; expected a folder"),
    ("correlation", "--data {missing} --out {out}/c.json", "--data", "file not found"),
    ("correlation", "--data {empty} --out {out}/c.json", "--data", "is a folder; expected a file"),
    ("fit_audit", "--out {out} --sarcos {missing} --quick", "--sarcos", "file not found"),
    ("study_plots", "--json {missing} --out {out}", "--json", "file not found"),
    ("study_plots", "--json {file} --out {out}", "--json", "expected a study's results.json"),
    ("study_plots", "--json {other_json} --out {out}", "--json", "no 'jaco' or 'sarcos'"),
    ("bench_env", "--out {file}", "--out", "is a file"),
    ("soak", "--minutes 1 --out {file}", "--out", "is a file"),
    ("residual_breakdown", "--out {file}/sub", "--out", "cannot be created"),
    ("pour_separation", "--out {file}", "--out", "is a file"),
    ("generate_urdf", "--out {empty}", "--out", "is a folder"),
    ("bench_parallel", "--json {empty}", "--json", "is a folder"),
    ("compare_study", "{other_json} {other_json}", "other.json", "no 'jaco' or 'sarcos'"),
    ("compare_transfer", "--json {empty} {other_json} {other_json}", "--json", "is a folder"),
]


@pytest.mark.parametrize("script, args, option, phrase", CASES, ids=[f"{c[0]}-{i}" for i, c in enumerate(CASES)])
def test_bad_path_is_one_error_line(paths, capsys, script, args, option, phrase):
    before = sorted(paths["root"].rglob("*"))
    main = importlib.import_module(f"scripts.{script}").main
    with pytest.raises(SystemExit) as exc:
        main(args.format(**paths).split())
    err = capsys.readouterr().err
    assert exc.value.code == 2
    last = err.strip().splitlines()[-1]
    assert "error:" in last and option in last and phrase in last, err
    assert "Traceback" not in err
    assert sorted(paths["root"].rglob("*")) == before  # nothing written


def _study(grid: int) -> dict:
    scores = np.full((3, grid, 2), 0.2).tolist()
    return {"jaco": {"models": {"np-standard": {"nrmse_all": scores}}}}


def test_compare_study_names_different_grids(tmp_path, capsys):
    from scripts.compare_study import main

    (tmp_path / "a.json").write_text(json.dumps(_study(4)))
    (tmp_path / "b.json").write_text(json.dumps(_study(5)))
    with pytest.raises(SystemExit) as exc:
        main([str(tmp_path / "a.json"), str(tmp_path / "b.json")])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "Traceback" not in err
    assert "cannot be compared" in err and "(3, 4, 2) / (3, 5, 2)" in err and "grid points" in err
    (tmp_path / "c.json").write_text(json.dumps({"jaco": {"no models": 1}}))
    with pytest.raises(SystemExit) as exc:
        main([str(tmp_path / "a.json"), str(tmp_path / "c.json")])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "Traceback" not in err and "one lacks what a study writes (no 'models')" in err
