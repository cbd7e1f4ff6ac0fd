"""Form-finding of a discrete minimal surface as an orthogonal A-net (Fig. 18, bottom left).

The boundary frame is held: the four boundary polylines of a grid on Enneper's surface in
asymptotic coordinates, a saddle-shaped closed space curve. The interior starts as the
hyperbolic paraboloid spanned by the frame's four corners -- neither minimal nor an A-net,
its two families meeting at 28 to 152 degrees -- and the optimizer finds the interior: every
vertex star planar (an A-net: the net lines are asymptotic) and the two families orthogonal,
so the principal curvatures are opposite and the mean curvature vanishes.

The result is checked with a measure that fabplan does not use: the mean curvature of a
quadric fitted to every interior vertex's two-ring, and the distance to the smooth Enneper
surface sampled at the same parameters.

Run ``python examples/formfind_minimal.py -o out/``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

import fabplan
from fabplan.net.geometry import canonical_stars, intersection_angles, star_planarity

# Form-finding needs the fairness term to hold the interior together until the net has
# nearly found its shape: strong fairness fading slowly. With the library defaults
# (fairness 1e-3 fading by 0.3 per iteration) the solve diverges from this start; weaker or
# faster-fading fairness stalls, or converges to one of the other, oscillating A-nets with
# the same boundary (the fixed-boundary problem has many; fairness selects the smooth one).
SETTINGS = fabplan.SolverSettings(
    epsilon=0.3,
    fairness_weight=1.0,
    fade=0.93,
    max_iterations=300,
    stagnation=40,
    tolerance=1e-9,
)


def enneper(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(..., 3) points of Enneper's minimal surface at curvature-line parameters (u, v)."""
    return np.stack([u - u**3 / 3 + u * v**2, v - v**3 / 3 + v * u**2, u**2 - v**2], axis=-1)


def enneper_grid(size: int, extent: float) -> np.ndarray:
    """(size, size, 3) samples of Enneper's surface on a grid of its asymptotic lines.

    The grid lines ``i = const`` and ``j = const`` run at 45 degrees to the curvature lines
    ``u``, ``v`` (asymptotic directions of a minimal surface); ``i, j`` cover
    ``[-extent, extent]``.
    """
    t = np.linspace(-extent, extent, size)
    i, j = np.meshgrid(t, t, indexing="ij")
    return enneper((i - j) / np.sqrt(2), (i + j) / np.sqrt(2))


def saddle_start(frame: np.ndarray) -> np.ndarray:
    """(m, k, 3) the boundary of `frame` kept, the interior on the hyperbolic paraboloid
    through its four corners (bilinear interpolation)."""
    m, k = frame.shape[:2]
    s = np.linspace(0.0, 1.0, m)[:, None, None]
    r = np.linspace(0.0, 1.0, k)[None, :, None]
    hypar = ((1 - s) * (1 - r) * frame[0, 0] + (1 - s) * r * frame[0, -1]
             + s * (1 - r) * frame[-1, 0] + s * r * frame[-1, -1])
    start = frame.copy()
    start[1:-1, 1:-1] = hypar[1:-1, 1:-1]
    return start


def two_rings(mesh: fabplan.QuadMesh, centres: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertices within two edges of each centre, padded.

    Returns
    -------
    ring : (c, k) int, the centre first, padded with the centre.
    valid : (c, k) bool, False on padding.
    """
    e = mesh.edges
    n = mesh.vertex_count
    adj = sp.coo_matrix((np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])),
                        shape=(n, n)).tocsr()
    reach = (adj + adj @ adj)[centres].tocsr()
    reach.setdiag(0)
    reach.eliminate_zeros()
    counts = np.diff(reach.indptr)
    k = 1 + counts.max()
    ring = np.repeat(centres[:, None], k, axis=1)
    rows = np.repeat(np.arange(len(centres)), counts)
    slots = 1 + np.arange(len(reach.indices)) - np.repeat(reach.indptr[:-1], counts)
    ring[rows, slots] = reach.indices
    valid = np.zeros(ring.shape, bool)
    valid[:, 0] = True
    valid[rows, slots] = True
    return ring, valid


def jet_curvatures(X: np.ndarray, ring: np.ndarray, valid: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Mean and Gaussian curvature of a quadric height function fitted to each two-ring.

    Each neighbourhood is put in a frame whose z axis is its least-squares plane normal,
    and ``z = a x^2 + b xy + c y^2 + d x + e y + f`` is fitted by least squares; the
    curvatures are those of the graph at the centre's foot point.

    Parameters
    ----------
    X : (n, 3) float, vertex positions.
    ring, valid : from `two_rings`.

    Returns
    -------
    H, K : (c,) float, mean curvature (sign up to the frame) and Gaussian curvature.
    """
    P = X[ring] - X[ring[:, :1]]
    w = valid.astype(np.float64)
    mean = np.sum(P * w[..., None], axis=1) / w.sum(axis=1)[:, None]
    _, _, vt = np.linalg.svd((P - mean[:, None]) * w[..., None])
    x, y, z = (np.einsum("ckj,cj->ck", P, vt[:, i]) for i in range(3))
    A = np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], axis=-1) * w[..., None]
    coef = np.linalg.solve(np.einsum("cki,ckj->cij", A, A),
                           np.einsum("cki,ck->ci", A, z * w)[..., None])[..., 0]
    a, b, c, d, e = (coef[:, i] for i in range(5))
    g = 1 + d * d + e * e
    H = ((1 + e * e) * 2 * a - 2 * d * e * b + (1 + d * d) * 2 * c) / (2 * g**1.5)
    K = (4 * a * c - b * b) / g**2
    return H, K


