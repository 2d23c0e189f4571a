"""A building's model does not depend on the other tiles of the run (the run's origin)."""

import json

import numpy as np
import pytest


def _models(path):
    """``{id: sorted LoD2.2 vertices in world millimetres}`` of a CityJSON file."""
    doc = json.loads(path.read_text())
    v = np.asarray(doc["vertices"], dtype=np.int64)
    v = v * np.rint(np.asarray(doc["transform"]["scale"]) / 0.001).astype(np.int64) \
        + np.rint(np.asarray(doc["transform"]["translate"]) / 0.001).astype(np.int64)
    out = {}
    for oid, o in doc["CityObjects"].items():
        for g in o.get("geometry", []):
            if g["lod"] == "2.2":
                idx = np.asarray(list(_flat(g["boundaries"])), dtype=np.int64)
                out[oid] = np.unique(v[idx], axis=0)
    return out


def _flat(b):
    if isinstance(b, int):
        yield b
    else:
        for x in b:
            yield from _flat(x)


@pytest.mark.slow
def test_a_buildings_roof_does_not_depend_on_the_other_tiles_of_the_run(data, tmp_path):
    """The same buildings, alone and with a tile 229 m south of them in the run (which
    moves the run's origin, the lower corner of its tiles, by 229 m): the same LoD2.2."""
    import laspy

    from lidar2city.tools.reconstruct import reconstruct

    las = laspy.read(data / "delft" / "ahn3_cropped_1.laz")
    x, y = las.x, las.y
    keep = (x > 84900) & (x < 84960) & (y > 447480) & (y < 447560)
    crop = laspy.LasData(las.header)
    crop.points = las.points[keep].copy()
    crop.update_header()
    crop.write(tmp_path / "crop.laz")
    far = laspy.LasData(las.header)  # a few ground points 229 m south of the crop
    far.points = las.points[np.flatnonzero(keep & (las.classification == 2))[:20]].copy()
    far.Y = far.Y - 229_000
    far.update_header()
    far.write(tmp_path / "far.laz")
    fp = data / "delft" / "footprints_bgt.gpkg"
    models = []
    for name, tiles in {"alone": ["crop.laz"], "with": ["crop.laz", "far.laz"]}.items():
        out = tmp_path / f"{name}.city.json"
        reconstruct([tmp_path / t for t in tiles], out, footprints=fp, crs="EPSG:7415",
                    lods=("1.2", "2.2"))
        models.append(_models(out))
    alone, other = models
    inside = [k for k in alone if k in other]
    assert len(inside) >= 10
    assert [k for k in inside if not np.array_equal(alone[k], other[k])] == []
