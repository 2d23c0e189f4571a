"""The viewer's pure drawing helpers."""

import numpy as np

from lidar2city.viewer import scene


def test_numeric_and_categorical_colours():
    attrs = {"a": {"rmse_lod12": 0.1}, "b": {"rmse_lod12": 0.5}, "c": {}}
    colours, legend = scene.colours_for(scene.attribute_values(attrs, "RMSE"))
    assert colours["a"] != colours["b"] and colours["c"] == (170, 170, 170)
    assert legend[-1][0] == "no value" and len(legend) == 6
    colours, legend = scene.colours_for(scene.attribute_values(
        {"a": {"roof_type": "gable"}, "b": {"roof_type": "flat"}, "c": {"roof_type": "gable"}},
        "roof type"))
    assert colours["a"] == colours["c"] != colours["b"]
    assert [label for label, _ in legend] == ["flat", "gable"]


def test_worst_first_and_subsample():
    attrs = {"ok": {"rmse_lod12": 0.1}, "bad": {"rmse_lod12": 2.0},
             "failed": {"status": "failed"}, "invalid": {"valid": False, "rmse_lod12": 0.0}}
    assert [b for b, _ in scene.worst_buildings(attrs)] == ["failed", "invalid", "bad", "ok"]
    assert len(scene.subsample(1000, 100)) <= 100 and len(scene.subsample(10, 100)) == 10
    assert len(scene.subsample(10, 0)) == 0


def test_building_meshes_are_in_the_display_frame():
    from lidar2city.lod.prism import prism_solid
    import shapely

    s = prism_solid(shapely.box(100000.0, 400000.0, 100010.0, 400005.0), 0.0, 6.0)
    meshes = scene.building_meshes({"x": [s]}, origin=(100000.0, 400000.0, 0.0))
    v, t = meshes["x"]
    assert v.dtype == np.float32 and v.max() <= 10.0 and t.shape[1] == 3
    assert len(t) == 12  # 6 rectangles, 2 triangles each


def test_reasons_are_shown_whole_and_do_not_break_the_table():
    """A fallback reason ('LoD1.2 prism: LoD2.2 solid invalid (...)') is what a user
    clicks a building to read: it is not cut at 60 characters, and a '|' in a value
    does not split the row."""
    reason = "LoD1.2 prism: LoD2.2 solid invalid (303 NON_MANIFOLD_EDGE edge 12-13 used 3 times)"
    md = scene.attributes_markdown("b", {"lod22_fallback": reason, "note": "a | b",
                                         "long": "x" * 100})
    assert f"| lod22_fallback | {reason} |" in md
    assert "| note | a \\| b |" in md
    assert "| long | " + "x" * 60 + "... |" in md
