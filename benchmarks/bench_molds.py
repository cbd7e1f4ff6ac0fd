"""Do neighbouring panels meet on their molds? Mold plans rechecked from their exports.

Run from the repository root::

    python benchmarks/bench_molds.py --study /tmp/st        # stadium nets of a study run
    python benchmarks/bench_molds.py --study /tmp/st --surface shared local_fit \
        --nets stadium-lw44 stadium-lw38 stadium-lw50 stadium-isogonal60 wein99
    python benchmarks/bench_molds.py --nets wein99

``--study DIR`` reads the candidates' ``net.obj`` (``DIR/candidates/linear-weingarten-44/``,
``baseline/`` and so on) of a ``fabplan study stadium -o DIR`` run (the study is run into a
temporary folder when no folder is given). Each net is planned with
`fabplan.plan_molds` (stadium nets at 1 mm, wein99 at 5 mm) for every panel surface asked
for, and the plan's ``molds.json`` record is measured by `measure_record`, which reads
only the net's vertices and faces and the record's molds and placements (no planner code):

- *step*: the midpoint of every shared edge is put on panel A's mold (closest point of
  ``z = (k1 x^2 + k2 y^2) / 2`` in A's placement), taken back to model coordinates by
  A's placement and measured against panel B's mold in B's placement; both ways, the
  larger counts. This is the step a fabricator sees between the two finished panels.
- *corner miss*: the distance of every panel's corners (net vertices) from its mold in its
  placement: whether the panel cast is the panel of the net.

The table printed (and written to ``benchmarks/results/molds-<label>.json``) has the
molds, the largest step, the edges with a step over twice the tolerance, the largest
corner miss and the panels whose corners miss by more than the tolerance; then where the
steps are: the *free vertices* (corners in no star, which no condition of an S-net holds:
the tips of a zigzag boundary), the edges over twice the tolerance at faces with such a
corner, the largest step at the other edges and between faces whose corners are all two
rings or more from the boundary, and the molds only faces with a free corner use.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
# the stadium template's candidates (its linear Weingarten angle searched in [36, 52])
STUDY_NETS = {"stadium-lw41": "linear-weingarten-41.3333", "stadium-baseline": "baseline",
              "stadium-lw36": "linear-weingarten-36", "stadium-lw44": "linear-weingarten-44",
              "stadium-lw52": "linear-weingarten-52", "stadium-isogonal60": "isogonal-60"}


# ----------------------------------------------------------------------------- the recheck
def closest_mold_points(q: np.ndarray, shape: np.ndarray, iterations: int = 30) -> np.ndarray:
    """Closest points of molds ``z = (k1 x^2 + k2 y^2) / 2`` to points.

    The closest point ``c`` of ``q`` has ``c_x = q_x / (1 + k1 t)``, ``c_y = q_y / (1 + k2 t)``
    with ``t = c_z - q_z``; ``t`` solves one scalar equation, by Newton's method.

    Parameters
    ----------
    q : (p, 3) float, points in mold coordinates (mm).
    shape : (p, 2) float, ``(k1, k2)`` of each point's mold (1/mm).

    Returns
    -------
    (p, 3) float, mm.
    """
    k1, k2 = shape[:, 0], shape[:, 1]
    x, y, z = q.T
    t = 0.5 * (k1 * x * x + k2 * y * y) - z
    for _ in range(iterations):
        a, b = 1.0 + k1 * t, 1.0 + k2 * t
        g = 0.5 * (k1 * x * x / a**2 + k2 * y * y / b**2) - z - t
        dg = -(k1 * k1 * x * x / a**3 + k2 * k2 * y * y / b**3) - 1.0
        t = t - g / dg
    a, b = 1.0 + k1 * t, 1.0 + k2 * t
    return np.column_stack([x / a, y / b, z + t])


def _apply(M: np.ndarray, p: np.ndarray) -> np.ndarray:
    return np.einsum("pij,pj->pi", M[:, :3, :3], p) + M[:, :3, 3]


def measure_record(vertices: np.ndarray, faces: list, record: dict) -> dict:
    """Steps between neighbouring molds and corner misses of a ``molds.json`` record.

    Parameters
    ----------
    vertices : (n, 3) float, the net's vertices (model units).
    faces : list of (k,) int arrays, the net's faces, in the order of the record's panels.
    record : the plan's JSON record (``fabplan-molds/1``).

    Returns
    -------
    dict with ``molds``, ``max_step_mm``, ``median_step_mm``, ``edges``,
    ``edges_over_2tol``, ``max_corner_miss_mm`` and ``panels_corner_over_tol``.
    """
    X = np.asarray(vertices, float)
    tol = float(record["tolerance_mm"])
    shapes = {m["id"]: (m["k1"], m["k2"]) for m in record["molds"]}
    by_face = {p["face"]: p for p in record["panels"]}
    M = np.array([by_face[f]["placement"] for f in range(len(faces))])        # (f, 4, 4)
    K = np.array([shapes[by_face[f]["mold"]] for f in range(len(faces))])    # (f, 2)
    sizes = np.array([len(f) for f in faces])
    face_of = np.repeat(np.arange(len(faces)), sizes)
    a = np.concatenate(faces)
    b = np.concatenate([np.roll(f, -1) for f in faces])
    # corners on their panels' molds
    q = _apply(M[face_of], X[a])
    corner = np.linalg.norm(q - closest_mold_points(q, K[face_of]), axis=1)
    worst_corner = np.zeros(len(faces))
    np.maximum.at(worst_corner, face_of, corner)
    # shared edges: the two faces of every undirected edge
    key = np.minimum(a, b) * len(X) + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    same = key[order][1:] == key[order][:-1]
    fa, fb = face_of[order][:-1][same], face_of[order][1:][same]
    ea, eb = np.minimum(a, b)[order][:-1][same], np.maximum(a, b)[order][:-1][same]
    mid = 0.5 * (X[ea] + X[eb])
    step = np.zeros(len(fa))
    for A, B in ((fa, fb), (fb, fa)):
        on_a = closest_mold_points(_apply(M[A], mid), K[A])
        back = np.linalg.solve(M[A][:, :3, :3], (on_a - M[A][:, :3, 3])[..., None])[..., 0]
        qb = _apply(M[B], back)
        step = np.maximum(step, np.linalg.norm(qb - closest_mold_points(qb, K[B]), axis=1))
    # where the steps are: at the faces with a free vertex (a corner in no star, held by
    # no condition of the net: the tips of a zigzag boundary) and in the interior rings
    free = free_vertices(X, faces)
    at_free = np.zeros(len(faces), bool)
    at_free[face_of[free[a]]] = True
    near = at_free[fa] | at_free[fb]
    ring = vertex_rings(X, faces)
    face_ring = np.full(len(faces), len(X))
    np.minimum.at(face_ring, face_of, ring[a])
    deep = (face_ring[fa] >= 2) & (face_ring[fb] >= 2)
    mold = np.array([by_face[f]["mold"] for f in range(len(faces))])
    return {
        "molds": int(record["mold_count"]),
        "free_vertices": int(free.sum()),
        "faces_with_a_free_vertex": int(at_free.sum()),
        "molds_only_for_faces_with_a_free_vertex": len(set(mold[at_free]) - set(mold[~at_free])),
        "edges_at_free_faces_over_2tol": int(np.sum(step[near] > 2 * tol)),
        "max_step_elsewhere_mm": float(step[~near].max()) if (~near).any() else 0.0,
        "edges_elsewhere_over_2tol": int(np.sum(step[~near] > 2 * tol)),
        "max_step_rings_2_and_in_mm": float(step[deep].max()) if deep.any() else 0.0,
        "panels": len(faces),
        "max_step_mm": float(step.max()) if step.size else 0.0,
        "median_step_mm": float(np.median(step)) if step.size else 0.0,
        "edges": int(step.size),
        "edges_over_2tol": int(np.sum(step > 2 * tol)),
        "max_corner_miss_mm": float(worst_corner.max()),
        "panels_corner_over_tol": int(np.sum(worst_corner > tol)),
        "reported_max_deviation_mm": float(record["max_deviation_mm"]),
        "reported_fits_all": bool(record["fits_all"]),
    }


def _edge_table(faces: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(h,) face, first and second vertex of every half-edge of the faces."""
    sizes = np.array([len(f) for f in faces])
    return (np.repeat(np.arange(len(faces)), sizes), np.concatenate(faces),
            np.concatenate([np.roll(f, -1) for f in faces]))


