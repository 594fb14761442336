"""File helpers shared by every cascgp format and by the experiment scripts.

One way to write a file: :func:`atomic_write` (temporary file in the destination folder,
flushed and fsync'ed, then :func:`os.replace`), so a reader never sees a half-written file
and a killed writer leaves the old file intact. :func:`atomic_savez` and :func:`write_json`
build on it; :func:`read_npz` and :func:`check_format_header` read and check the ``.npz``
formats (no pickle anywhere).

Temporary files are named ``.<name>.<host>-<pid>.<random>.tmp`` (``host``: a short hash of the
host name). A writer killed with SIGKILL cannot remove its own; the next write into the same
folder removes those of this host whose process no longer exists
(:func:`remove_stale_temporaries`), so they do not pile up. Files of other hosts (a shared
network folder) are left alone.

Reading is bounded: :func:`read_npz` refuses a file that is not a zip archive (a ``.npy``
array, random bytes) with a message naming the file, and, before decompressing anything, an
archive whose members would inflate beyond ``max_bytes`` (default :data:`MAX_NPZ_BYTES`) or
that looks like a zip bomb: more than :data:`BOMB_MIN_BYTES` decompressed at a ratio above
:data:`BOMB_RATIO` to the file size. cascgp writes ``.npz`` files uncompressed (ratio ~1), so
only a crafted file trips the ratio test.
"""

from __future__ import annotations

import json
import math
import os
import re
import socket
import tempfile
import zipfile
import zlib
from pathlib import Path
from typing import IO, Any, Callable, cast

import numpy as np

__all__ = ["atomic_write", "atomic_write_text", "atomic_savez", "write_json", "read_json", "json_safe",
           "read_npz", "check_format_header", "remove_stale_temporaries", "MAX_NPZ_BYTES", "BOMB_MIN_BYTES",
           "BOMB_RATIO"]

#: Default cap of the decompressed size of an ``.npz`` file read by :func:`read_npz` (bytes).
MAX_NPZ_BYTES = 1 << 30
#: An archive inflating to more than BOMB_MIN_BYTES at more than BOMB_RATIO times its size is refused.
BOMB_MIN_BYTES = 64 << 20
BOMB_RATIO = 100
_ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")  # local file header; empty archive
_TMP = re.compile(r"^\.(?P<name>.+)\.(?P<host>[0-9a-f]{8})-(?P<pid>\d+)\.[^.]+\.tmp$")
_HOST = f"{zlib.crc32(socket.gethostname().encode()):08x}"
_UMASK = os.umask(0o022)  # read the process umask once (os.umask can only read it by setting it) ...
os.umask(_UMASK)  # ... and put it back


def _pid_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    return True


def remove_stale_temporaries(folder: str | os.PathLike[str]) -> list[Path]:
    """Remove the temporary files of :func:`atomic_write` in ``folder`` whose writing process is gone
    (killed before it could clean up). Returns the removed paths."""
    removed: list[Path] = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for e in entries:
        m = _TMP.match(e.name)
        if m and m["host"] == _HOST and e.is_file(follow_symlinks=False) and not _pid_alive(int(m["pid"])):
            try:
                os.unlink(e.path)
                removed.append(Path(e.path))
            except OSError:
                pass
    return removed


def file_in_path(folder: Path) -> Path:
    """The first part of ``folder``'s path that exists and is not a folder (``folder`` itself if none is found):
    what to name when a folder cannot be created."""
    for part in reversed([folder, *folder.parents]):
        if part.exists() and not part.is_dir():
            return part
    return folder


def atomic_write(path: str | os.PathLike, write: Callable[[IO[bytes]], object], *, exclusive: bool = False) -> Path:
    """Create ``path`` atomically: ``write(fh)`` fills a temporary binary file in the same
    folder, which is fsync'ed and moved over ``path``. On any error the temporary file is
    removed and ``path`` is left as it was. Returns ``path``.

    ``exclusive=True`` never replaces an existing file: the finished file is published with a
    hard link, which fails with ``FileExistsError`` when ``path`` exists (also when another
    process created it in the meantime). A ``path`` that is a folder raises ``IsADirectoryError``,
    a folder path through a file ``NotADirectoryError``, each naming the path.
    """
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(f"{path}: is a folder; expected the path of a file")
    folder = path.parent if str(path.parent) else Path(".")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):  # a part of the folder's path is a file
        raise NotADirectoryError(f"{path}: cannot create its folder {folder}: {file_in_path(folder)} is a "
                                 "file") from None
    remove_stale_temporaries(folder)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.{_HOST}-{os.getpid()}.", suffix=".tmp", dir=folder)
    except OSError as exc:  # read-only or not ours: its message names the temporary file, not the caller's path
        msg = f"{path}: cannot write in its folder {folder} ({exc.strerror or exc})"
        raise (type(exc)(exc.errno, msg) if exc.errno is not None else type(exc)(msg)) from None
    try:
        os.fchmod(fd, 0o666 & ~_UMASK)  # mkstemp makes 0600; give the file the mode open() would
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        if exclusive:
            os.link(tmp, path)
            os.unlink(tmp)
        else:
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


