"""Every command checks where it will write before it runs: a file output that is a folder, a folder output that is
a file, a path through a file are refused with exit status 2 and one line naming the option, before the command
reads its inputs or fits anything (a fit can take minutes). The library's atomic writes name the path too."""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest
from tests.conftest import write_tiny_ias

from cascgp.io import atomic_write_text


@pytest.fixture()
def places(tmp_path: Path) -> dict[str, Path]:
    (tmp_path / "folder").mkdir()
    (tmp_path / "file.txt").write_text("x")
    return {"folder": tmp_path / "folder", "file": tmp_path / "file.txt", "missing": tmp_path / "missing.csv"}


def _refused(module: str, argv: list[str], capsys) -> str:
    cli = importlib.import_module(f"cascgp_experiments.cli.{module}")
    main = getattr(cli, argv.pop(0) if module == "model_commands" else "main")
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and ": error: " in err.splitlines()[-1]  # argparse's usage, then one error line
    return err.splitlines()[-1]


def test_file_outputs_are_checked_before_the_inputs_are_read(places: dict[str, Path], capsys) -> None:
    """The log and the model named here do not exist: the error is about the output, so it came first."""
    folder, file, missing = places["folder"], places["file"], places["missing"]
    fit = ["fit_main", "--data", str(missing), "--model", "np-standard"]
    cases = [
        (fit + ["--out", str(folder)], f"--out: {folder} is a folder; expected the path of a file"),
        (fit + ["--out", str(file / "m.npz")], f"--out: {file} is a file, so {file / 'm.npz'} cannot be created"),
        (fit + ["--out", str(folder / "m.csv")], "--out: expected a model file name ending in .npz"),
        (["predict_main", "--model", str(missing), "--data", str(missing), "--out", str(folder)],
         f"--out: {folder} is a folder"),
        (["evaluate_main", "--model", str(missing), "--data", str(missing), "--json", str(file / "a" / "s.json")],
         f"--json: {file} is a file, so {file / 'a' / 's.json'} cannot be created"),
    ]
    for argv, expected in cases:
        assert expected in _refused("model_commands", list(argv), capsys), argv
    assert sorted(p.name for p in folder.parent.iterdir()) == ["file.txt", "folder"]  # nothing written


def test_an_output_that_is_an_input_is_refused(places: dict[str, Path], capsys) -> None:
    """Writing an output over one of the command's inputs (the same file by another spelling or a link too) would
    destroy the input: refused before anything is read or written."""
    folder = places["folder"]
    log, model = folder / "log.npz", folder / "model.npz"
    log.write_bytes(b"log")
    model.write_bytes(b"model")
    (folder / "link.npz").symlink_to(log)
    other = str(folder / ".." / "folder" / "log.npz")
    cases = [
        (["fit_main", "--data", str(log), "--model", "np-standard", "--out", other], "--out", "--data"),
        (["fit_main", "--data", str(folder / "link.npz"), "--model", "np-standard", "--out", str(log)], "--out",
         "--data"),
        (["evaluate_main", "--model", str(model), "--data", str(log), "--json", str(model)], "--json", "--model"),
        (["evaluate_main", "--model", str(model), "--data", str(log), "--json", str(log)], "--json", "--data"),
        (["predict_main", "--model", str(model), "--data", str(log), "--out", str(model)], "--out", "--model"),
        (["predict_main", "--model", str(model), "--data", str(log), "--out", str(log)], "--out", "--data"),
        (["fit_main", "--data", str(log), "--model", "sp-standard", "--urdf", str(model), "--out", str(model)],
         "--out", "--urdf"),
    ]
    for argv, option, other_option in cases:
        err = _refused("model_commands", list(argv), capsys)
        assert f"{option}: " in err and f"is also {other_option}; writing it would replace that input" in err, argv
    assert log.read_bytes() == b"log" and model.read_bytes() == b"model"


@pytest.mark.parametrize("module,extra", [("transfer", ["--quick"]), ("study", ["--smoke", "--no-sarcos"]),
                                          ("sarcos", ["--quick"]), ("collect", ["--smoke"])])
