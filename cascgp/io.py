"""File helpers shared by every cascgp format and by the experiment scripts.

One way to write a file: :func:`atomic_write` (temporary file in the destination folder,
flushed and fsync'ed, then :func:`os.replace`), so a reader never sees a half-written file
and a killed writer leaves the old file intact. :func:`atomic_savez` and :func:`write_json`
build on it; :func:`read_npz` and :func:`check_format_header` read and check the ``.npz``
formats (no pickle anywhere).
"""

from __future__ import annotations

import json
import math
import os
import tempfile
import zipfile
from pathlib import Path
from typing import IO, Any, Callable

import numpy as np

__all__ = ["atomic_write", "atomic_write_text", "atomic_savez", "write_json", "read_json", "json_safe",
           "read_npz", "check_format_header"]


def atomic_write(path: str | os.PathLike, write: Callable[[IO[bytes]], None]) -> Path:
    """Create ``path`` atomically: ``write(fh)`` fills a temporary binary file in the same
    folder, which is fsync'ed and moved over ``path``. On any error the temporary file is
    removed and ``path`` is left as it was. Returns ``path``."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    folder.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder)
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    return path


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically (see :func:`atomic_write`)."""
    return atomic_write(path, lambda f: f.write(text.encode("utf-8")))


def atomic_savez(path: str | os.PathLike, arrays: dict[str, np.ndarray]) -> Path:
    """Write ``arrays`` to ``path`` (``.npz``) atomically. ``numpy.savez`` would append
    ``.npz`` to a name without it; the path is kept exactly as given."""
    return atomic_write(path, lambda f: np.savez(f, **arrays))


def json_safe(x: Any) -> Any:
    """JSON-safe copy: numpy arrays to lists, numpy scalars to Python, non-finite floats to None."""
    if isinstance(x, dict):
        return {str(k): json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_safe(v) for v in x]
    if isinstance(x, np.ndarray):
        return json_safe(x.tolist())
    if isinstance(x, (np.floating, float)):
        f = float(x)
        return f if math.isfinite(f) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def write_json(path: str | os.PathLike, obj: Any, indent: int = 1) -> Path:
    """Write ``obj`` as indented JSON atomically (numpy values converted, NaN/inf as null)."""
    return atomic_write_text(path, json.dumps(json_safe(obj), indent=indent) + "\n")


def read_json(path: str | os.PathLike) -> Any:
    """Read a JSON file."""
    with open(path, encoding="utf-8") as f:
        return json.load(f)


def read_npz(path: str | os.PathLike, what: str) -> dict[str, np.ndarray]:
    """Read every array of an ``.npz`` file eagerly (no pickle).

    Raises ``FileNotFoundError`` for a missing file and ``ValueError`` naming ``path`` and
    ``what`` for anything unreadable (truncated or corrupt archive, bad CRC, pickled data).
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{what} file not found: {path}")
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: np.asarray(z[k]) for k in z.files}
    except (zipfile.BadZipFile, ValueError, OSError, EOFError, KeyError) as exc:
        raise ValueError(
            f"{path}: not a readable {what} .npz file (corrupt or truncated?): "
            f"{type(exc).__name__}: {exc}") from exc


def check_format_header(z: dict[str, np.ndarray], path: str | os.PathLike, kind: str, version: int) -> None:
    """Raise ``ValueError`` naming the file and field unless ``z`` holds ``format_kind == kind``
    and ``format_version == version`` (shared by every cascgp file format)."""
    got_kind = str(z["format_kind"]) if "format_kind" in z else None
    if got_kind != kind:
        raise ValueError(f"{path}: format_kind: expected {kind!r}, got {got_kind!r}")
    got_version = int(z["format_version"]) if "format_version" in z else None
    if got_version != version:
        raise ValueError(f"{path}: format_version: expected {version}, got {got_version}")
