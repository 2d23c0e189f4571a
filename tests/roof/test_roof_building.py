import numpy as np
import pytest
import shapely

from lidar2city.roof.building import reconstruct_lod22
from lidar2city.synthetic import make_town


@pytest.fixture(scope="module")
def town():
    return make_town(density=8, seed=0)


@pytest.fixture(scope="module")
def models(town):
    xyz = town.cloud.xyz
    pts = xyz[town.cloud.get("classification") == 6]
    return {b.id: reconstruct_lod22(b.footprint, pts, b.ground_z) for b in town.buildings}


def test_roof_types(town, models):
    expected = {"gable": "gable", "hip": "hip", "flat": "flat", "shed": "shed", "L": "flat",
                "courtyard": "flat", "stepped": "flat"}
    for b in town.buildings:
        assert models[b.id].attributes["roof_type"] == expected[b.roof_type], b.id


def test_roof_surface_matches_truth(town, models):
    from tests.roof.test_roof_solid import shell_errors

    for b in town.buildings:
        (solid,) = models[b.id].solids
        bad, vol = shell_errors(solid)
        assert not bad
        # every roof vertex lies on the true roof (within noise) or on a wall line
        V = solid.vertices
        for s in solid.surfaces:
            if s.semantic != "RoofSurface":
                continue
            P = V[s.rings[0]]
            inner = np.asarray(shapely.contains_xy(b.footprint.buffer(-0.3), P[:, 0], P[:, 1]))
            if inner.any():
                dz = P[inner, 2] - b.roof_z(P[inner, :2])
                assert np.nanmax(np.abs(dz)) < 0.35, (b.id, b.roof_type)


def test_ridges_land_on_truth(town, models):
    for b in town.buildings:
        if b.roof_type not in ("gable", "hip"):
            continue
        (solid,) = models[b.id].solids
        top = solid.vertices[np.isclose(solid.vertices[:, 2], solid.vertices[:, 2].max(), atol=0.05)]
        (x0, y0, z0), (x1, y1, z1) = b.ridges[0]
        assert abs(top[:, 2].max() - z0) < 0.15
        # ridge end points: horizontal distance to the true ridge segment
        seg = shapely.LineString([(x0, y0), (x1, y1)])
        d = [seg.distance(shapely.Point(p[:2])) for p in top]
        assert max(d) < 0.3, (b.id, d)
