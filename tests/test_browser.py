"""The reports' interactive 3D view, opened in a real headless browser.

Playwright drives Debian's chromium (``apt-get install chromium``; `.ci/run` installs
it). WebGL runs on the CPU (SwiftShader). Screenshots of every state are saved in
``tests/artifacts/`` (not versioned) to be looked at.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest
from helpers import chromium

from fabplan.cli import main

ARTIFACTS = Path(__file__).parent / "artifacts"

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def browser():
    """A chromium with a fresh profile, or a skip that says what is missing."""
    with chromium(1200, 900) as context:
        yield context


class Report:
    """A report page with its 3D view ready, and the console errors it logged."""

    def __init__(self, context, path: Path):
        self.page = context.new_page()
        self.errors: list[str] = []
        self.page.on("console", lambda m: self.errors.append(m.text) if m.type == "error" else None)
        self.page.on("pageerror", lambda e: self.errors.append(f"uncaught: {e}"))
        self.page.goto(path.resolve().as_uri())
        self.page.wait_for_function("window.fabplanViewers && window.fabplanViewers.length > 0",
                                    timeout=30_000)
        self.view = self.page.locator("div.fp-viewer").first
        self.view.scroll_into_view_if_needed()
        self.canvas = self.view.locator("canvas")

    def pixels(self, name: str) -> np.ndarray:
        """(h, w, 3) uint8 of the canvas, saved as tests/artifacts/NAME.png."""
        from PIL import Image

        self.page.wait_for_timeout(150)
        png = self.canvas.screenshot()
        ARTIFACTS.mkdir(exist_ok=True)
        (ARTIFACTS / f"{name}.png").write_bytes(png)
        self.view.screenshot(path=str(ARTIFACTS / f"{name}-with-legend.png"))
        return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))

    def js(self, expression: str):
        return self.page.evaluate(expression)

    def click_face(self, face: int) -> tuple[int, int | None]:
        """Click where `face` is drawn; the face id and mold id the info line shows (the
        face hit may be a nearer one hiding `face`)."""
        point = self.js(f"window.fabplanViewers[0].screenPointOfFace({face})")
        self.page.mouse.click(point["x"], point["y"])
        info = self.view.locator(".fp-info")
        shown = info.locator('[data-key="face"] .fp-value')
        if shown.count() == 0:
            return -1, None
        mold = info.locator('[data-key="mold"] .fp-value').inner_text()
        return int(shown.inner_text()), int(mold)


def _drawn(pixels: np.ndarray) -> float:
    """Share of the canvas not in the background colour."""
    background = np.array([0xF4, 0xF5, 0xF7])
    return float(np.mean(np.abs(pixels.astype(int) - background).sum(axis=2) > 24))


def _changed(a: np.ndarray, b: np.ndarray) -> float:
    """Share of the pixels that differ clearly between two pictures."""
    return float(np.mean(np.abs(a.astype(int) - b.astype(int)).sum(axis=2) > 30))


def _check_view(context, report: Path, molds_json_of, name: str) -> Report:
    """The properties every report's 3D view must have; returns the page for more."""
    page = Report(context, report)
    first = page.pixels(f"{name}-mold")
    assert _drawn(first) > 0.05, "the 3D view drew (almost) nothing"
    assert len(np.unique(first.reshape(-1, 3), axis=0)) > 50, "the 3D view is flat colour"
    modes = page.js("window.fabplanViewers[0].data.modes.map(m => m.key)")
    assert {"mold", "deviation", "kink"} <= set(modes)
    page.js("window.fabplanViewers[0].setMode('deviation')")
    deviation = page.pixels(f"{name}-deviation")
    assert _changed(first, deviation) > 0.02, "switching the colour mode changed no pixels"
    legend = page.view.locator(".fp-legend").inner_text()
    assert "mm" in legend
    for view in ("front", "top", "eye"):
        page.js(f"window.fabplanViewers[0].setView('{view}')")
        assert _drawn(page.pixels(f"{name}-view-{view}")) > 0.01, f"nothing seen from {view}"
    page.js("window.fabplanViewers[0].setMode('mold')")
    faces = page.js("window.fabplanViewers[0].triFace.length")
    molds = molds_json_of(page.js("window.fabplanViewers[0].index"))
    picked = set()
    for face in np.linspace(0, faces - 1, 25).astype(int):
        face = int(page.js(f"window.fabplanViewers[0].triFace[{face}]"))
        shown, mold = page.click_face(face)
        if shown < 0:
            continue                      # the face is off the picture from this view
        picked.add(shown)
        assert mold == molds[shown], f"face {shown}: the view says mold {mold}, molds.json " \
                                     f"{molds[shown]}"
    assert len(picked) >= 5, f"only {len(picked)} panels could be clicked"
    page.pixels(f"{name}-picked")
    return page


