"""Peak memory of the commands against the sizes known before their work: the figures
behind the resource guards of `fabplan.io.resources`.

Run from the repository root::

    python benchmarks/bench_memory.py                      # every workload, three sizes each
    python benchmarks/bench_memory.py --workloads molds mill

Each run is one ``python -m fabplan.cli`` process under ``/usr/bin/time -v``; its
"Maximum resident set size" is the peak. The nets are grids on a saddle
``z = 0.02 (x^2 - y^2)`` with unit panels (model units metres), for `mill` a dome
``z = -(x^2 + y^2) / (4 w)`` of width ``w`` planned without the simulation, whose cost
per grid cell is measured apart (``mill-simulation``: the same 2,500 faces in cm, the
``--sim-step`` giving the cells); the designs are the
built-in hyperbolic paraboloid triangulated with ``--triangles N``. The fit is
``peak = base + slope * size`` by least squares over the sizes; the table and the fit
are printed and written to ``benchmarks/results/memory.json`` (a workload run again
replaces its record).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
ROOT = Path(__file__).resolve().parents[1]


def grid_net(path: Path, faces: int, *, dome: bool = False) -> None:
    """A grid net of about `faces` unit quads on a saddle (or a dome, for milling from one
    side), written to `path`."""
    from fabplan.net.mesh import QuadMesh

    side = round(faces ** 0.5) + 1
    u, v = np.meshgrid(np.arange(side, dtype=float), np.arange(side, dtype=float), indexing="ij")
    u, v = u - u.mean(), v - v.mean()
    # a dome of radius twice its width: the safety spheres hold a 40 mm cutter at any size
    z = -(u**2 + v**2) / (4 * side) if dome else 0.02 * (u**2 - v**2)
    QuadMesh.grid(np.stack([u, v, z], axis=-1)).write_obj(path)


def saddle_triangles(path: Path, triangles: int) -> None:
    """A binary STL of about `triangles` triangles on the same saddle."""
    side = round((triangles / 2) ** 0.5) + 1
    u, v = np.meshgrid(np.linspace(-10, 10, side), np.linspace(-10, 10, side), indexing="ij")
    P = np.stack([u, v, 0.02 * (u**2 - v**2)], axis=-1).reshape(-1, 3)
    i = (np.arange(side - 1)[:, None] * side + np.arange(side - 1)[None, :]).ravel()
    T = np.concatenate([np.stack([i, i + side, i + side + 1], 1), np.stack([i, i + side + 1, i + 1], 1)])
    record = np.zeros(len(T), dtype=[("n", "<f4", (3,)), ("c", "<f4", (3, 3)), ("a", "<u2")])
    record["c"] = P[T]
    path.write_bytes(b"saddle".ljust(80, b" ") + len(T).to_bytes(4, "little") + record.tobytes())


#: workload -> (sizes, what the size counts, argv maker(folder, size) -> argv)
WORKLOADS = {
    "molds": ([2_500, 10_000, 40_000], "faces",
              lambda f, n: ["molds", str(f / "net.obj"), "--tolerance-mm", "5", "--no-3d", "-q",
                            "-o", str(f / "out")]),
    "mill": ([2_500, 10_000, 40_000], "faces",
             lambda f, n: ["mill", str(f / "net.obj"), "--units", "m", "--tool", "face:D=40",
                           "--no-simulation", "-q", "-o", str(f / "out")]),
    # the simulation grid of a 2,500-face dome 500 mm wide at 250,000 and 1 million cells
    "mill-simulation": ([250_000, 1_000_000], "cells",
                        lambda f, n: ["mill", str(f / "net.obj"), "--units", "cm", "--tool",
                                      "face:D=40", "--sim-step", f"{500 / n ** 0.5:.3f}",
                                      "-q", "-o", str(f / "out")]),
    "layout-triangles": ([100_000, 400_000, 1_600_000], "triangles",
                         lambda f, n: ["layout", "hyperbolic-paraboloid", "--net", "snet",
                                       "--panel-size", "2", "--triangles", str(n), "--max-iter",
                                       "3", "-q", "-o", str(f / "out" / "l.obj")]),
    "reference-file": ([100_000, 400_000, 1_600_000], "triangles",
                       lambda f, n: ["optimize", str(f / "net.obj"), "--net", "snet", "--reference",
                                     str(f / "design.stl"), "--max-iter", "2", "-q",
                                     "-o", str(f / "out" / "o.obj")]),
}


def peak_of(argv: list[str], folder: Path) -> tuple[float, float, int]:
    """(peak resident memory in bytes, wall seconds, exit code) of one fabplan command."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    started = time.perf_counter()
    run = subprocess.run(["/usr/bin/time", "-v", sys.executable, "-m", "fabplan.cli", *argv],
                         cwd=folder, env=env, capture_output=True, text=True)
    seconds = time.perf_counter() - started
    kb = re.search(r"Maximum resident set size \(kbytes\): (\d+)", run.stderr)
    if kb is None:
        raise RuntimeError(run.stderr[-2000:])
    return int(kb.group(1)) * 1024.0, seconds, run.returncode


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workloads", nargs="+", choices=list(WORKLOADS), default=list(WORKLOADS))
    args = parser.parse_args()
    sys.path.insert(0, str(ROOT))
    path = RESULTS / "memory.json"
    records = json.loads(path.read_text()) if path.is_file() else {}
    for name in args.workloads:
        sizes, unit, make = WORKLOADS[name]
        rows = []
        for size in sizes:
            with tempfile.TemporaryDirectory() as tmp:
                folder = Path(tmp)
                faces = {"reference-file": 400, "mill-simulation": 2_500}.get(name, size)
                grid_net(folder / "net.obj", faces, dome=name.startswith("mill"))
                if name == "reference-file":
                    saddle_triangles(folder / "design.stl", size)
                peak, seconds, code = peak_of(make(folder, size), folder)
            rows.append({"size": size, "peak_bytes": peak, "seconds": seconds, "exit": code})
            print(f"{name:<18} {size:>10,} {unit:<10} peak {peak / 2**20:8.0f} MiB  "
                  f"{seconds:6.1f} s  exit {code}", flush=True)
        x = np.array([r["size"] for r in rows], float)
        y = np.array([r["peak_bytes"] for r in rows])
        slope, base = np.polyfit(x, y, 1)
        print(f"{name:<18} fit: {base / 2**20:.0f} MiB + {slope:,.0f} bytes per {unit[:-1]}")
        records[name] = {"unit": unit, "rows": rows, "base_bytes": base, "bytes_per_unit": slope}
        RESULTS.mkdir(exist_ok=True)
        path.write_text(json.dumps(records, indent=1) + "\n")


if __name__ == "__main__":
    main()
