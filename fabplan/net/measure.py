"""The measured properties of a net: what `fabplan measure` prints and every result carries.

Everything here is recomputed from the vertex positions with `fabplan.geometry`, never
copied from a solver's residuals.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .buildable import BuildLimits, measure_buildable
from .fairness import fairness_record
from .folds import SurfaceWithNormals, measure_folds
from .geometry import (
    canonical_stars,
    face_planarity,
    fit_mannheim_spheres,
    fit_star_spheres,
    intersection_angles,
    principal_curvatures,
    ruling_angles,
    star_planarity,
)

if TYPE_CHECKING:
    from .mesh import QuadMesh

__all__ = ["measure_net", "format_summary", "buildable_summary", "edge_jump_warning"]


def _stats(values: np.ndarray) -> dict:
    """min / max / median / mean of the finite values (None when there are none)."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return {"min": None, "max": None, "median": None, "mean": None, "count": 0}
    return {"min": float(v.min()), "max": float(v.max()), "median": float(np.median(v)),
            "mean": float(v.mean()), "count": int(v.size)}


def measure_net(mesh: QuadMesh, *, reference: SurfaceWithNormals | None = None,
                limits: BuildLimits | None = None) -> dict:
    """Measure the S-net properties of a quad mesh.

    Parameters
    ----------
    mesh : `fabplan.mesh.QuadMesh`
    reference : optional reference surface (`fabplan.solve.reference.ReferenceSurface` or a
        design surface's) to measure the distance to, and to judge flipped faces against.
    limits : what a buildable net keeps to (`fabplan.net.buildable.BuildLimits`; the
        default: lines turning by at most 90 deg, no deviation limit).

    Returns
    -------
    dict, JSON-ready. Lengths are in model units; ``*_relative`` values are divided by the
    mean edge length; angles are in degrees; ``folds`` holds the counts and element ids
    of `fabplan.net.folds.measure_folds`, ``buildable`` the non-convex and self-crossing
    faces, sharp line turns, edge jumps and far vertices of
    `fabplan.net.buildable.measure_buildable` with their worst places, ``fairness`` the
    line turns, edge ratios and angle range of `fabplan.net.fairness.fairness_record`
    with their worst places.
    """
    X = mesh.vertices
    L = mesh.mean_edge_length
    stars = canonical_stars(X, mesh.stars)
    sizes, counts = np.unique(mesh.face_sizes, return_counts=True)
    record: dict = {
        "vertices": mesh.vertex_count,
        "faces": int(len(mesh.face_sizes)),
        "face_sizes": {str(int(k)): int(c) for k, c in zip(sizes, counts, strict=True)},
        "regular_stars": int(len(stars)),
        "irregular_vertices": mesh.irregular_vertices.tolist(),
        "boundary_vertices": int(mesh.is_boundary_vertex.sum()),
        "mean_edge_length": L,
    }
    if len(stars):
        spheres = fit_star_spheres(X, stars)
        k1, k2 = principal_curvatures(X, stars, spheres.curvature)
        with np.errstate(invalid="ignore"):     # a collapsed star's curvatures: inf - inf
            mean_curvature = (k1 + k2) / 2      # (its stats keep the finite values only)
        record.update({
            "sphere_residual": _stats(spheres.residual),
            "sphere_residual_relative": _stats(spheres.residual / L),
            "meusnier_radius": _stats(spheres.radius),
            "normal_curvature": _stats(spheres.curvature),
            "intersection_angle_deg": _stats(np.degrees(intersection_angles(X, stars))),
            "principal_curvature_1": _stats(k1),
            "principal_curvature_2": _stats(k2),
            "mean_curvature": _stats(mean_curvature),
            "star_planarity_relative": _stats(star_planarity(X, stars) / L),
        })
    if mesh.normals is not None and len(stars):
        mannheim = fit_mannheim_spheres(X, mesh.normals, stars)
        record.update({
            "mannheim_residual_relative": _stats(mannheim.residual / L),
            "mannheim_radius": _stats(mannheim.radius),
            "ruling_angle_deg": _stats(np.degrees(ruling_angles(X, mesh.normals, stars))),
        })
    record["face_planarity_relative"] = _stats(face_planarity(X, mesh.quads) / L)
    if reference is not None:
        d = reference.distances(X)
        record["distance_to_reference"] = _stats(d)
        record["distance_to_reference_relative"] = _stats(d / L)
    folds = measure_folds(mesh, reference=reference)
    record["folds"] = folds.record()
    record["buildable"] = measure_buildable(mesh, reference=reference, limits=limits,
                                            folds=folds).record()
    record["fairness"] = fairness_record(mesh)
    return record


def _fmt(stats: dict | None, key: str = "max", spec: str = ".4g") -> str:
    if not stats or stats.get(key) is None:
        return "n/a"
    return format(stats[key], spec)


