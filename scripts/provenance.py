"""What the benchmark scripts record about the code they measured (not a command)."""

from __future__ import annotations

import subprocess
from pathlib import Path


def git(*args: str) -> str | None:
    """``git ARGS`` run in this checkout: its stripped output (possibly empty), or None where git or the checkout is
    missing."""
    try:
        return subprocess.run(["git", *args], capture_output=True, text=True, check=True,
                              cwd=Path(__file__).resolve().parent).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None


def git_commit() -> str | None:
    """The checkout's ``HEAD`` commit, or None outside a git checkout."""
    return git("rev-parse", "HEAD") or None
