"""Every module of the packages, ``studies/``, ``scripts/`` and ``tests/`` is at most 500 lines
(docs/architecture.md)."""

from __future__ import annotations

from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
MAX_LINES = 500


def test_no_module_is_over_500_lines() -> None:
    tops = ("cascgp", "jaco_env", "cascgp_experiments", "studies", "scripts", "tests")
    files = [p for top in tops for p in (REPO / top).rglob("*.py")]
    assert len(files) > 60
    long = {str(p.relative_to(REPO)): n for p in files
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_LINES}
    assert not long, f"modules over {MAX_LINES} lines: {long}"