def free_vertices(X: np.ndarray, faces: list) -> np.ndarray:
    """(n,) bool, vertices in no star: neither an interior vertex with four edges nor one of
    its neighbours (no sphere or curvature condition of an S-net holds them)."""
    n = len(X)
    _, a, b = _edge_table(faces)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key, count = np.unique(lo * n + hi, return_counts=True)
    u, v = key // n, key % n
    boundary = np.zeros(n, bool)
    boundary[u[count == 1]] = boundary[v[count == 1]] = True
    valence = np.bincount(np.r_[u, v], minlength=n)
    centre = ~boundary & (valence == 4)
    held = centre.copy()
    held[u[centre[v]]] = held[v[centre[u]]] = True
    return ~held


def vertex_rings(X: np.ndarray, faces: list) -> np.ndarray:
    """(n,) int, edges from each vertex to the nearest boundary vertex."""
    n = len(X)
    _, a, b = _edge_table(faces)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key, count = np.unique(lo * n + hi, return_counts=True)
    u, v = key // n, key % n
    ring = np.full(n, n)
    ring[u[count == 1]] = ring[v[count == 1]] = 0
    for _ in range(n):
        new = ring.copy()
        np.minimum.at(new, u, ring[v] + 1)
        np.minimum.at(new, v, ring[u] + 1)
        if np.array_equal(new, ring):
            break
        ring = new
    return ring


