"""The viewer's actions without a browser: select, refit, outline edits, accept, undo."""

import json

import numpy as np
import pytest

from lidar2city.io.cityjson import read_cityjson


def test_loopback_scene_and_colours(viewer):
    assert viewer.server.get_host() == "127.0.0.1"
    assert set(viewer.lods) == {"1.2", "2.2"}
    assert set(viewer.attrs) == {"b00", "b01", "b02", "b03"}
    # one mesh per colour, holding every building once
    drawn = [b for ids, _ in viewer.groups["2.2"].values() for b in ids]
    assert sorted(drawn) == sorted(viewer.attrs)
    # the RMSE of the LoD shown, from the points, for every building
    assert all(isinstance(a.get("viewer_rmse"), float) for a in viewer.attrs.values())
    for by in ("RMSE", "roof type", "status", "validity", "height", "edited"):
        viewer.colour_by.value = by
        viewer.recolour()
        assert viewer.legend.content.startswith(f"**{by}**")
    assert viewer.points_handle.points.shape[0] <= 20_000
    # LoD2.2 is shown first; LoD1.2's meshes are made when it is chosen
    assert set(viewer.groups) == {"2.2"}
    viewer.lod_choice.value = "1.2"
    viewer._show_lod()
    assert set(viewer.groups) == {"1.2", "2.2"}
    assert all(h.visible for _, h in viewer.groups["1.2"].values())
    assert not any(h.visible for _, h in viewer.groups["2.2"].values())


def test_selection_is_its_own_group_and_a_click_ray_finds_the_building(viewer):
    from shapely.geometry import shape

    viewer.select("b01")
    groups = viewer.groups["2.2"]
    assert groups[(255, 225, 0)][0] == ("b01",)
    assert sum(ids.count("b01") for ids, _ in groups.values()) == 1
    for bid in viewer.attrs:  # straight down onto each building's footprint centre
        c = shape(viewer.session.footprint(bid)).representative_point()
        origin = (c.x - viewer.origin[0], c.y - viewer.origin[1], 500.0)
        assert viewer.pick(origin, (0.0, 0.0, -1.0)) == bid
    assert viewer.pick((-1e4, -1e4, 500.0), (0.0, 0.0, -1.0)) is None


def test_refit_undo_accept(viewer):
    viewer.select("b00")
    assert "Building b00" in viewer.info.content
    shown = viewer._meshes["2.2"]["b00"]
    seconds = viewer.refit_primitive("gable")
    assert seconds is not None and "refit as gable" in viewer.status
    assert viewer.attrs["b00"]["primitive"] == "gable"
    # the candidate is drawn (in the selection's colour) in place of the building
    candidate = viewer._meshes["2.2"]["b00"]
    assert candidate[0].shape != shown[0].shape or not np.array_equal(candidate[0], shown[0])
    assert viewer.groups["2.2"][(255, 225, 0)][0] == ("b00",)
    viewer.undo()
    assert "primitive" not in viewer.attrs["b00"]
    assert np.array_equal(viewer._meshes["2.2"]["b00"][0], shown[0])
    assert not (viewer.edits_path).exists()
    viewer.refit_primitive("box")
    out = viewer.accept()
    assert out == viewer.path and "Saved" in viewer.status
    model = read_cityjson(viewer.path)
    assert model.objects["b00"]["attributes"]["primitive"] == "box"
    edits = json.loads(viewer.edits_path.read_text())["edits"]
    assert [(e["building"], e["primitive"]) for e in edits] == [("b00", "box")]
    from lidar2city.tools.validate import validate_file

    assert validate_file(viewer.path).valid


def test_outline_edit_and_rebuild(viewer):
    viewer.select("b02")
    viewer.start_outline()
    n = len(viewer.outline)
    viewer.add_vertex()
    assert len(viewer.outline) == n + 1
    viewer.delete_vertex()
    assert len(viewer.outline) == n
    centre = viewer.outline.mean(axis=0)
    viewer.move_vertex(0, viewer.outline[0] + 0.5 * (viewer.outline[0] - centre)
                       / np.linalg.norm(viewer.outline[0] - centre))
    assert viewer.rebuild_from_outline() is not None, viewer.status
    assert viewer.attrs["b02"]["edit"].startswith("footprint edited")
    viewer.accept()
    edits = json.loads(viewer.edits_path.read_text())["edits"]
    assert edits[0]["action"] == "footprint"


