"""Checks of command-line options shared by the subcommands: one message for one kind of bad value."""

from __future__ import annotations

import argparse
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
