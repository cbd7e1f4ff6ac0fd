"""The calls a Rhino 8 Python script (or a Grasshopper Python component) makes to fabplan.

In Rhino 8 the script editor runs CPython, and ``# r: fabplan`` at the top of a script
installs fabplan into it. A script takes a Rhino mesh (the net), gives fabplan its
vertices and faces as arrays, and turns what comes back into Rhino geometry again::

    # r: fabplan
    import Rhino.Geometry as rg
    import scriptcontext as sc
    net = rs.coercemesh(rs.GetObject("net", 32))     # or a Grasshopper mesh input
    solved, molds, arcs = plan(net)                  # this file's `plan`
    mesh = to_rhino_mesh(solved.vertices, solved.faces, rg)
    curves = to_rhino_arcs(arcs, rg)

Every function here works with RhinoCommon (``Rhino.Geometry``) and with rhino3dm, which
stands in for it outside Rhino: the test of this example (``tests/test_api.py``) runs it
on a .3dm file written with rhino3dm. Run it as
``python examples/grasshopper.py NET.3dm -o OUT.3dm``.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

import numpy as np

import fabplan


def mesh_arrays(mesh: Any) -> tuple[np.ndarray, list[list[int]]]:
    """(V, F) of a Rhino mesh: vertices in double precision, quads and triangles as they are.

    RhinoCommon's faces are ``MeshFace`` objects (``A, B, C, D``, ``IsQuad``); rhino3dm's
    are tuples ``(a, b, c, d)`` with ``c == d`` for a triangle.
    """
    count = mesh.Vertices.Count if hasattr(mesh.Vertices, "Count") else len(mesh.Vertices)
    points = [mesh.Vertices.Point3dAt(i) for i in range(count)]
    V = np.array([[p.X, p.Y, p.Z] for p in points], dtype=np.float64)
    F = []
    for k in range(mesh.Faces.Count):
        face = mesh.Faces[k]
        a, b, c, d = (face.A, face.B, face.C, face.D) if hasattr(face, "A") else face
        F.append([a, b, c] if c == d else [a, b, c, d])
    return V, F


def to_rhino_mesh(V: np.ndarray, F: list, geometry: Any) -> Any:
    """A Rhino mesh (of `geometry`: ``Rhino.Geometry`` or ``rhino3dm``) from (V, F)."""
    mesh = geometry.Mesh()
    mesh.Vertices.UseDoublePrecisionVertices = True
    for x, y, z in np.asarray(V, dtype=np.float64).tolist():
        if hasattr(mesh.Vertices, "AddPoint3d"):     # rhino3dm keeps doubles this way
            mesh.Vertices.AddPoint3d(x, y, z)
        else:
            mesh.Vertices.Add(x, y, z)
    for face in F:
        mesh.Faces.AddFace(*[int(i) for i in face])
    return mesh


def to_rhino_arcs(arcs: fabplan.ArcStructure, geometry: Any) -> list:
    """One ArcCurve per edge (a LineCurve where the arc is straight), built from three
    points of the arc: its ends and its middle."""
    X = arcs.mesh.vertices
    middle = arcs.points(0.5)
    curves = []
    for k, (v, w) in enumerate(arcs.edges.tolist()):
        a, m, b = (geometry.Point3d(*p) for p in (X[v].tolist(), middle[k].tolist(), X[w].tolist()))
        if arcs.straight[k]:
            curves.append(geometry.LineCurve(a, b))
            continue
        arc = geometry.Arc(a, m, b)
        make = getattr(geometry.ArcCurve, "CreateFromArc", None)     # rhino3dm
        curves.append(make(arc) if make else geometry.ArcCurve(arc))  # RhinoCommon
    return curves


def plan(net: Any, *, tolerance_mm: float = 5.0, units: str = "m") -> tuple:
    """The script's work: solve the Rhino mesh as an S-net, plan its molds, build its arcs.

    Returns
    -------
    solved : `fabplan.NetResult` (``.vertices``, ``.faces``, ``.converged``, ``.to_json()``)
    molds : `fabplan.MoldResult` (``.mold`` per face, ``.to_json()``)
    arcs : `fabplan.ArcStructure`
    """
    V, F = mesh_arrays(net)
    solved = fabplan.optimize((V, F), "snet")
    molds = fabplan.plan_molds(solved, tolerance_mm=tolerance_mm, units=units)
    arcs = fabplan.arcs(solved)
    return solved, molds, arcs


def main(argv: list[str] | None = None) -> int:
    """Read the first mesh of a .3dm file, plan it, write the net, panels by mold and arcs
    into a new .3dm file (what the script would add to the Rhino document)."""
    import rhino3dm

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("net", help="a .3dm file whose first mesh is the net")
    parser.add_argument("-o", "--output", required=True, help="the .3dm file to write")
    args = parser.parse_args(argv)
    doc = rhino3dm.File3dm.Read(args.net)
    net = next(o.Geometry for o in doc.Objects if isinstance(o.Geometry, rhino3dm.Mesh))
    solved, molds, arcs = plan(net)
    out = rhino3dm.File3dm()
    out.Settings.ModelUnitSystem = rhino3dm.UnitSystem.Meters
    net_layer = out.Layers.AddLayer("net", (170, 170, 170, 255))
    arc_layer = out.Layers.AddLayer("arcs", (200, 40, 40, 255))
    attributes = rhino3dm.ObjectAttributes()
    attributes.LayerIndex = net_layer
    attributes.SetUserString("status", solved.status)
    attributes.SetUserString("molds", str(molds.mold_count))
    out.Objects.AddMesh(to_rhino_mesh(solved.vertices, solved.faces, rhino3dm), attributes)
    for k, curve in enumerate(to_rhino_arcs(arcs, rhino3dm)):
        attributes = rhino3dm.ObjectAttributes()
        attributes.LayerIndex = arc_layer
        attributes.Name = f"edge {k}"
        out.Objects.AddCurve(curve, attributes)
    if not out.Write(args.output, 8):
        print(f"could not write {args.output}", file=sys.stderr)
        return 2
    summary = arcs.summary()
    print(f"{solved.net}: {solved.status}; {molds.mold_count} molds for {molds.panel_count} "
          f"panels; {summary['arcs']} arcs, tangent-plane defect up to "
          f"{summary['tangent_plane_defect_deg']['max']:.1e} deg")
    return 0


if __name__ == "__main__":
    sys.exit(main())
