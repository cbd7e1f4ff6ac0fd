"""A design continued past its edges, and the nets solved on it (`fabplan.layout.margin`)."""

import numpy as np
import pytest

from fabplan.design.mesh_surface import DesignSurface
from fabplan.design.parametric import hyperbolic_paraboloid, revolution
from fabplan.layout.margin import (
    continued_design,
    design_layout,
    faces_on_design,
    held_vertices,
)


def test_a_saddle_is_continued_on_the_same_grid():
    saddle = hyperbolic_paraboloid(width=4.0, depth=3.0, rise=1.0).triangulate((12, 9))
    more = continued_design(saddle, 1.0)
    assert more is not None
    (u0, u1), (v0, v1) = more.design.parametric.domain
    # whole cells of the grid, an even number of them on each side
    assert u0 < -5.0 and u1 > 5.0 and v0 < -4.0 and v1 > 4.0
    cells_u = round((-4.0 - u0) / (8.0 / 12))
    assert cells_u % 2 == 0 and np.isclose(-4.0 - cells_u * 8.0 / 12, u0)
    # the design's own triangles, corner for corner
    mine = np.sort(saddle.vertices[saddle.triangles].reshape(-1, 9), axis=1)
    theirs = np.sort(more.design.vertices[more.design.triangles[more.inside]].reshape(-1, 9), axis=1)
    assert np.allclose(mine, theirs, atol=1e-12)
    # points over the design and past its edge
    inner = saddle.vertices[saddle.triangles[:, 0]].mean(axis=0, keepdims=True) * 0.5
    outer = more.design.parametric.points(np.array([-4.8]), np.array([0.0]))
    assert more.on_design(np.vstack([inner, outer])).tolist() == [True, False]


def test_a_closed_tower_is_continued_up_and_down_only():
    profile = np.array([[10.0, 0.0], [10.5, 5.0], [11.5, 10.0]])
    tower = revolution(profile).triangulate((24, 10))
    more = continued_design(tower, 2.0)
    assert more is not None
    (u0, u1), (v0, v1) = more.design.parametric.domain
    assert (u0, u1) == tower.parametric.domain[0]
    assert v0 <= -2.0 and v1 >= 12.0
    assert len(more.inside) == len(tower.triangles)


def _bezier_roof():
    """A bicubic Bezier patch over 3 x 3 m: control points (4, 4, 3) and its knots."""
    grid = np.stack(np.meshgrid(np.linspace(0, 3, 4), np.linspace(0, 3, 4), indexing="ij"), -1)
    P = np.concatenate([grid, 0.1 * (grid[..., :1] - 1.5) ** 2 - 0.05 * grid[..., 1:]], axis=-1)
    return P, np.r_[0.0, 0, 0, 0, 1, 1, 1, 1]


