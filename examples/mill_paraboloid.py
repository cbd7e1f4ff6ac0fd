"""Curvature-adaptive face milling of a mold: an orthogonal S-net on a paraboloid cap.

The part is the 150 x 150 mm cap of the elliptic paraboloid
``z = x^2 / (2 * 500) + y^2 / (2 * 520)`` (mm), a shallow mold 11 mm deep whose principal
radii differ by 4 % at the apex (its umbilics lie outside the cap). An orthogonal S-net
with panels of 9 mm is laid out on it and optimized gliding on the surface
(`fabplan.layout`); its Meusnier radii are the harmonic means of the principal radii
(paper section 3.2.4). A 50 mm face mill then finishes it along the first family
(`fabplan.fabricate.milling`), and the cut is simulated and compared with a ball end of the
same diameter along the same passes (`fabplan.fabricate.milling.mill_simulation`). The passes are
placed on the paraboloid itself and the cut is measured against it; the net's own distance
from it, and the cut measured against the net's surface, are reported beside
(`fabplan.fabricate.milling.mill_design`).

Run ``python examples/mill_paraboloid.py -o out/mill``: writes ``net.obj`` and the files of
`fabplan mill` (``path.cl``, ``path.csv``, ``mill.json``, ``report.html``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fabplan.design.load import load_design
from fabplan.fabricate.milling import MillSettings, parse_tool
from fabplan.fabricate.milling.mill_report import MillResult, mill_net, write_mill_report
from fabplan.fabricate.milling.mill_simulation import SimulationSettings
from fabplan.layout.surface_layout import glide, layout_surface

DESIGN = "paraboloid:radius_x=500,radius_y=520,width=75,depth=75"
PANEL_MM = 9.0
TOOL = "face:D=50"


def make_net(folder: Path, design):
    """Lay out and optimize the orthogonal S-net on the cap; write it to ``net.obj``."""
    layout = layout_surface(design, PANEL_MM, angle=90.0)
    result = glide(layout, "orthogonal")
    if not result.converged:
        raise RuntimeError(f"the layout did not converge: {result.message}")
    result.write(folder / "net.obj")
    return result.mesh


def main(argv: list[str] | None = None, *, simulation: SimulationSettings | None = None
         ) -> MillResult:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", default="out/mill", help="output folder")
    args = parser.parse_args(argv)
    folder = Path(args.output)
    design = load_design(DESIGN)
    mesh = make_net(folder, design)
    result = mill_net(mesh, parse_tool(TOOL), MillSettings(along="A", units="mm"),
                      simulation=simulation, design=design)
    write_mill_report(result, folder)
    print(result.summary())
    return result


if __name__ == "__main__":
    main(sys.argv[1:])
