"""What the C++ URDF parser (urdfdom, inside Pinocchio) prints while it parses: captured, so that an error message
can carry its reason for refusing a file instead of a raw C++ line on the process's stderr."""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
import threading
from collections.abc import Iterator

#: One parse at a time redirects the process's stderr (fd 2 is shared by every thread).
_PARSER_OUTPUT_LOCK = threading.Lock()


@contextlib.contextmanager
def parser_output() -> Iterator[list[str]]:
    """Capture what the C++ URDF parser (urdfdom, inside Pinocchio) prints to the process's stderr while the block
    runs; the yielded list receives it. Its reason for refusing a file (e.g. ``XML_ERROR_PARSING_ELEMENT ... Line
    number=2``) is printed there, not put in the exception, so the error message takes it from here (rather than
    a raw C++ line before it). Output of a parse that succeeds is passed on to stderr unchanged. Parses in several
    threads take turns; other threads' output to stderr during a parse is captured with it. Where stderr cannot
    be redirected (no temporary file, no fd 2), the block runs as is. A parse that succeeded but dropped an
    inertial it could not read (:func:`dropped_inertials`) is not passed on: the caller refuses it."""
    said: list[str] = []
    with _PARSER_OUTPUT_LOCK:
        try:
            if sys.stderr is not None:
                sys.stderr.flush()
            tmp = tempfile.TemporaryFile()
        except (OSError, ValueError):
            yield said
            return
        with tmp:
            try:
                saved = os.dup(2)
            except OSError:
                yield said
                return
            try:
                os.dup2(tmp.fileno(), 2)
            except OSError:
                os.close(saved)
                yield said
                return
            failed = True
            try:
                yield said
                failed = False
            finally:
                os.dup2(saved, 2)
                os.close(saved)
                tmp.seek(0)
                text = tmp.read().decode("utf-8", "replace")
                said.append(text)
                if text and not failed and not dropped_inertials(said) and sys.stderr is not None:
                    sys.stderr.write(text)  # what a parse that succeeded printed (unless the caller refuses it)


def parser_reason(said: list[str]) -> str:
    """The parser's own words (from :func:`parser_output`) for an error message, without its source location."""
    text = " ".join(line.strip() for line in "".join(said).splitlines()
                    if line.strip() and not line.strip().startswith("at line "))
    text = " ".join(text.split()).removeprefix("Error:").strip()
    return f" (urdfdom: {text})" if text else ""


def dropped_inertials(said: list[str]) -> list[str]:
    """The errors the parser reported (from :func:`parser_output`, without their source location) if it dropped a
    link's ``<inertial>`` it could not read (``<mass value="heavy"/>``, NaN in its origin), else none. urdfdom then
    prints "Could not parse inertial element for Link [...]" and the parse succeeds: the link has no mass, and the
    file describes another robot than it says. (An unreadable visual, collision or material loses only geometry,
    which the dynamics do not use: urdfdom reads a link's inertial first; such errors are passed on as they are.)"""
    errors = [" ".join(line.strip().removeprefix("Error:").split()) for line in "".join(said).splitlines()
              if line.strip().startswith("Error:")]
    return errors if any("inertial element" in e for e in errors) else []