def test_folder_outputs_are_checked_before_anything_runs(module: str, extra: list[str], places: dict[str, Path],
                                                         capsys, monkeypatch) -> None:
    file = places["file"]
    if module == "sarcos":  # its file check comes first; give it a valid one
        extra = ["--quick", "--sarcos", str(write_tiny_ias(places["folder"] / "ias.mat"))]
    err = _refused(module, [*extra, "--out", str(file)], capsys)
    assert f"--out: {file} is a file; expected a folder (created if missing)" in err
    err = _refused(module, [*extra, "--out", str(file / "sub")], capsys)
    assert f"--out: {file} is a file, so {file / 'sub'} cannot be created" in err
    if module == "transfer":
        err = _refused(module, [*extra, "--out", str(places["folder"] / "o"), "--video", str(file)], capsys)
        assert f"--video: {file} is a file; expected a folder (created if missing)" in err
    assert file.read_text() == "x"


def test_a_dangling_link_or_a_path_that_cannot_be_looked_at_is_a_message(places: dict[str, Path],
                                                                         monkeypatch) -> None:
    from cascgp_experiments.cli.options import output_path_problem

    link = places["folder"] / "out"
    link.symlink_to(places["folder"] / "gone")
    gone = places["folder"] / "gone"
    assert output_path_problem(link, "folder") == f"{link} is a link to {gone}, which does not exist"

    def denied(self: Path) -> bool:
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(Path, "is_symlink", denied)  # as Path.exists does under a folder without search permission
    assert output_path_problem(places["folder"] / "x.npz", "file") == f"{places['folder'] / 'x.npz'}: Permission denied"


def test_atomic_write_names_a_folder_or_a_file_in_the_way(places: dict[str, Path]) -> None:
    folder, file = places["folder"], places["file"]
    with pytest.raises(IsADirectoryError, match=f"{folder}: is a folder; expected the path of a file"):
        atomic_write_text(folder, "y")
    with pytest.raises(NotADirectoryError, match=f"cannot create its folder .*: {file} is a file"):
        atomic_write_text(file / "a" / "b.txt", "y")
    assert list(folder.iterdir()) == [] and file.read_text() == "x"  # no temporary left, nothing replaced


