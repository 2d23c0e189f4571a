"""The LoD2.2 roof against the LoD1.2 prism: the batch keeps the better-founded model."""

from __future__ import annotations

import numpy as np
import pytest
from shapely.geometry import box

from lidar2city.lod.prism import prism_solid
from lidar2city.lod.roofcheck import roof_residuals, worse_than_prism


def _shed(x0, y0, x1, y1, z0, z1):
    """A closed shed-roof solid: roof rising from z0 at x0 to z1 at x1 (floor at 0)."""
    from lidar2city.datamodel import Solid, Surface

    v = np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0],
                  [x0, y0, z0], [x1, y0, z1], [x1, y1, z1], [x0, y1, z0]], dtype=float)
    faces = [Surface([[0, 3, 2, 1]], "GroundSurface"), Surface([[4, 5, 6, 7]], "RoofSurface"),
             Surface([[0, 1, 5, 4]], "WallSurface"), Surface([[1, 2, 6, 5]], "WallSurface"),
             Surface([[2, 3, 7, 6]], "WallSurface"), Surface([[3, 0, 4, 7]], "WallSurface")]
    return Solid(v, faces)


def test_roof_residuals_are_exact_on_a_sloped_roof():
    s = _shed(0, 0, 10, 6, 3.0, 8.0)
    pts = np.array([[0.5, 1, 3.25 + 0.1], [5, 3, 5.5 - 0.2], [9.5, 5, 7.75], [12, 3, 1.0]])
    r = roof_residuals(s, pts)
    assert r[:3] == pytest.approx([0.1, -0.2, 0.0], abs=1e-12) and np.isnan(r[3])
    # two solids (a multi-part building): each point against the roof over it
    two = [s, prism_solid(box(20, 0, 30, 6), 0.0, 4.0)]
    r = roof_residuals(two, np.vstack([pts, [[25, 3, 4.5]]]))
    assert r[4] == pytest.approx(0.5)


def test_a_roof_worse_than_the_prism_is_named_and_a_better_one_kept():
    rng = np.random.default_rng(0)
    xy = rng.uniform(0.2, 9.8, (500, 2)) * [1, 0.6]
    z = 3.0 + 0.5 * xy[:, 0] + rng.normal(0, 0.03, len(xy))  # a shed roof, 3 to 8 m
    pts = np.column_stack([xy, z])
    prism = prism_solid(box(0, 0, 10, 6), 0.0, float(np.percentile(z, 70)))
    assert worse_than_prism(_shed(0, 0, 10, 6, 3.0, 8.0), prism, pts, margin=0.3) == ""
    low = _shed(0, 0, 10, 6, 1.0, 2.0)  # a roof far under its points
    why = worse_than_prism(low, prism, pts, margin=0.3)
    assert why.startswith("the LoD2.2 roof fits its points worse") and "m against" in why


def test_reconstruct_falls_back_to_the_prism_with_the_reason(monkeypatch):
    """A LoD2.2 roof 2 m under its flat roof's points: the prism stands in, said why."""
    from lidar2city.datamodel import Footprints, PointCloud
    from lidar2city.roof import building
    from lidar2city.tools.reconstruct import reconstruct_buildings
    from lidar2city.config import stage_config

    rng = np.random.default_rng(1)
    xy = rng.uniform(0, 30, (9000, 2))
    roof = (xy[:, 0] > 10) & (xy[:, 0] < 20) & (xy[:, 1] > 10) & (xy[:, 1] < 18)
    z = np.where(roof, 6.0, 0.0) + rng.normal(0, 0.02, len(xy))
    cloud = PointCloud(np.column_stack([xy, z]),
                       attributes={"classification": np.where(roof, 6, 2).astype(np.uint8)})
    fps = Footprints([box(10, 10, 20, 18)], ["A"])
    lod22 = stage_config("lod22", None)
    ok = reconstruct_buildings(cloud, fps, lod22=lod22)[0]
    assert "lod22_fallback" not in ok.attributes

    real = building.reconstruct_lod22

    def sunk(*args, **kwargs):
        out = real(*args, **kwargs)
        out.solids[0].vertices[out.solids[0].vertices[:, 2] > 1.0, 2] -= 2.0
        return out

    monkeypatch.setattr(building, "reconstruct_lod22", sunk)
    r = reconstruct_buildings(cloud, fps, lod22=lod22)[0]
    assert r.attributes["lod22_fallback"].startswith("LoD1.2 prism: the LoD2.2 roof fits")
    assert r.solids["2.2"] is r.solids["1.2"]


def test_nebraska_narrow_building_keeps_its_roof(data, tmp_path):
    """Nebraska's traced b1 (9 x 2.7 m at the tile's edge, canopy over its roof labelled
    building): its 3-D RMSE is 4.7 m in LoD2.2 against 1.05 m for the prism, since no
    point inside a 2.7 m wide prism is more than 1.35 m from a wall; vertically the
    LoD2.2 roof is the right one (median 0.3 m against the prism's 6.3 m, which sits
    in the canopy), so it is kept."""
    import json

    from lidar2city.tools.reconstruct import reconstruct

    out = tmp_path / "neb.city.json"
    reconstruct([data / "misc" / "file_with_both_wkt_and_geotiff_vlrs.las"], out,
                lods=("1.2", "2.2"))
    objs = json.loads(out.read_text())["CityObjects"]
    assert len(objs) == 2
    assert not any("lod22_fallback" in o["attributes"] for o in objs.values())


def test_a_roof_corner_far_above_every_point_is_refused():
    """The median of worse_than_prism never sees one small spike; the top check does."""
    from lidar2city.lod.roofcheck import rises_above_points

    spiked = [_shed(0, 0, 10, 6, 3.0, 8.0), _shed(10, 0, 12, 6, 3.0, 40.0)]  # a 2 m wide spike
    pts = np.array([[x, y, 3.0 + 0.5 * x] for x in np.arange(0.25, 12, 0.5) for y in (1.0, 5.0)])
    reason = rises_above_points(spiked, pts, tolerance=1.0)
    assert reason.startswith("the LoD2.2 roof rises 31.1")
    assert worse_than_prism(spiked, prism_solid(box(0, 0, 12, 6), 0.0, 8.0), pts, margin=0.3) == ""
    assert rises_above_points(spiked[:1], pts, tolerance=1.0) == ""
    assert rises_above_points(spiked, np.zeros((0, 3)), tolerance=1.0) == ""