def atomic_savez(path: str | os.PathLike, arrays: dict[str, np.ndarray], *, exclusive: bool = False) -> Path:
    """Write ``arrays`` to ``path`` (``.npz``) atomically (``exclusive``: see :func:`atomic_write`).
    ``numpy.savez`` would append ``.npz`` to a name without it; the path is kept exactly as given."""
    named = cast("dict[str, Any]", arrays)  # numpy's stub checks **kwds against its allow_pickle: bool
    return atomic_write(path, lambda f: np.savez(f, **named), exclusive=exclusive)


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


def read_npz(path: str | os.PathLike, what: str, max_bytes: int = MAX_NPZ_BYTES) -> dict[str, np.ndarray]:
    """Read every array of an ``.npz`` file eagerly (no pickle).

    Raises ``FileNotFoundError`` for a missing file and ``ValueError`` naming ``path`` and
    ``what`` for anything else: not a zip archive (e.g. a ``.npy`` array or random bytes),
    members that would decompress to more than ``max_bytes`` in total (checked from the
    archive's directory before anything is inflated), truncated or corrupt archive, bad CRC,
    pickled data.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{what} file not found: {path}")
    if not path.is_file():
        raise ValueError(f"{path}: not a file (expected a {what} .npz file)")
    with open(path, "rb") as fh:
        head = fh.read(4)
    if head not in _ZIP_MAGIC:
        kind = "is a .npy array" if head == b"\x93NUM" else f"starts with {head!r}"
        raise ValueError(f"{path}: not a {what} .npz file (a .npz file is a zip archive; this file {kind})")
    try:
        with zipfile.ZipFile(path) as zf:
            total = sum(info.file_size for info in zf.infolist())
    except (zipfile.BadZipFile, OSError, EOFError, ValueError) as exc:
        raise ValueError(f"{path}: not a readable {what} .npz file (corrupt or truncated?): "
                         f"{type(exc).__name__}: {exc}") from exc
    if total > max_bytes:
        raise ValueError(f"{path}: the {what} file would decompress to {total / 2**20:.0f} MiB, over the limit of "
                         f"{max_bytes / 2**20:.0f} MiB (max_bytes); refusing to load it")
    size = path.stat().st_size
    if total > BOMB_MIN_BYTES and total > BOMB_RATIO * size:
        raise ValueError(f"{path}: the {what} file would decompress to {total / 2**20:.0f} MiB from "
                         f"{size / 2**10:.0f} KiB (ratio {total / max(size, 1):.0f}, over {BOMB_RATIO}): a zip bomb "
                         "or a crafted file; refusing to load it")
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: np.asarray(z[k]) for k in z.files}
    except (zipfile.BadZipFile, ValueError, OSError, EOFError, KeyError, zlib.error) as exc:  # zlib: a damaged
        raise ValueError(                                                                     # compressed member
            f"{path}: not a readable {what} .npz file (corrupt or truncated?): "
            f"{type(exc).__name__}: {exc}") from exc


def check_format_header(z: dict[str, np.ndarray], path: str | os.PathLike, kind: str, version: int) -> None:
    """Raise ``ValueError`` naming the file and field unless ``z`` holds ``format_kind == kind``
    and ``format_version == version`` (shared by every cascgp file format)."""
    got_kind = str(z["format_kind"]) if "format_kind" in z and z["format_kind"].shape == () else None
    if got_kind != kind:
        raise ValueError(f"{path}: format_kind: expected {kind!r}, got {got_kind!r}")
    raw = z.get("format_version")
    got_version: int | str | None
    if raw is None or (raw.shape == () and raw.dtype.kind in "iu"):
        got_version = None if raw is None else int(raw)
    else:
        got_version = f"an array of dtype {raw.dtype} and shape {raw.shape}"
    if got_version != version:
        raise ValueError(f"{path}: format_version: expected {version}, got {got_version}")
