"""Nothing a user has is lost, and nothing in an output folder runs.

Regression tests of an attack on the commands: a crafted ``--resume`` cache ran a shell
command, a FIFO in its place hung the study; a study deleted its own study file; commands
wrote over their reference, their handle file and the layout record beside their input;
killed `strips` runs left their workers running; SIGTERM left staging behind; ``-o ''``
wrote into the working folder, ``-o new/a/../m.json`` failed after creating ``new/a``,
``-o x.json/`` wrote a file. Every input is hashed before and after each command.
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from helpers import process_alive

import fabplan
from fabplan.cli import main
from fabplan.io.typed_data import decode, encode
from fabplan.net.mesh import QuadMesh
from fabplan.study.cache import CACHE_FOLDER, CandidateCache
from fabplan.study.spec import read_study

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
name = "{name}"
"""

FABPLAN = [sys.executable, "-c", "import sys; from fabplan.cli import main; sys.exit(main())"]


def hashes(folder: Path) -> dict:
    """sha256 of every file under `folder` (links and FIFOs by what they are)."""
    out = {}
    for p in sorted(folder.rglob("*")):
        if p.is_symlink() or p.is_fifo():
            out[str(p.relative_to(folder))] = "link" if p.is_symlink() else "fifo"
        elif p.is_file():
            out[str(p.relative_to(folder))] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def refused(argv: list, capsys, *fragments: str) -> str:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert code == 2, err
    assert err.startswith("fabplan: error: ") and err.count("\n") == 1, err
    for fragment in fragments:
        assert fragment in err, err
    return err


def grid_net(path: Path) -> Path:
    u, v = np.meshgrid(np.arange(6.0), np.arange(5.0), indexing="ij")
    QuadMesh.grid(np.stack([u, v, 0.05 * u * v], axis=-1)).write_obj(path)
    return path


# ---------------------------------------------------------------------------- the cache
class _Payload:
    """Unpickled, it creates the file it names: what a crafted pickle cache did."""

    def __init__(self, path: str):
        self.path = path

    def __reduce__(self):
        return (Path.touch, (Path(self.path),))


def test_typed_data_reads_only_the_types_it_is_given():
    data, arrays = encode({"a": (1, np.float32(2.5), np.arange(6).reshape(2, 3)), 3: [None, "x"]},
                          {})
    back = decode(json.loads(json.dumps(data)), arrays, {})
    assert back[3] == [None, "x"] and back["a"][0] == 1
    assert type(back["a"][1]) is np.float32 and back["a"][1] == np.float32(2.5)
    assert np.array_equal(back["a"][2], np.arange(6).reshape(2, 3))
    with pytest.raises(TypeError, match="not a type"):
        encode({"f": print}, {})
    with pytest.raises(TypeError, match="dtype object"):
        encode(np.array([None]), {})
    for tree, fragment in [({"$type": "Popen", "fields": {}}, "may not be read"),
                           ({"$array": "<f8", "shape": [10**9], "at": 0}, "beyond"),
                           ({"$array": "<f8", "shape": [-1], "at": 0}, "malformed"),
                           ({"$scalar": "|O", "value": 0}, "dtype"),
                           ({"$eval": "1"}, "unknown")]:
        with pytest.raises(ValueError, match=fragment):
            decode({"dtypes": ["<f8"], "tree": tree}, [np.zeros(3)], {})


@pytest.fixture(scope="module")
def resumed_study(tmp_path_factory):
    """A study run with --resume: its folder keeps its candidates in the cache."""
    folder = tmp_path_factory.mktemp("resume")
    (folder / "s.toml").write_text(STUDY.format(name="mine"), encoding="utf-8")
    assert main(["study", str(folder / "s.toml"), "-o", str(folder / "out"), "--resume", "-q"]) == 0
    return folder


def test_every_file_a_study_writes_is_one_a_later_study_may_replace(resumed_study):
    from fabplan.study.report import study_files

    listed = json.loads((resumed_study / "out" / ".fabplan-files").read_text())["files"]
    written = {p.relative_to(resumed_study / "out").as_posix()
               for p in (resumed_study / "out").rglob("*")
               if p.is_file() and CACHE_FOLDER not in p.parts}
    assert set(listed) == written
    assert study_files(resumed_study / "out") == written


