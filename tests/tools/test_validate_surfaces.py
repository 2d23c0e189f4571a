"""``validate`` on objects that are surfaces, not volumes (terrain, roads), as in
3dfier's and 3DBAG's files: checked polygon by polygon, as val3dity does."""

import json

from lidar2city.tools.validate import validate_file


def _model(path, otype, boundaries, gtype="MultiSurface"):
    verts = [[0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0], [5, 5, 0]]
    doc = {"type": "CityJSON", "version": "2.0", "transform": {"scale": [1, 1, 1], "translate": [0, 0, 0]},
           "vertices": verts,
           "CityObjects": {"o": {"type": otype, "geometry": [{"type": gtype, "lod": "1", "boundaries": boundaries}]}}}
    path.write_text(json.dumps(doc))
    return path


def test_open_terrain_is_valid_but_an_open_building_is_not(tmp_path):
    # a flat square in two triangles: a valid surface, not a closed shell
    quad = [[[0, 1, 2]], [[0, 2, 3]]]
    ground = validate_file(_model(tmp_path / "t.city.json", "TINRelief", quad), schema=False)
    assert ground.valid, ground.objects[0].issues
    road = validate_file(_model(tmp_path / "r.city.json", "Road", quad, "CompositeSurface"), schema=False)
    assert road.valid, road.objects[0].issues
    house = validate_file(_model(tmp_path / "b.city.json", "Building", quad), schema=False)
    assert not house.valid and {i.code for _, _, i in house.objects[0].issues} == {301}


def test_polygons_of_surfaces_are_still_checked(tmp_path):
    # a ring that collapses to a line is an error on any object
    bad = [[[0, 4, 2]], [[0, 2, 3]]]
    rep = validate_file(_model(tmp_path / "t.city.json", "TINRelief", bad), schema=False)
    assert not rep.valid and {i.code for _, _, i in rep.objects[0].issues} == {104}
