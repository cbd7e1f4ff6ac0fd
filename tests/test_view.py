"""The page of one net (``--html`` of `fabplan layout` and `fabplan optimize`): its key
numbers with units, its 3D view with the boundary panels, written with the net or not at
all. The browser half is in test_browser.py."""

from __future__ import annotations

import base64
import json
import re
from pathlib import Path

import numpy as np
import pytest

import fabplan
from fabplan.cli import main
from fabplan.design.load import load_design
from fabplan.layout.surface_layout import glide, layout_surface
from fabplan.layout.view import boundary_layer, net_numbers

WEIN99 = str(fabplan.data_path("wein99.obj"))
TYPES = {"f4": np.float32, "i4": np.int32, "u2": np.uint16, "u1": np.uint8, "i1": np.int8}


def decoded(text: str) -> np.ndarray:
    """The array of an ``encode_array`` text, read back as the viewer reads it."""
    kind, data = text.split(":", 1)
    return np.frombuffer(base64.b64decode(data), dtype=TYPES[kind])


def page_scenes(page: str) -> list[dict]:
    block = re.search(r'class="fp-scenes">(.*?)</script>', page, re.S)
    assert block is not None, "the page has no 3D view"
    return json.loads(block.group(1).replace("<\\/", "</"))["scenes"]


def key_numbers(page: str) -> dict[str, tuple[str, str]]:
    """quantity -> (value, unit) of the page's key-number table."""
    table = page[page.index('id="key-numbers"'):]
    table = table[:table.index("</table>")]
    rows = re.findall(r"<tr><td>([^<]*)</td><td[^>]*>([^<]*)</td><td>([^<]*)</td></tr>", table)
    return {q: (v, u) for q, v, u in rows}


def read_obj(path: Path) -> tuple[np.ndarray, list[list[int]]]:
    """Vertices (n, 3) and faces (0-based) of an OBJ file."""
    lines = path.read_text().splitlines()
    vertices = np.array([[float(t) for t in line.split()[1:4]] for line in lines
                         if line.startswith("v ")])
    faces = [[int(t.split("/")[0]) - 1 for t in line.split()[1:]]
             for line in lines if line.startswith("f ")]
    return vertices, faces


@pytest.fixture(scope="module")
def dome_layout(tmp_path_factory):
    """`fabplan layout paraboloid --html`: a dome with boundary panels all round."""
    out = tmp_path_factory.mktemp("dome") / "dome.obj"
    code = main(["layout", "paraboloid", "--net", "snet", "--panel-size", "1", "--triangles",
                 "8000", "--html", "-q", "-o", str(out)])
    assert code == 0
    return out


def test_layout_html_holds_the_net_its_boundary_panels_and_its_numbers(dome_layout):
    out = dome_layout
    page = out.with_suffix(".html").read_text()
    record = json.loads(out.with_suffix(".json").read_text())
    props = record["properties"]
    # self-contained: no file or network reference, the picture embedded
    assert not re.search(r'(src|href)="(https?:|file:|[^"#d][^"]*\.(js|png|css))', page)
    # the picture and the design's |k1 - k2| map, which says where the lines turn most
    assert page.count('<img src="data:image/png;base64,') == 2
    assert "Where the design makes lines kink" in page and "|k1 - k2| is" in page
    scene, = page_scenes(page)
    assert len(decoded(scene["face_sizes"])) == props["faces"]
    modes = [m["key"] for m in scene["modes"]]
    assert modes[0] == "deviation" and {"radius", "angle", "kink", "turn", "gaps"} <= set(modes)
    # the deviation mode is the distance from the design, in mm, as the record measured it
    deviation = decoded(next(m for m in scene["modes"] if m["key"] == "deviation")["values"])
    assert deviation.max() == pytest.approx(1000 * props["distance_to_design"]["max"], rel=1e-3)
    # the layer holds every boundary panel of OUT.boundary.obj, outline for outline
    layer = scene["layer"]
    V, outlines = read_obj(out.with_name("dome.boundary.obj"))
    net_vertices, _ = read_obj(out)
    sizes = decoded(layer["face_sizes"])
    assert sizes.tolist() == [len(f) for f in outlines]
    # the same points, moved as the scene is (its box's centre to the origin)
    centre = 0.5 * (net_vertices.min(axis=0) + net_vertices.max(axis=0))
    points = decoded(layer["positions"]).reshape(-1, 3)[decoded(layer["face_indices"])]
    np.testing.assert_allclose(points, V[np.concatenate(outlines)] - centre, atol=1e-5)
    panel = decoded(layer["triangle_panel"])
    assert set(panel.tolist()) == set(range(len(outlines))), "a boundary panel has no triangle"
    extensions = len(props["boundary_panels"]["extensions"])
    assert len(outlines) == props["boundary_panels"]["count"] + extensions
    assert f"{props['boundary_panels']['count']} boundary panels" in layer["toggle"]
    # every number of the key-number table has a unit or is a count
    numbers = key_numbers(page)
    assert len(numbers) >= 12
    for quantity, (value, unit) in numbers.items():
        if re.match(r"^[-+\d.]", value):
            assert unit, f"{quantity}: {value} has no unit"
    assert float(numbers["distance from the design, largest"][0]) == pytest.approx(
        1000 * props["distance_to_design"]["max"], rel=1e-3)
    assert numbers["distance from the design, largest"][1] == "mm"
    assert numbers["boundary panels"] == (str(props["boundary_panels"]["count"]), "count")


