"""Test helpers shared by several test modules."""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from fabplan.net.mesh import QuadMesh


def noisy(mesh: QuadMesh, fraction: float, seed: int = 0) -> QuadMesh:
    """Every vertex moved by a seeded random vector of length `fraction` x mean edge."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=mesh.vertices.shape)
    d *= fraction * mesh.mean_edge_length / np.linalg.norm(d, axis=1, keepdims=True)
    return mesh.with_vertices(mesh.vertices + d)


def jet_curvatures(X: np.ndarray, faces: list, vertices: np.ndarray):
    """Principal curvatures at the given vertices from a degree-4 height function fitted
    to the two face rings around each vertex (25 points on a regular quad grid, for 15
    coefficients) in a PCA frame (osculating jet, Cazals and Pouget 2003): an estimator
    independent of fabplan's spheres.

    Returns
    -------
    k1, k2 : (k,) float, signed with respect to `normal` (k1 <= k2).
    normal : (k, 3) float, the unit normal of the fitted height function.
    """
    n = len(X)
    adj = np.eye(n, dtype=int)
    for face in faces:  # vertices sharing a face are neighbours
        adj[np.ix_(face, face)] = 1
    two_ring = (adj @ adj) > 0
    powers = [(i, k - i) for k in range(5) for i in range(k + 1)]  # x^i y^j, degree <= 4
    k1, k2, normals = [], [], []
    for v in vertices:
        P = X[two_ring[v]] - X[v]
        _, _, vt = np.linalg.svd(P - P.mean(axis=0))
        x, y, z = P @ vt[0], P @ vt[1], P @ vt[2]
        coef = np.linalg.lstsq(np.column_stack([x**i * y**j for i, j in powers]), z, rcond=None)[0]
        c = dict(zip(powers, coef, strict=True))
        fx, fy = c[(1, 0)], c[(0, 1)]
        fxx, fxy, fyy = 2 * c[(2, 0)], c[(1, 1)], 2 * c[(0, 2)]
        w = np.sqrt(1 + fx * fx + fy * fy)
        first = np.array([[1 + fx * fx, fx * fy], [fx * fy, 1 + fy * fy]])
        second = np.array([[fxx, fxy], [fxy, fyy]]) / w
        a, b = np.sort(np.linalg.eigvals(np.linalg.solve(first, second)).real)
        k1.append(a)
        k2.append(b)
        normals.append((-fx * vt[0] - fy * vt[1] + vt[2]) / w)
    return np.array(k1), np.array(k2), np.array(normals)


def patch_of(mesh: QuadMesh, fraction: float, *, name: str = "patch.obj") -> QuadMesh:
    """The faces of `mesh` whose vertices all lie within `fraction` of the bounding box
    diagonal from its centre vertex, as a mesh of its own (vertices renumbered in order)."""
    X = mesh.vertices
    centre = X[np.argmin(np.linalg.norm(X - X.mean(axis=0), axis=1))]
    radius = fraction * np.linalg.norm(np.ptp(X, axis=0))
    inside = np.linalg.norm(X - centre, axis=1) < radius
    faces = [f for f in mesh.faces if inside[f].all()]
    used = np.unique(np.concatenate(faces))
    renumber = np.full(len(X), -1)
    renumber[used] = np.arange(len(used))
    return QuadMesh(X[used], [renumber[f] for f in faces], name=name)


def without_timings(value):
    """A JSON record without its timings (keys naming seconds), to compare runs."""
    if isinstance(value, dict):
        return {k: without_timings(v) for k, v in value.items() if "second" not in k}
    if isinstance(value, list):
        return [without_timings(v) for v in value]
    return value


def closest_on_mold(q: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Closest points of molds z = (k1 x^2 + k2 y^2) / 2 (mm), written apart from the
    planner: c_x = q_x / (1 + k1 t), c_y = q_y / (1 + k2 t), t = c_z - q_z by Newton."""
    k1, k2 = k[:, 0], k[:, 1]
    x, y, z = q.T
    t = 0.5 * (k1 * x * x + k2 * y * y) - z
    for _ in range(40):
        a, b = 1.0 + k1 * t, 1.0 + k2 * t
        g = 0.5 * (k1 * x * x / a**2 + k2 * y * y / b**2) - z - t
        dg = -(k1 * k1 * x * x / a**3 + k2 * k2 * y * y / b**3) - 1.0
        t = t - g / dg
    return np.column_stack([x / (1 + k1 * t), y / (1 + k2 * t), z + t])


