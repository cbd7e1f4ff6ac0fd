"""Do two commits write the same files? Every template study and a set of command examples,
run with this checkout and with an earlier commit, their outputs compared file by file.

For moves that must not change a result (a module split, a function cut into steps)::

    python benchmarks/same_outputs.py --against d3ef6c3            # about 6 min idle
    python benchmarks/same_outputs.py --against d3ef6c3 --keep /tmp/outputs

What is set aside, since it differs between two runs of the same code: times (JSON keys
naming seconds, timings or dates, CSV columns of seconds, "done in 3 s" and progress
lines), dates and random ids (DXF header dates and handles' GUIDs, IFC GUIDs, PDF dates),
the SHA-256 of such files, and the output folders' names. PDFs are compared by their text
(spaces aside: a timing's length rewraps its line) and their drawing; ``.3dm`` files by
their objects (geometry as rhino3dm encodes it, name, layer) and layers. Everything else
must be equal to the byte. Each run uses ``PYTHONHASHSEED=0`` (ezdxf writes its objects in
set order). Exit 0 when every file is equal, 1 when one differs or exists on one side only.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import zlib
from pathlib import Path

from bench_study import ROOT, RUN, checkout

TEMPLATES = ("canopy", "pavilion", "stadium", "tower")

#: command examples: (name, arguments); OUT is the output folder, DATA the bundled nets
EXAMPLES = [
    ("layout", "layout paraboloid --net snet --panel-size 0.8 --html --3dm --ifc "
               "-o OUT/layout/net.obj"),
    ("layout-z", "layout tower-facade --net snet --panel-size 2 --family z -o OUT/layoutz/net.obj"),
    ("optimize", "optimize OUT/layout/net.obj --net linear-weingarten --angle 45 "
                 "--reference paraboloid --max-deviation 0.05 --html -o OUT/opt/lw.obj"),
    ("optimize-cmc", "optimize DATA/cmc1.obj --net cmc --html -o OUT/optc/cmc.obj"),
    ("molds", "molds DATA/wein99.obj --tolerance-mm 5 --material glass-tempered:8mm --3dm --ifc "
              "-o OUT/molds"),
    ("molds-layout", "molds OUT/opt/lw.obj --tolerance-mm 2 --units m -o OUT/molds2"),
    ("strips", "strips DATA/wein99.obj --height 60 --thickness 4 --3dm -o OUT/strips"),
    ("strips-layout", "strips OUT/layout/net.obj --height 60 --thickness 4 --units m "
                      "-o OUT/strips2"),
    ("mill", "mill DATA/wein99.obj --tool face:D=3 -o OUT/mill"),
    ("arcs", "arcs DATA/wein99.obj -o OUT/arcs.dxf"),
    ("arcs-3dm", "arcs DATA/wein99.obj -o OUT/arcs.3dm"),
    ("measure", "measure DATA/wein99.obj -o OUT/measure.json"),
    ("bad-input", "molds /nonexistent.obj --tolerance-mm 5 -o OUT/bad"),
]

#: keys and columns of times, dates and hashes of them: whole words of a snake_case name
#: (a bare "date" matched "candidates", and the study's candidates went uncompared)
TIME_KEY = re.compile(r"(?:^|_)(?:sha256|seconds?|timings?|elapsed|wall|created|date|time|"
                      r"duration|timestamp)(?:_|$)", re.I)
MASKS = [
    (rb"\d{4}-\d\d-\d\d[T ]\d\d:\d\d(:\d\d(\.\d+)?)?([+-]\d\d:?\d\d|Z)?", b"DATE"),
    (rb"\d{4}-\d\d-\d\d", b"DATE"), (rb"\b\d\d:\d\d(:\d\d)?\b", b"TIME"),
    (rb"[0-9a-fA-F]{8}-[0-9a-fA-F]{4}-[0-9a-fA-F]{4}-[0-9a-fA-F]{4}-[0-9a-fA-F]{12}", b"UUID"),
    (rb"'[0-9A-Za-z_$]{22}'", b"'GUID'"),
    (rb"\b24\d\d\d\d\d\.\d+", b"JULIAN"), (rb"D:\d{14}[^)]*", b"PDFDATE"),
    (rb"(total|layout|optimize|molds|strips|solve|mill|search|measure) \d+(\.\d+)? ?s",
     rb"\1 T"),
    (rb"\d+(\.\d+)? ?(s|ms|min|seconds)(?![a-z])", b"T"),
]


def run_examples(code: Path, out: Path) -> None:
    """Every template study and command example with the code in `code`, into `out`."""
    out.mkdir(parents=True)
    env = dict(os.environ, PYTHONPATH=str(code), PYTHONHASHSEED="0")
    data = code / "fabplan" / "data"
    runs = [(f"study-{t}", f"study {t} -o OUT/study-{t} -q --3dm --ifc") for t in TEMPLATES]
    for name, arguments in runs + EXAMPLES:
        argv = arguments.replace("OUT", str(out)).replace("DATA", str(data)).split()
        done = subprocess.run([sys.executable, "-c", RUN, *argv], cwd=out.parent, env=env,
                              capture_output=True)
        (out / f"{name}.stdout").write_bytes(done.stdout + f"rc {done.returncode}\n".encode())
        (out / f"{name}.stderr").write_bytes(done.stderr)
        print(f"  {code.name}: {name}: exit {done.returncode}", file=sys.stderr)


def _text(data: bytes, folders: dict[bytes, bytes]) -> bytes:
    """Text with its times, dates, ids and `folders` (path -> name) masked, its progress
    lines left out."""
    for folder, name in folders.items():
        data = data.replace(folder, name)
    lines = [line for line in data.split(b"\n")
             if not re.search(rb"\.\.\.$|: done in |^\s+\.\.\. ", line)]
    data = b"\n".join(lines)
    for pattern, replacement in MASKS:
        data = re.sub(pattern, replacement, data)
    return data


def _without_times(value):
    if isinstance(value, dict):
        return {k: _without_times(v) for k, v in value.items() if not TIME_KEY.search(k)}
    if isinstance(value, list):
        return [_without_times(v) for v in value]
    return value


def _pdf(data: bytes, folders: dict[bytes, bytes]) -> bytes:
    """A PDF's text (spaces aside) and drawing, from its decompressed streams."""
    streams = []
    for match in re.finditer(rb"stream\r?\n(.*?)endstream", data, re.S):
        try:
            streams.append(zlib.decompress(match.group(1)))
        except zlib.error:
            streams.append(match.group(1))
    whole = b"\n".join(streams)
    texts = b"\n".join(re.findall(rb"BT.*?ET", whole, re.S))
    glyphs = b"".join(re.findall(rb"\(((?:\\.|[^)\\])*)\)", texts))
    drawing = re.sub(rb"BT.*?ET", b"BT ET", whole, flags=re.S)
    return re.sub(rb"\s", b"", _text(glyphs, folders)) + b"\n--\n" + _text(drawing, folders)


