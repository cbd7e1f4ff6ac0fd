"""`fabplan nets`: the net types and their defining properties."""

from __future__ import annotations

import argparse

from ..solve.net_types import NETS
from .registry import Command, register

__all__ = ["COMMAND", "add_arguments", "run"]


def run(args: argparse.Namespace) -> int:
    width = max(len(n) for n in NETS)
    for net in NETS.values():
        print(f"{net.name:<{width}}  {net.summary}")
    return 0


def add_arguments(p: argparse.ArgumentParser) -> None:
    """None: the command lists them all."""


COMMAND = register(Command("nets", "list the net types and their defining properties",
                           add_arguments, run))