@pytest.fixture(scope="module")
def molds_report(wein99_molds):
    """The session's `fabplan molds wein99.obj --tolerance-mm 5 -q` (tests/conftest.py)."""
    code, out = wein99_molds
    assert code == 0
    return out


def _mold_of_face(path: Path) -> dict:
    return {p["face"]: p["mold"] for p in json.loads(path.read_text())["panels"]}


def test_the_molds_report_3d_view_draws_recolours_and_names_the_mold_of_a_clicked_panel(
        browser, molds_report):
    molds = _mold_of_face(molds_report / "molds.json")
    page = _check_view(browser, molds_report / "report.html", lambda scene: molds, "molds")
    page.js("document.querySelector('input.fp-strips').click()")
    strips = page.pixels("molds-strips-by-family")
    assert _drawn(strips) > 0.05
    assert page.errors == [], page.errors


def test_the_stadium_study_3d_view_shows_every_candidate_and_its_molds(browser, stadium_study):
    out, run = stadium_study
    assert run.code == 0, run.lines[-5:]
    record = json.loads((out / "study.json").read_text())
    scenes = {}                              # scene index -> candidate folder
    page = Report(browser, out / "report.html")
    titles = page.js("window.fabplanViewers[0].scenes.map(s => s.title)")
    for i, title in enumerate(titles):
        scenes[i] = title.split(". ", 1)[1]
    measured = [c["name"] for c in record["candidates"] if not c["error"] and not c["same_net_as"]]
    assert sorted(scenes.values()) == sorted(measured)
    page.page.close()

    def molds_of_scene(scene: int) -> dict:
        return _mold_of_face(out / "candidates" / scenes[scene] / "molds.json")

    page = _check_view(browser, out / "report.html", molds_of_scene, "stadium")
    first = page.pixels("stadium-scene-0")
    page.js("window.fabplanViewers[0].setScene(1)")
    second = page.pixels("stadium-scene-1")
    assert _changed(first, second) > 0.01, "another candidate looks the same"
    shown, mold = page.click_face(int(page.js("window.fabplanViewers[0].triFace[0]")))
    if shown >= 0:
        assert mold == molds_of_scene(1)[shown]
    modes = page.js("window.fabplanViewers[0].data.modes.map(m => m.key)")
    assert {"radius", "angle"} <= set(modes)
    for mode in ("radius", "angle", "kink") + (("gaps",) if "gaps" in modes else ()):
        page.js(f"window.fabplanViewers[0].setMode('{mode}')")
        assert _drawn(page.pixels(f"stadium-{mode}")) > 0.05
    assert page.errors == [], page.errors


