"""`fabplan templates [NAME [-o FILE]]`: the study templates listed, one printed or copied."""

from __future__ import annotations

import argparse

from ..io.output import output_argument
from .registry import Command, register

__all__ = ["COMMAND", "add_arguments", "run"]


def run(args: argparse.Namespace) -> int:
    from ..study.templates import copy_template, template_names, template_summary

    if args.name is None:
        names = template_names()
        width = max(map(len, names), default=0)
        for name in names:
            print(f"{name:<{width}}  {template_summary(name)}")
        print("run one with `fabplan study NAME -o DIR`; copy one with "
              "`fabplan templates NAME -o my-study.toml`")
        return 0
    if args.output is None:
        from ..study.templates import template_path

        print(template_path(args.name).read_text(encoding="utf-8"), end="")
        return 0
    output_argument(args.output, folder=True)       # named, and short enough
    for path in copy_template(args.name, args.output):
        print(f"wrote {path}")
    return 0


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("name", nargs="?", help="template to print (or copy with -o)")
    p.add_argument("-o", "--output", metavar="FILE",
                   help="copy the template here: a .toml file, or a folder (an existing one, "
                        "or a path ending in /) that gets NAME.toml")


COMMAND = register(Command("templates", "list the study templates, print or copy one",
                           add_arguments, run))