def _3dm(path: Path) -> bytes:
    import rhino3dm

    model = rhino3dm.File3dm.Read(str(path))
    objects = [(json.dumps(o.Geometry.Encode(), sort_keys=True), o.Attributes.Name,
                o.Attributes.LayerIndex) for o in model.Objects]
    return repr((objects, [layer.FullPath for layer in model.Layers],
                 model.Settings.ModelUnitSystem)).encode()


def comparable(path: Path, folders: dict[bytes, bytes]) -> bytes:
    """The bytes of `path` that must be equal between two runs; `folders` (path -> name)
    are the run's own folders, masked."""
    data = path.read_bytes()
    if path.suffix == ".json":
        try:
            return _text(json.dumps(_without_times(json.loads(data)), sort_keys=True,
                                    indent=0).encode(), folders)
        except ValueError:
            pass
    if path.suffix == ".csv":
        rows = list(csv.reader(io.StringIO(_text(data, folders).decode("utf-8", "replace"))))
        if rows:
            keep = [i for i, head in enumerate(rows[0]) if not TIME_KEY.search(head)]
            return repr([[r[i] for i in keep if i < len(r)] for r in rows]).encode()
    if path.suffix == ".pdf":
        return _pdf(data, folders)
    if path.suffix == ".3dm":
        return _3dm(path)
    if path.suffix == ".html":
        data = re.sub(rb"(time|seconds)</td><td class=\"num\">[^<]*", rb"\1 T", data)
    return _text(data, folders)


def compare(old: Path, new: Path, old_code: Path, new_code: Path) -> list[str]:
    """The files that differ, or exist on one side only, as lines to print; `old_code`
    and `new_code` the code folders of the runs (named in messages)."""
    mask_old = {str(old).encode(): b"OUT", str(old_code).encode(): b"CODE"}
    mask_new = {str(new).encode(): b"OUT", str(new_code).encode(): b"CODE"}
    before = {p.relative_to(old) for p in old.rglob("*") if p.is_file()}
    after = {p.relative_to(new) for p in new.rglob("*") if p.is_file()}
    found = [f"only in {'the earlier' if p in before else 'this'} run: {p}"
             for p in sorted(before ^ after)]
    found += [f"differs: {p}" for p in sorted(before & after)
              if comparable(old / p, mask_old) != comparable(new / p, mask_new)]
    return found


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", required=True, help="the earlier commit")
    parser.add_argument("--keep", type=Path, help="a new folder to leave both runs' files in")
    args = parser.parse_args(argv)
    work = Path(tempfile.mkdtemp(prefix="fabplan-same-"))
    try:
        old_code = checkout(args.against, work / "code")
        run_examples(old_code, work / "same-outputs-old")
        run_examples(ROOT, work / "same-outputs-new")
        found = compare(work / "same-outputs-old", work / "same-outputs-new", old_code, ROOT)
        count = sum(1 for p in (work / "same-outputs-new").rglob("*") if p.is_file())
        print("\n".join(found) if found else
              f"{count} files, every one the same as with {args.against} (times, dates and "
              "ids set aside)")
        if args.keep:
            shutil.copytree(work / "same-outputs-old", args.keep / "old")
            shutil.copytree(work / "same-outputs-new", args.keep / "new")
        return 1 if found else 0
    finally:
        subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force",
                        str(work / "code")], check=False, capture_output=True)
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
