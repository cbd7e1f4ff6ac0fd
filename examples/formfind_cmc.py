"""Form-finding of a CMC surface from combinatorics (Fig. 18, top, of the paper).

The start is a coarse quad mesh with tetrahedral symmetry: four open tubes along the axes
to the vertices of a regular tetrahedron, joined at a core. Its combinatorics is the
diagonal mesh of a curvature-line layout of a tetranoid (umbilics of valence 6 at the
centres of the tetrahedron's faces). The optimizer turns it into an orthogonal S-net with
one common, free Meusnier radius: a discrete surface of constant mean curvature whose ends
narrow to a neck at the core and widen again (unduloids). No vertex is held and nothing
pulls towards the start (``closeness=False``); a fading fairness term keeps the net smooth.

The start's vertex positions are far from any such net: its stars are off their spheres by
up to 5 % of an edge, its intersection angles range from 57 to 106 degrees and its
Meusnier radii from 0.9 to 5.1; the net found has the common radius 1.48 and necks of
three quarters of the start's tube radius.

Run ``python examples/formfind_cmc.py -o out/``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

import fabplan
from fabplan.net.geometry import canonical_stars, fit_star_spheres, intersection_angles

# Unit vectors to the vertices of a regular tetrahedron (the four tube axes).
TETRAHEDRON = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]]) / np.sqrt(3)

# Form-finding needs fairness strong enough, and fading slowly enough, to hold the net
# together until it is close to its shape; residual-scaled damping (epsilon) keeps the
# early steps short. With the library defaults (fairness 1e-3 fading by 0.3 per iteration)
# this start converges in 10 iterations, but to a crumpled S-net (net lines bending by half
# an edge from star to star, edges down to 44 % of the mean); with longer ends (7 rings)
# these settings too end crumpled or with pinched necks.
SETTINGS = fabplan.SolverSettings(
    epsilon=0.3,
    fairness_weight=1.0,
    fade=0.95,
    max_iterations=400,
    stagnation=60,
    tolerance=1e-9,
)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _slerp(p: np.ndarray, q: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(k, 3) points on the great circle arc from unit `p` to unit `q` at fractions `t`."""
    angle = np.arccos(np.clip(p @ q, -1.0, 1.0))
    t = np.asarray(t, dtype=np.float64)[:, None]
    return (np.sin((1 - t) * angle) * p + np.sin(t * angle) * q) / np.sin(angle)


def _foot_point(axis: np.ndarray, towards: np.ndarray, polar: float) -> np.ndarray:
    """Point at polar angle `polar` from unit `axis` on the unit sphere, in the azimuth of `towards`."""
    side = _unit(towards - (towards @ axis) * axis)
    return np.cos(polar) * axis + np.sin(polar) * side


def _core_cell(face: int, tube: int, other: int, *, polar: float, rows: int,
               columns: int) -> np.ndarray:
    """(rows + 1, columns + 1, 3) grid of one core cell on the unit sphere.

    The cell lies between the foot circle of `tube` (row 0), the centre of the
    tetrahedron's face opposite vertex `face` (column 0 of the last row) and the point
    between `tube` and `other` (last column of the last row): the curvature-line layout of
    a tetranoid, whose umbilics sit at the four face centres.
    """
    x = TETRAHEDRON[tube]
    corner_face = _unit(-TETRAHEDRON[face])
    corner_saddle = _unit(TETRAHEDRON[tube] + TETRAHEDRON[other])
    u = np.linspace(0.0, 1.0, rows + 1)
    w = np.linspace(0.0, 1.0, columns + 1)
    foot_face = _foot_point(x, corner_face, polar)
    foot_saddle = _foot_point(x, corner_saddle, polar)
    # the foot arc runs at constant polar angle, its azimuth linear in w
    side_face, side_saddle = foot_face - np.cos(polar) * x, foot_saddle - np.cos(polar) * x
    azimuth = np.arccos(np.clip(_unit(side_face) @ _unit(side_saddle), -1, 1)) * w
    normal = _unit(np.cross(side_face, side_saddle))
    e1 = _unit(side_face)
    e2 = np.cross(normal, e1)
    arc = np.cos(polar) * x + np.sin(polar) * (np.cos(azimuth)[:, None] * e1
                                              + np.sin(azimuth)[:, None] * e2)
    far = _slerp(corner_face, corner_saddle, w)
    left = _slerp(foot_face, corner_face, u)
    right = _slerp(foot_saddle, corner_saddle, u)
    # bilinearly blended Coons patch of the four sides, pushed back onto the sphere
    U, W = u[:, None, None], w[None, :, None]
    coons = ((1 - U) * arc[None] + U * far[None] + (1 - W) * left[:, None] + W * right[:, None]
             - ((1 - U) * (1 - W) * arc[0] + (1 - U) * W * arc[-1]
                + U * (1 - W) * far[0] + U * W * far[-1]))
    return _unit(coons)