# ----------------------------------------------------------------------------- the one surface
def sphere_consistency(mesh) -> dict:
    """How far the ``shared`` panel surface's curvature along each net edge at a star is
    from the curvature of the star's Meusnier sphere (1/m, model units m).

    For star centre v with discrete normal n (Def. 2.13) and edge neighbour w at distance
    L: the one surface's edge midpoint p lies ``s = ((v + w) / 2 - p) . n`` off the chord
    (away from n when the surface bends towards n), as on a circle of curvature
    ``2 s / (s^2 + L^2 / 4)`` through v and w; the sphere through the star and tangent to
    n at v has ``2 (w - v) . n / L^2`` (all four edges share it on an S-net). A tilt of n
    changes the sagitta only to second order.
    """
    from fabplan.fabricate.molds.panels import fit_panel_surfaces, shared_edge_points
    from fabplan.net.geometry import star_normals

    X, stars = mesh.vertices, mesh.stars
    if not len(stars):
        return {}
    edge = shared_edge_points(mesh, fit_panel_surfaces(mesh, "local_fit"), np.array([0.5]))[:, :, 0]
    midpoint = {}
    for f, face in enumerate(mesh.faces):
        for j, (a, b) in enumerate(zip(face, np.roll(face, -1), strict=True)):
            midpoint[(int(a), int(b))] = midpoint[(int(b), int(a))] = edge[f, j]
    n = star_normals(X, stars)
    diff = []
    for k in range(1, 5):
        v, w = stars[:, 0], stars[:, k]
        p = np.array([midpoint[(int(a), int(b))] for a, b in zip(v, w, strict=True)])
        c = X[w] - X[v]
        half = 0.25 * np.sum(c * c, 1)
        rise = np.sum((0.5 * (X[v] + X[w]) - p) * n, 1)
        diff.append(np.abs(2 * rise / (rise * rise + half) - 2 * np.sum(c * n, 1) / (4 * half)))
    diff = np.concatenate(diff)
    return {"edge_vs_sphere_curvature_median_per_m": float(np.median(diff)),
            "edge_vs_sphere_curvature_p95_per_m": float(np.percentile(diff, 95)),
            "edge_vs_sphere_curvature_max_per_m": float(diff.max())}


# ----------------------------------------------------------------------------- the cases
def _study_dir(given: str | None) -> Path:
    if given:
        return Path(given)
    out = Path(tempfile.mkdtemp(prefix="bench-molds-")) / "stadium"
    # exit 3 (no candidate meets every limit) still writes the nets measured here
    code = subprocess.run([sys.executable, "-m", "fabplan.cli", "study", "stadium", "-o", str(out),
                           "-q"]).returncode
    if code not in (0, 3):
        raise SystemExit(f"fabplan study stadium exited with {code}")
    return out