def format_summary(record: dict) -> str:
    """A few human-readable lines summarizing a `measure_net` record."""
    lines = [
        f"vertices {record['vertices']}, faces {record['faces']} "
        f"(sizes {record['face_sizes']}), regular stars {record['regular_stars']}, "
        f"irregular vertices {len(record['irregular_vertices'])}",
        f"mean edge length {record['mean_edge_length']:.6g}",
    ]
    if record["regular_stars"]:
        r = record["meusnier_radius"]
        a = record["intersection_angle_deg"]
        lines += [
            f"sphere residual / mean edge: max {_fmt(record['sphere_residual_relative'], 'max', '.3e')}"
            f", median {_fmt(record['sphere_residual_relative'], 'median', '.3e')}",
            f"Meusnier radius: {_fmt(r, 'min')} .. {_fmt(r, 'max')} (median {_fmt(r, 'median')})",
            f"intersection angle: {_fmt(a, 'min', '.4f')} .. {_fmt(a, 'max', '.4f')} deg",
            f"mean curvature: {_fmt(record['mean_curvature'], 'min')} .. "
            f"{_fmt(record['mean_curvature'], 'max')}",
        ]
    if "mannheim_radius" in record:
        m, a = record["mannheim_radius"], record["ruling_angle_deg"]
        lines += [
            f"Mannheim spheres (S*-net): residual / mean edge max "
            f"{_fmt(record['mannheim_residual_relative'], 'max', '.3e')}, radius {_fmt(m, 'min')} .. "
            f"{_fmt(m, 'max')}, ruling angle {_fmt(a, 'min', '.4f')} .. {_fmt(a, 'max', '.4f')} deg",
        ]
    lines.append(f"face planarity / mean edge: max {_fmt(record['face_planarity_relative'], 'max', '.3e')}")
    if "distance_to_reference" in record:
        d = record["distance_to_reference"]
        unit = record.get("units") or "model units"
        lines.append(f"distance to reference: max {_fmt(d, 'max', '.3e')}, mean "
                     f"{_fmt(d, 'mean', '.3e')} ({unit})")
    folds = record.get("folds")
    if folds:
        counts = [(folds["flipped_faces"]["count"], "flipped faces"),
                  (folds["fold_edges"]["count"], "fold edges"),
                  (folds["degenerate_stars"]["count"], "degenerate stars"),
                  (folds["collapsed_edges"]["count"], "collapsed edges")]
        lines.append("folds: " + (", ".join(f"{n} {what}" for n, what in counts if n) or "none"))
    build = record.get("buildable")
    if build:
        lines.append(buildable_summary(build, folds))
    turn = (record.get("fairness") or {}).get("line_turn_deg") or {}
    if turn.get("max") is not None:
        lines.append(f"lines turn in the surface by up to {turn['max']:.2f} deg (median "
                     f"{turn['median']:.2f}), worst at vertex {turn['vertex']}")
    return "\n".join(lines)


def buildable_summary(build: dict, folds: dict | None = None) -> str:
    """One line from the ``buildable`` part of a `measure_net` record (and its ``folds``,
    whose degenerate stars and collapsed edges keep a net from being built too): what
    keeps the net from being built, or that nothing does."""
    said = [(build["nonconvex_faces"], "non-convex faces"),
            (build["self_crossing_faces"], "self-crossing faces"),
            (build["sharp_line_turns"], f"vertices where a line turns more than "
             f"{build['sharp_line_turns']['turn_above_deg']:g} deg"),
            (build.get("far_vertices") or {"count": 0}, "vertices beyond the deviation limit")]
    if folds:
        said += [(folds["degenerate_stars"], "stars whose lines run together"),
                 (folds["collapsed_edges"], "collapsed edges")]
    found = ", ".join(f"{part['count']} {what}" for part, what in said if part["count"])
    jumps = build["edge_jumps"]
    jump = (f"; {jumps['count']} edge jumps over {jumps['ratio_above']:g}x along the lines"
            if jumps["count"] else "")
    if build["buildable"]:
        return f"buildable: no fold, dart or line doubling back{jump}"
    return f"not buildable: {found or 'folded'}{jump}"


def edge_jump_warning(build: dict | None) -> str | None:
    """The edge jumps of the ``buildable`` part of a net's record in plain words, or None
    when there are none: a net that meets its conditions with panels that change size
    abruptly along a line is buildable, but rarely what was meant.

    Examples
    --------
    >>> print(edge_jump_warning({"edge_jumps": {"count": 2, "ratio_above": 3.0,
    ...                          "worst": {"edge_ratio": 9.3, "id": 214}}})[:101])
    2 vertices where consecutive edges of a line differ more than 3x in length (up to 9.3x at vertex 214)
    """
    jumps = (build or {}).get("edge_jumps") or {}
    if not jumps.get("count"):
        return None
    worst = jumps.get("worst") or {}
    return (f"{jumps['count']} vertices where consecutive edges of a line differ more than "
            f"{jumps['ratio_above']:g}x in length (up to {worst.get('edge_ratio', float('nan')):.2g}x "
            f"at vertex {worst.get('id')}): the panels change size abruptly there, where the "
            "net's conditions pull it out of shape (ids under properties.buildable.edge_jumps)")

