"""The ``cascgp`` command: one console script, one subcommand per job.

======================  ==========================================================================
subcommand              what it does
======================  ==========================================================================
``cascgp fit``          fit a model to logged data (CSV or ``.npz``) and save it
``cascgp evaluate``     per-joint nRMSE of a saved model on logged data (and of its nominal model)
``cascgp predict``      a saved model's torque predictions for logged states, as CSV
``cascgp transfer``     the task-transfer pouring experiment on ``JacoPour-v0``
``cascgp study``        the paper's data-efficiency study (simulated Jaco data, SARCOS)
``cascgp sarcos``       the SARCOS block of the study alone
``cascgp collect``      the simulated Jaco data collection of the study
``cascgp plots``        a study's figures, tables and claims, redrawn from its ``results.json``
======================  ==========================================================================

Each subcommand is a function ``f(argv, prog) -> int | None`` in a module of this package; this module only
dispatches, and imports a subcommand's module (and with it torch or MuJoCo) only when that subcommand runs.
"""

from __future__ import annotations

import importlib
import sys
from typing import Sequence

__all__ = ["COMMANDS", "main"]

#: subcommand -> ("module:function" that implements it, one-line summary for ``cascgp --help``).
COMMANDS: dict[str, tuple[str, str]] = {
    "fit": ("cascgp_experiments.cli.model_commands:fit_main", "fit a model to logged data and save it (.npz)"),
    "evaluate": ("cascgp_experiments.cli.model_commands:evaluate_main",
                 "per-joint nRMSE of a saved model on logged data"),
    "predict": ("cascgp_experiments.cli.model_commands:predict_main",
                "torque predictions of a saved model, written as CSV"),
    "transfer": ("cascgp_experiments.cli.transfer:main", "task-transfer pouring episodes on JacoPour-v0"),
    "study": ("cascgp_experiments.cli.study:main", "the paper's data-efficiency study (Jaco data, SARCOS)"),
    "sarcos": ("cascgp_experiments.cli.sarcos:main", "SARCOS data-efficiency curves (NP models)"),
    "collect": ("cascgp_experiments.cli.collect:main", "collect the simulated Jaco data set of the study"),
    "plots": ("cascgp_experiments.cli.plots:main", "redraw a study's figures and tables from its results.json"),
}


#: The subcommands that resume from their output folder.
_RESUMABLE = ("transfer", "study", "sarcos")


def _usage() -> str:
    from cascgp import __version__

    width = max(map(len, COMMANDS))
    lines = ["usage: cascgp [--version] [--help] <command> [options]", "",
             f"cascgp {__version__}: cascaded Gaussian processes for robot inverse dynamics.", "", "commands:"]
    lines += [f"  {name:<{width}}  {summary}" for name, (_, summary) in COMMANDS.items()]
    lines += ["", "'cascgp <command> --help' shows a command's options."]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``cascgp`` console script; returns the exit status."""
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) == 2 and args[0] == "help" and args[1] in COMMANDS:  # 'cascgp help fit': fit's own help
        args = [args[1], "--help"]
    if not args or args[0] in ("-h", "--help", "help"):
        print(_usage(), file=sys.stdout if args else sys.stderr)  # no command: an error, on stderr
        return 0 if args else 2
    if args[0] == "--version":
        from cascgp import __version__

        print(f"cascgp {__version__}")
        return 0
    name = args[0]
    if name not in COMMANDS:
        print(f"cascgp: unknown command {name!r}; expected one of {', '.join(COMMANDS)}\n\n{_usage()}",
              file=sys.stderr)
        return 2
    module, func = COMMANDS[name][0].split(":")
    try:
        status = getattr(importlib.import_module(module), func)(args[1:], prog=f"cascgp {name}")
    except KeyboardInterrupt:  # Ctrl-C: one line instead of a traceback through the job runner
        hint = (": run the same command again to resume (finished jobs are kept in --out)" if name in _RESUMABLE
                else "")
        print(f"\ncascgp {name}: interrupted{hint}", file=sys.stderr)
        return 130
    except PermissionError as exc:  # a folder of --out that cannot be written, found during the run
        print(f"cascgp {name}: error: {exc}", file=sys.stderr)
        return 2
    return int(status or 0)