@pytest.mark.parametrize("case", ["unknown", "unfittable", "self-intersecting"])
def test_bad_edits_give_a_message_and_change_nothing(viewer, case):
    before = viewer.path.read_bytes()
    if case == "unknown":
        viewer.select("nope")
        assert "unknown building id" in viewer.status
    elif case == "unfittable":
        viewer.select("b02")
        assert viewer.refit_primitive("gable") is None
        assert "cannot be fitted" in viewer.status
    else:
        viewer.select("b00")
        viewer.start_outline()
        viewer.outline[[1, 2]] = viewer.outline[[2, 1]]  # crossed edges
        assert viewer.rebuild_from_outline() is None
        assert "self-intersecting" in viewer.status
    assert "Error" in viewer.status_md.content
    assert viewer.pending is None and viewer.path.read_bytes() == before


def test_view_only_without_points(edit_town, port):
    from lidar2city.viewer.app import Viewer

    v = Viewer(edit_town.model, port=port)
    v.start()
    try:
        v.select("b01")
        assert v.refit_primitive("box") is None and "--points" in v.status
    finally:
        v.stop()


def test_missing_viser_is_a_one_line_error(monkeypatch):
    import sys

    from lidar2city.errors import DependencyError
    from lidar2city.viewer.app import require_viser

    monkeypatch.setitem(sys.modules, "viser", None)
    with pytest.raises(DependencyError, match=r"lidar2city\[view\]"):
        require_viser()


def test_cli_view_errors(runner, tmp_path):
    from lidar2city.cli.main import cli

    res = runner.invoke(cli, ["view", str(tmp_path / "absent.city.json"), "--no-browser"])
    assert res.exit_code == 1 and "no such file" in res.output


def test_other_hosts_are_warned_about(edit_town, caplog):
    import logging

    from lidar2city.viewer.app import Viewer

    with caplog.at_level(logging.WARNING, logger="lidar2city.viewer.app"):
        Viewer(edit_town.model, host="0.0.0.0")  # not started: nothing is bound
    assert "anyone who can reach this machine" in caplog.text
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="lidar2city.viewer.app"):
        Viewer(edit_town.model)
    assert caplog.text == ""


def test_refit_from_a_placed_primitive(viewer):
    viewer.select("b00")
    viewer.place.value = True
    viewer._toggle_place()
    assert viewer._placed is not None and viewer.p_len.value > viewer.p_wid.value > 0
    approx = viewer._approx()
    assert set(approx) == {"x", "y", "azimuth", "length", "width"}
    assert viewer.refit_primitive("gable") is not None, viewer.status
    assert viewer.attrs["b00"]["edit"] == "refit as gable (user-placed)"
    viewer.place.value = False
    viewer._toggle_place()
    assert viewer._placed is None


def test_gui_controls_are_wired(viewer):
    import time

    viewer.colour_by.value = "validity"  # as if chosen in the page: the callback recolours
    end = time.monotonic() + 10
    while not viewer.legend.content.startswith("**validity**") and time.monotonic() < end:
        time.sleep(0.05)
    assert viewer.legend.content.startswith("**validity**")
    viewer.show_points.value = False
    end = time.monotonic() + 10
    while viewer.points_handle.visible and time.monotonic() < end:
        time.sleep(0.05)
    assert not viewer.points_handle.visible


def test_background_rmse_arrives_and_matches(edit_town, tmp_path, port):
    """`view` computes every building's RMSE in the background (a forked child where the
    platform forks) and recolours when the values arrive: the same values as computed
    in place."""
    import shutil

    from lidar2city.viewer.app import Viewer

    model = tmp_path / "m.city.json"
    shutil.copy(edit_town.model, model)
    v = Viewer(model, points=[edit_town.laz], port=port, max_points=5_000)
    v.start()
    try:
        v._rmse_thread.join(timeout=60)
        assert not v._rmse_thread.is_alive()
        got = {b: a.get("viewer_rmse") for b, a in v.attrs.items()}
        assert got == v._rmse_values() and all(isinstance(x, float) for x in got.values())
        assert v.legend.content.startswith("**RMSE**")
    finally:
        v.stop()


def test_a_port_in_use_gives_the_real_url_and_a_warning(edit_town, port, caplog):
    """viser takes the next free port when the one asked for is taken: the URL printed
    (and opened) must be the one listened on, not another viewer's page."""
    import logging
    import socket

    from lidar2city.viewer.app import Viewer

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", port))
        busy.listen()
        v = Viewer(edit_town.model, port=port)
        with caplog.at_level(logging.WARNING, logger="lidar2city.viewer.app"):
            url = v.start()
        try:
            real = v.server.get_port()
            assert real != port and url == f"http://127.0.0.1:{real}"
            assert f"port {port} is in use" in caplog.text
        finally:
            v.stop()


def _rewrite(src, dst, change):
    doc = json.loads(src.read_text())
    change(doc)
    dst.write_text(json.dumps(doc))
    return dst


