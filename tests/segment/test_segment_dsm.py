"""DSM segmentation: DTM by region growing, vegetation, building mask, gridding."""

from __future__ import annotations

import numpy as np
import pytest

from lidar2city.errors import EmptyInputError, InputError
from lidar2city.segment.dsm import (
    building_mask,
    dtm_from_dsm,
    grid_points,
    label_buildings,
    roughness,
    vegetation_from_colour,
)

CELL = 1.0


def synthetic_scene(seed=3):
    """Sloped terrain (3 %), three flat/pitched boxes, two rough trees; exact masks."""
    rng = np.random.default_rng(seed)
    h, w = 120, 160
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    terrain = 10.0 + 0.03 * xx + 0.01 * yy
    dsm = terrain.copy()
    buildings = np.zeros((h, w), bool)
    boxes = [(10, 30, 15, 45, 8.0, 0.0), (60, 90, 20, 40, 12.0, 0.0), (30, 55, 90, 140, 6.0, 0.3)]
    for r0, r1, c0, c1, hgt, pitch in boxes:
        rr = yy[r0:r1, c0:c1]
        ridge = (r0 + r1 - 1) / 2.0
        roof = hgt + pitch * (np.abs(rr - ridge).max() - np.abs(rr - ridge))
        dsm[r0:r1, c0:c1] = terrain[r0:r1, c0:c1] + roof
        buildings[r0:r1, c0:c1] = True
    trees = np.zeros((h, w), bool)
    for cy, cx, rad in ((95, 110, 8), (15, 120, 6)):
        d2 = (yy - cy) ** 2 + (xx - cx) ** 2
        crown = d2 <= rad**2
        dome = 7.0 * np.sqrt(np.clip(1 - d2 / rad**2, 0, 1)) + rng.normal(0, 1.2, (h, w))
        dsm = np.where(crown, terrain + np.maximum(dome, 3.0), dsm)
        trees |= crown
    dsm += rng.normal(0, 0.03, (h, w))
    return dsm, terrain, buildings, trees


def test_dtm_from_dsm_recovers_sloped_terrain():
    dsm, terrain, buildings, trees = synthetic_scene()
    dtm, ground = dtm_from_dsm(dsm, cell=CELL, seed_window=60.0)
    assert not (ground & (buildings | trees)).any()
    err = np.abs(dtm - terrain)
    assert np.median(err) < 0.1
    assert np.percentile(err, 99) < 0.5
    assert (dtm <= dsm + 1e-9).all()


def test_dtm_respects_nodata_and_validates():
    dsm, terrain, *_ = synthetic_scene()
    dsm = dsm.copy()
    dsm[:5, :5] = np.nan
    dtm, ground = dtm_from_dsm(dsm, cell=CELL, seed_window=60.0)
    assert np.isnan(dtm[:5, :5]).all() and not ground[:5, :5].any()
    assert np.isfinite(dtm[5:, 5:]).all()
    with pytest.raises(EmptyInputError):
        dtm_from_dsm(np.full((10, 10), np.nan), cell=1.0)
    with pytest.raises(InputError):
        dtm_from_dsm(dsm, cell=-1.0)
    with pytest.raises(InputError):
        dtm_from_dsm(dsm[0], cell=1.0)


def test_building_mask_separates_boxes_from_trees():
    dsm, terrain, buildings, trees = synthetic_scene()
    ndsm = dsm - terrain
    mask = building_mask(ndsm, cell=CELL, roughness_threshold=0.6)
    assert (mask & trees).sum() < 0.05 * trees.sum()
    assert (mask & buildings).sum() > 0.9 * buildings.sum()
    labels, n = label_buildings(mask)
    assert n == 3


def test_roughness_zero_on_planes():
    yy, xx = np.mgrid[0:20, 0:20].astype(float)
    plane = 3.0 + 0.5 * xx - 0.2 * yy
    assert np.allclose(roughness(plane)[1:-1, 1:-1], 0.0, atol=1e-6)  # borders are padded
    bumpy = plane + np.random.default_rng(0).normal(0, 1.0, plane.shape)
    assert np.nanmedian(roughness(bumpy)) > 0.5


def test_courtyard_kept_small_hole_filled():
    nd = np.zeros((60, 60))
    nd[10:50, 10:50] = 9.0
    nd[25:35, 25:35] = 0.0  # 100 m2 courtyard
    nd[40:42, 40:42] = 0.0  # 4 m2 hole
    m = building_mask(nd, cell=1.0)
    assert not m[30, 30] and m[40, 40]


def test_vegetation_from_colour():
    rng = np.random.default_rng(1)
    h, w = 40, 40
    rgb = np.zeros((h, w, 3))
    rgb[...] = [150, 140, 135]  # grey roofs
    veg = np.zeros((h, w), bool)
    veg[:, 20:] = True
    rgb[veg] = [60, 120, 50]
    rgb += rng.normal(0, 6, rgb.shape)
    elevated = np.ones((h, w), bool)
    got = vegetation_from_colour(np.moveaxis(rgb, -1, 0), elevated)
    assert (got == veg).mean() > 0.97
    with pytest.raises(InputError):
        vegetation_from_colour(rgb[..., :2], elevated)


def test_grid_points_highest_and_values():
    xyz = np.array([[0.2, 0.2, 1.0], [0.7, 0.4, 5.0], [1.5, 0.5, 2.0], [0.5, 1.5, 3.0]])
    rgb = np.array([[1, 1, 1], [9, 9, 9], [2, 2, 2], [3, 3, 3]])
    g = grid_points(xyz, rgb, cell=1.0, fill_gaps=0)
    # rows run south: y in [1, 2) is row 0
    assert g["dsm"].shape == (2, 2)
    assert g["dsm"][1, 0] == 5.0 and g["dsm"][1, 1] == 2.0 and g["dsm"][0, 0] == 3.0
    assert np.isnan(g["dsm"][0, 1])
    assert g["values"][:, 1, 0].tolist() == [9, 9, 9]
    assert g["count"][1, 0] == 2
    filled = grid_points(xyz, rgb, cell=1.0, fill_gaps=1)
    assert np.isfinite(filled["dsm"]).all()
    with pytest.raises(EmptyInputError):
        grid_points(np.zeros((0, 3)), cell=1.0)