@pytest.mark.slow
def test_a_crafted_cache_runs_nothing_and_a_fifo_does_not_hang(resumed_study, tmp_path):
    out = tmp_path / "out"
    shutil.copytree(resumed_study / "out", out)
    study = read_study(resumed_study / "s.toml")
    cache = CandidateCache(out, study)
    baseline, mine = (cache.key(c) for c in study.candidates)
    kept = out / CACHE_FOLDER
    assert sorted(p.name for p in kept.iterdir()) == sorted(
        f"{k}.{ext}" for k in (baseline, mine) for ext in ("json", "npz"))
    marker = tmp_path / "ran"
    # a pickle where the old cache looked, a kept entry naming a class outside the
    # cached types, and a FIFO for the other entry
    (kept / f"{baseline}.pkl").write_bytes(pickle.dumps(_Payload(str(marker))))
    header = json.loads((kept / f"{baseline}.json").read_text())
    header["data"]["tree"] = {"$type": "Popen", "fields": {"args": ["touch", str(marker)]}}
    (kept / f"{baseline}.json").write_text(json.dumps(header))
    (kept / f"{mine}.json").unlink()
    os.mkfifo(kept / f"{mine}.json")
    before = hashes(resumed_study)
    run = subprocess.run([*FABPLAN, "study", str(resumed_study / "s.toml"), "-o", str(out),
                          "--resume"], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert not marker.exists()
    assert run.stderr.count(f"{CACHE_FOLDER}/") == 2 and "ignored" in run.stderr
    assert "taken from the cache" not in run.stderr
    assert hashes(resumed_study) == before                 # the study's own folder untouched
    assert json.loads((out / "study.json").read_text())["recommended"] == "mine"


def test_a_kept_candidate_is_read_back_whole(resumed_study, tmp_path):
    """The kept candidate gives the same record as the run that kept it (the slow
    resume test compares whole studies)."""
    study = read_study(resumed_study / "s.toml")
    cache = CandidateCache(resumed_study / "out", study)
    result = cache.load(study.candidates[1])
    assert result is not None and result.name == "mine" and not result.failed
    record = json.loads((resumed_study / "out" / "candidates" / "mine" / "net.json").read_text())
    assert record["status"] == result.net.status
    written = QuadMesh.from_obj(resumed_study / "out" / "candidates" / "mine" / "net.obj")
    assert np.allclose(written.vertices, result.net.mesh.vertices, rtol=0, atol=1e-9)
    assert result.molds.mold_count == json.loads(
        (resumed_study / "out" / "study.json").read_text())["candidates"][1]["metrics"]["molds"]["count"]


def test_a_linked_cache_folder_is_refused(resumed_study, tmp_path, capsys):
    out = tmp_path / "out"
    shutil.copytree(resumed_study / "out", out, ignore=shutil.ignore_patterns(CACHE_FOLDER))
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (out / CACHE_FOLDER).symlink_to(elsewhere)
    refused(["study", resumed_study / "s.toml", "-o", out, "--resume"], capsys,
            "not a folder of its own")
    assert list(elsewhere.iterdir()) == []


# ---------------------------------------------------------------------------- studies
def test_a_study_never_removes_its_own_study_file(tmp_path, capsys):
    folder = tmp_path / "s"
    folder.mkdir()
    (folder / "study.toml").write_text(STUDY.format(name="mine"), encoding="utf-8")
    (folder / "study.json").write_text('{"earlier": true}', encoding="utf-8")
    before = hashes(tmp_path)
    refused(["study", folder / "study.toml", "-o", folder], capsys, "holds the study file")
    assert hashes(tmp_path) == before


@pytest.mark.slow
def test_a_study_replaces_only_what_an_earlier_study_wrote(resumed_study, tmp_path):
    out = tmp_path / "out"
    shutil.copytree(resumed_study / "out", out)
    (out / "notes.txt").write_text("mine")
    (out / "candidates" / "mine" / "sketch.dxf").write_text("mine too")
    victim = tmp_path / "victim.txt"
    victim.write_text("outside")
    # a crafted manifest may name only files of the folder
    manifest = json.loads((out / ".fabplan-files").read_text())
    manifest["files"] += ["../victim.txt", str(victim), "candidates/../../victim.txt"]
    (out / ".fabplan-files").write_text(json.dumps(manifest))
    (tmp_path / "s.toml").write_text(STUDY.format(name="other"), encoding="utf-8")
    assert main(["study", str(tmp_path / "s.toml"), "-o", str(out), "-q"]) == 0
    assert (out / "notes.txt").read_text() == "mine"
    assert (out / "candidates" / "mine" / "sketch.dxf").read_text() == "mine too"
    assert victim.read_text() == "outside"
    # the earlier candidate's files are gone, the folder kept for the file that is not its
    assert sorted(p.name for p in (out / "candidates" / "mine").iterdir()) == ["sketch.dxf"]
    assert (out / "candidates" / "other" / "net.obj").is_file()
    listed = json.loads((out / ".fabplan-files").read_text())["files"]
    assert "notes.txt" not in listed and "candidates/other/net.obj" in listed


@pytest.mark.slow
def test_a_study_refuses_to_replace_a_file_it_did_not_write(resumed_study, tmp_path, capsys):
    out = tmp_path / "out"
    shutil.copytree(resumed_study / "out", out)
    manifest = json.loads((out / ".fabplan-files").read_text())
    manifest["files"].remove("candidates.csv")       # as if the user had put it there
    (out / ".fabplan-files").write_text(json.dumps(manifest))
    before = hashes(out)
    code = main(["study", str(resumed_study / "s.toml"), "-o", str(out), "-q"])
    err = capsys.readouterr().err
    assert code == 2 and "candidates.csv: exists and no earlier run wrote it" in err
    assert hashes(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]      # no staging left


# ---------------------------------------------------------------------------- inputs
@pytest.fixture
def work(tmp_path) -> Path:
    grid_net(tmp_path / "lay.obj")
    (tmp_path / "lay.json").write_text('{"properties": {}}', encoding="utf-8")
    shutil.copyfile(fabplan.data_path("cmc1.obj"), tmp_path / "design.boundary.obj")
    (tmp_path / "h.json").write_text("0 0 0 0.1\n", encoding="utf-8")
    return tmp_path


@pytest.mark.parametrize("argv, what", [
    (["optimize", "{w}/lay.obj", "--net", "snet", "--reference", "{w}/design.boundary.obj",
      "-o", "{w}/design.obj"], "the reference"),
    (["optimize", "{w}/lay.obj", "--net", "snet", "--handle", "{w}/h.json", "-o", "{w}/h.obj"],
     "a handle file"),
    (["optimize", "{w}/lay.obj", "--net", "snet", "-o", "{w}/lay.obj"], "the input net"),
    (["arcs", "{w}/lay.obj", "-o", "{w}/lay.dxf"], "the record of lay.obj"),
    (["measure", "{w}/lay.obj", "-o", "{w}/lay.json"], "the record of lay.obj"),
    (["optimize", "{w}/lay.obj", "--net", "snet", "-o", "{w}/linked.obj"], "the input net"),
])
def test_no_command_writes_over_its_inputs(work, capsys, argv, what):
    os.link(work / "lay.obj", work / "linked.obj")       # a hard link to the input
    before = hashes(work)
    refused([a.format(w=work) for a in argv], capsys, what, "refusing to overwrite the input")
    assert hashes(work) == before


def test_a_folder_command_never_writes_over_an_input_inside_its_folder(work, capsys):
    out = work / "out"
    out.mkdir()
    grid_net(out / "panels.csv")          # a net named as molds' schedule
    before = hashes(work)
    refused(["molds", out / "panels.csv", "--tolerance-mm", "2", "-o", out], capsys,
            "the input net")
    assert hashes(work) == before


# ---------------------------------------------------------------------------- -o
@pytest.mark.parametrize("argv", [
    ["measure", "{net}", "-o", ""],
    ["molds", "{net}", "--tolerance-mm", "2", "-o", ""],
    ["strips", "{net}", "--height", "40", "--thickness", "4", "-o", ""],
    ["mill", "{net}", "--tool", "face:D=20", "-o", ""],
    ["templates", "canopy", "-o", ""],
    ["arcs", "{net}", "-o", ""],
])
def test_an_empty_output_is_refused(tmp_path, capsys, monkeypatch, argv):
    monkeypatch.chdir(tmp_path)
    grid_net(tmp_path / "n.obj")
    before = hashes(tmp_path)
    refused([a.format(net=tmp_path / "n.obj") for a in argv], capsys, "-o is empty")
    assert hashes(tmp_path) == before


@pytest.mark.parametrize("out, fragment", [
    ("new/a/../m.json", "goes up (..) out of"),
    ("x.json/", "ends in '/'"),
    ("x" * 300 + ".json", "file names take at most 255"),
    ("d/" * 2100 + "m.json", "paths take at most"),
])
def test_a_bad_output_path_is_refused_before_the_work(tmp_path, capsys, monkeypatch, out,
                                                      fragment):
    monkeypatch.chdir(tmp_path)
    grid_net(tmp_path / "n.obj")
    before = hashes(tmp_path)
    refused(["measure", tmp_path / "n.obj", "-o", out], capsys, fragment)
    assert hashes(tmp_path) == before and sorted(os.listdir(tmp_path)) == ["n.obj"]


def test_an_output_name_too_long_for_its_record_is_refused_before_the_layout(tmp_path, capsys):
    """OUT.boundary.obj is 9 bytes longer than OUT.obj: checked before the layout."""
    out = tmp_path / ("x" * 246 + ".obj")
    started = time.perf_counter()
    refused(["layout", "hyperbolic-paraboloid", "--net", "snet", "--panel-size", "1", "-o", out],
            capsys, "file names take at most 255")
    assert time.perf_counter() - started < 5
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------- processes
def test_stale_temporary_files_of_a_dead_run_are_removed_before_the_next(tmp_path):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True).stdout.strip()
    stale = tmp_path / f".fabplan-{dead}-0123456789ab.tmp"
    stale.write_text("half a file")
    mine = tmp_path / ".fabplan-notes.tmp"            # not a name of ours: kept
    mine.write_text("keep")
    grid_net(tmp_path / "n.obj")
    assert main(["measure", str(tmp_path / "n.obj"), "-o", str(tmp_path / "m.json")]) == 0
    assert not stale.exists() and mine.read_text() == "keep"


