"""Flank milling with a cone on an S*-net: a saddle-shaped mold finished by a 45 deg cutter.

The part is the saddle ``z = -x^2 / (2 * 250) + y^2 / (2 * 70)`` (mm): hollow across y
(radius 70 mm) and slightly domed along x (radius 250 mm), the mold of a saddle-shaped
panel. A quad grid with lines at +-45 degrees to the axes, 3 mm apart (a diamond of 85 mm
diagonals), is optimized into a general S*-net (`fabplan optimize --net sstar`): contact
elements whose five tangent planes per star touch one Mannheim sphere, here 32 .. 68 mm
in radius on the hollow side. A cone of 45 deg half angle (a 45 deg chamfer or lead-angle
cutter: 24 mm at the tip, 44 mm where the 10 mm flank ends) then cuts with its flank
along the first family, circumscribed to safety spheres inside the Mannheim spheres
(`fabplan.fabricate.milling.flank_milling`), and the cut is simulated
(`fabplan.fabricate.milling.mill_simulation`). The S*-net leaves the saddle by up to 0.05 mm as it
is optimized: the passes are placed on the saddle itself (`DESIGN`, the same surface as a
built-in spec) and the cut is measured against it, the net's own distance from it reported
beside (`fabplan.fabricate.milling.mill_design`).

Run ``python examples/mill_cone_saddle.py -o out/cone``: writes ``start.obj``, ``net.obj``
(with its ``vn`` normals) and the files of `fabplan mill` (``path.cl``, ``path.csv``,
``mill.json``, ``report.html``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import fabplan
from fabplan.design.load import load_design
from fabplan.fabricate.milling import MillSettings, parse_tool
from fabplan.fabricate.milling.mill_report import MillResult, mill_net, write_mill_report
from fabplan.fabricate.milling.mill_simulation import SimulationSettings
from fabplan.net.mesh import QuadMesh

RADIUS_X_MM = 250.0    # domed along x
RADIUS_Y_MM = 70.0     # hollow across y
HALF_MM = 30.0         # half side of the grid in its own (diagonal) coordinates
STEP_MM = 3.0
TOOL = "cone:angle=45,length=10,tip=24"
SCALLOP_MM = 0.025
#: the saddle as `fabplan mill --design` reads it: z = x^2 / (2 rx) + y^2 / (2 ry)
DESIGN = f"paraboloid:radius_x={-RADIUS_X_MM:g},radius_y={RADIUS_Y_MM:g},width=45,depth=45"


def saddle_start() -> QuadMesh:
    """The start: a grid on the saddle with lines at +-45 degrees to the axes (mm)."""
    u = np.arange(-HALF_MM, HALF_MM + STEP_MM / 2, STEP_MM)
    U, V = np.meshgrid(u, u, indexing="ij")
    x, y = (U - V) / np.sqrt(2), (U + V) / np.sqrt(2)
    z = -x**2 / (2 * RADIUS_X_MM) + y**2 / (2 * RADIUS_Y_MM)
    return QuadMesh.grid(np.stack([x, y, z], axis=-1), name="saddle")


def make_net(folder: Path) -> QuadMesh:
    """Optimize the start into a general S*-net (as ``fabplan optimize start.obj --net
    sstar``); write ``start.obj`` and ``net.obj``."""
    folder.mkdir(parents=True, exist_ok=True)
    start = saddle_start()
    start.write_obj(folder / "start.obj")
    result = fabplan.optimize(QuadMesh.from_obj(folder / "start.obj"), "sstar")
    if not result.converged:
        raise RuntimeError(f"the S*-net did not converge: {result.status}")
    result.write(folder / "net.obj")
    return QuadMesh.from_obj(folder / "net.obj")


def main(argv: list[str] | None = None, *, simulation: SimulationSettings | None = None
         ) -> MillResult:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", default="out/cone", help="output folder")
    args = parser.parse_args(argv)
    folder = Path(args.output)
    mesh = make_net(folder)
    result = mill_net(mesh, parse_tool(TOOL), MillSettings(along="A", units="mm",
                                                           scallop_mm=SCALLOP_MM),
                      simulation=simulation, design=load_design(DESIGN))
    write_mill_report(result, folder)
    print(result.summary())
    return result


if __name__ == "__main__":
    main(sys.argv[1:])