def test_cityjson_1_lod_numbers_are_shown(edit_town, tmp_path, port):
    """3dfier writes CityJSON 1.0 with ``"lod": 1``: its buildings are drawn at LoD 1."""
    from lidar2city.viewer.app import Viewer

    def lod1(doc):
        doc["version"] = "1.0"
        for o in doc["CityObjects"].values():
            o["geometry"] = [dict(g, lod=1) for g in o.get("geometry", []) if g["lod"] == "1.2"]

    v = Viewer(_rewrite(edit_town.model, tmp_path / "old.city.json", lod1), port=port)
    v.start()
    try:
        assert v.lods == ["1"] and v.lod_choice.value == "1"
        drawn = sorted(b for ids, _ in v.groups["1"].values() for b in ids)
        assert drawn == sorted(v.attrs)
        assert all(h.name.startswith("/lod1/") for _, h in v.groups["1"].values())
    finally:
        v.stop()


def test_points_of_another_area_are_a_one_line_error(edit_town, tmp_path, port):
    from lidar2city.errors import InputError
    from lidar2city.viewer.app import Viewer

    def far(doc):
        doc["transform"]["translate"][0] += 50_000.0

    with pytest.raises(InputError, match="do not cover the model"):
        Viewer(_rewrite(edit_town.model, tmp_path / "far.city.json", far),
               points=[edit_town.laz], port=port)


@pytest.mark.parametrize("case", ["no configuration", "no transform", "CityJSONSeq"])
def test_a_model_from_another_tool_is_shown_read_only_with_its_points(edit_town, tmp_path,
                                                                      port, case):
    """A 3DBAG or 3dfier model with --points: drawn with its points, and an edit says
    why it cannot apply (reconstruct --edits could not reproduce it)."""
    from lidar2city.io.cityjson import _apply_transform
    from lidar2city.viewer.app import Viewer

    def foreign(doc):
        doc.pop("+lidar2city", None)
        if case == "no transform":
            v = _apply_transform(doc["vertices"], doc.pop("transform"))
            doc["vertices"] = v.round(3).tolist()

    if case == "CityJSONSeq":
        from lidar2city.tools.reconstruct import reconstruct

        model = tmp_path / "m.city.jsonl"
        reconstruct([edit_town.laz], model, footprints=edit_town.footprints, lods=("1.2",))
    else:
        model = _rewrite(edit_town.model, tmp_path / "other.city.json", foreign)
    before = model.read_bytes()
    v = Viewer(model, points=[edit_town.laz], port=port, max_points=5_000)
    v.start(compute_rmse=False)
    try:
        assert v.points_handle.points.shape[0] > 0
        assert "view only" in v.status_md.content.lower()
        assert v.refit_btn.disabled and v.outline_btn.disabled
        v.select("b00")
        why = "CityJSONSeq cannot be edited" if case == "CityJSONSeq" else "not made by lidar2city"
        assert v.refit_primitive("box") is None and why in v.status
        v.start_outline()
        assert v.outline is None and why in v.status
        assert model.read_bytes() == before
    finally:
        v.stop()


@pytest.mark.slow
def test_rmse_is_in_metres_in_a_feet_crs(data, tmp_path, port):
    """A model in US survey feet (EPSG:6880): the viewer's RMSE is in metres, as labelled
    and as reconstruct's own rmse_lod12 (it was in feet, 3.3 times larger)."""
    from lidar2city.tools.reconstruct import reconstruct
    from lidar2city.viewer.app import Viewer

    tile = data / "misc" / "file_with_both_wkt_and_geotiff_vlrs.las"
    model = tmp_path / "feet.city.json"
    reconstruct([tile], model, lods=("1.2",))
    v = Viewer(model, points=[tile], port=port)
    v.start(compute_rmse=False)
    try:
        for bid, a in v.attrs.items():
            assert v._rmse_of(bid, v._world_solids(bid, "1.2")) == pytest.approx(
                a["rmse_lod12"], abs=0.002)
    finally:
        v.stop()


def test_building_points_come_from_an_index_and_equal_a_full_scan(viewer):
    """The RMSE of every building took a scan of all points per building (84 s for
    2,160 buildings over 16 tiles): the building points are indexed by x once and each
    building reads its strip, giving the very points (and order) of a full scan."""
    import shapely
    from shapely.geometry import shape

    xyz, build = viewer._world_xyz, viewer._building_mask
    assert len(viewer._build_x) == int(build.sum())
    for bid in viewer.attrs:
        fp = shape(viewer.session.footprint(bid))
        inside = build & shapely.contains_xy(fp, xyz[:, 0], xyz[:, 1])
        assert np.array_equal(viewer._building_points(bid), xyz[inside])


