"""The library ``cascgp`` knows no simulator: importing every one of its modules loads neither ``mujoco`` nor
``jaco_env`` (nor ``cascgp_experiments``, which sits on top of it)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

_CODE = """
import importlib, pkgutil, sys
import cascgp
names = sorted(m.name for m in pkgutil.walk_packages(cascgp.__path__, "cascgp."))
for name in names:
    try:
        importlib.import_module(name)
    except ModuleNotFoundError as exc:  # the fast extra's kernel module, without numba installed
        if (name, exc.name) != ("cascgp.models.online_kernel", "numba"):
            raise
bad = sorted(m for m in sys.modules if m.split(".")[0] in ("mujoco", "jaco_env", "cascgp_experiments", "dm_control"))
assert len(names) > 20, names
assert not bad, bad
print(len(names))
"""


def _python(code: str, *args: str) -> None:
    """Runs ``code`` (with ``args`` in ``sys.argv[1:]``) in a fresh interpreter (nothing imported yet) from the
    checkout; fails with its stderr."""
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    out = subprocess.run([sys.executable, "-c", code, *args], env=env, cwd=REPO, capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]


def test_importing_every_cascgp_module_loads_no_simulator() -> None:
    _python(_CODE)


_EXPERIMENTS = """
import importlib, pkgutil, sys
import cascgp_experiments
names = sorted(m.name for m in pkgutil.walk_packages(cascgp_experiments.__path__, "cascgp_experiments."))
for name in names:
    importlib.import_module(name)
bad = sorted(m for m in sys.modules if m.split(".")[0] == "studies")
assert len(names) > 15, names
assert not bad, bad
"""


def test_the_experiments_import_no_study() -> None:
    """The product's experiments stand without the research studies (``studies/`` is not installed)."""
    _python(_EXPERIMENTS)


_HELP = """
import sys
from cascgp_experiments.cli import main
for command in ("transfer", "study", "sarcos", "collect", "plots"):
    try:
        main([command, "--help"])
    except SystemExit as exc:
        assert exc.code == 0, (command, exc.code)
heavy = sorted(m for m in ("torch", "pinocchio") if m in sys.modules)
assert not heavy, heavy
"""


def test_the_experiment_commands_help_without_torch() -> None:
    """``--help`` answers at once: ``cascgp transfer --help`` imported torch for its defaults (about 5 s)."""
    _python(_HELP)


_BAD_SETTINGS = """
import contextlib, io, sys
from cascgp_experiments.cli import main
for args in (["--controllers", "pd,sp-inwrd"], ["--attempts", "0"], ["--tasks", "nowhere"], ["--payload", "-1"],
             ["--restarts", "0"], ["--rate", "nan"]):
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        try:
            main(["transfer", "--out", sys.argv[1], *args])
        except SystemExit as exc:
            assert exc.code == 2, (args, exc.code)
        else:
            raise AssertionError(f"{args} accepted")
    assert "cascgp transfer: error: --" in err.getvalue(), (args, err.getvalue())
heavy = sorted(m for m in ("torch", "pinocchio") if m in sys.modules)
assert not heavy, heavy
"""


def test_a_bad_transfer_setting_is_refused_without_torch(tmp_path: Path) -> None:
    """A bad ``cascgp transfer`` setting is refused at once, naming its option: its checks imported torch through
    the library (3-4 s before the error)."""
    _python(_BAD_SETTINGS, str(tmp_path / "out"))
