"""The script API: `import fabplan` chains the pipeline; nets go in as (V, F) arrays or a
QuadMesh, typed results with `.to_json()` come out; `plan_*` share one convention; the
Grasshopper example runs with rhino3dm standing in for RhinoCommon."""

from __future__ import annotations

import importlib
import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import patch_of

import fabplan
from fabplan.errors import InputError
from fabplan.io.records import json_text

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
PIPELINE = ["load_design", "layout_net", "optimize", "measure", "plan_molds", "plan_strips",
            "run_study", "arcs", "mill", "read_obj", "write_obj", "read_3dm", "write_3dm",
            "write_glb"]


@pytest.fixture(scope="module")
def patch(wein99):
    return patch_of(wein99, 0.1)


def test_the_pipeline_is_at_the_top_level():
    for name in PIPELINE:
        assert callable(getattr(fabplan, name)) and name in fabplan.__all__
    assert fabplan.optimize.__module__ == "fabplan.study.api"
    importlib.import_module("fabplan.layout.surface_layout")   # the subpackage shadows nothing
    assert fabplan.layout_net.__module__ == "fabplan.study.api"


def test_arrays_and_meshes_give_the_same_results(patch):
    V, F = patch.vertices, [f.tolist() for f in patch.faces]
    by_arrays, by_mesh = fabplan.measure((V, F)), fabplan.measure(patch)
    assert json_text(by_arrays.to_json()) == json_text(by_mesh.to_json())
    assert isinstance(by_arrays, fabplan.Measurement)
    molds_arrays = fabplan.plan_molds((V, np.array(F)), tolerance_mm=5)
    molds_mesh = fabplan.plan_molds(patch, tolerance_mm=5)
    assert np.array_equal(molds_arrays.mold, molds_mesh.mold)
    arcs = fabplan.arcs((V, F))
    assert np.array_equal(arcs.radius, fabplan.arcs(patch).radius)
    with pytest.raises(InputError, match=r"QuadMesh or a \(V, F\)"):
        fabplan.measure(V)


def test_results_are_typed_and_serialise(patch):
    solved = fabplan.optimize(patch, "snet")
    assert isinstance(solved, fabplan.NetResult) and isinstance(solved, fabplan.OptimizationResult)
    assert solved.converged and solved.vertices.shape == patch.vertices.shape
    assert solved.to_json() == solved.record()
    molds = fabplan.plan_molds(solved, tolerance_mm=5)
    assert isinstance(molds, fabplan.MoldResult)
    record = json.loads(json_text(molds.to_json()))
    assert record["panel_count"] == len(patch.faces) and record["fits_all"]
    arcs = json.loads(json_text(fabplan.arcs(solved).to_json()))
    assert len(arcs["arcs"]) == len(patch.edges)
    assert arcs["summary"]["end_vertex_gap_relative_to_edge"] < 1e-9


def test_plan_functions_take_settings_or_keywords(patch):
    by_keywords = fabplan.plan_molds(patch, tolerance_mm=5, units="m")
    by_settings = fabplan.plan_molds(patch, fabplan.MoldSettings(tolerance_mm=5, units="m"))
    assert np.array_equal(by_keywords.mold, by_settings.mold)
    small = patch_of(patch, 0.15)
    strips_keywords = fabplan.plan_strips(small, height_mm=100, thickness_mm=5)
    strips_settings = fabplan.plan_strips(small, fabplan.StripSettings(height_mm=100, thickness_mm=5))
    assert isinstance(strips_keywords, fabplan.StripResult)
    assert (json_text(strips_keywords.to_json()["strips"])
            == json_text(strips_settings.to_json()["strips"]))
    for plan_function, settings in ((fabplan.plan_molds, fabplan.MoldSettings(tolerance_mm=5)),
                                    (fabplan.plan_strips,
                                     fabplan.StripSettings(height_mm=100, thickness_mm=5))):
        with pytest.raises(InputError, match="either settings or keyword options"):
            plan_function(small, settings, units="m")


def test_obj_and_3dm_round_trip_exactly(tmp_path, patch):
    obj = fabplan.write_obj((patch.vertices, patch.faces), tmp_path / "net.obj")
    back = fabplan.read_obj(obj)
    assert np.array_equal(back.vertices, patch.vertices)
    path = fabplan.write_3dm(back, tmp_path / "net.3dm")
    again = fabplan.read_3dm(path)
    assert np.array_equal(again.vertices, patch.vertices)
    assert [f.tolist() for f in again.faces] == [f.tolist() for f in patch.faces]


def test_run_study_names_an_unknown_study(tmp_path):
    with pytest.raises(InputError):
        fabplan.run_study(tmp_path / "missing.toml")


def _load_example(name: str):
    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def test_grasshopper_example_with_rhino3dm(tmp_path, patch, capsys):
    """The example's calls on a Rhino mesh (rhino3dm standing in for RhinoCommon): the mesh
    comes over exactly, the solved net and its arcs go back as Rhino geometry."""
    rhino3dm = pytest.importorskip("rhino3dm")
    example = _load_example("grasshopper")
    doc = rhino3dm.File3dm()
    doc.Objects.AddMesh(example.to_rhino_mesh(patch.vertices, patch.faces, rhino3dm))
    doc.Write(str(tmp_path / "in.3dm"), 8)
    V, F = example.mesh_arrays(rhino3dm.File3dm.Read(str(tmp_path / "in.3dm")).Objects[0].Geometry)
    assert np.array_equal(V, patch.vertices) and F == [f.tolist() for f in patch.faces]

    assert example.main([str(tmp_path / "in.3dm"), "-o", str(tmp_path / "out.3dm")]) == 0
    assert "snet: converged" in capsys.readouterr().out
    out = rhino3dm.File3dm.Read(str(tmp_path / "out.3dm"))
    meshes = [o for o in out.Objects if isinstance(o.Geometry, rhino3dm.Mesh)]
    arcs = [o.Geometry for o in out.Objects if isinstance(o.Geometry, rhino3dm.ArcCurve)]
    assert len(meshes) == 1 and meshes[0].Attributes.GetUserString("status") == "converged"
    solved, _ = example.mesh_arrays(meshes[0].Geometry)
    assert len(arcs) == len(patch.edges)
    ends = np.array([[c.PointAtStart.X, c.PointAtStart.Y, c.PointAtStart.Z] for c in arcs])
    # every arc starts on a vertex of the solved net
    gap = np.linalg.norm(ends[:, None, :] - solved[None, :, :], axis=2).min(axis=1)
    assert gap.max() < 1e-9 * patch.mean_edge_length
