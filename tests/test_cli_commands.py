"""The command line is one module per command, each registered (`fabplan.cli.registry`):
every command the parser knows is in the registry and runs through it, each lives in the
module named for it, and each command's ``--help`` still lists every option it had."""

from __future__ import annotations

import argparse
import ast
import dataclasses
import re
from pathlib import Path

import pytest

from fabplan.cli import COMMANDS, InRange, build_parser, main

CLI = Path(__file__).resolve().parents[1] / "fabplan" / "cli"

#: each command's positional arguments and options, in the order its parser had them when
#: the command line was split into a module per command (new options may join them)
OPTIONS = {
    "nets": [],
    "measure": ["net", "--output", "--reference", "--max-deviation", "--max-line-turn", "--units",
                "--strict-units"],
    "optimize": ["input", "--net", "--angle", "--radius", "--reference", "--fix", "--handle",
                 "--coherent", "--guards", "--no-guards", "--settle-free", "--max-deviation",
                 "--max-line-turn", "--max-iter", "--no-multilevel", "--output", "--html", "--3dm",
                 "--ifc", "--units", "--strict-units", "--quiet", "--verbose"],
    "molds": ["net", "--tolerance-mm", "--units", "--strict-units", "--max-mold-size",
              "--panel-surface", "--design", "--triangles", "--step-limit", "--material",
              "--max-deviation-mm", "--max-panels", "--boundary", "--no-boundary", "--output",
              "--3dm", "--ifc", "--no-3d", "--quiet", "--verbose"],
    "layout": ["surface", "--net", "--angle", "--panel-size", "--family", "--triangles",
               "--max-iter", "--smoothing", "--starts", "--max-panels", "--max-line-turn",
               "--output", "--html", "--3dm", "--ifc", "--units", "--strict-units", "--quiet",
               "--verbose"],
    "strips": ["net", "--height", "--thickness", "--units", "--strict-units", "--sheet",
               "--spacing", "--margin", "--kerf", "--clearance", "--tolerance", "--max-twist",
               "--end", "--extension", "--boundary", "--no-boundary", "--boundary-member",
               "--design", "--triangles", "--max-deviation-mm", "--splice", "--splice-length",
               "--labels", "--label-height", "--layer", "--one-file", "--no-previews", "--workers",
               "--max-panels", "--output", "--3dm", "--ifc", "--quiet", "--verbose"],
    "arcs": ["net", "--units", "--strict-units", "--output", "--max-arc-angle", "--quiet",
             "--verbose"],
    "mill": ["net", "--tool", "--along", "--units", "--strict-units", "--margin", "--scallop",
             "--side", "--max-panels", "--sim-step", "--no-simulation", "--design", "--triangles",
             "--paths-on", "--output", "--3dm", "--quiet", "--verbose"],
    "study": ["study", "--output", "--workers", "--scheduler", "--resume", "--max-panels", "--3dm",
              "--ifc", "--no-3d", "--quiet"],
    "templates": ["name", "--output"],
    "edit": ["input", "--net", "--angle", "--radius", "--reference", "--port", "--no-open",
             "--output", "--units", "--strict-units", "--quiet", "--verbose"],
}


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def _help(capsys, argv: list[str]) -> str:
    assert main([*argv, "--help"]) == 0
    out = capsys.readouterr()
    assert out.err == ""
    return out.out


def test_the_registry_holds_every_command_in_the_order_of_the_help(capsys):
    """The parser's commands, ``fabplan --help`` and the registry name the same commands in
    the same order, each with the help its registration gives."""
    assert list(_subparsers(build_parser())) == list(COMMANDS) == list(OPTIONS)
    text = _help(capsys, [])
    choices = re.search(r"\{([a-z,]+)\}", text)
    assert choices is not None and choices.group(1).split(",") == list(OPTIONS)
    listed = re.findall(r"^    ([a-z]+) ", text, flags=re.MULTILINE)
    assert listed == list(OPTIONS)
    flat = " ".join(text.split())
    for command in COMMANDS.values():
        assert " ".join(command.help.split()) in flat, command.name


def test_each_command_lives_in_the_module_named_for_it():
    """A command module registers one command, its own; every registration is in one."""
    registering = sorted(path.stem for path in CLI.glob("*.py")
                         if any(isinstance(node, ast.Call) and ast.unparse(node.func) == "register"
                                for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))))
    assert registering == sorted(COMMANDS)
    for name, command in COMMANDS.items():
        assert command.run.__module__ == command.add_arguments.__module__ == f"fabplan.cli.{name}"


def _smallest_argv(name: str, parser: argparse.ArgumentParser) -> list[str]:
    """The command with its required arguments, each given a value its parser takes."""
    argv = [name]
    for action in parser._actions:
        if not action.required:
            continue
        if action.choices:
            value = str(next(iter(action.choices)))
        elif isinstance(action, InRange):
            low = re.match(r"[\[(]([^,]+),", action.parameter.interval)
            assert low is not None
            value = str(max(float(low.group(1)), 1.0))
        else:
            value = "x.obj"
        argv += [value] if not action.option_strings else [action.option_strings[0], value]
    return argv


@pytest.mark.parametrize("name", list(OPTIONS))
def test_main_runs_the_registered_command(name, monkeypatch):
    """`main` parses the command's arguments and hands them to the run its registry entry
    names, returning what it returns."""
    seen = []

    def run(args: argparse.Namespace) -> int:
        seen.append(args)
        return 7

    monkeypatch.setitem(COMMANDS, name, dataclasses.replace(COMMANDS[name], run=run))
    argv = _smallest_argv(name, _subparsers(build_parser())[name])
    assert main(argv) == 7
    assert len(seen) == 1 and seen[0].command == name


@pytest.mark.parametrize("name", list(OPTIONS))
def test_each_command_help_lists_its_options(name, capsys):
    """``fabplan NAME --help`` shows every positional argument and option it had, and every
    one its parser has now."""
    text = _help(capsys, [name])
    assert text.startswith(f"usage: fabplan {name}")
    positionals = re.search(r"^positional arguments:\n(.*?)(?:\n\n|\Z)", text, flags=re.S | re.M)
    shown = set(re.findall(r"^  (\w+)", positionals.group(1), flags=re.M)) if positionals else set()
    options = set(re.findall(r"(?<![\w-])(--[a-z0-9][a-z0-9-]*)", text.split("\noptions:\n")[1]))
    expected = {o for o in OPTIONS[name] if not o.startswith("-")}
    assert expected <= shown, f"{name} --help lacks {sorted(expected - shown)}"
    missing = {o for o in OPTIONS[name] if o.startswith("-")} - options
    assert not missing, f"{name} --help lacks {sorted(missing)}"
    parser = _subparsers(build_parser())[name]
    now = {s for a in parser._actions for s in a.option_strings if s.startswith("--")}
    assert now <= options, f"{name} --help lacks {sorted(now - options)}"