def test_atomic_write_in_a_folder_it_cannot_write_names_the_path(places: dict[str, Path], monkeypatch) -> None:
    """A read-only folder (a read-only mount: root is refused too) is reported with the path asked for, not the
    temporary file's name."""
    import errno
    import tempfile

    def read_only(*args, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system", str(places["folder"] / ".m.npz.host-1.abc.tmp"))

    monkeypatch.setattr(tempfile, "mkstemp", read_only)
    target = places["folder"] / "m.npz"
    with pytest.raises(OSError, match=f"{target}: cannot write in its folder {places['folder']} "
                                      r"\(Read-only file system\)$") as err:
        atomic_write_text(target, "y")
    assert err.value.errno == errno.EROFS and ".tmp" not in str(err.value)


def test_a_data_buffer_on_a_file_names_it(places: dict[str, Path]) -> None:
    from cascgp import DataBuffer

    file = places["file"]
    for folder in (file, file / "episodes"):
        with pytest.raises(NotADirectoryError, match=f"folder: cannot keep the buffer's episodes in {folder}: {file} "
                                                     "is a file"):
            DataBuffer(folder)
    assert file.read_text() == "x"



def _experiment_folder(out: Path, kind: str) -> None:
    """A finished run's result file of ``kind`` in ``out`` (only what the commands look at)."""
    import json

    out.mkdir()
    layout = {"transfer": ("results.json", {"config": {}, "controllers": {}}),
              "study": ("results.json", {"meta": {}, "jaco": {}}), "sarcos": ("sarcos.json", {"models": {}})}
    name, content = layout[kind]
    (out / name).write_text(json.dumps(content))


@pytest.mark.parametrize("command, argv, other", [
    ("study", ["--smoke", "--no-sarcos"], "transfer"),
    ("study", ["--smoke", "--no-sarcos"], "sarcos"),
    ("transfer", ["--quick"], "study"),
    ("sarcos", ["--quick", "--sarcos", "x.mat"], "study"),
    ("sarcos", ["--quick", "--sarcos", "x.mat"], "transfer"),
])
def test_an_experiment_refuses_a_folder_of_another_experiment(command: str, argv: list[str], other: str,
                                                               tmp_path: Path, monkeypatch, capsys) -> None:
    """A study run into a transfer's --out replaced its results.json (and the reverse): refused, folder untouched."""
    monkeypatch.chdir(tmp_path)
    write_tiny_ias(tmp_path / "x.mat")
    out = tmp_path / "out"
    _experiment_folder(out, other)
    before = {p: p.read_bytes() for p in out.rglob("*")}
    msg = _refused(command, ["--out", str(out), *argv], capsys)
    assert f"--out: {out} holds a 'cascgp {other}' run" in msg and "choose another --out folder" in msg
    assert {p: p.read_bytes() for p in out.rglob("*")} == before


def test_a_study_refuses_a_collection_of_other_settings_unless_told_to_overwrite(tmp_path: Path, monkeypatch,
                                                                                  capsys) -> None:
    """The study replaced its folder's collection of other settings without a word (its earlier results stayed
    beside the new data until the run ended); now it refuses, as cascgp collect does, unless --overwrite."""
    from dataclasses import asdict, replace

    from tests.conftest import make_arm, sinusoid_data

    from cascgp_experiments import collect as col
    from cascgp_experiments.cli import study as cli
    from cascgp_experiments.study import PRESETS, collection_config

    out = tmp_path / "out"
    data = sinusoid_data(make_arm(2), 1.0, 10.0, seed=0)
    data.meta["collection"] = asdict(replace(collection_config(PRESETS["smoke"]), seed=7))
    data.save(col.data_path(out / "data", "train"))
    before = col.data_path(out / "data", "train").read_bytes()
    msg = _refused("study", ["--out", str(out), "--smoke", "--no-sarcos"], capsys)
    assert f"--out: {col.data_path(out / 'data', 'train')} holds a collection with other settings (seed 7 (now " \
           "0)); pass --overwrite" in msg
    assert col.data_path(out / "data", "train").read_bytes() == before
    seen: dict = {}

    def fake_run_study(*args, **kw):
        seen["ran"] = True
        return {"meta": {"timings": {}}}

    monkeypatch.setattr(cli, "run_study", fake_run_study)
    monkeypatch.setattr(cli, "limit_threads", lambda n=1: None)
    cli.main(["--out", str(out), "--smoke", "--no-sarcos", "--overwrite", "--workers", "1"])
    assert seen == {"ran": True}
    cli.main(["--out", str(out), "--smoke", "--no-sarcos", "--seed", "7", "--workers", "1"])  # its own settings
    # a file without its settings, or one that cannot be read, is refused too (collect raised mid-run on the latter)
    del data.meta["collection"]
    data.save(col.data_path(out / "data", "train"))
    assert "holds a collection with other settings (settings not recorded)" in \
        _refused("study", ["--out", str(out), "--smoke", "--no-sarcos"], capsys)
    col.data_path(out / "data", "train").write_bytes(b"PK\x03\x04 not a whole archive")
    assert "jaco_train.npz cannot be read" in _refused("study", ["--out", str(out), "--smoke", "--no-sarcos"], capsys)
    seen.clear()
    cli.main(["--out", str(out), "--smoke", "--no-sarcos", "--overwrite", "--workers", "1"])
    assert seen == {"ran": True}


@pytest.mark.parametrize("command, argv, left, shown, other", [
    ("transfer", ["--quick"], "data/jaco_train.npz", "data/jaco_train.npz", "study"),  # stopped while collecting
    ("transfer", ["--quick"], "cache/sarcos/x.json", "cache/sarcos", "sarcos"),  # stopped before its sarcos.json
    ("study", ["--smoke", "--no-sarcos"], "buffers/pd/x.npz", "buffers", "transfer"),  # a transfer stopped mid-run
])
def test_a_stopped_run_of_another_experiment_is_seen_too(command: str, argv: list[str], left: str, shown: str,
                                                          other: str, tmp_path: Path, capsys) -> None:
    out = tmp_path / "out"
    (out / left).parent.mkdir(parents=True)
    (out / left).write_bytes(b"x")
    assert f"holds a 'cascgp {other}' run ({out / shown})" in _refused(command, ["--out", str(out), *argv], capsys)
