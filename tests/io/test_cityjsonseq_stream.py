"""The streaming CityJSONSeq writer gives the bytes of write_cityjsonseq, and nothing on failure."""

import pytest

from lidar2city.io.cityjson import write_cityjsonseq
from lidar2city.io.cityjsonseq import CityJSONSeqWriter
from lidar2city.synthetic import make_town
from lidar2city.tools.reconstruct import reconstruct_buildings


@pytest.fixture(scope="module")
def town_results():
    town = make_town(size=(90.0, 70.0), density=3.0, seed=8, n_trees=2)
    return town, reconstruct_buildings(town.cloud, town.footprints)


def test_streamed_features_are_the_bytes_of_the_whole_file(town_results, tmp_path):
    town, results = town_results
    c = town.cloud
    common = dict(origin=c.origin, crs=c.crs, xy_unit=c.xy_unit, z_unit=c.z_unit,
                  configuration={"lod1": {"x": 1}}, title="t")
    fields = {"source": [f"s{i}" for i in range(len(results))]}
    write_cityjsonseq(tmp_path / "whole.city.jsonl", results, attributes=fields, **common)
    with CityJSONSeqWriter(tmp_path / "stream.city.jsonl", **common) as w:
        for i, r in enumerate(results):
            w.add(r, {"source": fields["source"][i]})
    assert len(results) > 1
    assert (tmp_path / "stream.city.jsonl").read_bytes() == \
        (tmp_path / "whole.city.jsonl").read_bytes()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_a_failed_stream_leaves_nothing(town_results, tmp_path):
    town, results = town_results
    c = town.cloud
    with pytest.raises(RuntimeError):
        with CityJSONSeqWriter(tmp_path / "x.city.jsonl", origin=c.origin, crs=c.crs) as w:
            w.add(results[0])
            raise RuntimeError("stop")
    assert list(tmp_path.iterdir()) == []