def _children(pid: int) -> list[int]:
    """The processes whose parent is `pid` (Linux /proc)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                found.append(int(entry.name))
    return found


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_killed_strips_leave_no_worker_running(tmp_path, sig):
    u, v = np.meshgrid(np.arange(25.0), np.arange(25.0), indexing="ij")
    net = tmp_path / "net.obj"
    QuadMesh.grid(np.stack([u, v, 0.02 * (u - 12) * (v - 12)], axis=-1)).write_obj(net)
    out = tmp_path / "out"
    run = subprocess.Popen([*FABPLAN, "strips", str(net), "--height", "40", "--thickness", "4",
                            "--sheet", "400x300", "--workers", "2", "-o", str(out)],
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    workers: list[int] = []
    for line in run.stderr:
        if line.startswith("writing"):
            deadline = time.monotonic() + 60
            while len(workers) < 2 and time.monotonic() < deadline and run.poll() is None:
                workers = _children(run.pid)
                time.sleep(0.01)
            break
    assert len(workers) == 2, "the sheets were not written by two workers"
    run.send_signal(sig)
    run.communicate(timeout=60)
    deadline = time.monotonic() + 10
    while any(process_alive(w) for w in workers) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(process_alive(w) for w in workers)
    if sig == signal.SIGTERM:
        assert run.returncode == 128 + signal.SIGTERM
        assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["net.obj"]


# ---------------------------------------------------------------------------- second attack
def _recrafted(kept: Path, key: str, *, data: bytes | None = None, tree=None) -> None:
    """Rewrite a kept entry as an attacker who recomputes its checksum would."""
    header = json.loads((kept / f"{key}.json").read_text())
    if data is not None:
        (kept / f"{key}.npz").write_bytes(data)
        header["arrays_sha256"] = hashlib.sha256(data).hexdigest()
    if tree is not None:
        header["data"]["tree"] = tree(header["data"]["tree"])
    (kept / f"{key}.json").write_text(json.dumps(header))


def test_kept_entries_that_do_not_hold_together_are_ignored(resumed_study, tmp_path):
    import io
    import zipfile

    study = read_study(resumed_study / "s.toml")
    out = tmp_path / "out"
    shutil.copytree(resumed_study / "out", out)
    kept = out / CACHE_FOLDER
    baseline, mine = (CandidateCache(out, study).key(c) for c in study.candidates)
    # a truncated zip for one, a net that is a string for the other
    _recrafted(kept, baseline, data=(kept / f"{baseline}.npz").read_bytes()[:-100])

    def net_as_text(tree):
        tree["fields"]["net"] = "not a net"
        return tree

    _recrafted(kept, mine, tree=net_as_text)
    notes: list[str] = []
    cache = CandidateCache(out, study, note=notes.append)
    assert [cache.load(c) for c in study.candidates] == [None, None]
    assert len(notes) == 2 and all("ignored" in n for n in notes)
    # a small file that would unpack into far more than it lists is refused unread
    with zipfile.ZipFile(resumed_study / "out" / CACHE_FOLDER / f"{baseline}.npz") as original:
        names = original.namelist()
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        for name in names:
            archive.writestr(name, b"\0" * (64 << 20))
    assert len(buffer.getvalue()) < 1 << 20
    _recrafted(kept, baseline, data=buffer.getvalue())
    assert cache.load(study.candidates[0]) is None and "unpacks to" in notes[-1]


@pytest.mark.slow
def test_a_study_never_removes_its_inputs_or_files_it_does_not_name(resumed_study, tmp_path):
    out = tmp_path / "out"
    shutil.copytree(resumed_study / "out", out)
    (out / ".fabplan-files").write_text("{not json")          # a damaged list
    (out / "candidates" / "mine" / "notes.txt").write_text("mine")
    design = out / "candidates" / "mine" / "net.obj"           # an earlier study's net as design
    text = STUDY.format(name="other").replace('surface = "hyperbolic-paraboloid"',
                                              f'file = "{design}"')
    (tmp_path / "s.toml").write_text(text.replace("size = 2.0", "size = 1.0"), encoding="utf-8")
    before = design.read_bytes()
    assert main(["study", str(tmp_path / "s.toml"), "-o", str(out), "-q"]) == 0
    assert design.read_bytes() == before
    assert (out / "candidates" / "mine" / "notes.txt").read_text() == "mine"


def test_files_a_surface_or_a_linked_net_reads_are_inputs(work, capsys):
    (work / "h.json").write_text("0 0 0\n0 1 0\n0 0 1\n")
    before = hashes(work)
    refused(["layout", "height-field:heights=" + str(work / "h.json"), "--net", "snet",
             "--panel-size", "2", "-o", work / "h.obj"], capsys, "refusing to overwrite the input")
    (work / "L.obj").symlink_to(work / "lay.obj")
    refused(["arcs", work / "L.obj", "-o", work / "lay.dxf"], capsys, "the record of lay.obj")
    assert hashes(work) == {**before, "L.obj": "link"}


def test_an_output_name_that_is_not_utf8_is_refused_before_the_work(tmp_path, capsys):
    name = os.fsdecode(b"bad\xff\xfename.obj")
    refused(["layout", "hyperbolic-paraboloid", "--net", "snet", "--panel-size", "2",
             "-o", str(tmp_path / name)], capsys, "not valid UTF-8")
    assert list(tmp_path.iterdir()) == []


def test_a_boundary_file_without_faces_means_no_boundary_panels(tmp_path, capsys):
    grid_net(tmp_path / "lay.obj")
    (tmp_path / "lay.boundary.obj").write_text("# no panels\n")
    assert main(["molds", str(tmp_path / "lay.obj"), "--tolerance-mm", "2",
                 "-o", str(tmp_path / "m"), "-q"]) in (0, 3)


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_a_second_signal_does_not_hang_the_cleanup(tmp_path):
    u, v = np.meshgrid(np.arange(25.0), np.arange(25.0), indexing="ij")
    net = tmp_path / "net.obj"
    QuadMesh.grid(np.stack([u, v, 0.02 * (u - 12) * (v - 12)], axis=-1)).write_obj(net)
    run = subprocess.Popen([*FABPLAN, "strips", str(net), "--height", "40", "--thickness", "4",
                            "--sheet", "400x300", "--workers", "2", "-o", str(tmp_path / "out")],
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    for line in run.stderr:
        if line.startswith("writing"):
            break
    run.send_signal(signal.SIGTERM)
    time.sleep(0.3)
    run.send_signal(signal.SIGTERM)
    _, err = run.communicate(timeout=60)
    # stopped by the first (exit 143), or, its cleanup done, by the second
    assert run.returncode in (128 + signal.SIGTERM, -signal.SIGTERM), err
    assert err.startswith("fabplan: stopped by SIGTERM")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["net.obj"]


def test_a_run_started_with_sighup_ignored_keeps_it_ignored(tmp_path):
    code = ("import signal, sys\nsignal.signal(signal.SIGHUP, signal.SIG_IGN)\n"
            "from fabplan.cli import stopped_by_signals\n"
            "with stopped_by_signals():\n"
            "    assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN\n"
            "    signal.raise_signal(signal.SIGHUP)\n"
            "print('alive')\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0 and run.stdout.strip() == "alive", run.stderr


@pytest.mark.slow
def test_strips_remove_only_their_own_earlier_files(tmp_path):
    """A strips run removes the sheets of an earlier run it no longer writes, but only
    files still as that run wrote them: a user's file named like a sheet, listed in a
    crafted strips.json, or a sheet edited since, stays."""
    net = fabplan.data_path("cmc1.obj")
    out = tmp_path / "strips"
    common = ["--height", "60", "--thickness", "4", "--workers", "1", "-q", "-o", str(out)]
    assert main(["strips", str(net), *common]) in (0, 3)
    sheets = sorted(out.glob("strips-sheet-*.dxf"))
    assert sheets
    edited, *rest = sheets
    edited.write_text(edited.read_text() + "\n", encoding="utf-8")
    record = json.loads((out / "strips.json").read_text())
    mine = out / "strips-sheet-999.png"
    mine.write_bytes(b"the user's own picture")
    record["files"].append(mine.name)
    (out / "strips.json").write_text(json.dumps(record), encoding="utf-8")
    # one file of every sheet: the separate sheets are no longer written
    assert main(["strips", str(net), *common, "--one-file"]) in (0, 3)
    assert (out / "strips-sheets.dxf").is_file()
    assert mine.read_bytes() == b"the user's own picture" and edited.is_file()
    assert not any(p.exists() for p in rest)


def test_a_candidate_with_strips_is_kept_for_resume(tmp_path, capsys):
    """A candidate that gets strips keeps them, their limits checked, in the cache: its
    strip plan's limit checks were a type the cache would not hold, so every candidate
    with strips was computed again on every resumed run."""
    text = (STUDY.format(name="mine").replace('net = "isogonal"\nangle = 80', 'net = "cmc"')
            + "[strips]\nheight_mm = 60\nthickness_mm = 4\nnets = \"all\"\n")
    (tmp_path / "s.toml").write_text(text, encoding="utf-8")
    out = tmp_path / "out"
    argv = ["study", str(tmp_path / "s.toml"), "-o", str(out), "--resume", "--workers", "1",
            "--no-3d"]
    main(argv)
    said = capsys.readouterr()
    assert "is not kept for --resume" not in said.out + said.err
    study = read_study(tmp_path / "s.toml")
    cache = CandidateCache(out, study)
    kept = [cache.load(c) for c in study.candidates]
    assert all(k is not None and k.strips is not None for k in kept)
    assert all(k.strips.limits for k in kept)