def _merge(points: np.ndarray, quads: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weld coincident points (cells share their sides) and renumber the quads."""
    key = np.round(points * 1e6).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    return points[first], inverse.ravel()[quads]


def _grid_quads(rows: int, columns: int, offset: int) -> np.ndarray:
    """(rows * columns, 4) quads of a (rows + 1) x (columns + 1) grid numbered row-major."""
    idx = offset + np.arange((rows + 1) * (columns + 1)).reshape(rows + 1, columns + 1)
    return np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]],
                    axis=-1).reshape(-1, 4)


def junction_distance(directions: np.ndarray, tube_radius: float,
                      sharpness: float) -> np.ndarray:
    """(k,) distance from the centre, along unit `directions`, to the start surface of the core.

    The core is a smoothed union of four solid cylinders of radius `tube_radius` around the
    tube axes: the ray along ``u`` leaves the cylinder around axis ``a`` at
    ``tube_radius / sin(u, a)``; the union takes the largest of these, smoothed by a power
    mean of exponent `sharpness` (the union itself has creases where two tubes meet).
    """
    cosine = np.clip(directions @ TETRAHEDRON.T, -1.0, 1.0)
    exit_ = np.where(cosine > 0, tube_radius / np.sqrt(1 - cosine**2 + 1e-300), 0.0)
    return np.sum(exit_**sharpness, axis=1) ** (1 / sharpness)


def tetrapod_layout(*, rows: int = 2, columns: int = 2, rings: int = 5, polar_deg: float = 30.0,
                    tube_radius: float = 0.5, sharpness: float = 4.0
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The curvature-line quad layout of a tetranoid: four tubes joined at a core.

    24 cells of ``rows x columns`` quads cover the core; each tube foot (at polar angle
    `polar_deg` from its axis, seen from the centre) is a ring of ``6 columns`` vertices,
    extruded by `rings` rings along the tube axis. Core points are placed along their
    directions by `junction_distance`. Rings are spaced so that the quads between them are
    squares (their diagonals, the edges of the S-net, then meet at right angles).

    Returns
    -------
    vertices : (n, 3) float
    quads : (q, 4) int, oriented with outward normals.
    centres : (q, 3) float, a point on the start surface inside each quad.
    """
    polar = np.radians(polar_deg)
    cells, quads, count = [], [], 0
    for face in range(4):
        corners = [v for v in range(4) if v != face]
        for tube in corners:
            for other in corners:
                if other == tube:
                    continue
                grid = _core_cell(face, tube, other, polar=polar, rows=rows, columns=columns)
                q = _grid_quads(rows, columns, count)
                # outward normals: rows run away from the tube, columns around it
                e_row, e_col = grid[1, 0] - grid[0, 0], grid[0, 1] - grid[0, 0]
                if np.cross(e_col, e_row) @ grid[0, 0] < 0:
                    q = q[:, ::-1]
                cells.append(grid.reshape(-1, 3))
                quads.append(q)
                count += grid.shape[0] * grid.shape[1]
    directions, quads = _merge(np.concatenate(cells), np.concatenate(quads))
    vertices = directions * junction_distance(directions, tube_radius, sharpness)[:, None]
    centres = _unit(directions[quads].mean(axis=1))
    centres *= junction_distance(centres, tube_radius, sharpness)[:, None]
    # extrude every boundary loop (a tube foot) along its tube axis
    boundary = fabplan.QuadMesh(vertices, quads).boundary_edges
    foot = np.unique(boundary)
    axis = np.zeros_like(vertices)
    axis[foot] = TETRAHEDRON[np.argmax(vertices[foot] @ TETRAHEDRON.T, axis=1)]
    foot_radius = np.linalg.norm(np.cross(vertices[foot], axis[foot]), axis=1).mean()
    half_ring = foot_radius * np.pi / (6 * columns)
    ring_id = np.full((len(vertices), rings + 1), -1)
    ring_id[foot, 0] = foot
    new = []
    for j in range(1, rings + 1):
        ring_id[foot, j] = len(vertices) + (j - 1) * len(foot) + np.arange(len(foot))
        new.append(vertices[foot] + 2 * j * half_ring * axis[foot])
    p, q = boundary[:, 0], boundary[:, 1]
    tube_quads, tube_centres = [], []
    for j in range(rings):
        tube_quads.append(np.stack([ring_id[q, j], ring_id[p, j], ring_id[p, j + 1],
                                    ring_id[q, j + 1]], axis=1))
        # the middle of the arc p q, half a ring up the tube
        ax = axis[p]
        mid = vertices[p] + vertices[q]
        mid -= np.sum(mid * ax, axis=1, keepdims=True) * ax
        height = np.sum(vertices[p] * ax, axis=1, keepdims=True) + (2 * j + 1) * half_ring
        tube_centres.append(height * ax + foot_radius * _unit(mid))
    return (np.concatenate([vertices, *new]), np.concatenate([quads, *tube_quads]),
            np.concatenate([centres, *tube_centres]))


def diagonal_mesh(vertices: np.ndarray, quads: np.ndarray, centres: np.ndarray | None = None,
                  *, name: str = "diagonal mesh") -> fabplan.QuadMesh:
    """The quad mesh whose edges are the diagonals of `quads`.

    Vertices are the old vertices followed by one point per quad, `centres` ((q, 3),
    by default the centroids). Every interior edge
    ``(a, b)`` between faces ``f`` (on its left) and ``g`` becomes the quad
    ``(a, c_g, b, c_f)``, which keeps the orientation; a boundary edge ``(a, b)`` becomes
    the triangle ``(a, b, c_f)``, so the boundary stays the old one instead of zigzagging
    through vertices that no star would constrain.
    """
    n = len(vertices)
    a, b = quads.ravel(), np.roll(quads, -1, axis=1).ravel()
    left = n + np.repeat(np.arange(len(quads)), 4)
    key = a * n + b
    order = np.argsort(key)
    pos = np.clip(np.searchsorted(key[order], b * n + a), 0, len(key) - 1)
    interior = key[order][pos] == b * n + a
    right = left[order][pos]
    keep = interior & (a < b)
    diagonal = np.stack([a[keep], right[keep], b[keep], left[keep]], axis=1)
    ends = np.stack([a[~interior], b[~interior], left[~interior]], axis=1)
    if centres is None:
        centres = vertices[quads].mean(axis=1)
    points = np.concatenate([vertices, centres])
    return fabplan.QuadMesh(points, [*diagonal, *ends], name=name)


def tetrapod_mesh(*, rows: int = 2, columns: int = 2, rings: int = 5, polar_deg: float = 30.0,
                  tube_radius: float = 0.5, sharpness: float = 4.0) -> fabplan.QuadMesh:
    """The start net: the diagonal mesh of `tetrapod_layout`."""
    return diagonal_mesh(*tetrapod_layout(rows=rows, columns=columns, rings=rings,
                                          polar_deg=polar_deg, tube_radius=tube_radius,
                                          sharpness=sharpness), name="tetrapod")


def boundary_loops(mesh: fabplan.QuadMesh) -> list[np.ndarray]:
    """The vertex ids of each boundary loop (the open ends), in no particular order."""
    be = mesh.boundary_edges
    n = mesh.vertex_count
    graph = sp.coo_matrix((np.ones(len(be)), (be[:, 0], be[:, 1])), shape=(n, n))
    _, label = csgraph.connected_components(graph, directed=False)
    on = np.unique(be)
    return [on[label[on] == k] for k in np.unique(label[on])]


def second_differences(mesh: fabplan.QuadMesh) -> np.ndarray:
    """(s,) float, the larger of ``|v1 - 2v + v3|`` and ``|v2 - 2v + v4|`` at each star: how
    much the net lines bend from one edge to the next (small on a fair net, about an edge
    length on a crumpled one)."""
    X, stars = mesh.vertices, mesh.stars
    first = X[stars[:, 1]] - 2 * X[stars[:, 0]] + X[stars[:, 3]]
    second = X[stars[:, 2]] - 2 * X[stars[:, 0]] + X[stars[:, 4]]
    return np.maximum(np.linalg.norm(first, axis=1), np.linalg.norm(second, axis=1))


def measure_cmc(mesh: fabplan.QuadMesh) -> dict:
    """The defining properties of a discrete CMC net and its shape, from the vertices.

    Returns
    -------
    dict with the mean edge, the largest sphere residual of a star, the median Meusnier
    radius and the spread of the radii (model units), the intersection angle range
    (degrees), the shortest edge, the median and largest `second_differences`, the
    bounding-box diagonal, and per open end: its length
    (distance from the centroid of the net to the centroid of the end loop), the radius of
    the end loop and the neck radius (smallest distance from its axis, the line from the
    centroid to the end, of the vertices on the outer half of the end).
    """
    X = mesh.vertices
    stars = canonical_stars(X, mesh.stars)
    spheres = fit_star_spheres(X, stars)
    angles = np.degrees(intersection_angles(X, stars))
    edges = np.linalg.norm(X[mesh.edges[:, 0]] - X[mesh.edges[:, 1]], axis=1)
    centre = X.mean(axis=0)
    loops = boundary_loops(mesh)
    axes = np.array([_unit(X[loop].mean(axis=0) - centre) for loop in loops])
    lengths = np.array([np.linalg.norm(X[loop].mean(axis=0) - centre) for loop in loops])
    # every vertex belongs to the end whose axis it is most aligned with
    owner = np.argmax((X - centre) @ axes.T, axis=1)
    height = np.sum((X - centre) * axes[owner], axis=1)
    distance = np.linalg.norm(X - centre - height[:, None] * axes[owner], axis=1)
    beyond = height > 0.5 * lengths[owner]
    necks = np.array([distance[beyond & (owner == k)].min() for k in range(len(loops))])
    ends = np.array([distance[loop].mean() for loop in loops])
    bending = second_differences(mesh)
    return {
        "mean_edge": float(edges.mean()),
        "shortest_edge": float(edges.min()),
        "second_difference_median": float(np.median(bending)),
        "second_difference_max": float(bending.max()),
        "bounding_box_diagonal": float(np.linalg.norm(np.ptp(X, axis=0))),
        "sphere_residual_max": float(spheres.residual.max()),
        "radius_median": float(np.median(spheres.radius)),
        "radius_spread": float(np.ptp(spheres.radius)),
        "angle_min_deg": float(angles.min()),
        "angle_max_deg": float(angles.max()),
        "end_lengths": lengths.tolist(),
        "end_radii": ends.tolist(),
        "neck_radii": necks.tolist(),
    }


def format_record(title: str, record: dict) -> str:
    edge, radius = record["mean_edge"], record["radius_median"]
    return "\n".join([
        f"{title}:",
        f"  sphere residual / mean edge: max {record['sphere_residual_max'] / edge:.2e}",
        f"  Meusnier radius: median {radius:.6f}, spread / median "
        f"{record['radius_spread'] / radius:.2e}",
        f"  intersection angle: {record['angle_min_deg']:.6f} .. {record['angle_max_deg']:.6f} deg",
        f"  shortest edge / mean edge {record['shortest_edge'] / edge:.3f}, bounding box "
        f"diagonal {record['bounding_box_diagonal']:.4f}",
        f"  fairness, second differences / mean edge: median "
        f"{record['second_difference_median'] / edge:.3f}, max "
        f"{record['second_difference_max'] / edge:.3f}",
        "  ends (length, neck radius, end radius): " + ", ".join(
            f"({L:.4f}, {n:.4f}, {r:.4f})" for L, n, r in zip(
                record["end_lengths"], record["neck_radii"], record["end_radii"], strict=True)),
    ])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--outdir", default="out/", help="output folder (default: out/)")
    parser.add_argument("--rings", type=int, default=5, help="rings of quads along each end")
    args = parser.parse_args(argv)
    outdir = Path(args.outdir)
    outdir.mkdir(parents=True, exist_ok=True)

    start = tetrapod_mesh(rings=args.rings)
    start.write_obj(outdir / "formfind_cmc_start.obj",
                    header="start of examples/formfind_cmc.py: tetrahedrally symmetric tetrapod")
    print(format_record("start", measure_cmc(start)))
    print(f"optimizing {start.vertex_count} vertices, {len(start.stars)} stars, "
          f"{len(start.irregular_vertices)} irregular vertices into a CMC net")

    def progress(record) -> None:
        print(f"  iteration {record.iteration:3d}: hard residual {record.hard_residual:.3e}, "
              f"step {record.step:.3e}")

    result = fabplan.optimize(start, "cmc", closeness=False, fairness=True,
                              settings=SETTINGS, progress=progress)
    obj, json_path = result.write(outdir / "formfind_cmc.obj")
    print(f"{result.status} after {result.iterations} iterations in {result.seconds:.2f} s "
          f"(common Meusnier radius {result.parameters['radius']:.6f}); "
          f"wrote {obj} and {json_path}")
    print(format_record("result", measure_cmc(result.mesh)))
    return 0 if result.converged else 1


if __name__ == "__main__":
    sys.exit(main())
