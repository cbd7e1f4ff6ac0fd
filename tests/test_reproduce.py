"""A study's figures come back from the command line: every candidate folder's
``reproduce.sh`` runs `fabplan molds` (and `strips`) on its ``net.obj`` and gives the
study's molds and strips.

Regression: a study planned a gliding candidate on the design's patches (3 molds, all
fit) while `fabplan molds` on its net.obj gave 9 molds and 10 failures, and offered no
way to plan on the design.
"""

from __future__ import annotations

import csv
import json
import shlex
from pathlib import Path

import pytest

from fabplan.cli import main

STUDY = """
[design]
surface = "hyperbolic-paraboloid"
[panels]
size = 2.0
[limits]
max_deviation_mm = 30
mold_tolerance_mm = 2
[[candidates]]
net = "isogonal"
angle = 80
"""


def _run_script(folder: Path, monkeypatch) -> list[list[str]]:
    """Run a candidate's reproduce.sh line by line through `main`, in its folder."""
    lines = (folder / "reproduce.sh").read_text(encoding="utf-8").splitlines()
    assert lines[0] == "#!/bin/sh" and 'cd "$(dirname "$0")" || exit 2' in lines
    commands = [shlex.split(line.partition(" || ")[0]) for line in lines
                if line.startswith("fabplan ")]
    monkeypatch.chdir(folder)
    for command in commands:
        assert main([*command[1:], "-q"]) in (0, 3), command
    return commands


def _mold_rows(path: Path) -> list[dict]:
    rows = [r for r in csv.DictReader(line for line in path.read_text().splitlines()
                                      if not line.startswith("#"))]
    assert rows
    return rows


def _same_molds(study_folder: Path, made: Path) -> None:
    """The molds the command gave are the study's: count, every panel's mold, type and fit,
    and its gap and placement within 0.01 mm (and a unit of the last digit written: the
    footprints are written to 0.1 mm) (a candidate that is the same net as an
    earlier one takes that one's plan: its vertices agree to 1e-5 of the panel size,
    `fabplan.study.twins.SAME_NET_TOLERANCE`, 0.01 mm on a 1 m panel)."""
    ours = json.loads((made / "molds.json").read_text())
    theirs = json.loads((study_folder / "molds.json").read_text())
    for key in ("mold_count", "panel_count", "panel_surface", "tolerance_mm", "units",
                "molds_made", "molds_saved_by_material"):
        assert ours[key] == theirs[key], key
    rows, study_rows = _mold_rows(made / "panels.csv"), _mold_rows(study_folder / "molds.csv")
    assert len(rows) == len(study_rows)
    for a, b in zip(rows, study_rows, strict=True):
        assert a.keys() == b.keys()
        for key in a:
            if key in ("face", "mold", "type", "fits", "class", "class_unit"):
                assert a[key] == b[key], (key, a, b)
            else:   # a number written to fewer digits may round the other way
                printed = 10.0 ** -len(a[key].partition(".")[2]) if "." in a[key] else 0.0
                assert float(a[key]) == pytest.approx(float(b[key]), rel=1e-6,
                                                      abs=1e-2 + printed), key


@pytest.mark.slow
def test_a_gliding_candidate_is_planned_on_the_design_by_its_reproduce_commands(
        tmp_path, monkeypatch):
    (tmp_path / "s.toml").write_text(STUDY, encoding="utf-8")
    assert main(["study", str(tmp_path / "s.toml"), "-o", str(tmp_path / "out"), "-q"]) == 0
    record = json.loads((tmp_path / "out" / "study.json").read_text())
    for candidate in record["candidates"]:
        folder = tmp_path / "out" / "candidates" / candidate["name"]
        assert candidate["outputs"]["reproduce"].endswith("reproduce.sh")
        commands = _run_script(folder, monkeypatch)
        assert "--design" in commands[0]          # the candidates glide on the design
        _same_molds(folder, folder / "reproduced" / "molds")
        molds = candidate["metrics"]["molds"]
        assert json.loads((folder / "reproduced" / "molds" / "molds.json").read_text())[
            "mold_count"] == molds["count"] - (molds["boundary_own_molds"] or 0)