def cases(names: list[str], study: str | None) -> list[tuple[str, Path, float]]:
    """(name, OBJ path, tolerance mm) of the nets asked for."""
    import fabplan

    out = []
    if any(n in STUDY_NETS for n in names):
        root = _study_dir(study)
        out += [(n, root / "candidates" / STUDY_NETS[n] / "net.obj", 1.0)
                for n in names if n in STUDY_NETS]
    if "wein99" in names:
        out.append(("wein99", Path(fabplan.data_path("wein99.obj")), 5.0))
    return out


def main(argv: list[str] | None = None) -> int:
    import fabplan

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--nets", nargs="+", default=["stadium-lw44", "stadium-baseline", "wein99"],
                        help=f"among {', '.join([*STUDY_NETS, 'wein99'])}")
    parser.add_argument("--study", help="folder of a `fabplan study stadium -o` run")
    parser.add_argument("--surface", nargs="+", default=["auto"], help="panel surface models")
    parser.add_argument("--label", default=datetime.date.today().isoformat())
    args = parser.parse_args(argv)
    rows = []
    print("| net | surface | molds | largest step mm | edges over 2 x tol | "
          "largest corner miss mm | panels with a corner over tol | free vertices | "
          "edges over 2 x tol at their faces | largest step elsewhere mm | largest step, "
          "rings >= 2 mm | molds only their faces use | panels fitting no mold | s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, path, tol in cases(args.nets, args.study):
        mesh = fabplan.QuadMesh.from_obj(path)
        for surface in args.surface:
            t0 = time.perf_counter()
            record = fabplan.plan_molds(mesh, tolerance_mm=tol, units="m",
                                        panel_surface=surface).to_json()
            seconds = time.perf_counter() - t0
            row = {"net": name, "surface": surface, "model": record["panel_surface"],
                   "tolerance_mm": tol, "seconds": round(seconds, 1)}
            row.update(measure_record(mesh.vertices, mesh.faces, record))
            row["panels_fitting_no_mold"] = len(record["failures"])
            row["mold_reach_per_m"] = 1000.0 * record["curvature_reach_per_mm"]["median_panel"]
            if record["panel_surface"] == "shared":
                row.update(sphere_consistency(mesh))
            rows.append(row)
            print(f"| {name} | {row['model']} | {row['molds']} | {row['max_step_mm']:.2f} | "
                  f"{row['edges_over_2tol']} of {row['edges']} | {row['max_corner_miss_mm']:.2f} | "
                  f"{row['panels_corner_over_tol']} | {row['free_vertices']} | "
                  f"{row['edges_at_free_faces_over_2tol']} | {row['max_step_elsewhere_mm']:.2f} | "
                  f"{row['max_step_rings_2_and_in_mm']:.2f} | "
                  f"{row['molds_only_for_faces_with_a_free_vertex']} | "
                  f"{row['panels_fitting_no_mold']} | {seconds:.0f} |", flush=True)
    shared = [r for r in rows if "edge_vs_sphere_curvature_median_per_m" in r]
    if shared:
        print("\n| net | edge curvature - Meusnier sphere, median / p95 / max (1/m) "
              "| one mold's reach (1/m) |")
        print("|---|---|---|")
        for r in shared:
            print(f"| {r['net']} | {r['edge_vs_sphere_curvature_median_per_m']:.2g} / "
                  f"{r['edge_vs_sphere_curvature_p95_per_m']:.2g} / "
                  f"{r['edge_vs_sphere_curvature_max_per_m']:.2g} | {r['mold_reach_per_m']:.2g} |")
    RESULTS.mkdir(exist_ok=True)
    target = RESULTS / f"molds-{args.label}.json"
    target.write_text(json.dumps({"label": args.label, "rows": rows,
                                  "sqrt_panels": {r["net"]: math.sqrt(r["panels"]) for r in rows}},
                                 indent=1))
    print(f"wrote {target}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
