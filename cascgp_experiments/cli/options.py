"""Checks of command-line options shared by the subcommands: one message for one kind of bad value."""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
from typing import Mapping, NoReturn


def require_at_least(parser: argparse.ArgumentParser, args: argparse.Namespace, minimum: int, *names: str) -> None:
    """``parser.error`` (exit status 2) for the first of the integer options ``names`` (``args`` attributes) that is
    set and below ``minimum``: ``--max-samples: expected an integer >= 1, got 0``."""
    for name in names:
        value = getattr(args, name)
        if value is not None and value < minimum:
            parser.error(f"--{name.replace('_', '-')}: expected an integer >= {minimum}, got {value}")


def settings_error(parser: argparse.ArgumentParser, exc: Exception, options: Mapping[str, str]) -> NoReturn:
    """``parser.error`` with the message of a settings class's ``ValueError`` / ``TypeError``, its leading field name
    (``rate_hz: ...``) replaced by the option that set the field (``options``: field -> ``--option``)."""
    msg = str(exc)
    for field, option in options.items():
        if msg.startswith((field + ":", field + " ")):
            msg = option + msg[len(field):]
            break
    parser.error(msg)


def check_sarcos_file(parser: argparse.ArgumentParser, path: str, source: str = "--sarcos") -> None:
    """``parser.error`` unless ``path`` is the IAS SARCOS file (names and shapes of its variables, read without
    the data): a wrong file stops the command before it runs anything, not after the hour of the Jaco part.
    ``source`` names where the path came from (the option, or the environment variable that set its default)."""
    from cascgp.sarcos import check_ias

    if Path(path).is_dir():
        parser.error(f"{source}: {path} is a folder; expected the file ias_sarcos_data.mat")
    try:
        check_ias(path)
    except FileNotFoundError:
        parser.error(f"{source}: file not found: {path}")
    except ValueError as exc:
        parser.error(f"{source}: {exc}")


def check_input(parser: argparse.ArgumentParser, path: str | os.PathLike | None, option: str, kind: str,
                contains: tuple[str, ...] = ()) -> None:
    """``parser.error`` (exit status 2) naming ``option`` unless ``path`` is an existing ``kind`` (``"file"`` or
    ``"folder"``; a folder holding the files named in ``contains``). ``None`` (the option left out) passes."""
    if path is None:
        return
    path = Path(path)
    try:
        if not path.exists():
            parser.error(f"{option}: {kind} not found: {path}")
        if kind == "file" and path.is_dir():
            parser.error(f"{option}: {path} is a folder; expected a file")
        if kind == "folder" and not path.is_dir():
            parser.error(f"{option}: {path} is a file; expected a folder")
        missing = [name for name in contains if not (path / name).is_file()]
    except OSError as exc:  # e.g. a folder on the way that this process may not search
        parser.error(f"{option}: {path}: {exc.strerror or exc}")
    if missing:
        parser.error(f"{option}: {path} has no {' or '.join(missing)}; expected a folder with {', '.join(contains)}")


def output_path_problem(path: str | os.PathLike, kind: str) -> str | None:
    """What stops a command from writing its output ``path`` (``kind``: ``"file"`` or ``"folder"``), checked
    before the command's work (a fit can take minutes): ``None`` when nothing does. Refused: a file path that is
    a folder, a folder path that is a file, a dangling link, a path through a file, a nearest existing folder this
    process cannot write to, and a path it cannot even look at."""
    path = Path(path)
    try:
        if path.is_symlink() and not path.exists():
            return f"{path} is a link to {os.readlink(path)}, which does not exist"
        if kind == "file" and path.is_dir():
            return f"{path} is a folder; expected the path of a file"
        if kind == "folder" and path.exists() and not path.is_dir():
            return f"{path} is a file; expected a folder (created if missing)"
        if kind == "folder" and path.is_dir():
            return None if os.access(path, os.W_OK | os.X_OK) else f"{path} is not writable"
        nearest = next(p for p in path.parents if p.exists())  # the file's folder, or a missing one's first existing
        if not nearest.is_dir():
            return f"{nearest} is a file, so {path} cannot be created"
        if not os.access(nearest, os.W_OK | os.X_OK):
            return f"{nearest} is not writable, so {path} cannot be created"
    except OSError as exc:  # e.g. a folder on the way that this process may not search
        return f"{path}: {exc.strerror or exc}"
    return None


def check_output(parser: argparse.ArgumentParser, path: str | os.PathLike | None, option: str, kind: str,
                 inputs: Mapping[str, str | os.PathLike | None] | None = None) -> None:
    """``parser.error`` (exit status 2) naming ``option`` when :func:`output_path_problem` finds one, or when the
    output is one of the command's ``inputs`` (option -> path): writing it would replace that input."""
    problem = None if path is None else output_path_problem(path, kind)
    if problem:
        parser.error(f"{option}: {problem}")
    for other, src in (inputs or {}).items():
        if path is not None and src is not None and _same_file(Path(path), Path(src)):
            parser.error(f"{option}: {path} is also {other}; writing it would replace that input; choose another "
                         "path")


def _same_file(a: Path, b: Path) -> bool:
    """Whether ``a`` and ``b`` name the same file (through links, ``..`` or another spelling)."""
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
        return a.resolve() == b.resolve()
    except OSError:
        return False


#: What each experiment command leaves in its ``--out`` folder (relative paths), to tell one's folder from another's.
_MARKS = {"study": ("cache/jaco", "cache/iterations.json", "data/jaco_train.npz"),
          "transfer": ("buffers", "cache/transfer"),
          "sarcos": ("sarcos.json", "cache/sarcos", "data/sarcos_train.npz")}


def experiments_in(out: str | os.PathLike) -> dict[str, str]:
    """The experiment commands whose runs ``out`` holds (``"study"``, ``"transfer"``, ``"sarcos"``), each with the
    file or folder that shows it: their marks (:data:`_MARKS`), and ``results.json`` by its layout."""
    out = Path(out)
    found: dict[str, str] = {}
    results = out / "results.json"
    if results.is_file():
        try:
            with results.open() as f:
                top = json.load(f)
        except (OSError, ValueError):
            top = None
        if isinstance(top, dict) and "controllers" in top:
            found["transfer"] = str(results)
        elif isinstance(top, dict) and "meta" in top and ("jaco" in top or "sarcos" in top):
            found["study"] = str(results)
    for kind, marks in _MARKS.items():
        for mark in marks:
            if kind not in found and (out / mark).exists():
                found[kind] = str(out / mark)
    return found


def refuse_other_experiment(parser: argparse.ArgumentParser, out: str | os.PathLike, command: str,
                            allowed: tuple[str, ...] = ()) -> None:
    """``parser.error`` (exit status 2) when ``out`` holds a run of another experiment command than ``command``
    (or those ``allowed`` beside it): its results would be replaced or mixed with this run's."""
    for kind, where in experiments_in(out).items():
        if kind != command and kind not in allowed:
            parser.error(f"--out: {out} holds a 'cascgp {kind}' run ({where}); this run would replace or mix with "
                         "its results: choose another --out folder")