def second_differences(mesh: fabplan.QuadMesh) -> np.ndarray:
    """(s,) float, the larger of ``|v1 - 2v + v3|`` and ``|v2 - 2v + v4|`` at each star: how
    much the net lines bend from one edge to the next (small on a fair net)."""
    X, stars = mesh.vertices, mesh.stars
    first = X[stars[:, 1]] - 2 * X[stars[:, 0]] + X[stars[:, 3]]
    second = X[stars[:, 2]] - 2 * X[stars[:, 0]] + X[stars[:, 4]]
    return np.maximum(np.linalg.norm(first, axis=1), np.linalg.norm(second, axis=1))


def measure_minimal(mesh: fabplan.QuadMesh, exact: np.ndarray | None = None) -> dict:
    """The defining properties of a discrete minimal surface, measured on the vertices.

    Returns
    -------
    dict: star planarity, mean edge and largest `second_differences` (model units), the
    intersection angle range (degrees), the jet-fitted mean curvature on vertices at least
    three edges from the boundary, as ``|H| * diameter`` and as ``|k1 + k2| / |k1 - k2|``
    (0 on a minimal surface, 1 where one principal curvature vanishes), and the largest
    distance to `exact`.
    """
    X = mesh.vertices
    stars = canonical_stars(X, mesh.stars)
    angles = np.degrees(intersection_angles(X, stars))
    e = mesh.edges
    adj = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(mesh.vertex_count,) * 2)
    depth = csgraph.shortest_path(adj, directed=False, unweighted=True,
                                     indices=np.flatnonzero(mesh.is_boundary_vertex)).min(axis=0)
    inner = np.flatnonzero(depth >= 3)
    H, K = jet_curvatures(X, *two_rings(mesh, inner))
    spread = np.sqrt(np.maximum(H * H - K, 0.0))  # |k1 - k2| / 2
    diameter = float(np.linalg.norm(np.ptp(X, axis=0)))
    record = {
        "mean_edge": mesh.mean_edge_length,
        "diameter": diameter,
        "star_planarity_max": float(star_planarity(X, stars).max()),
        "second_difference_max": float(second_differences(mesh).max()),
        "angle_min_deg": float(angles.min()),
        "angle_max_deg": float(angles.max()),
        "inner_vertices": int(len(inner)),
        "mean_curvature_times_diameter_max": float(np.abs(H).max() * diameter),
        "mean_over_principal_max": float(np.max(np.abs(H) / spread)),
        "mean_over_principal_median": float(np.median(np.abs(H) / spread)),
    }
    if exact is not None:
        record["distance_to_exact_max"] = float(np.linalg.norm(X - exact, axis=1).max())
    return record


def format_record(title: str, record: dict) -> str:
    edge = record["mean_edge"]
    lines = [
        f"{title}:",
        f"  star planarity / mean edge: max {record['star_planarity_max'] / edge:.2e}",
        f"  intersection angle: {record['angle_min_deg']:.6f} .. {record['angle_max_deg']:.6f} deg",
        f"  fairness, second differences / mean edge: max {record['second_difference_max'] / edge:.3f}",
        f"  jet-fitted mean curvature on {record['inner_vertices']} inner vertices: "
        f"max |H| x diameter {record['mean_curvature_times_diameter_max']:.3e}, "
        f"|k1 + k2| / |k1 - k2| max {record['mean_over_principal_max']:.3e} "
        f"(median {record['mean_over_principal_median']:.3e})",
    ]
    if "distance_to_exact_max" in record:
        lines.append(f"  distance to the smooth Enneper surface / mean edge: max "
                     f"{record['distance_to_exact_max'] / edge:.3e}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--outdir", default="out/", help="output folder (default: out/)")
    parser.add_argument("--size", type=int, default=15, help="vertices along each family")
    parser.add_argument("--extent", type=float, default=0.9,
                        help="half width of the patch in Enneper's asymptotic parameters")
    args = parser.parse_args(argv)
    outdir = Path(args.outdir)
    outdir.mkdir(parents=True, exist_ok=True)

    frame = enneper_grid(args.size, args.extent)
    start = fabplan.QuadMesh.grid(saddle_start(frame), name="enneper-frame")
    fixed = np.flatnonzero(start.is_boundary_vertex)
    start.write_obj(outdir / "formfind_minimal_start.obj",
                    header="start of examples/formfind_minimal.py: Enneper frame, saddle interior")
    exact = frame.reshape(-1, 3)
    print(format_record("start", measure_minimal(start, exact)))
    reference = fabplan.QuadMesh.grid(frame)
    print(format_record("for comparison, the smooth Enneper surface sampled on the same grid "
                        "(an A-net, not quite orthogonal)", measure_minimal(reference, exact)))
    print(f"optimizing {start.vertex_count} vertices ({len(fixed)} held) into a minimal net")

    def progress(record) -> None:
        print(f"  iteration {record.iteration:3d}: hard residual {record.hard_residual:.3e}, "
              f"step {record.step:.3e}")

    # fabplan's measured principal curvatures are undefined on an A-net (planar stars) and
    # warn about it; this example measures the mean curvature itself, below
    with np.errstate(invalid="ignore", divide="ignore"):
        result = fabplan.optimize(start, "minimal", closeness=False, fairness=True,
                                  fixed=fixed, settings=SETTINGS, progress=progress)
    obj, json_path = result.write(outdir / "formfind_minimal.obj")
    print(f"{result.status} after {result.iterations} iterations in {result.seconds:.2f} s; "
          f"wrote {obj} and {json_path}")
    print(format_record("result", measure_minimal(result.mesh, exact)))
    return 0 if result.converged else 1


if __name__ == "__main__":
    sys.exit(main())
