"""The live editor's page in a real headless chromium: click a vertex to make it a handle,
drag it with the mouse by a set distance, save, and check the saved net with code of this
file (an S-net within 1e-6 of an edge, the handle where the drag put it, no fold).

Like tests/test_browser.py it drives Debian's chromium through Playwright (WebGL on the
CPU); `.ci/run` installs chromium. The page is saved as tests/artifacts/edit-page.png.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from helpers import chromium
from test_edit_server import check_snet  # the checks of our own

import fabplan

pytest.importorskip("starlette", reason="the edit extra is missing: pip install -e '.[edit]'")

from fabplan.edit.server import EditServer  # noqa: E402
from fabplan.edit.session import EditOptions, EditSession  # noqa: E402

pytestmark = pytest.mark.slow

ARTIFACTS = Path(__file__).parent / "artifacts"
DRAG_PX = 30           # how far the mouse drags the handle, in CSS pixels (upwards)


@pytest.fixture(scope="module")
def browser():
    """A chromium with a fresh profile, or a skip that says what is missing."""
    with chromium(1100, 820) as context:
        yield context


def test_dragging_a_handle_with_the_mouse_keeps_an_snet_and_saves_it(browser, wein99, tmp_path):
    out = tmp_path / "edited.obj"
    server = EditServer(EditSession(wein99, EditOptions("snet")), out).start()
    page = browser.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    try:
        page.goto(server.url)
        page.wait_for_function("window.fabplanEdit && window.fabplanEdit.state", timeout=60_000)
        seq = lambda: page.evaluate("window.fabplanEdit.updates")  # noqa: E731
        # the interior vertex drawn nearest the middle of the view
        box = page.locator("#fe-view canvas").bounding_box()
        middle = (box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
        interior = np.flatnonzero(wein99.star_of_vertex >= 0)[::7]
        points = page.evaluate(f"{interior.tolist()}.map(v => window.fabplanEdit.screenPointOfVertex(v))")
        order = np.argsort([math.hypot(p["x"] - middle[0], p["y"] - middle[1]) for p in points])
        vid, point = int(interior[order[0]]), points[order[0]]
        before = seq()
        page.mouse.click(point["x"], point["y"])
        page.wait_for_function(f"window.fabplanEdit.updates > {before} && "
                               f"'{vid}' in window.fabplanEdit.state.handles", timeout=60_000)
        # drag it upwards on the screen, in the view plane, in small steps as a hand does
        page.mouse.move(point["x"], point["y"])
        page.mouse.down()
        for k in range(1, 13):
            page.mouse.move(point["x"], point["y"] - DRAG_PX * k / 12)
            page.wait_for_timeout(30)
        page.mouse.up()
        last = page.evaluate("window.fabplanEdit.lastTarget")
        assert last["vertex"] == vid
        target = np.array(last["target"])
        # the release comes after the last drag: with it done, so is that drag
        page.wait_for_function("window.fabplanEdit.state.undo >= 2", timeout=120_000)
        state = page.evaluate("window.fabplanEdit.state")
        camera = page.evaluate("window.fabplanEdit.camera()")
        assert state["status"] == "converged", state["message"]
        assert np.array_equal(state["handles"][str(vid)], target)
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "edit-page.png"))
        page.click("button.fe-save")
        page.wait_for_function("!window.fabplanEdit.state.unsaved",
                               timeout=60_000)
        assert errors == [], errors
    finally:
        page.close()
        server.stop()
        server.join(20)

    net = fabplan.QuadMesh.from_obj(out)
    X = net.vertices
    check_snet(X, [f.tolist() for f in net.faces])
    assert np.array_equal(X[vid], target), "the handle is not where the drag put it"
    # the drag's distance: DRAG_PX at the handle's depth, in the plane facing the camera
    moved = target - wein99.vertices[vid]
    direction = np.array(camera["direction"])
    depth = float(np.dot(wein99.vertices[vid] - np.array(camera["position"]), direction))
    per_px = 2 * depth * math.tan(math.radians(camera["fov"]) / 2) / camera["height"]
    # (the page holds the view in float32: its start point is good to about 1e-6 of
    # the net's size)
    assert abs(np.dot(moved, direction)) <= 1e-4 * np.linalg.norm(moved)
    assert np.linalg.norm(moved) == pytest.approx(DRAG_PX * per_px, rel=0.15)
    assert np.linalg.norm(moved) > 0.2 * wein99.mean_edge_length
    record = json.loads(out.with_suffix(".json").read_text())
    assert record["edit"]["handles"] == [{"vertex": vid, "position": target.tolist()}]
    assert [h["action"] for h in record["edit"]["history"]] == ["handle", "drag"]
