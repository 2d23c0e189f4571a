"""Editing one building: the edit record, the refit, the atomic save, and `reconstruct --edits`."""

import json
import shutil

import numpy as np
import pytest

from lidar2city.errors import FileFormatError, FitError, InputError
from lidar2city.io.cityjson import read_cityjson
from lidar2city.tools.edit import (
    Edit,
    EditSession,
    append_edit,
    apply_edit,
    footprint_local,
    load_edits,
)
from lidar2city.tools.reconstruct import reconstruct

SQUARE = {"type": "Polygon", "coordinates": [[[0, 0], [10, 0], [10, 10], [0, 10], [0, 0]]]}
BOWTIE = {"type": "Polygon", "coordinates": [[[0, 0], [10, 10], [10, 0], [0, 10], [0, 0]]]}


@pytest.fixture
def work(edit_town, tmp_path):
    """A copy of the town's model to edit, and an EditSession on it."""
    model = tmp_path / "m.city.json"
    shutil.copy(edit_town.model, model)
    session = EditSession(model, [edit_town.laz], footprints=edit_town.footprints)
    return edit_town, model, session


def _vertices(model, bid, lod):
    solids = model.solids(bid, lod=lod)
    return np.concatenate([s.vertices for s in solids]) if solids else np.zeros((0, 3))


def test_edit_record_checks_and_round_trips(tmp_path):
    e = Edit("b1", "primitive", SQUARE, "gable", {"azimuth": 30.0, "length": 12.0})
    assert Edit.from_dict(json.loads(json.dumps(e.to_dict()))) == e
    with pytest.raises(InputError, match="action"):
        Edit("b1", "paint", SQUARE)
    with pytest.raises(InputError, match="unknown primitive"):
        Edit("b1", "primitive", SQUARE, "dome")
    with pytest.raises(InputError, match="parameter"):
        Edit("b1", "primitive", SQUARE, "box", {"colour": 1.0})
    with pytest.raises(InputError, match="takes no primitive"):
        Edit("b1", "footprint", SQUARE, "box")
    path = tmp_path / "E.json"
    assert append_edit(path, e) == 1
    assert append_edit(path, Edit("b2", "footprint", SQUARE)) == 2
    assert [x.building for x in load_edits(path)] == ["b1", "b2"]
    path.write_text("{not json")
    with pytest.raises(FileFormatError, match="not a JSON"):
        load_edits(path)
    with pytest.raises(FileFormatError, match="no such file"):
        load_edits(tmp_path / "absent.json")


def test_self_intersecting_footprint_is_refused(work):
    _, _, session = work
    with pytest.raises(InputError, match="self-intersecting"):
        footprint_local(Edit("b00", "footprint", BOWTIE), session.reader)
    with pytest.raises(InputError, match="self-intersecting"):
        session.refit(session.make_edit("b00", footprint=BOWTIE))


def test_refit_as_primitive_is_pure_and_records_the_edit(work):
    town, _, session = work
    edit = session.make_edit("b00", primitive="gable")
    cloud, classes = session.points(edit.footprint)
    before = session.current_result("b00")
    attrs = dict(before.attributes)
    res = apply_edit(before, edit, cloud, classes, context=session.context)
    assert before.attributes == attrs  # the input result is not changed
    assert res.ok and res.attributes["primitive"] == "gable"
    assert res.attributes["primitive_choice"] == "user"
    assert res.attributes["edit"] == "refit as gable (least squares)"
    assert res.attributes["edit_count"] == 1
    assert "lod22_fallback" not in res.attributes
    # the ridge of the synthetic gable (8.50 m) is found
    top = np.concatenate([s.vertices for s in ([res.solids["2.2"]] if not
                                               isinstance(res.solids["2.2"], list) else
                                               res.solids["2.2"])])[:, 2].max()
    assert top == pytest.approx(town.town.buildings[0].ridges[0][0][2], abs=0.15)


