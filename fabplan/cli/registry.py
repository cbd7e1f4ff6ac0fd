"""The commands of `fabplan`, each registered by its module: its name, its help, its
arguments and how it runs. `fabplan.cli.main` builds the parser from them and dispatches
to the one named on the command line."""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from typing import Any, Callable

__all__ = ["COMMANDS", "Command", "register"]


@dataclass(frozen=True)
class Command:
    """One subcommand of `fabplan`.

    Attributes
    ----------
    name : the word on the command line (``fabplan NAME``).
    help : its line in ``fabplan --help``.
    add_arguments : adds its arguments to its parser.
    run : runs it on the parsed arguments; returns the exit code.
    parser_options : the other keywords of its parser (a description, an epilog), made
        when the parser is built: some are read from modules imported only then.
    """

    name: str
    help: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]
    parser_options: Callable[[], dict[str, Any]] = field(default=dict)


#: every command by its name, in the order `fabplan --help` lists them (that of registration)
COMMANDS: dict[str, Command] = {}


def register(command: Command) -> Command:
    """Add `command` to `COMMANDS`; a second command of the same name is refused."""
    if command.name in COMMANDS:
        raise ValueError(f"a fabplan command {command.name!r} is registered already")
    COMMANDS[command.name] = command
    return command
