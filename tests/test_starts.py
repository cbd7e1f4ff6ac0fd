"""Several starts of one net on a design (`fabplan.layout.starts`): each laid out, solved
and measured, the fairest kept.

The line turns are measured here again, independently of `fabplan.net.fairness`: the
angle between consecutive edges of a line projected onto the plane normal to the star's
diagonals' cross product.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from fabplan.cli import main
from fabplan.design.parametric import surface_from_spec
from fabplan.errors import InputError
from fabplan.layout.settings import LayoutSettings
from fabplan.layout.starts import glide_fairest, layout_starts
from fabplan.layout.surface_layout import glide, layout_again, layout_surface
from fabplan.study.spec import parse_study
from fabplan.study.templates import template_path


def line_turns_p95(X: np.ndarray, stars: np.ndarray) -> float:
    """95th percentile of both lines' turns at every star (degrees), in the star's plane."""
    P = X[stars]
    n = np.cross(P[:, 3] - P[:, 1], P[:, 4] - P[:, 2])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    turns = []
    for a, b in ((1, 3), (2, 4)):
        d0, d1 = P[:, 0] - P[:, a], P[:, b] - P[:, 0]
        d0 -= np.sum(d0 * n, axis=1, keepdims=True) * n
        d1 -= np.sum(d1 * n, axis=1, keepdims=True) * n
        c = np.sum(d0 * d1, axis=1) / np.linalg.norm(d0, axis=1) / np.linalg.norm(d1, axis=1)
        turns.append(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))
    return float(np.percentile(np.concatenate(turns), 95))


@pytest.fixture(scope="module")
def tower():
    """The built-in tower facade, laid out at about 120 panels."""
    surface = surface_from_spec("tower-facade")
    design = surface.triangulate(surface.resolution_for(8000))
    return design, math.sqrt(design.area / 120)


def edge_spread(mesh) -> float:
    """Longest edge over the shortest, measured here."""
    length = np.linalg.norm(np.diff(mesh.vertices[mesh.edges], axis=1)[:, 0], axis=1)
    return float(length.max() / length.min())


def test_the_kept_start_is_the_fairest_whose_panels_are_as_even(tower):
    design, h = tower
    layout, result = glide_fairest(design, h, "snet", angle=90.0)
    starts = result.properties["layout_starts"]
    # at 90 deg the bisector is no choice, and the output says so
    assert [t["start"] for t in starts] == ["as set", "fairness held longer", "smoothing doubled",
                                            "line field"]
    assert [t["start"] for t in result.properties["layout_starts_left_out"]] == ["bisector"]
    assert sum(t["chosen"] for t in starts) == 1
    kept = next(t for t in starts if t["chosen"])
    assert result.converged and result.properties["coverage"] >= 0.999
    measured = line_turns_p95(result.mesh.vertices, result.mesh.stars)
    assert measured == pytest.approx(kept["line_turn_p95_deg"], abs=0.5)
    first = starts[0]
    assert not kept["less_even_than_first"]
    # no start that ended as well, with panels as even as the first's, has lines clearly
    # straighter than the kept one's
    p95 = kept["line_turn_p95_deg"]
    for t in starts:
        if t["status"] == "converged" and t["coverage"] >= 0.999 and not t["less_even_than_first"]:
            assert t["line_turn_p95_deg"] >= min(p95 - 1.0, 0.9 * p95) - 0.05
    # the starts left for uneven panels are so: their edges spread more than the first's
    spread = first["edge_length_relative_to_panel"]
    for t in starts:
        if t["less_even_than_first"] == "its edges are less even":
            edges = t["edge_length_relative_to_panel"]
            assert edges["max"] / edges["min"] > 1.15 * spread["max"] / spread["min"]
    # the kept layout is the one the net was solved from
    assert layout.smoothing == kept["smoothing_panels"]


@pytest.mark.slow
def test_an_isogonal_net_on_a_torus_is_fairer_from_another_start():
    """The torus's isogonal 60 deg net from one start turns its lines by 28 deg at the 95th
    percentile (measured when this was written); bisected by the other principal direction
    14 deg, solved with the fairness term held longer and its edges held to the first
    start's range 9 deg: with edges no less even."""
    surface = surface_from_spec("torus")
    design = surface.triangulate(surface.resolution_for(8000))
    h = math.sqrt(design.area / 120)
    _, result = glide_fairest(design, h, "isogonal", angle=60.0, net_angle=60.0)
    kept = next(t for t in result.properties["layout_starts"] if t["chosen"])
    assert kept["start"] != "as set" and result.converged
    single = glide(layout_surface(design, h, angle=60.0), "isogonal", angle=60.0)
    assert single.converged
    assert line_turns_p95(result.mesh.vertices, result.mesh.stars) <= \
        0.6 * line_turns_p95(single.mesh.vertices, single.mesh.stars)
    assert edge_spread(result.mesh) <= 1.15 * edge_spread(single.mesh)