def test_errors_unknown_building_and_unfittable_primitive(work):
    _, _, session = work
    with pytest.raises(InputError, match="unknown building id 'nope'"):
        session.make_edit("nope", primitive="box")
    # a gable on the flat roof: the rise is not significant
    with pytest.raises(FitError, match="gable"):
        session.refit(session.make_edit("b02", primitive="gable"))
    # an outline where there is no building point: too few points
    x, y = session.reader.origin[:2] + 2.0
    empty = {"type": "Polygon", "coordinates": [[[x, y], [x + 3, y], [x + 3, y + 3], [x, y + 3],
                                                  [x, y]]]}
    with pytest.raises(FitError, match="points"):
        session.refit(session.make_edit("b00", footprint=empty))


def test_user_placed_primitive_starts_the_fit(work):
    _, _, session = work
    from shapely.geometry import shape

    c = shape(session.footprint("b00")).centroid
    edit = session.make_edit("b00", primitive="gable",
                             approximate={"x": c.x + 0.5, "y": c.y - 0.3, "azimuth": 2.0,
                                          "length": 16.0, "width": 9.0})
    res = session.refit(edit)
    assert res.attributes["edit"] == "refit as gable (user-placed)"
    assert abs(res.attributes["primitive_x"] - c.x) < 0.5


def test_save_is_valid_and_reconstruct_edits_reproduces_it(work, tmp_path):
    town, model_path, session = work
    edits = tmp_path / "E.json"
    # 1) b00 refit as a gable; 2) b02's outline moved: one vertex 0.6 m outwards
    e1 = session.make_edit("b00", primitive="gable")
    session.save(session.refit(e1), e1, edits=edits)
    from shapely.geometry import mapping, shape

    import shapely

    poly = shapely.get_parts(shape(session.footprint("b02")))[0]
    coords = np.asarray(poly.exterior.coords)
    centre = coords[:-1].mean(axis=0)
    k = 0
    coords[k] = coords[k] + 0.6 * (coords[k] - centre) / np.linalg.norm(coords[k] - centre)
    coords[-1] = coords[0]
    outline = mapping(type(poly)(coords))
    e2 = session.make_edit("b02", footprint=outline)
    session.save(session.refit(e2), e2, edits=edits)
    assert len(load_edits(edits)) == 2

    from lidar2city.tools.validate import validate_file

    assert validate_file(model_path).valid
    edited = read_cityjson(model_path)
    assert edited.objects["b00"]["attributes"]["primitive"] == "gable"
    assert edited.objects["b02"]["attributes"]["edit"].startswith("footprint edited")
    original = read_cityjson(town.model)
    for bid in ("b01", "b03"):  # the others are untouched
        assert edited.objects[bid]["attributes"] == original.objects[bid]["attributes"]
        np.testing.assert_array_equal(_vertices(edited, bid, "2.2"), _vertices(original, bid, "2.2"))

    rerun = tmp_path / "rerun.city.json"
    reconstruct([town.laz], rerun, footprints=town.footprints, lods=("1.2", "2.2"), edits=edits)
    again = read_cityjson(rerun)
    for bid in edited.buildings():
        for lod in ("1.2", "2.2"):
            a, b = _vertices(edited, bid, lod), _vertices(again, bid, lod)
            assert a.shape == b.shape
            assert np.abs(a - b).max(initial=0.0) <= 0.001
        assert edited.objects[bid]["attributes"] == again.objects[bid]["attributes"]


def test_reconstruct_edits_unknown_id_and_failing_edit(edit_town, tmp_path):
    edits = tmp_path / "E.json"
    append_edit(edits, Edit("nope", "footprint", SQUARE))
    with pytest.raises(InputError, match="unknown building id"):
        reconstruct([edit_town.laz], tmp_path / "x.city.json", footprints=edit_town.footprints,
                    lods=("1.2",), edits=edits)
    assert not (tmp_path / "x.city.json").exists()
    # an edit that no longer fits leaves the building as reconstructed, with the reason
    session = EditSession(edit_town.model, [edit_town.laz])
    bad = tmp_path / "bad.json"
    append_edit(bad, session.make_edit("b02", primitive="gable"))
    out = tmp_path / "y.city.json"
    s = reconstruct([edit_town.laz], out, footprints=edit_town.footprints, lods=("1.2", "2.2"),
                    edits=bad)
    assert s.failed == 0
    a = read_cityjson(out).objects["b02"]["attributes"]
    assert "gable" in a["edit_error"] and "edit" not in a


