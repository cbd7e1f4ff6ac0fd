"""Milling benchmark: time to plan and to simulate face and cone milling, and what the cut leaves.

Run from the repository root::

    python benchmarks/bench_mill.py            # the paraboloid example and a 10k-vertex net
    python benchmarks/bench_mill.py --quick    # the examples only
    python benchmarks/bench_mill.py --case cone-saddle

Cases:

- ``paraboloid``: the example's orthogonal S-net on the 150 x 150 mm paraboloid cap
  (`examples/mill_paraboloid.py`, 9 mm panels), 50 mm face mill, default margin, at the
  default scallop limit 0.01 mm and at 0.02 mm; planning, target
  height map, simulation of the adaptive cut and of the conventional ball end.
- ``bowl-100x100``: a 100 x 100 grid (10,000 vertices, 1.5 mm apart) on the inside of a
  sphere of radius 400 mm (every net on a sphere is an S-net), the same tool: planning,
  and the simulation of the adaptive cut on a 0.5 mm grid.
- ``cone-saddle``: flank milling with a cone (`examples/mill_cone_saddle.py`): the S*-net
  on the saddle mold from ``fabplan optimize --net sstar`` (its time included), the cone
  ``cone:angle=45,length=10,tip=24`` at the example's scallop limit; planning, target and
  simulation of the cut on a 0.5 mm grid.

Results are printed as a markdown table and written as JSON to
``benchmarks/results/mill-<date>.json``. The machine is shared: check ``uptime``.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fabplan.fabricate.milling import MillSettings, parse_tool  # noqa: E402
from fabplan.fabricate.milling.mill_report import mill_net  # noqa: E402
from fabplan.net.mesh import QuadMesh  # noqa: E402


def load_example(name: str):
    import importlib.util

    spec = importlib.util.spec_from_file_location(f"example_{name}", ROOT / "examples" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


CASES = ["paraboloid", "cone-saddle", "bowl-100x100"]


def paraboloid_net(folder: Path) -> QuadMesh:
    return load_example("mill_paraboloid").make_net(folder)


def bowl_net(count: int = 100, spacing: float = 1.5, radius: float = 400.0) -> QuadMesh:
    u = (np.arange(count) - (count - 1) / 2) * spacing
    x, y = np.meshgrid(u, u, indexing="ij")
    z = radius - np.sqrt(radius**2 - x**2 - y**2)
    return QuadMesh.grid(np.stack([x, y, z], axis=-1), name=f"bowl-{count}x{count}")


def run_case(name: str, mesh: QuadMesh, scallop: float, conventional: bool,
             tool: str = "face:D=50", extra_seconds: dict | None = None) -> dict:
    started = time.perf_counter()
    result = mill_net(mesh, parse_tool(tool), MillSettings(scallop_mm=scallop),
                      conventional=conventional)
    record = result.record()
    record["seconds"].update(extra_seconds or {})
    row = {"case": name, "tool": tool, "vertices": mesh.vertex_count, "scallop_limit_mm": scallop,
           "passes": record["passes"], "cutter_locations": record["cutter_locations"],
           "margin_mm": record["margin_mm"],
           "predicted_scallop_mm": record["predicted_scallop_mm"],
           "simulated_scallop_mm": record["simulation"]["max_scallop_mm"],
           "gouge_mm": record["simulation"]["max_gouge_mm"],
           "conventional_scallop_mm": record.get("comparison", {}).get("conventional_max_scallop_mm"),
           "seconds": record["seconds"], "wall_seconds": time.perf_counter() - started}
    ball = row["conventional_scallop_mm"]
    print(f"| {name} | {row['vertices']} | {scallop:g} | {row['passes']} | {row['margin_mm']:.3g} | "
          f"{row['predicted_scallop_mm']:.4f} | {row['simulated_scallop_mm']:.4f} | "
          f"{row['gouge_mm']:.4f} | {'-' if ball is None else f'{ball:.3f}'} | "
          f"{row['seconds']['plan']:.2f} | {row['seconds'].get('target', 0):.2f} | "
          f"{row['seconds'].get('simulate', 0):.1f} | {row['seconds'].get('conventional', 0):.1f} |",
          flush=True)
    return row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the examples only")
    parser.add_argument("--case", action="append", choices=CASES,
                        help="run only this case (repeatable)")
    parser.add_argument("--output", help="JSON file (default benchmarks/results/mill-<date>.json)")
    args = parser.parse_args(argv)
    cases = args.case or [c for c in CASES if not (args.quick and c == "bowl-100x100")]
    print("| case | vertices | scallop limit [mm] | passes | margin [mm] | predicted [mm] | "
          "simulated [mm] | gouge [mm] | ball end [mm] | plan [s] | target [s] | simulate [s] | "
          "ball end [s] |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    rows = []
    if "paraboloid" in cases:
        with tempfile.TemporaryDirectory() as tmp:
            mesh = paraboloid_net(Path(tmp))
        rows.append(run_case("paraboloid", mesh, 0.01, True))
        rows.append(run_case("paraboloid", mesh, 0.02, True))
    if "cone-saddle" in cases:
        with tempfile.TemporaryDirectory() as tmp:
            cone = load_example("mill_cone_saddle")
            clock = time.perf_counter()
            sstar = cone.make_net(Path(tmp))
            optimize_seconds = time.perf_counter() - clock
        rows.append(run_case("cone-saddle", sstar, cone.SCALLOP_MM, False, cone.TOOL,
                             {"optimize_sstar": optimize_seconds}))
    if "bowl-100x100" in cases:
        rows.append(run_case("bowl-100x100", bowl_net(), 0.01, False))
    out = Path(args.output or ROOT / "benchmarks" / "results" /
               f"mill-{datetime.date.today().isoformat()}.json")
    out.write_text(json.dumps({"load": os.getloadavg(), "cases": rows}, indent=2) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