def test_one_start_is_one_layout_and_one_solve(tower):
    design, h = tower
    layout, result = glide_fairest(design, h, "snet", angle=90.0, starts=1)
    plain = glide(layout_surface(design, h), "snet")
    assert [t["start"] for t in result.properties["layout_starts"]] == ["as set"]
    np.testing.assert_array_equal(result.mesh.vertices, plain.mesh.vertices)
    with pytest.raises(InputError, match="starts must lie between 1 and 5, got 0"):
        glide_fairest(design, h, "snet", angle=90.0, starts=0)


def test_a_first_start_made_already_is_kept_not_made_again(tower, monkeypatch):
    """`first_solved`: the first start's layout and net are taken as given (a study's
    stalled glide solved again from the other starts); only the others are laid out and
    glided, and the record lists every start."""
    import fabplan.layout.starts as starts_module

    design, h = tower
    layout, result = glide_fairest(design, h, "snet", angle=90.0, starts=1)
    calls: list[str] = []
    for name in ("glide", "layout_surface"):
        real = getattr(starts_module, name)
        monkeypatch.setattr(starts_module, name,
                            lambda *a, _real=real, _name=name, **k: calls.append(_name) or
                            _real(*a, **k))
    glide_fairest(design, h, "snet", angle=90.0, starts=3)
    made = {name: calls.count(name) for name in ("glide", "layout_surface")}
    calls.clear()
    _, kept = glide_fairest(design, h, "snet", angle=90.0, starts=3, first_solved=(layout, result))
    assert calls.count("glide") == made["glide"] - 1
    assert calls.count("layout_surface") == made["layout_surface"] - 1
    records = kept.properties["layout_starts"]
    assert len(records) == 3 and records[0]["start"] == "as set"