def edge_midpoint_steps(record: dict, mesh: QuadMesh, *, with_faces: bool = False):
    """Step at the midpoint of every shared edge from the exported placements (mm): the
    point put on panel A's mold, measured against panel B's mold, both ways. With
    `with_faces`, also the (e, 2) faces of every edge."""
    X = mesh.vertices
    shapes = {m["id"]: (m["k1"], m["k2"]) for m in record["molds"]}
    M = np.array([p["placement"] for p in record["panels"]])
    K = np.array([shapes[p["mold"]] for p in record["panels"]])
    faces_of: dict = {}
    for f, face in enumerate(mesh.faces):
        for a, b in zip(face, np.roll(face, -1), strict=True):
            faces_of.setdefault((min(a, b), max(a, b)), []).append(f)
    pairs = [(e, fs) for e, fs in faces_of.items() if len(fs) == 2]
    mid = np.array([0.5 * (X[a] + X[b]) for (a, b), _ in pairs])
    fa = np.array([fs[0] for _, fs in pairs])
    fb = np.array([fs[1] for _, fs in pairs])

    def into(F, p):
        return np.einsum("pij,pj->pi", M[F][:, :3, :3], p) + M[F][:, :3, 3]

    step = np.zeros(len(pairs))
    for A, B in ((fa, fb), (fb, fa)):
        on_a = closest_on_mold(into(A, mid), K[A])
        back = np.linalg.solve(M[A][:, :3, :3], (on_a - M[A][:, :3, 3])[..., None])[..., 0]
        qb = into(B, back)
        step = np.maximum(step, np.linalg.norm(qb - closest_on_mold(qb, K[B]), axis=1))
    return (step, np.column_stack([fa, fb])) if with_faces else step


def measured_saddle_candidate(tolerance_mm: float):
    """A gliding S-net on an 8 x 8 m hyperbolic paraboloid as a study measures a candidate:
    ``(result, plan, metrics)`` with its molds at `tolerance_mm`
    (`fabplan.study.candidate_measure.measure_candidate`), for tests of a study's limits."""
    import fabplan
    from fabplan.study.candidate_measure import measure_candidate

    design = fabplan.load_design("hyperbolic-paraboloid:width=8,depth=8,rise=2.5", triangles=4000)
    result = fabplan.glide(fabplan.layout_surface(design, 1.5), "snet")
    plan = fabplan.plan_molds(result.mesh, tolerance_mm=tolerance_mm)
    return result, plan, measure_candidate(result, design, plan, None, mm_per_unit=1000.0)


def interruptible() -> None:
    """`preexec_fn` for a process a test interrupts with SIGINT: Ctrl-C acts in it even
    when the tests run as a background job (whose children start with SIGINT ignored)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _placed(M: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Points (k, 3) placed by the 4 x 4 matrices M (k, 4, 4)."""
    return np.einsum("kij,kj->ki", M[:, :3, :3], p) + M[:, :3, 3]