def test_primitive_edit_needs_lod22(edit_town, tmp_path):
    lod1 = tmp_path / "lod1.city.json"
    reconstruct([edit_town.laz], lod1, footprints=edit_town.footprints, lods=("1.2",))
    session = EditSession(lod1, [edit_town.laz])
    with pytest.raises(InputError, match="no LoD2.2"):
        session.refit(session.make_edit("b00", primitive="box"))
    # a footprint edit works on a LoD1 model, from the LoD1.2 ground outline
    res = session.refit(session.make_edit("b00", footprint=session.footprint("b00")))
    assert res.ok and set(res.solids) == {"1.2"}


def test_invalid_model_is_not_written(work, tmp_path, monkeypatch):
    _, model_path, session = work
    before = model_path.read_bytes()
    edit = session.make_edit("b00", primitive="box")
    res = session.refit(edit)
    from lidar2city.datamodel import Solid

    s = res.solids["2.2"]
    s = s if isinstance(s, Solid) else s[0]
    broken = Solid(s.vertices, s.surfaces[:-1])  # a face missing: not closed
    res.solids["2.2"] = broken
    with pytest.raises(InputError, match="invalid"):
        session.save(res, edit, edits=tmp_path / "E.json")
    assert model_path.read_bytes() == before
    assert not (tmp_path / "E.json").exists()


def test_replacing_a_building_by_itself_gives_the_same_document(edit_town):
    import copy

    from lidar2city.tools.edit import replace_building

    doc = json.loads(edit_town.model.read_text())
    for bid in ("b00", "b03"):
        objs = {bid: copy.deepcopy(doc["CityObjects"][bid])}
        used = sorted({i for g in objs[bid]["geometry"] for shell in g["boundaries"]
                       for face in shell for r in face for i in r})
        # the building's own vertices, re-indexed from 0
        index = {old: new for new, old in enumerate(used)}
        for g in objs[bid]["geometry"]:
            g["boundaries"] = [[[[index[int(i)] for i in r] for r in face] for face in shell]
                               for shell in g["boundaries"]]
        verts = [doc["vertices"][i] for i in used]
        assert replace_building(doc, bid, objs, verts) == doc
    with pytest.raises(InputError, match="unknown building"):
        replace_building(doc, "nope", {}, [])


# --------------------------------------------------------------- on the block engine (issue 14)


@pytest.fixture(scope="module")
def town_edits(edit_town, tmp_path_factory):
    """An EDITS.json with two edits (b00 refit as a gable, b02's outline moved 0.5 m)."""
    import shapely
    from shapely import affinity
    from shapely.geometry import mapping, shape

    session = EditSession(edit_town.model, [edit_town.laz], footprints=edit_town.footprints)
    path = tmp_path_factory.mktemp("town_edits") / "E.json"
    append_edit(path, session.make_edit("b00", primitive="gable"))
    moved = affinity.translate(shapely.get_parts(shape(session.footprint("b02")))[0], xoff=0.5)
    append_edit(path, session.make_edit("b02", footprint=mapping(moved)))
    return path


@pytest.mark.slow
def test_reconstruct_edits_on_two_workers_gives_the_same_bytes(edit_town, town_edits, tmp_path,
                                                                runner):
    from lidar2city.cli.main import cli

    outs = []
    for workers in ("1", "2"):  # blocks of 60 m: the edited buildings lie in different blocks
        out = tmp_path / f"w{workers}.city.json"
        r = runner.invoke(cli, ["reconstruct", str(edit_town.laz), "--footprints",
                                str(edit_town.footprints), "--lod", "1.2", "--lod", "2.2",
                                "--block-size", "60", "--edits", str(town_edits),
                                "--workers", workers, "-q", "-o", str(out)])
        assert r.exit_code == 0, r.output
        outs.append(out.read_bytes())
    assert outs[0] == outs[1]
    objects = json.loads(outs[0])["CityObjects"]
    assert objects["b00"]["attributes"]["primitive"] == "gable"
    assert objects["b02"]["attributes"]["edit"].startswith("footprint edited")
    assert "edit" not in objects["b01"]["attributes"]