def test_molds_on_the_design_needs_the_design(tmp_path, capsys):
    net = tmp_path / "net.obj"
    net.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
    code = main(["molds", str(net), "--tolerance-mm", "1", "--panel-surface", "design",
                 "-o", str(tmp_path / "m")])
    err = capsys.readouterr().err
    assert code == 2 and "--panel-surface design needs --design SURFACE" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["net.obj"]


@pytest.mark.slow
def test_every_canopy_candidate_is_reproduced_by_its_commands(canopy_study, tmp_path, monkeypatch):
    import shutil

    from fabplan.study.report import study_files

    # the session's `fabplan study canopy` (tests/conftest.py), copied: the commands write
    # beside the candidates' files
    shared, run = canopy_study
    assert run.code == 0, run.lines[-5:]
    shutil.copytree(shared, tmp_path / "out")
    record = json.loads((tmp_path / "out" / "study.json").read_text())
    # every file it wrote (strip sheets included) is one a later study replaces
    written = {p.relative_to(tmp_path / "out").as_posix() for p in (tmp_path / "out").rglob("*")
               if p.is_file()}
    assert study_files(tmp_path / "out") == written
    for candidate in record["candidates"]:
        if candidate.get("error"):
            continue
        folder = tmp_path / "out" / "candidates" / candidate["name"]
        commands = _run_script(folder, monkeypatch)
        _same_molds(folder, folder / "reproduced" / "molds")
        if any(c[1] == "strips" for c in commands):
            ours = json.loads((folder / "reproduced" / "strips" / "strips.json").read_text())["summary"]
            study = candidate["metrics"]["strips"]
            assert ours["strips"] == study["strips"] and ours["sheets"] == study["sheets"]


@pytest.mark.parametrize("molds_exit, strips_run, script_exit", [(0, True, 0), (3, True, 3),
                                                                 (2, False, 2)])
def test_reproduce_sh_goes_on_past_a_limit_not_met_and_stops_at_a_failure(
        tmp_path, monkeypatch, molds_exit, strips_run, script_exit):
    """An infeasible candidate's molds end with exit 3 (written, a limit not met): its
    strips are still made and the script ends with 3; an error stops the script with its
    code. (`set -e` stopped at the molds, so an infeasible candidate never had strips.)"""
    import os
    import subprocess
    from types import SimpleNamespace

    from fabplan.study import report

    monkeypatch.setattr(report, "reproduce_commands", lambda c, study: [
        ["fabplan", "molds", "net.obj", "-o", "reproduced/molds"],
        ["fabplan", "strips", "net.obj", "-o", "reproduced/strips"]])
    folder = tmp_path / "candidate"
    folder.mkdir()
    script = folder / "reproduce.sh"
    script.write_text(report.reproduce_script(SimpleNamespace(name="c"), None), encoding="utf-8")
    bin_folder = tmp_path / "bin"
    bin_folder.mkdir()
    stub = bin_folder / "fabplan"          # records each command and its folder
    stub.write_text('#!/bin/sh\necho "$1 $(pwd)" >> "$LOG"\n'
                    '[ "$1" = molds ] && exit "$MOLDS_EXIT"\nexit 0\n', encoding="utf-8")
    stub.chmod(0o755)
    log = tmp_path / "log"
    env = {**os.environ, "PATH": f"{bin_folder}:{os.environ['PATH']}", "LOG": str(log),
           "MOLDS_EXIT": str(molds_exit)}
    done = subprocess.run(["sh", str(script)], cwd=tmp_path, env=env)
    assert done.returncode == script_exit
    ran = log.read_text().splitlines()
    assert ran == [f"molds {folder}"] + ([f"strips {folder}"] if strips_run else [])