def mold_gaps(points: np.ndarray, M: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(k,) mm, vertical gaps of points (k, 3) placed by M (k, 4, 4) to molds K (k, 2)."""
    q = _placed(M, points)
    return np.abs(q[:, 2] - 0.5 * (K[:, 0] * q[:, 0] ** 2 + K[:, 1] * q[:, 1] ** 2))


STEP_FRACTIONS = np.linspace(0.02, 0.98, 13)
"""Where `chord_steps` measures along a side: other points than the planner's."""


def chord_steps(chords: np.ndarray, A: np.ndarray, KA: np.ndarray, B: np.ndarray,
                KB: np.ndarray, fractions: np.ndarray = STEP_FRACTIONS) -> np.ndarray:
    """(k,) mm, the step between two placed molds along chords (k, 2, 3), written apart
    from the planner: every chord point put on mold A (closest point) and measured against
    mold B, and the other way round."""
    out = np.zeros(len(chords))
    for t in fractions:
        p = (1 - t) * chords[:, 0] + t * chords[:, 1]
        for (M, K), (N, L) in (((A, KA), (B, KB)), ((B, KB), (A, KA))):
            on = closest_on_mold(_placed(M, p), K)
            back = np.linalg.solve(M[:, :3, :3], (on - M[:, :3, 3])[..., None])[..., 0]
            q = _placed(N, back)
            out = np.maximum(out, np.linalg.norm(q - closest_on_mold(q, L), axis=1))
    return out


def exported_molds(net_obj, boundary_obj, molds_json, boundary_csv, cut_obj) -> dict:
    """Everything about a net's molds read from the files a study or `fabplan molds`
    writes, and rechecked here: ``steps`` (mm) of the sides two panels share, by kind
    (``net-net``, ``net-boundary``, ``boundary-boundary``), ``cut_gap_mm`` (the largest
    gap of the boundary panels as cut to their molds), ``molds_in_all`` (the curved molds
    the panels use, boundary panels' own included), ``panels`` (full and boundary panels
    made as panels) and ``record`` (molds.json)."""
    import csv
    import json

    from fabplan.io.obj import read_obj

    record = json.loads(open(molds_json, encoding="utf-8").read())
    shapes = {m["id"]: (m["k1"], m["k2"]) for m in record["molds"]}
    for j, shape in enumerate(record["boundary_panels"]["own_mold_shapes_per_mm"]):
        shapes[len(record["molds"]) + j] = tuple(shape)
    with open(boundary_csv, newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    M = np.array([[float(r[f"m{i}{j}"]) for i in range(4) for j in range(4)]
                  for r in rows]).reshape(-1, 4, 4)
    K = np.array([shapes[int(r["mold"])] for r in rows])
    cut_v, cut_f = read_obj(cut_obj)
    assert len(cut_f) == len(rows)
    cut_gap = max((mold_gaps(cut_v[f], np.repeat(M[k][None], len(f), 0),
                             np.repeat(K[k][None], len(f), 0)).max()
                   for k, f in enumerate(cut_f)), default=0.0)
    V, outlines = read_obj(boundary_obj)
    _, faces = read_obj(net_obj)
    NM = np.array([p["placement"] for p in record["panels"]])
    NK = np.array([shapes[p["mold"]] for p in record["panels"]])
    owner = {}
    for f, q in enumerate(faces):
        for a, b in zip(q, np.roll(q, -1), strict=True):
            owner[(int(a), int(b))] = ("net", f)
    for k, q in enumerate(outlines):
        for a, b in zip(q, np.roll(q, -1), strict=True):
            owner[(int(a), int(b))] = ("boundary", k)
    groups: dict = {"net-net": [], "net-boundary": [], "boundary-boundary": []}
    for (a, b), (kind, i) in owner.items():
        other = owner.get((b, a))
        if other is None or (kind, i) > other:
            continue
        key = "net-net" if kind == other[0] == "net" else (
            "boundary-boundary" if kind == other[0] else "net-boundary")
        sides = [(NM[j], NK[j]) if which == "net" else (M[j], K[j])
                 for which, j in ((kind, i), other)]
        groups[key].append((V[[a, b]], *sides[0], *sides[1]))
    steps = {}
    for key, rows_ in groups.items():
        if rows_:
            chords, A, KA, B, KB = (np.array(v) for v in zip(*rows_, strict=True))
            steps[key] = chord_steps(chords, A, KA, B, KB)
        else:
            steps[key] = np.zeros(0)
    curved = {p["mold"] for p in record["panels"] if p["type"] != "planar"}
    own = {int(r["mold"]) for r in rows if int(r["mold"]) >= len(record["molds"])}
    panels = len(faces) + sum(1 for r in rows if r["kind"] != "extension")
    return {"steps": steps, "cut_gap_mm": cut_gap, "molds_in_all": len(curved) + len(own),
            "panels": panels, "record": record}


@contextlib.contextmanager
def memory_cap(extra: int):
    """Cap this process's address space at its current size plus `extra` bytes while
    fuzzing: an example that slips past the guards ends in a MemoryError (a failure of the
    test), not in the machine's swap; the commands then also see the cap as the memory
    they may use."""
    import resource

    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    with open("/proc/self/statm") as handle:
        size = int(handle.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    cap = size + extra if hard == resource.RLIM_INFINITY else min(hard, size + extra)
    resource.setrlimit(resource.RLIMIT_AS, (cap, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--no-first-run", "--disable-sync",
                 # WebGL on the CPU: chromium no longer falls back to SwiftShader by itself
                 "--enable-unsafe-swiftshader", "--use-angle=swiftshader"]


@contextlib.contextmanager
def chromium(width: int, height: int):
    """A headless Debian chromium driven by Playwright, with a fresh profile and a viewport
    of `width` x `height` CSS pixels; a pytest skip that says what is missing."""
    import pytest

    playwright_api = pytest.importorskip(
        "playwright.sync_api", reason="Playwright is missing: pip install -e '.[test]'")
    if not Path(CHROMIUM).is_file():
        pytest.skip("chromium is missing: apt-get install -y chromium (.ci/run does)")
    profile = tempfile.mkdtemp(prefix="fabplan-chromium-")
    try:
        with playwright_api.sync_playwright() as p:
            context = p.chromium.launch_persistent_context(
                profile, executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True,
                viewport={"width": width, "height": height})
            try:
                yield context
            finally:
                context.close()
    finally:
        shutil.rmtree(profile, ignore_errors=True)


# ----------------------------------------------------------------------------- panel classes
# The class checks of a material (`fabplan.fabricate.molds.panel_classes`) recomputed from the
# exported data with the tests' own frames, fits and plate formulas (docs/materials.md).
# Only the panels' dense samples come from fabplan: the panel surfaces the mold plan
# verifies (`fabplan.fabricate.molds.panels`), never the classifier.

VERIFY_LEVEL = 12          # the mold plan's dense samples (MoldSettings.verify_level)
COVER_LEVEL = 4            # the samples a design model's quadrics are fitted to (cover_level)
PANEL_CLASSES = ("flat", "cold_bent", "roll_bent", "molded")


def dense_panel_samples(mesh: QuadMesh, panel_surface: str, design=None) -> np.ndarray:
    """(f, s, 3) model units: the dense samples of the panel surface a mold plan verified
    (``panel_surface`` of molds.json; ``design`` needs the design the net was held on)."""
    from fabplan.fabricate.molds.panels import (
        design_panel_samples,
        fit_design_panels,
        fit_panel_surfaces,
        panel_samples,
        shared_panel_samples,
    )

    if panel_surface == "shared":
        return shared_panel_samples(mesh, fit_panel_surfaces(mesh, "local_fit"), VERIFY_LEVEL)
    if panel_surface == "design":
        assert design is not None, "a design-surface plan needs its design"
        surfaces, _ = fit_design_panels(mesh, design, COVER_LEVEL)
        return design_panel_samples(mesh, surfaces, design, VERIFY_LEVEL)
    return panel_samples(mesh, fit_panel_surfaces(mesh, panel_surface), VERIFY_LEVEL)


def own_frame(corners: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """x along a face's first edge (its corners (k, 3) in order) in the plane normal to
    `normal`, y = n x x."""
    e = corners[1] - corners[0]
    e = e - (e @ normal) * normal
    x = e / np.linalg.norm(e)
    return np.array([x, np.cross(normal, x), normal])


def own_bent_shape(points_mm: np.ndarray, frame: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Least-squares z = c0 + c1 x + c2 y + (a x^2 + 2 b x y + c y^2)/2: (a, c, b), its gap
    once shifted, and the radius of the disk around the centre that holds the points."""
    q = (points_mm - points_mm.mean(axis=0)) @ frame.T
    x, y, z = q.T
    A = np.column_stack([np.ones_like(x), x, y, x * x / 2, x * y, y * y / 2])
    c, *_ = np.linalg.lstsq(A, z, rcond=None)
    r = z - A @ c
    return np.array([c[3], c[5], c[4]]), 0.5 * (r.max() - r.min()), float(np.hypot(x, y).max())


def own_stress(material: dict, kxx: float, kyy: float, kxy: float, radius: float) -> float:
    """Kirchhoff bending of the principal curvatures plus E |K| rho^2 / 8 (docs/materials.md)."""
    E, nu, t = material["youngs_modulus_mpa"], material["poisson"], material["stress_thickness_mm"]
    k1, k2 = np.linalg.eigvalsh(np.array([[kxx, kxy], [kxy, kyy]]))
    bending = E * t / (2 * (1 - nu**2)) * max(abs(k1 + nu * k2), abs(k2 + nu * k1))
    return bending + E * abs(k1 * k2) * radius**2 / 8


def recheck_panel_classes(mesh: QuadMesh, record: dict, dense=None) -> dict:
    """Recompute every panel's class checks from molds.json (`record`) and the net, on the
    dense samples (model units; default: those of the ``shared`` surface), with the default
    class order (flat, cold-bent, roll-bent, molded). Returns the counts per class."""
    import pytest

    mm = record["mm_per_unit"]
    tol = record["tolerance_mm"]
    classes = record["panel_classes"]
    material = classes["material"]
    if dense is None:
        dense = dense_panel_samples(mesh, "shared")
    dense = dense * mm
    counts = dict.fromkeys(PANEL_CLASSES, 0)
    faces = mesh.faces                     # built on every access: once here
    for p in classes["panels"]:
        i, cls, shape = p["face"], p["class"], p["bent_shape"]
        counts[cls] += 1
        normal = np.array(shape["normal"])
        frame = own_frame(mesh.vertices[faces[i]], normal)
        assert np.allclose(frame[0], shape["x_axis"], atol=1e-9)
        k, gap, radius = own_bent_shape(dense[i], frame)
        stress = own_stress(material, *k, radius)
        assert np.allclose(k, shape["curvature_per_mm"], rtol=1e-5, atol=1e-12), i
        assert shape["twist_per_mm"] == pytest.approx(k[2], rel=1e-5, abs=1e-12)
        assert shape["stress_mpa"] == pytest.approx(stress, rel=1e-5, abs=1e-9), i
        assert shape["gap_mm"] == pytest.approx(gap, rel=1e-5, abs=1e-6)
        cold_ok = gap <= tol and stress <= material["max_bend_stress_mpa"]
        q = dense[i] @ frame.T
        A = np.column_stack([np.ones(len(q)), q[:, 0], q[:, 1]])
        r = q[:, 2] - A @ np.linalg.lstsq(A, q[:, 2], rcond=None)[0]
        plane_gap = 0.5 * (r.max() - r.min())
        flat_limit = tol if material["flatness_mm_per_m"] is None else \
            min(tol, material["flatness_mm_per_m"] * 2 * radius / 1000)
        flat_ok = plane_gap <= flat_limit
        if cls == "flat":
            assert flat_ok and p["figure"] == pytest.approx(plane_gap, rel=1e-5, abs=1e-6)
        elif cls == "cold_bent":
            assert cold_ok and not flat_ok
            assert p["figure"] == pytest.approx(stress, rel=1e-5) and p["unit"] == "MPa"
            assert p["limit"] == material["max_bend_stress_mpa"]
        elif cls == "roll_bent":
            roll = p["roll"]
            C = np.array(roll["axis_point"]) * mm
            d = np.array(roll["axis_direction"])
            v = dense[i] - C
            s = v @ d
            rho = np.linalg.norm(v - np.outer(s, d), axis=1)
            t = roll["taper"]
            dist = (rho - roll["radius_mm"] - t * s) / np.sqrt(1 + t * t)
            assert np.abs(dist).max() <= tol + 1e-6, (i, np.abs(dist).max())
            smallest = ((roll["radius_mm"] + t * s) * np.sqrt(1 + t * t)).min()
            assert smallest == pytest.approx(roll["min_radius_mm"], rel=1e-6)
            assert smallest >= material["min_roll_radius_mm"]
            assert not flat_ok and not cold_ok
        else:
            assert not flat_ok and not cold_ok, i
            if "roll" in p and material["min_roll_radius_mm"] is not None:
                assert (p["roll"]["gap_mm"] > tol
                        or p["roll"]["min_radius_mm"] < material["min_roll_radius_mm"])
    assert counts == classes["counts"]
    return counts


def recheck_made_molds(record: dict) -> None:
    """Molds are made for molded panels only; the saving is the curved molds left unmade."""
    classes = {p["face"]: p["class"] for p in record["panel_classes"]["panels"]}
    molded_on = {p["mold"] for p in record["panels"] if classes[p["face"]] == "molded"}
    for m in record["molds"]:
        assert m["made"] == (m["type"] != "plane" and m["id"] in molded_on), m["id"]
    curved = sum(m["type"] != "plane" for m in record["molds"])
    made = sum(m["made"] for m in record["molds"])
    assert record["molds_made"] == made
    assert record["molds_saved_by_material"] == curved - made


def exported_class_counts(molds_json, panels_csv, boundary_csv=None) -> dict:
    """The four class counts of a net's panels as its files give them: the ``class``
    column of its panels CSV (``panels.csv`` of `fabplan molds`, ``molds.csv`` of a study
    candidate) and, with ``boundary-panels.csv``, its boundary panels by the rule of
    docs/materials.md, read from the files: a boundary panel on a plane mold is flat, one
    cut from a net mold no molded panel uses takes the class of the net panel it continues
    (``neighbour_face``), one on a made mold or a mold of its own is molded; extensions
    (cut with their full panel) are not panels of their own."""
    import csv
    import json

    record = json.loads(open(molds_json, encoding="utf-8").read())
    with open(panels_csv, newline="", encoding="utf-8") as handle:
        net_class = [row["class"] for row in csv.DictReader(handle)]
    counts = dict.fromkeys(PANEL_CLASSES, 0)
    for cls in net_class:
        counts[cls] += 1
    if boundary_csv is None:
        return counts
    molds = {m["id"]: m for m in record["molds"]}
    with open(boundary_csv, newline="", encoding="utf-8") as handle:
        for row in csv.DictReader(handle):
            if row["kind"] == "extension":
                continue
            mold, face = molds.get(int(row["mold"])), int(row["neighbour_face"])
            if mold is not None and mold["type"] == "plane":
                cls = "flat"
            elif mold is not None and not mold["made"]:
                cls = net_class[face] if face >= 0 else "molded"
            else:
                cls = "molded"
            counts[cls] += 1
    return counts


def process_alive(pid: int) -> bool:
    """Whether process `pid` runs (Linux /proc; a zombie is not running)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"