@pytest.mark.slow
def test_a_layout_whose_page_fails_writes_nothing(tmp_path, monkeypatch, capsys):
    """The page is written with the net: when building it fails, neither it nor the net,
    its record, picture or boundary panels land, and no temporary file is left."""
    import fabplan.layout.view as view

    def broken(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(view, "net_view_html", broken)
    code = main(["layout", "paraboloid", "--net", "snet", "--panel-size", "1.5", "--triangles",
                 "4000", "--html", "-q", "-o", str(tmp_path / "out" / "dome.obj")])
    assert code == 2
    assert "No space left on device" in capsys.readouterr().err
    assert list(tmp_path.rglob("*")) == []


def test_optimize_html_measures_the_deviation_from_the_reference(tmp_path):
    out = tmp_path / "w.obj"
    assert main(["optimize", WEIN99, "--net", "snet", "--html", "-q", "-o", str(out)]) == 0
    page = out.with_suffix(".html").read_text()
    record = json.loads(out.with_suffix(".json").read_text())
    scene, = page_scenes(page)
    deviation = next(m for m in scene["modes"] if m["key"] == "deviation")
    assert "reference" in deviation["label"]
    assert decoded(deviation["values"]).max() == pytest.approx(
        1000 * record["properties"]["distance_to_reference"]["max"], rel=1e-3)
    assert "layer" not in scene and "gaps" not in [m["key"] for m in scene["modes"]]
    assert page.count('<img src="data:image/png;base64,') == 1      # a picture drawn for it
    assert key_numbers(page)["solver iterations"] == (str(record["iterations"]), "count")


def test_without_html_no_page_is_written(tmp_path):
    out = tmp_path / "w.obj"
    assert main(["optimize", WEIN99, "--net", "snet", "--max-iter", "1", "-q", "-o", str(out)]) in (0, 3)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["w.json", "w.obj"]


def test_boundary_panel_triangles_cover_each_panel_once():
    """The triangles the view draws are those of the trimming: per panel their area is the
    panel's area on the design, and the fan kept for older results gives the same for
    these outlines."""
    design = load_design("paraboloid", triangles=4000)
    result = glide(layout_surface(design, 1.5), "snet")
    panels = result.boundary_panels
    assert panels is not None and panels.count > 4
    layer = boundary_layer(panels, units="m")
    T = layer.vertices[layer.triangles]
    area = 0.5 * np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1)
    np.testing.assert_allclose(np.bincount(layer.triangle_panel, area, minlength=panels.count),
                               panels.area, rtol=1e-9)
    assert [i.label for i in layer.info][:2] == ["kind", "continues face"]
    np.testing.assert_array_equal(layer.info[1].values, panels.neighbour_face)


def test_net_numbers_say_a_fold_and_leave_out_what_is_not_measured():
    rows = net_numbers({"status": "folded", "iterations": 3, "seconds": 1.0,
                        "properties": {"folds": {"folded": True, "flipped_faces": {"count": 2}}}},
                       units="m", mm_per_unit=1000.0)
    assert ["folds", "2 flipped panels", ""] in rows
    assert not any(r[0].startswith("distance") for r in rows)


@pytest.mark.slow
def test_a_net_from_the_api_writes_its_page(tmp_path):
    from fabplan.study.api import layout_net

    net = layout_net(load_design("paraboloid", triangles=4000), 1.5)
    path = net.write_html(tmp_path / "dome.html")
    scene, = page_scenes(path.read_text())
    assert scene["modes"][0]["label"] == "deviation from the design [mm]"
    assert len(decoded(scene["layer"]["face_sizes"])) == net.boundary_panels.count
