import numpy as np
from shapely.geometry import Polygon

from lidar2city.datamodel import BuildingResult
from lidar2city.io.obj import read_obj, write_obj
from lidar2city.lod.prism import prism_solid


def test_obj_round_trip(tmp_path):
    poly = Polygon([(0, 0), (10, 0), (10, 10), (0, 10)], [[(3, 3), (3, 6), (6, 6), (6, 3)]])
    r1 = BuildingResult("a", solids={"1.2": prism_solid(poly, 0.0, 5.0)})
    r2 = BuildingResult("b", solids={"1.2": prism_solid(Polygon([(20, 0), (25, 0), (25, 4)]), 1.0, 3.0)})
    path = tmp_path / "m.obj"
    write_obj(path, [r1, r2, BuildingResult("c", status="failed")], origin=[85000, 447000, 0])
    verts, objects = read_obj(path)
    assert set(objects) == {"a", "b"}
    assert len(verts) == 16 + 6
    assert all(len(f) == 3 for f in objects["a"])
    # 8 walls (2 triangles each) + roof and ground with a hole (8 triangles each)
    assert len(objects["a"]) == 16 + 16
    assert verts[:, 0].min() == 85000 and verts[:, 2].max() == 5.0
    # faces point outward: the signed volume is positive
    tri = verts[np.array(objects["a"])]
    vol = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6
    assert np.isclose(vol, (100 - 9) * 5)
    write_obj(tmp_path / "l.obj", [r1], origin=[85000, 447000, 0], local=True)
    assert "# origin 85000.000" in (tmp_path / "l.obj").read_text()


def test_obj_carries_its_crs(tmp_path):
    """OBJ has no CRS field: the CRS goes in a header comment and a ``.prj`` sidecar
    beside the file (as GIS tools read it), and none is written without a CRS."""
    from pyproj import CRS

    solid = prism_solid(Polygon([(0, 0), (4, 0), (4, 4)]), 0.0, 3.0)
    r = BuildingResult("a", solids={"1.2": solid})
    path = tmp_path / "m.obj"
    write_obj(path, [r], origin=[85000, 447000, 0], crs=CRS.from_epsg(7415))
    assert "# crs EPSG:7415\n" in path.read_text()
    assert CRS.from_user_input((tmp_path / "m.prj").read_text()).equals(CRS.from_epsg(7415))
    write_obj(tmp_path / "n.obj", [r], origin=[85000, 447000, 0])
    assert not (tmp_path / "n.prj").exists() and "# crs" not in (tmp_path / "n.obj").read_text()