def test_the_study_table_sorts_by_a_clicked_column(browser, stadium_study):
    """A click on a header sorts the candidates by that column, a second click the other
    way; numbers sort as numbers, by their full value."""
    out, run = stadium_study
    assert run.code == 0, run.lines[-5:]
    record = json.loads((out / "study.json").read_text())
    deviation = {c["name"]: c["metrics"]["largest_deviation_mm"] for c in record["candidates"]
                 if not c["error"]}
    page = browser.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto((out / "report.html").resolve().as_uri())
    table = page.locator("table.sortable").first
    headers = table.locator("thead th").all_inner_texts()
    name_col, dev_col = headers.index("candidate"), headers.index("max deviation [mm]")

    def names() -> list[str]:
        return page.evaluate(f"""Array.from(document.querySelector('table.sortable').tBodies[0]
            .rows).map(r => r.cells[{name_col}].textContent.trim())""")

    ranked = names()
    table.locator("thead th").nth(dev_col).click()
    ascending = [n for n in names() if n in deviation]
    assert ascending == sorted(deviation, key=deviation.get)
    assert ascending != [n for n in ranked if n in deviation]   # the click changed the order
    table.locator("thead th").nth(dev_col).click()
    assert [n for n in names() if n in deviation] == ascending[::-1]
    assert table.locator("thead th").nth(dev_col).get_attribute("aria-sort") == "descending"
    assert errors == []
    page.close()


# ------------------------------------------------------------------ one net's page (--html)
@pytest.fixture(scope="module")
def dome_page(tmp_path_factory):
    """`fabplan layout paraboloid --html`: a dome with boundary panels all round."""
    out = tmp_path_factory.mktemp("dome") / "dome.obj"
    assert main(["layout", "paraboloid", "--net", "snet", "--panel-size", "1", "--triangles",
                 "8000", "--html", "-q", "-o", str(out)]) == 0
    return out


def _obj(path: Path) -> tuple[int, list[list[int]]]:
    """Vertex count and faces (0-based) of an OBJ file."""
    lines = path.read_text().splitlines()
    faces = [[int(t.split("/")[0]) - 1 for t in line.split()[1:]]
             for line in lines if line.startswith("f ")]
    return sum(line.startswith("v ") for line in lines), faces


def _greenish(pixels: np.ndarray) -> np.ndarray:
    p = pixels.astype(int)
    return (p[..., 1] > p[..., 0] + 15) & (p[..., 1] > p[..., 2] + 15)


def _click_layer_panel(page: Report, panel: int) -> dict:
    """Click where boundary panel `panel` is drawn; the info line's items by key."""
    point = page.js(f"window.fabplanViewers[0].screenPointOfFace({panel}, true)")
    page.page.mouse.click(point["x"], point["y"])
    items = page.view.locator(".fp-info .fp-item")
    return {items.nth(i).get_attribute("data-key"): items.nth(i).locator(".fp-value").inner_text()
            for i in range(items.count())}