def test_a_start_whose_solve_breaks_down_leaves_the_others(tower, monkeypatch):
    """A later start's solver failing (here: made to) is recorded with its reason; the
    net comes from the starts that solved."""
    import fabplan.layout.starts as starts_module
    from fabplan.errors import SolverError

    design, h = tower
    real = starts_module.glide
    calls = []

    def failing_second(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise SolverError("the normal equations stay singular even with strong damping")
        return real(*args, **kwargs)

    monkeypatch.setattr(starts_module, "glide", failing_second)
    _, result = glide_fairest(design, h, "snet", angle=90.0, starts=3)
    records = result.properties["layout_starts"]
    assert [t["status"] for t in records][1] == "refused"
    assert "singular" in records[1]["message"] and result.converged


@pytest.mark.slow
def test_an_isogonal_net_tries_the_other_bisector_and_its_layout_is_made_again():
    surface = surface_from_spec("hyperbolic-paraboloid:width=5,depth=5,rise=3")
    design = surface.triangulate((60, 60))
    names = [s.name for s in layout_starts(LayoutSettings(), 70.0)]
    assert names == ["as set", "fairness held longer", "bisector min", "smoothing doubled",
                     "line field"]
    # the bisector start alone, then made again from the net's record
    layout, result = glide_fairest(design, 0.8, "isogonal", angle=70.0, net_angle=70.0,
                                   settings=LayoutSettings(bisector="min"), starts=1)
    record = result.properties["layout"]
    assert record["bisector"] == "min"
    again = layout_again(json.loads(json.dumps(record)))
    np.testing.assert_array_equal(again.mesh.vertices, layout.mesh.vertices)
    # a line field asked for (no cross field tried) is asked for again
    layout, result = glide_fairest(design, 0.8, "isogonal", angle=70.0, net_angle=70.0,
                                   settings=LayoutSettings(max_smoothing=0.0), starts=1)
    record = result.properties["layout"]
    assert record["direction_field"] == "line"
    again = layout_again(json.loads(json.dumps(record)))
    assert again.direction_symmetry == 2
    np.testing.assert_array_equal(again.mesh.vertices, layout.mesh.vertices)
    assert layout_starts(LayoutSettings(), 70.0, family="z")[2].name == "smoothing doubled"


def test_a_smoothing_reached_by_doubling_is_not_laid_out_twice():
    """The cross field doubles its smoothing until it has no quarter-turn singularity: on
    the paraboloid's dome the first try (half a panel) ends at four panels, and the longer
    tries it passed through (1, 2 and 4 panels) would give the same layout again."""
    surface = surface_from_spec("paraboloid")
    design = surface.triangulate(surface.resolution_for(8000))
    layout = layout_surface(design, math.sqrt(design.area / 120),
                            settings=LayoutSettings(good_coverage=1.01))
    assert [(t["smoothing_panels"], t["used"], t["field"]) for t in layout.smoothing_tried] == \
        [(0.5, 4.0, "cross")]


def test_the_cli_lists_its_starts_and_refuses_a_bad_count(tmp_path, capsys):
    out = tmp_path / "tower.obj"
    code = main(["layout", "tower-facade", "--net", "isogonal", "--angle", "60",
                 "--panel-size", "2", "--triangles", "8000", "--starts", "2", "-o", str(out)])
    stdout, _ = capsys.readouterr()
    props = json.loads(out.with_suffix(".json").read_text())["properties"]
    assert code in (0, 3)
    assert [t["start"] for t in props["layout_starts"]] == ["as set", "fairness held longer"]
    assert "starts (the fairest kept):\n  as set" in stdout
    code = main(["layout", "tower-facade", "--net", "snet", "--panel-size", "2",
                 "--starts", "6", "-o", str(tmp_path / "six.obj")])
    _, err = capsys.readouterr()
    assert code == 2 and err == ("fabplan: error: --starts 6: must be at most 5 (range [1, 5]) "
                                  "(see 'fabplan layout --help')\n")
    assert not list(tmp_path.glob("six*"))


def test_a_study_asks_for_starts_in_its_study_table():
    text = template_path("canopy").read_text()
    assert "[study]\n" in text and "layout_starts" not in text

    def asking(n: int) -> str:
        return text.replace("[study]\n", f"[study]\nlayout_starts = {n}\n", 1)

    assert parse_study(asking(3)).layout_starts == 3
    assert parse_study(text).layout_starts == 1
    with pytest.raises(InputError, match="layout_starts must lie between 1 and 5, got 6"):
        parse_study(asking(6))


def test_a_start_that_leaves_the_design_unclad_is_kept_last():
    """Regression: a start that converged with 94 % of the design clad was kept over one
    at the iteration cap cladding 99.99 % (bspline-a's orthogonal net in the corpus)."""
    from types import SimpleNamespace

    from fabplan.layout.starts import LayoutStart, _fairest, _Tried

    def tried(name: str, converged: bool, coverage: float, turn: float) -> _Tried:
        result = SimpleNamespace(converged=converged, properties={
            "coverage": coverage, "fairness": {"line_turn_deg": {"p95": turn}},
            "edge_length_relative_to_panel": {"min": 0.8, "max": 1.2}})
        return _Tried(LayoutStart(name, LayoutSettings()), None, result, None, 0.0)  # type: ignore[arg-type]

    capped = tried("as set", False, 0.9999, 30.0)
    unclad = tried("line field", True, 0.94, 10.0)
    clad = tried("smoothing doubled", True, 0.998, 20.0)
    assert _fairest([capped, unclad]) is capped
    # converged and clad comes first; fairness decides only among equals
    assert _fairest([capped, unclad, clad]) is clad
    fairer = tried("fairness held longer", True, 0.998, 12.0)
    assert _fairest([capped, clad, fairer]) is fairer


SADDLE_STUDY = """
[study]
name = "saddle"
layout_starts = 2

[design]
surface = "hyperbolic-paraboloid"
parameters = { width = 4, depth = 4, rise = 1.2 }
triangles = 4000

[panels]
size = 0.7

[limits]
max_deviation_mm = 200
mold_tolerance_mm = 1.5

[[candidates]]
net = "const-radius"
"""


@pytest.mark.slow
def test_a_study_with_starts_solves_its_gliding_nets_and_their_start_from_them():
    from fabplan.study.run import run_study

    result = run_study(parse_study(SADDLE_STUDY), progress=lambda line: None)
    baseline = next(c for c in result.candidates if c.candidate.baseline)
    other = next(c for c in result.candidates if not c.candidate.baseline)
    assert baseline.candidate.glides and not other.candidate.glides
    assert baseline.net is not None and other.net is not None
    # the baseline S-net from two starts; the constant-radius net, which leaves the design,
    # starts from the fairest of two S-nets on the design continued past its edges, is
    # kept where the design is and trimmed there
    assert len(baseline.net.properties["layout_starts"]) == 2
    continued = other.net.parameters["continued"]
    assert continued["starts"] == 2
    assert continued["faces_kept"] == len(other.net.mesh.faces) < continued["faces_solved"]
    assert other.net.properties["coverage"] >= 0.999