def test_an_untrimmed_nurbs_surface_is_continued_with_its_edge_curvature():
    from math import comb

    from fabplan.design.nurbs import NurbsSurface

    P, knots = _bezier_roof()
    patch = NurbsSurface(P, None, knots, knots, 3, 3).triangulate(8)
    more = continued_design(patch, 1.0)
    assert more is not None and len(more.inside) == len(patch.triangles)
    surface = more.design.parametric
    (u0, u1), (v0, v1) = surface.domain
    assert u0 < 0 and u1 > 1 and v0 < 0 and v1 > 1

    def bezier(u, v):
        # the patch written here on its own, with Bernstein polynomials
        def bernstein(t):
            return np.stack([comb(3, i) * t ** i * (1 - t) ** (3 - i) for i in range(4)], -1)
        return np.einsum("ni,nj,ijc->nc", bernstein(np.atleast_1d(u)), bernstein(np.atleast_1d(v)), P)

    # on the design it is the patch
    u, v = np.array([0.0, 0.3, 1.0]), np.array([0.7, 0.0, 1.0])
    np.testing.assert_allclose(surface.points(u, v), bezier(u, v), atol=1e-12)
    # past an edge, the second-order expansion about the edge with the second
    # derivative's normal part (derivatives by differences)
    h, t = 1e-4, 0.15
    du = (bezier(1 + h, 0.4) - bezier(1 - h, 0.4)) / (2 * h)
    dv = (bezier(1.0, 0.4 + h) - bezier(1.0, 0.4 - h)) / (2 * h)
    duu = (bezier(1 + h, 0.4) - 2 * bezier(1.0, 0.4) + bezier(1 - h, 0.4)) / h ** 2
    normal = np.cross(du, dv)
    normal /= np.linalg.norm(normal)
    expected = bezier(1.0, 0.4) + t * du + 0.5 * t * t * np.sum(duu * normal) * normal
    np.testing.assert_allclose(surface.points(np.array([1 + t]), np.array([0.4])), expected,
                               atol=1e-6)
    # the continuation reaches a metre past every edge of the 3 x 3 m roof, and no farther
    # than its cells need
    lo, hi = more.design.vertices.min(axis=0), more.design.vertices.max(axis=0)
    assert lo[0] <= -1.0 + 1e-9 and hi[0] >= 4.0 - 1e-9
    assert lo[1] <= -1.0 + 1e-9 and hi[1] >= 4.0 - 1e-9
    assert lo[0] > -2.0 and hi[0] < 5.0


def test_a_design_without_a_formula_or_one_that_breaks_down_is_not_continued():
    saddle = hyperbolic_paraboloid(width=2.0, depth=2.0).triangulate(6)
    as_mesh = DesignSurface(saddle.vertices, saddle.triangles, name="mesh")
    assert continued_design(as_mesh, 1.0) is None
    # a trimmed NURBS face: its design is the region its trims bound
    from fabplan.design.nurbs import NurbsSurface

    P, knots = _bezier_roof()
    loop = np.array([[0.1, 0.1], [0.9, 0.1], [0.9, 0.9], [0.1, 0.9], [0.1, 0.1]])
    trimmed = NurbsSurface(P, None, knots, knots, 3, 3, trims=[loop]).triangulate(8)
    assert continued_design(trimmed, 1.0) is None
    # a profile whose radius reaches zero just below the design: the cells collapse
    cone = revolution(np.array([[0.5, 0.0], [3.0, 2.5], [5.5, 5.0]])).triangulate((16, 8))
    assert continued_design(cone, 3.0) is None


@pytest.mark.slow
def test_a_net_solved_past_the_edge_is_kept_on_the_design_and_trimmed_there():
    from fabplan.layout.surface_layout import glide, layout_surface
    from fabplan.layout.trim import OFF_DESIGN_TOUCH, add_boundary_panels
    from fabplan.solve.optimize import kept_faces, optimize

    design = hyperbolic_paraboloid(width=6.0, depth=6.0, rise=2.0).triangulate(60)
    more = continued_design(design, 2.0)
    layout = layout_surface(more.design, 1.0, angle=60)
    start = glide(layout, "snet", boundary_panels=False)
    held = held_vertices(start.mesh, more)
    solved = optimize(start.mesh, "linear-weingarten", angle=60,
                      reference=more.design.reference, max_deviation=0.05,
                      deviation_vertices=held)
    keep = faces_on_design(solved.mesh, more)
    assert 0 < keep.sum() < len(keep)
    net = kept_faces(solved, keep, design.reference, max_deviation=0.05)
    assert net.parameters["continued"]["faces_kept"] == int(keep.sum())
    # every vertex kept stands over the design, within the limit where it is held
    assert more.on_design(net.mesh.vertices).all()
    panels = add_boundary_panels(net, design_layout(layout, more, design),
                                 touch=OFF_DESIGN_TOUCH, follow_net=True,
                                 follow=(solved.mesh.vertices[held], more.design))
    assert panels is not None and panels.coverage > 0.995
    # the boundary panels stand off the design as the net solved past its edge does:
    # within its limit, not curling away
    extra = panels.vertices[panels.net_vertex_count:]
    assert design.distances(extra).max() <= 0.05 * 1.05