def test_the_layout_page_3d_view_recolours_and_draws_its_boundary_panels(browser, dome_page):
    n_net, net_faces = _obj(dome_page)
    _, outlines = _obj(dome_page.with_name("dome.boundary.obj"))
    page = Report(browser, dome_page.with_suffix(".html"))
    viewer = "window.fabplanViewers[0]"
    page.js(f"{viewer}.setView('above')")
    first = page.pixels("layout-deviation")
    assert _drawn(first) > 0.05, "the 3D view drew (almost) nothing"
    assert len(np.unique(first.reshape(-1, 3), axis=0)) > 50, "the 3D view is flat colour"
    modes = page.js(f"{viewer}.data.modes.map(m => m.key)")
    assert {"deviation", "radius", "angle", "kink", "turn", "gaps"} <= set(modes)
    assert "mm" in page.view.locator(".fp-legend").inner_text()
    page.js(f"{viewer}.setMode('radius')")
    radius = page.pixels("layout-radius")
    assert _changed(first, radius) > 0.02, "switching the colour mode changed no pixels"
    assert " m" in page.view.locator(".fp-legend").inner_text()
    page.js(f"{viewer}.setMode('turn')")
    assert _changed(radius, page.pixels("layout-turn")) > 0.02

    # the boundary panels: drawn green (hatched) where the net leaves the design's rim
    page.js(f"{viewer}.setMode('deviation')")
    on = page.pixels("layout-boundary-on")
    page.js("document.querySelector('input.fp-layer').click()")
    off = page.pixels("layout-boundary-off")
    gone = np.abs(on.astype(int) - off.astype(int)).sum(axis=2) > 30
    assert gone.mean() > 0.01, "hiding the boundary panels changed no pixels"
    assert _greenish(on)[gone].mean() > 0.6, "the boundary panels are not drawn green"
    assert "boundary panel" not in page.view.locator(".fp-legend").inner_text()
    page.js("document.querySelector('input.fp-layer').click()")
    assert "boundary panel" in page.view.locator(".fp-legend").inner_text()

    # picked, a boundary panel names itself, its kind and the full panel it continues
    kinds = page.js(f"Array.from({viewer}.layer.info[0].values)")
    names = page.js(f"{viewer}.layer.info[0].names")
    assert len(kinds) == len(outlines), "the view lacks boundary panels of dome.boundary.obj"
    trimmed = [k for k, kind in enumerate(kinds) if kind == 0]
    picked, sharing, last = 0, 0, -1
    for panel in trimmed:
        shown = _click_layer_panel(page, panel)
        if "layer" not in shown:
            continue                      # hidden behind the net from this view
        picked, last = picked + 1, panel
        k = int(shown["layer"])
        assert shown["kind"] == names[kinds[k]]
        face = int(shown["continues face"])
        assert 0 <= face < len(net_faces)
        on_net = {v for v in outlines[k] if v < n_net}
        sharing += bool(on_net & set(net_faces[face])) or not on_net
    assert picked >= 5, f"only {picked} boundary panels could be clicked"
    assert sharing >= 0.8 * picked, "the face a boundary panel continues is not beside it"
    _click_layer_panel(page, last)
    page.pixels("layout-boundary-picked")
    # hidden, they are not picked: the same click reaches the net or nothing
    page.js("document.querySelector('input.fp-layer').click()")
    assert "layer" not in _click_layer_panel(page, trimmed[0])
    assert page.errors == [], page.errors


def test_the_stadium_3d_view_shows_boundary_panels_on_their_molds(browser, stadium_study):
    """Every candidate's boundary panels are drawn; a clicked one names the mold it is cut
    from, as its candidate's boundary-panels.csv does."""
    import csv

    out, run = stadium_study
    assert run.code == 0, run.lines[-5:]
    page = Report(browser, out / "report.html")
    viewer = "window.fabplanViewers[0]"
    titles = page.js(f"{viewer}.scenes.map(s => s.title)")
    assert all(page.js(f"!!{viewer}.scenes.map(s => s.layer)[{i}]") for i in range(len(titles)))
    page.js(f"{viewer}.setView('front')")
    on = page.pixels("stadium-boundary-on")
    page.js("document.querySelector('input.fp-layer').click()")
    off = page.pixels("stadium-boundary-off")
    assert _changed(on, off) > 0.005, "hiding the boundary panels changed no pixels"
    page.js("document.querySelector('input.fp-layer').click()")
    name = titles[0].split(". ", 1)[1]
    with open(out / "candidates" / name / "boundary-panels.csv", newline="") as handle:
        rows = {int(r["panel"]): r for r in csv.DictReader(handle)}
    count = page.js(f"{viewer}.layer.count")
    assert count == len(rows)
    picked, last = 0, -1
    for panel in np.linspace(0, count - 1, 30).astype(int):
        shown = _click_layer_panel(page, int(panel))
        if "layer" not in shown:
            continue
        picked, last = picked + 1, int(panel)
        row = rows[int(shown["layer"])]
        assert shown["continues face"] == row["neighbour_face"]
        assert shown["cut from mold"] == row["mold"]
    assert picked >= 5, f"only {picked} boundary panels could be clicked"
    _click_layer_panel(page, last)
    page.pixels("stadium-boundary-picked")
    assert page.errors == [], page.errors
