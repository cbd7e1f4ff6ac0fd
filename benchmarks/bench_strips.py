"""How long `fabplan strips` takes on the bundled net, against an earlier checkout.

Run from the repository root::

    git worktree add /tmp/fabplan-old <commit>          # the code to compare against
    python benchmarks/bench_strips.py --old /tmp/fabplan-old
    python benchmarks/bench_strips.py --old /tmp/fabplan-old --rounds 3 --workers 1 2

Each round runs ``fabplan strips fabplan/data/wein99.obj --height 100 --thickness 6``
once with the earlier checkout and once per ``--workers`` value with this one, in that
order (alternating, so that a change in the machine's load falls on both), each in its own
process (``PYTHONPATH`` set to the checkout). Wall and CPU times (user + system, of the
process and its children) are recorded, with ``uptime`` before and after.

The files are then compared, sheet by sheet: the DXF bytes with the header's dates and
GUIDs (and ezdxf's creation stamp) masked and the CLASSES and OBJECTS sections sorted
(ezdxf writes some in an order that changes from run to run, in the earlier code too),
every LWPOLYLINE's points and bulges read back
with ezdxf (largest difference in mm), and the preview PNGs pixel by pixel. The table is
printed and written to ``benchmarks/results/strips-<date>.json``.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
RESULTS = Path(__file__).resolve().parent / "results"
COMMAND = ["strips", "fabplan/data/wein99.obj", "--height", "100", "--thickness", "6"]
STAMPS = (b"$TDCREATE", b"$TDUCREATE", b"$TDUPDATE", b"$TDUUPDATE", b"$TDINDWG",
          b"$TDUSRTIMER")


def run_strips(checkout: Path, out: Path, extra: list[str]) -> dict:
    """Run the command with `checkout` first on the path; wall and CPU seconds."""
    shutil.rmtree(out, ignore_errors=True)
    env = dict(os.environ, PYTHONPATH=str(checkout))
    code = "import sys; from fabplan.cli import main; sys.exit(main())"
    command = [str(ROOT / c) if c.endswith(".obj") else c for c in COMMAND]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    # run outside both checkouts: `python -c` puts the working folder first on the path
    subprocess.run([sys.executable, "-c", code, *command, "-o", str(out), *extra],
                   cwd=out.parent, env=env, check=True, capture_output=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"wall_s": round(wall, 2), "cpu_s": round(cpu, 2)}


def masked_lines(data: bytes) -> list[bytes]:
    """The lines of a DXF file with the dates, GUIDs and ezdxf's creation stamp masked, and
    the classes and objects sorted (ezdxf writes some in an order that changes from run
    to run)."""
    lines = data.split(b"\n")
    for i in range(len(lines) - 2):
        if lines[i].strip() in STAMPS:
            lines[i + 2] = b"<date>"
    lines = [re.sub(rb"\{[0-9A-F-]{36}\}", b"<guid>", re.sub(rb" @ \d{4}-\S*", b" @ <time>", line))
             for line in lines]
    pairs = [(lines[i].strip(), lines[i + 1]) for i in range(0, len(lines) - 1, 2)]
    for name in (b"CLASSES", b"OBJECTS"):
        start = next((i for i in range(len(pairs) - 1) if pairs[i] == (b"0", b"SECTION")
                      and pairs[i + 1] == (b"2", name)), None)
        if start is None:
            continue
        stop = next(i for i in range(start, len(pairs)) if pairs[i] == (b"0", b"ENDSEC"))
        chunks: list[list] = []
        for pair in pairs[start + 2:stop]:
            if pair[0] == b"0" or not chunks:
                chunks.append([])
            chunks[-1].append(pair)
        pairs[start + 2:stop] = [pair for c in sorted(chunks) for pair in c]
    return [b"%s\n%s" % p for p in pairs]


def polylines(path: Path) -> list[tuple[str, bool, np.ndarray]]:
    """Layer, closed flag and (m, 3) rows ``x, y, bulge`` of every LWPOLYLINE, read back."""
    import ezdxf

    doc = ezdxf.readfile(str(path))
    return [(e.dxf.layer, bool(e.closed), np.array(list(e.get_points("xyb")), dtype=np.float64))
            for e in doc.modelspace().query("LWPOLYLINE")]


def compare_outputs(old: Path, new: Path) -> dict:
    """Compare two output folders: DXF bytes (masked), polylines, PNG pixels."""
    from PIL import Image

    names = sorted(p.name for p in old.glob("*.dxf"))
    if names != sorted(p.name for p in new.glob("*.dxf")):
        raise SystemExit(f"the DXF files differ in name: {old} and {new}")
    bytes_differ, worst, entities = 0, 0.0, 0
    for name in names:
        if masked_lines((old / name).read_bytes()) != masked_lines((new / name).read_bytes()):
            bytes_differ += 1
        a, b = polylines(old / name), polylines(new / name)
        if len(a) != len(b) or any(x[:2] != y[:2] or x[2].shape != y[2].shape
                                   for x, y in zip(a, b, strict=True)):
            raise SystemExit(f"{name}: the polylines differ in number, layer or shape")
        entities += len(a)
        for x, y in zip(a, b, strict=True):
            worst = max(worst, float(np.abs(x[2] - y[2]).max(initial=0.0)))
    pngs = sorted(p.name for p in old.glob("*.png"))
    pixels_differ = sum(
        not np.array_equal(np.asarray(Image.open(old / n)), np.asarray(Image.open(new / n)))
        for n in pngs)
    return {"dxf_files": len(names), "lwpolylines": entities,
            "dxf_differing_beyond_stamps": bytes_differ, "largest_difference_mm": worst,
            "png_files": len(pngs), "png_differing_in_pixels": pixels_differ}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", type=Path, required=True, help="checkout of the earlier code")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--workers", nargs="+", default=["1", "2"],
                        help="--workers values to run this checkout with (default 1 2)")
    parser.add_argument("--label", default=datetime.date.today().isoformat())
    args = parser.parse_args(argv)
    rows: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp:
        folders = {"old": Path(tmp) / "old"} | {f"new-w{w}": Path(tmp) / f"new-w{w}"
                                                 for w in args.workers}
        for r in range(args.rounds):
            for label, out in folders.items():
                load = os.getloadavg()[0]
                if label == "old":
                    times = run_strips(args.old.resolve(), out, [])
                else:
                    times = run_strips(ROOT, out, ["--workers", label.removeprefix("new-w")])
                rows.append({"round": r + 1, "code": label, **times,
                             "load_1min_before": round(load, 2)})
                print(f"round {r + 1} {label:8s} {times['wall_s']:6.1f} s wall "
                      f"{times['cpu_s']:6.1f} s cpu (load {load:.2f})", flush=True)
        checks = {label: compare_outputs(folders["old"], out)
                  for label, out in folders.items() if label != "old"}
    uptime = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    best = {label: min(r["wall_s"] for r in rows if r["code"] == label) for label in folders}
    record = {"command": "fabplan " + " ".join(COMMAND), "old": str(args.old),
              "cpus": os.cpu_count(), "uptime_after": uptime, "runs": rows,
              "best_wall_s": best,
              "speedup_best": {k: round(best["old"] / v, 2) for k, v in best.items()},
              "files": checks}
    print(json.dumps({k: record[k] for k in ("best_wall_s", "speedup_best", "files")}, indent=1))
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"strips-{args.label}.json").write_text(json.dumps(record, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