def test_footprints_from_the_model_transform_its_vertices_once(edit_town, tmp_path,
                                                               monkeypatch):
    """Without --footprints an outline comes from the model's LoD1.2 ground surface: the
    model's vertices are converted once, not once per building (17 ms each on 2,160)."""
    import lidar2city.io.cityjson as cj
    from lidar2city.tools.edit import EditSession

    s = EditSession(edit_town.model, [edit_town.laz])
    calls = []
    real = cj._apply_transform
    monkeypatch.setattr(cj, "_apply_transform", lambda *a: calls.append(1) or real(*a))
    got = [s.footprint(b) for b in s.buildings()]
    assert len(calls) <= 1 and all(g["type"] in ("Polygon", "MultiPolygon") for g in got)


def test_a_large_area_is_within_the_camera_far_plane(edit_town, tmp_path, port):
    """viser's camera sees 1,000 m: the 144-tile area (2.4 x 1.8 km) was a blank page.
    The far plane reaches past the whole model from the initial camera."""
    from lidar2city.viewer.app import Viewer

    def spread(doc):  # one building 3 km away
        used = set()

        def walk(b):
            if isinstance(b, list):
                for x in b:
                    walk(x)
            else:
                used.add(b)

        for g in doc["CityObjects"]["b03"]["geometry"]:
            walk(g["boundaries"])
        scale = doc["transform"]["scale"][0]
        for i in used:
            doc["vertices"][i][0] += round(3000.0 / scale)

    v = Viewer(_rewrite(edit_town.model, tmp_path / "wide.city.json", spread), port=port)
    v.start()
    try:
        cam = v.server.initial_camera
        pos, at = np.asarray(cam.position), np.asarray(cam.look_at)
        corners = np.array([[x, y, z] for x in (0, v.extent[0]) for y in (0, v.extent[1])
                            for z in (0, v.extent[2])])
        assert cam.far > np.linalg.norm(corners - pos, axis=1).max()
        assert cam.near <= max(0.01, max(v.extent[:2]) / 1000)  # roofs 1 m apart stay apart
    finally:
        v.stop()


def test_a_big_area_reads_its_points_per_building(edit_town, tmp_path, port, viewer,
                                                 monkeypatch):
    """Over LOAD_ALL_POINTS (a 144-tile area holds 17 M) the viewer keeps only the points
    it shows and reads a building's points when needed: the same RMSEs and refits."""
    import lidar2city.viewer.app as app

    monkeypatch.setattr(app, "LOAD_ALL_POINTS", 1000)
    model = tmp_path / "lazy.city.json"
    model.write_bytes(edit_town.model.read_bytes())
    lazy = app.Viewer(model, points=[edit_town.laz], footprints=edit_town.footprints,
                      port=port, max_points=20_000)
    lazy.start(compute_rmse=False)
    try:
        assert lazy._lazy and lazy.session._area is None
        assert 0 < lazy.points_handle.points.shape[0] <= 20_000
        got = lazy._rmse_values()
        want = {b: a["viewer_rmse"] for b, a in viewer.attrs.items()}
        assert got.keys() == want.keys()
        assert all(abs(got[b] - want[b]) <= 1e-4 for b in got)
        lazy.select("b00")
        viewer.select("b00")
        assert lazy.refit_primitive("gable") is not None, lazy.status
        assert viewer.refit_primitive("gable") is not None
        timing = ("reconstruction_time",)
        assert ({k: v for k, v in lazy.attrs["b00"].items() if k not in timing}
                == {k: v for k, v in viewer.attrs["b00"].items() if k not in timing})
    finally:
        lazy.stop()


def test_no_points_shown_is_no_cloud(edit_town, port):
    """--max-points 0: points kept for editing, none drawn, and the scene's expected nodes
    do not wait for an empty cloud (the page was never 'complete')."""
    from lidar2city.viewer.app import Viewer

    v = Viewer(edit_town.model, points=[edit_town.laz], port=port, max_points=0)
    v.start(compute_rmse=False)
    try:
        assert getattr(v, "points_handle", None) is None
        assert v.scene_prefixes() == ["/lod22/"]
    finally:
        v.stop()


def test_without_footprints_the_page_says_what_edits_can_reproduce(edit_town, port):
    """A traced model's edits cannot be re-applied by reconstruct --edits (it needs the
    footprint file): the page says so before the user edits, not the re-run after."""
    from lidar2city.viewer.app import Viewer

    v = Viewer(edit_town.model, points=[edit_town.laz], port=port, max_points=0)
    v.start(compute_rmse=False)
    try:
        assert "reconstruct --edits` re-applies edits only with the footprint file" in \
            v.status_md.content
    finally:
        v.stop()
