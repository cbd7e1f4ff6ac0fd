"""The `fabplan` command line: its parser, built from the registered commands
(`fabplan.cli.registry`), and `main`, which runs the command it names."""

from __future__ import annotations

import argparse
import functools
import sys

from .. import __version__

# every command module registers itself as it is imported, in this order: the order
# `fabplan --help` lists them in
# isort: off
from . import nets, measure, optimize, molds, layout, strips, arcs, mill  # noqa: F401
from . import study, templates, edit  # noqa: F401
# isort: on
from .arguments import Parser
from .registry import COMMANDS
from .running import EXIT_BAD_INPUT, run_command, unparsable

__all__ = ["build_parser", "command_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="fabplan", description="Fabrication planning with principal symmetric meshes.")
    parser.add_argument("--version", action="version", version=f"fabplan {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    for command in COMMANDS.values():
        command.add_arguments(sub.add_parser(command.name, help=command.help,
                                             **command.parser_options()))
    return parser


@functools.cache
def command_parser() -> argparse.ArgumentParser:
    """The parser `main` reads command lines with (`build_parser`), built once per process
    after every command registered: it keeps nothing of a run (each parse makes its own
    namespace), and building it takes about 10 ms, a tenth of a refused run's time when
    `main` is called from Python."""
    return build_parser()


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code."""
    parser = command_parser()
    refused = unparsable(sys.argv[1:] if argv is None else argv)
    if refused is not None:
        print(f"fabplan: error: {refused}", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        # a usage error or a value out of its range (one line printed), --help, --version
        return 0 if exc.code is None else exc.code if isinstance(exc.code, int) else EXIT_BAD_INPUT
    return run_command(COMMANDS[args.command].run, args)