def test_an_unknown_edit_id_is_refused_before_any_block_runs(edit_town, tmp_path, monkeypatch):
    from lidar2city.tools import task

    def no_block(spec, options):  # pragma: no cover - must not be called
        raise AssertionError("a block ran")

    monkeypatch.setattr(task, "run_block", no_block)
    edits = tmp_path / "E.json"
    append_edit(edits, Edit("nope", "footprint", SQUARE))
    with pytest.raises(InputError, match="unknown building id"):
        reconstruct([edit_town.laz], tmp_path / "x.city.json", footprints=edit_town.footprints,
                    lods=("1.2",), edits=edits)
    with pytest.raises(InputError, match="--edits needs --footprints"):
        reconstruct([edit_town.laz], tmp_path / "x.city.json", lods=("1.2",), edits=edits)


def test_a_run_resumed_with_other_edits_is_refused(edit_town, town_edits, tmp_path, monkeypatch,
                                                  crash_after_first_block):
    from lidar2city.io.journal import journal_path

    out = tmp_path / "r.city.json"
    run = dict(footprints=edit_town.footprints, lods=("1.2", "2.2"), block_size=60.0)
    with pytest.raises(crash_after_first_block):
        reconstruct([edit_town.laz], out, edits=town_edits, **run)
    assert journal_path(out).exists()
    monkeypatch.undo()
    other = tmp_path / "other.json"  # the same file name's content changed: one edit less
    doc = json.loads(town_edits.read_text())
    doc["edits"] = doc["edits"][:1]
    other.write_text(json.dumps(doc))
    with pytest.raises(InputError, match="another run"):
        reconstruct([edit_town.laz], out, edits=other, resume=True, **run)
    with pytest.raises(InputError, match="another run"):
        reconstruct([edit_town.laz], out, resume=True, **run)
    reconstruct([edit_town.laz], out, edits=town_edits, resume=True, **run)  # the same edits
    assert out.exists() and not journal_path(out).exists()


def test_a_tile_without_ground_class_is_ground_filtered_as_reconstruct_does(edit_town, tmp_path):
    """A tile whose ground is left in class 1 (buildings delivered classified, ground not):
    reconstruct filters the ground from the other points; a refit in `edit` must see the
    same ground, not the building's lowest point."""
    from lidar2city.io.las import read_points, write_points

    cloud = read_points(edit_town.laz)
    cls = np.asarray(cloud.get("classification"))
    laz = tmp_path / "noground.laz"
    write_points(laz, cloud.with_attributes(classification=np.where(cls == 2, 1, cls).astype(cls.dtype)))
    model = tmp_path / "m.city.json"
    reconstruct([laz], model, footprints=edit_town.footprints, lods=("1.2", "2.2"))
    session = EditSession(model, [laz], footprints=edit_town.footprints)
    assert session.classified and session.ground_filter
    bid = edit_town.town.footprints.ids[0]
    _, classes = session.points(session.footprint(bid))
    assert (classes == 2).sum() > 100


def test_save_checks_the_schema_of_what_it_changes(work, tmp_path, monkeypatch):
    """An accept answers at once on big models: the schema is checked on the document's
    top level and the edited building (with its parts), not on every City Object again
    (3.6 s per accept on the traced Delft model)."""
    import lidar2city.validate.schema as schema

    _, model_path, session = work
    seen = []
    real = schema.schema_errors

    def spy(doc, **kw):
        seen.append(set(doc.get("CityObjects", {})))
        return real(doc, **kw)

    monkeypatch.setattr(schema, "schema_errors", spy)
    edit = session.make_edit("b01", primitive="box")
    session.save(session.refit(edit), edit, edits=tmp_path / "E.json")
    kids = set(session.doc["CityObjects"]["b01"].get("children", []))
    assert seen == [{"b01", *kids}]
    assert real(json.loads(model_path.read_text())) == []
    # the edited building is still checked: a wrong LoD type in it is refused
    bad = session.updated_document(session.refit(edit))
    bad["CityObjects"]["b01"]["geometry"][0]["lod"] = 22
    from lidar2city.tools.edit import _check_document

    with pytest.raises(InputError, match="not be valid CityJSON"):
        _check_document(bad, "b01")
    bad = session.updated_document(session.refit(edit))
    bad["vertices"][0] = [1.5, 2, 3]
    with pytest.raises(InputError, match="not be valid CityJSON"):
        _check_document(bad, "b01")
