"""`lidar2city edit` and `lidar2city reconstruct --edits`: one refit, one-line errors."""

import json
import shutil

from lidar2city.cli.main import cli
from lidar2city.io.cityjson import read_cityjson


def _args(t, model, *extra):
    return ["edit", str(model), "--points", str(t.laz), "--edits", str(model.parent / "E.json"),
            *extra]


def test_edit_primitive_then_reconstruct_edits(edit_town, tmp_path, runner):
    model = tmp_path / "m.city.json"
    shutil.copy(edit_town.model, model)
    res = runner.invoke(cli, _args(edit_town, model, "--building", "b01", "--primitive", "hip"))
    assert res.exit_code == 0, res.output
    assert "refit as hip" in res.output
    assert read_cityjson(model).objects["b01"]["attributes"]["primitive"] == "hip"
    out = tmp_path / "re.city.json"
    res = runner.invoke(cli, ["reconstruct", str(edit_town.laz), "--footprints",
                              str(edit_town.footprints), "--lod", "1.2", "--lod", "2.2",
                              "--edits", str(tmp_path / "E.json"), "-o", str(out), "-q"])
    assert res.exit_code == 0, res.output
    assert out.read_bytes() == model.read_bytes()


def test_edit_footprint_file_and_one_line_errors(edit_town, tmp_path, runner):
    model = tmp_path / "m.city.json"
    shutil.copy(edit_town.model, model)
    before = model.read_bytes()
    bowtie = tmp_path / "bowtie.geojson"
    x, y = 85030.0, 447020.0
    bowtie.write_text(json.dumps({"type": "Feature", "properties": {}, "geometry": {
        "type": "Polygon", "coordinates": [[[x, y], [x + 9, y + 9], [x + 9, y], [x, y + 9],
                                            [x, y]]]}}))
    cases = [
        (["--building", "nope", "--primitive", "box"], "unknown building id 'nope'"),
        (["--building", "b02", "--primitive", "gable"], "gable primitive cannot be fitted"),
        (["--building", "b00", "--footprint", str(bowtie)], "self-intersecting"),
        (["--building", "b00"], "either --primitive"),
        (["--building", "b00", "--primitive", "box", "--param", "length"], "NAME=NUMBER"),
    ]
    for extra, message in cases:
        res = runner.invoke(cli, _args(edit_town, model, *extra))
        assert res.exit_code == 1, (extra, res.output)
        assert message in res.output and "Traceback" not in res.output
        assert res.output.strip().count("\n") == 0, res.output
    assert model.read_bytes() == before
    assert not (tmp_path / "E.json").exists()
    square = tmp_path / "sq.geojson"
    import shapely
    from shapely.geometry import mapping, shape

    from lidar2city.tools.edit import EditSession

    fp = shape(EditSession(model, [edit_town.laz]).footprint("b02"))
    square.write_text(json.dumps(mapping(shapely.get_parts(fp)[0].buffer(0.4, join_style="mitre"))))
    res = runner.invoke(cli, _args(edit_town, model, "--building", "b02", "--footprint",
                                   str(square), "-o", str(tmp_path / "out.city.json")))
    assert res.exit_code == 0, res.output
    assert model.read_bytes() == before  # -o leaves MODEL as it was
    a = read_cityjson(tmp_path / "out.city.json").objects["b02"]["attributes"]
    assert a["edit"].startswith("footprint edited") and a["valid"] is True
