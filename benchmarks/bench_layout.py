"""Layout benchmark: design surface -> S-net layout -> gliding optimization, against size.

Run from the repository root::

    python benchmarks/bench_layout.py                      # 10k, 50k, 200k triangles
    python benchmarks/bench_layout.py --sizes 10000        # one size
    python benchmarks/bench_layout.py --net isogonal --angle 75

The design surface is the freeform facade of the tests (a twisted saddle with a wave,
30 x 16 model units, negatively curved everywhere, no umbilics), triangulated with about
N triangles and written to an STL file, so every case goes the way of `fabplan layout`
on a modeller's mesh: reading and welding the STL, curvature estimated by libigl, no
analytic directions. Two panel sizes per surface:

- ``fixed``: panel 1.0, about 450 quads whatever the triangle count: the cost of a finer
  design mesh alone;
- ``scaled``: about one quad per 40 design triangles (panel ``sqrt(area * 40 / N)``): the
  net grows with the surface.

Each case is timed stage by stage: reading the STL, the layout's stages (from
`SurfaceLayout.seconds`), building the closest-point structure (libigl AABB tree), and
the gliding optimization. The closest-point share is measured by wrapping, in this script
only, `ReferenceSurface.__init__` (tree build), `ReferenceSurface.closest_points` (tree
queries: footpoints of the net's vertices every iteration, distances, hole centres) and
`closest_points_on_polylines` (footpoints on the boundary curves, brute force over
segments) with timers. Results are printed as a markdown table and written as JSON to
``benchmarks/results/layout-<date>.json``. The machine is shared: check ``uptime``.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import fabplan.solve.constraints.closeness as closeness
from fabplan.design.load import load_design
from fabplan.design.parametric import height_field
from fabplan.layout.surface_layout import glide, layout_surface
from fabplan.solve.reference import ReferenceSurface

RESULTS = Path(__file__).resolve().parent / "results"
WIDTH, DEPTH = 30.0, 16.0


def facade_height(x, y):
    return 0.03 * x * y + 0.5 * np.sin(0.2 * x) * np.cos(0.15 * y) + 0.004 * x * x


class Timers:
    """Accumulated seconds and calls of the wrapped closest-point functions."""

    def __init__(self):
        self.seconds: dict = {}
        self.calls: dict = {}

    def wrap(self, owner, name: str, label: str):
        original = getattr(owner, name)

        def timed(*args, **kwargs):
            start = time.perf_counter()
            try:
                return original(*args, **kwargs)
            finally:
                self.seconds[label] = self.seconds.get(label, 0.0) + time.perf_counter() - start
                self.calls[label] = self.calls.get(label, 0) + 1

        setattr(owner, name, timed)
        return original

    def reset(self):
        self.seconds.clear()
        self.calls.clear()


def run_case(triangles: int, regime: str, net: str, angle: float | None, timers: Timers,
             folder: Path) -> dict:
    surface = height_field(facade_height, width=WIDTH, depth=DEPTH)
    design = surface.triangulate(surface.resolution_for(triangles))
    stl = folder / f"facade-{triangles}.stl"
    design.write(stl)
    timers.reset()
    t0 = time.perf_counter()
    design = load_design(stl)
    read = time.perf_counter() - t0
    panel = 1.0 if regime == "fixed" else math.sqrt(design.area * 40 / len(design.triangles))
    t1 = time.perf_counter()
    layout = layout_surface(design, panel, angle=angle or 90.0)
    layout_seconds = time.perf_counter() - t1
    t2 = time.perf_counter()
    result = glide(layout, net, angle=angle)
    glide_seconds = time.perf_counter() - t2
    total = read + layout_seconds + glide_seconds
    props = result.properties
    iterations = [h for h in result.history if h["step"] > 0]
    closest = {k: round(v, 4) for k, v in timers.seconds.items()}
    closest_total = sum(timers.seconds.values())
    return {
        "triangles": int(len(design.triangles)),
        "regime": regime,
        "panel_size": panel,
        "net": net,
        "angle_deg": angle,
        "quads": int(np.sum(result.mesh.face_sizes == 4)),
        "vertices": int(result.mesh.vertex_count),
        "status": result.status,
        "iterations": result.iterations,
        "seconds": {
            "read_stl": round(read, 4),
            "layout": round(layout_seconds, 4),
            "layout_stages": layout.seconds,
            "glide": round(glide_seconds, 4),
            "glide_per_iteration_median": round(float(np.median([h["seconds"] for h in iterations])), 4)
            if iterations else None,
            "total": round(total, 4),
        },
        "closest_points": {
            "seconds": closest,
            "calls": dict(timers.calls),
            "total_seconds": round(closest_total, 4),
            "share_of_total": round(closest_total / total, 4),
        },
        "quality": {
            "sphere_residual_relative_max": props["sphere_residual_relative"]["max"],
            "distance_to_design_relative_to_panel_max":
                props["distance_to_design_relative_to_panel"]["max"],
            "edge_length_relative_to_panel": props["edge_length_relative_to_panel"],
            "intersection_angle_deg": [props["intersection_angle_deg"]["min"],
                                       props["intersection_angle_deg"]["max"]],
        },
    }


def environment() -> dict:
    root = Path(__file__).resolve().parent.parent

    def git(*args):
        try:
            return subprocess.run(["git", *args], cwd=root, capture_output=True, text=True,
                                  check=True).stdout.strip()
        except (OSError, subprocess.CalledProcessError):
            return None

    import igl
    import scipy

    return {
        "date": datetime.datetime.now().isoformat(timespec="seconds"),
        "commit": git("rev-parse", "HEAD"),
        "uncommitted": (git("status", "--porcelain", "fabplan") or "").splitlines(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "libigl": getattr(igl, "__version__", "unknown"),
        "cpus": os.cpu_count(),
        "load_average": os.getloadavg(),
    }


def table(records: list) -> str:
    lines = ["| triangles | panel | quads | iterations | read | layout | glide | total | "
             "closest points (share) | sphere res. | dist./panel | edges/panel |",
             "|---:|---|---:|---:|---:|---:|---:|---:|---|---:|---:|---|"]
    for r in records:
        s, c, q = r["seconds"], r["closest_points"], r["quality"]
        e = q["edge_length_relative_to_panel"]
        lines.append(
            f"| {r['triangles']:,} | {r['regime']} {r['panel_size']:.3g} | {r['quads']:,} | "
            f"{r['iterations']} ({r['status']}) | {s['read_stl']:.2f} | {s['layout']:.2f} | "
            f"{s['glide']:.2f} | {s['total']:.2f} | {c['total_seconds']:.2f} s "
            f"({100 * c['share_of_total']:.1f} %) | {q['sphere_residual_relative_max']:.1e} | "
            f"{q['distance_to_design_relative_to_panel_max']:.1e} | "
            f"{e['min']:.2f} .. {e['max']:.2f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[10_000, 50_000, 200_000],
                        help="approximate triangle counts of the design surface")
    parser.add_argument("--regimes", nargs="+", default=["fixed", "scaled"],
                        choices=["fixed", "scaled"])
    parser.add_argument("--net", default="orthogonal")
    parser.add_argument("--angle", type=float, default=None)
    parser.add_argument("--output", type=Path, default=None)
    args = parser.parse_args(argv)
    timers = Timers()
    timers.wrap(ReferenceSurface, "__init__", "aabb_build")
    timers.wrap(ReferenceSurface, "closest_points", "aabb_queries")
    timers.wrap(closeness, "closest_points_on_polylines", "boundary_curve_queries")
    records = []
    with tempfile.TemporaryDirectory() as folder:
        for size in args.sizes:
            for regime in args.regimes:
                record = run_case(size, regime, args.net, args.angle, timers, Path(folder))
                records.append(record)
                print(table([record]).splitlines()[-1], file=sys.stderr)
    print(table(records))
    out = args.output or RESULTS / f"layout-{datetime.date.today().isoformat()}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".json.tmp")
    tmp.write_text(json.dumps({"environment": environment(), "cases": records}, indent=2) + "\n")
    os.replace(tmp, out)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
