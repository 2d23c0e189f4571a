"""Bad inputs and interruptions, tried as a new user would (issue 17).

Every bad input must give one line on stderr starting with ``Error:`` and a
non-zero exit, never a traceback; an output that cannot be written, a write
failing half-way or an interrupt must leave nothing behind.
"""

from __future__ import annotations

import errno
import os
import re
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from shapely.geometry import box


def _error_line(res):
    """The single ``Error:`` line of a failed run (asserts there is nothing else)."""
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert res.exit_code not in (0, None), res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    assert len(lines) == 1 and lines[0].startswith("Error: "), res.output
    return lines[0]


@pytest.fixture(scope="module")
def block(tmp_path_factory):
    """A classified tile of two buildings on flat ground and their footprints (RD New)."""
    from pyproj import CRS

    from lidar2city.datamodel import PointCloud
    from lidar2city.io.las import write_points
    from lidar2city.io.vector import write_polygons

    folder = tmp_path_factory.mktemp("block")
    rng = np.random.default_rng(3)
    fps = [box(6, 6, 18, 16), box(24, 8, 34, 20)]
    xy = rng.uniform(0, 40, (16000, 2))
    z = rng.normal(0, 0.02, len(xy))
    cls = np.full(len(xy), 2, dtype=np.uint8)
    for fp, h in zip(fps, (7.0, 10.0), strict=True):
        x0, y0, x1, y1 = fp.bounds
        inside = (xy[:, 0] > x0) & (xy[:, 0] < x1) & (xy[:, 1] > y0) & (xy[:, 1] < y1)
        z[inside] += h
        cls[inside] = 6
    crs = CRS.from_epsg(28992)
    origin = np.array([85000.0, 447000.0])
    cloud = PointCloud.from_world(np.column_stack([xy + origin, z]), crs=crs,
                                  attributes={"classification": cls})
    write_points(folder / "t.laz", cloud)
    write_polygons(folder / "f.gpkg", fps, {"id": ["A", "B"]}, origin=origin, crs=crs)
    return folder


def _left(folder, keep=()):
    return sorted(p.name for p in folder.iterdir() if p.name not in keep)


# --- 4: an output folder that cannot be written, in every command ---------------------------

def _commands(block, out):
    t, f = str(block / "t.laz"), str(block / "f.gpkg")
    return {
        "ground": ["ground", t, "-o", str(out / "g.laz")],
        "ground --dtm": ["ground", t, "-o", str(block / "never.laz"), "--dtm", str(out / "d.tif")],
        "classify": ["classify", t, "-o", str(out / "c.laz")],
        "reconstruct json": ["reconstruct", t, "--footprints", f, "-o", str(out / "r.city.json")],
        "reconstruct gpkg": ["reconstruct", t, "--footprints", f, "-o", str(out / "r.gpkg")],
        "footprints": ["footprints", t, "-o", str(out / "f.gpkg")],
        "demo": ["demo", "-o", str(out / "demo")],
    }


@pytest.mark.parametrize("name", ["ground", "ground --dtm", "classify", "reconstruct json",
                                  "reconstruct gpkg", "footprints", "demo"])
def test_output_under_a_file_is_one_line(runner, block, tmp_path, name):
    from lidar2city.cli.main import cli

    blocker = tmp_path / "not-a-folder"
    blocker.write_text("")
    res = runner.invoke(cli, _commands(block, blocker)[name])
    assert "not-a-folder" in _error_line(res)
    assert not (block / "never.laz").exists()


@pytest.mark.parametrize("name", ["ground", "ground --dtm", "classify", "reconstruct json",
                                  "reconstruct gpkg", "footprints", "demo"])
def test_read_only_folder_is_one_line(runner, block, tmp_path, monkeypatch, name):
    """A folder refusing new files (what a read-only folder does to a non-root user)."""
    from lidar2city.cli.main import cli
    from lidar2city.io import _atomic

    ro = tmp_path / "ro"
    ro.mkdir()
    real_open = os.open

    def refusing_open(path, flags, *a, **k):
        if str(path).startswith(str(ro)) and flags & os.O_CREAT:
            raise PermissionError(errno.EACCES, "Permission denied", str(path))
        return real_open(path, flags, *a, **k)

    real_mkdir = _atomic.Path.mkdir

    def refusing_mkdir(self, *a, **k):
        if str(self).startswith(str(ro)):
            raise PermissionError(errno.EACCES, "Permission denied", str(self))
        return real_mkdir(self, *a, **k)

    monkeypatch.setattr(_atomic.os, "open", refusing_open)
    monkeypatch.setattr(_atomic.Path, "mkdir", refusing_mkdir)
    res = runner.invoke(cli, _commands(block, ro)[name])
    assert "Permission denied" in _error_line(res)
    assert _left(ro) == []


@pytest.mark.parametrize("exc", [PermissionError(errno.EACCES, "Permission denied"),
                                 OSError(errno.ENOSPC, "No space left on device")])
@pytest.mark.parametrize("name", ["ground --dtm", "reconstruct json", "reconstruct gpkg"])
def test_rename_failing_is_one_line_and_leaves_nothing(runner, block, tmp_path, monkeypatch,
                                                       name, exc):
    from lidar2city.cli.main import cli
    from lidar2city.io import _atomic

    def failing_replace(src, dst):
        raise exc

    monkeypatch.setattr(_atomic.os, "replace", failing_replace)
    out = tmp_path / "out"
    out.mkdir()
    res = runner.invoke(cli, _commands(block, out)[name])
    assert exc.strerror in _error_line(res)
    assert _left(out) == []
    assert not (block / "never.laz").exists()


def test_writer_library_errors_become_one_line(runner, block, tmp_path, monkeypatch):
    """pyogrio's and rasterio's own I/O errors (not OSError for pyogrio) are write failures."""
    import pyogrio
    import rasterio

    from lidar2city.cli.main import cli

    def pyogrio_fails(*a, **k):
        raise pyogrio.errors.DataSourceError("sqlite3_open(/x/r.gpkg) failed: unable to open")

    monkeypatch.setattr(pyogrio.raw, "write", pyogrio_fails)
    res = runner.invoke(cli, _commands(block, tmp_path)["reconstruct gpkg"])
    assert "cannot write" in _error_line(res) and "unable to open" in res.output
    monkeypatch.undo()

    real = rasterio.open

    def rasterio_fails(path, mode="r", *a, **k):
        if mode == "w":
            raise rasterio.errors.RasterioIOError(f"Attempt to create new tiff file '{path}' failed")
        return real(path, mode, *a, **k)

    monkeypatch.setattr(rasterio, "open", rasterio_fails)
    res = runner.invoke(cli, _commands(block, tmp_path)["ground --dtm"])
    assert "cannot write" in _error_line(res)
    # the blocks done are kept in the journal for --resume; no output is left
    assert _left(tmp_path, keep=("r.gpkg.journal",)) == []


# --- beyond: a write failing half-way (disk full) ---------------------------------------------

class _FullDisk:
    """A file that takes ``room`` bytes, then fails as a full disk does."""

    def __init__(self, f, room):
        self._f, self._room = f, room

    def write(self, data):
        if len(data) > self._room:
            self._f.write(data[:self._room])
            self._room = 0
            raise OSError(errno.ENOSPC, "No space left on device")
        self._room -= len(data)
        return self._f.write(data)

    def __getattr__(self, name):
        return getattr(self._f, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._f.close()
        return False


@pytest.mark.parametrize("name,output", [("reconstruct json", "r.city.json"),
                                         ("reconstruct jsonl", "r.city.jsonl"),
                                         ("reconstruct obj", "r.obj"),
                                         ("ground", "g.laz"),
                                         ("ground las", "g.las")])
def test_disk_full_half_way_leaves_nothing(runner, block, tmp_path, monkeypatch, name, output):
    import builtins

    from lidar2city.cli.main import cli

    out = tmp_path / "out"
    out.mkdir()
    real_open = builtins.open

    def open_on_small_disk(file, mode="r", *a, **k):
        f = real_open(file, mode, *a, **k)
        if str(file).startswith(str(out)) and ("w" in mode or "+" in mode):
            return _FullDisk(f, 300)
        return f

    monkeypatch.setattr(builtins, "open", open_on_small_disk)
    t, fp = str(block / "t.laz"), str(block / "f.gpkg")
    args = (["ground", t, "-o", str(out / output)] if name.startswith("ground") else
            ["reconstruct", t, "--footprints", fp, "-o", str(out / output)])
    res = runner.invoke(cli, args)
    monkeypatch.undo()
    line = _error_line(res)
    assert "cannot write" in line and output in line, line
    assert _left(out) == []


def test_failed_run_removes_its_earlier_outputs(runner, block, tmp_path, monkeypatch):
    """``ground --dtm``: the DTM is written first; when the LAZ then fails, neither is left."""
    from lidar2city.cli.main import cli
    from lidar2city.io import las

    def fails(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(las, "_write", fails)
    res = runner.invoke(cli, ["ground", str(block / "t.laz"), "-o", str(tmp_path / "g.laz"),
                              "--dtm", str(tmp_path / "d.tif")])
    assert "No space left" in _error_line(res)
    assert _left(tmp_path) == []


# --- 5: a truncated LAZ ------------------------------------------------------------------------

@pytest.fixture(scope="module")
def truncated(block, tmp_path_factory):
    data = (block / "t.laz").read_bytes()
    p = tmp_path_factory.mktemp("trunc") / "cut.laz"
    p.write_bytes(data[: len(data) // 2])
    return p


@pytest.mark.parametrize("command", [["info"], ["ground", "-o", "OUT/g.laz"],
                                     ["classify", "-o", "OUT/c.laz"],
                                     ["footprints", "-o", "OUT/f.gpkg"],
                                     ["reconstruct", "-o", "OUT/r.city.json"],
                                     ["reconstruct", "--footprints", "FP", "-o", "OUT/r.city.json"]])
def test_truncated_laz_is_one_line(truncated, block, tmp_path, command):
    """In a subprocess, so that the logging set up by the command line is the real one."""
    args = [a.replace("OUT", str(tmp_path)).replace("FP", str(block / "f.gpkg")) for a in command]
    args.insert(1, str(truncated))
    proc = subprocess.run([sys.executable, "-m", "lidar2city.cli.main", *args],
                          capture_output=True, text=True, timeout=120)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 1 and len(lines) == 1, proc.stderr
    assert lines[0].startswith("Error: ") and "cut.laz" in lines[0] and "not a readable" in lines[0]
    assert _left(tmp_path) == []


def test_truncated_laz_in_the_classes_scan_is_an_input_error(truncated):
    from lidar2city.errors import FileFormatError
    from lidar2city.io.las import TileReader, scan_tiles

    with pytest.raises(FileFormatError, match="not a readable LAS/LAZ"):
        # found when the tiles are scanned (their last points decoded), or else when
        # every chunk is read for a class not there
        TileReader(scan_tiles([truncated])).has_classes([17])


# --- 6: Ctrl-C at any time ---------------------------------------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("command", ["classify", "ground"])
def test_interrupt_is_clean_at_any_time(block, tmp_path, command):
    """SIGINT at several moments: exit 130 with one line, no traceback, no crash, nothing left."""
    from lidar2city.io.las import read_points, write_points

    # a bigger tile, so that the run takes a few seconds: the block repeated on a 3 x 3 grid
    cloud = read_points(block / "t.laz")
    xyz = np.concatenate([cloud.xyz + [40.0 * i, 40.0 * j, 0.0] for i in range(3) for j in range(3)])
    big = type(cloud)(xyz, cloud.origin, cloud.crs, cloud.xy_unit, cloud.z_unit,
                      {k: np.tile(v, 9) for k, v in cloud.attributes.items()})
    src = tmp_path / "big.laz"
    write_points(src, big)
    out = tmp_path / "out"
    out.mkdir()
    args = [sys.executable, "-m", "lidar2city.cli.main", command, str(src), "-o", str(out / "x.laz")]
    if command == "ground":
        args += ["--dtm", str(out / "d.tif")]
    t0 = time.perf_counter()
    subprocess.run(args, check=True, capture_output=True, timeout=300)
    full = time.perf_counter() - t0
    for f in out.iterdir():
        f.unlink()
    for frac in (0.2, 0.6, 0.85, 0.95):
        proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        time.sleep(frac * full)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
        if proc.returncode in (0, -signal.SIGINT):
            # finished before the signal, or caught while the interpreter was shutting
            # down after the run: a complete run, its outputs kept, no traceback
            assert "Traceback" not in err and {p.name for p in out.iterdir()} >= {"x.laz"}, err
            for f in out.iterdir():
                f.unlink()
            continue
        assert proc.returncode == 130, (frac, proc.returncode, err)
        assert "Traceback" not in err and err.strip().splitlines()[-1].startswith(
            "Error: interrupted"), err
        assert _left(out) == [], (frac, err)


# --- 2: a self-intersecting footprint ----------------------------------------------------------

def _footprints(folder, geoms, name="fp.gpkg"):
    """Write world-coordinate shapely geometries as a GeoPackage (RD New), ids f0, f1..."""
    import pyogrio
    import shapely

    path = folder / name
    pyogrio.raw.write(str(path), shapely.to_wkb(np.array(geoms, dtype=object)),
                      [np.array([f"f{k}" for k in range(len(geoms))], dtype=object)], ["id"],
                      driver="GPKG", geometry_type="Unknown", crs="EPSG:28992")
    return path


def _world(g):
    import shapely

    return shapely.affinity.translate(g, 85000.0, 447000.0)


@pytest.mark.parametrize("output", ["b.city.json", "b.city.jsonl"])
def test_bow_tie_footprint_gives_a_reason_and_a_valid_file(runner, block, tmp_path, output):
    from shapely.geometry import Polygon

    from lidar2city.cli.main import cli
    from lidar2city.tools.validate import validate_file

    bow = _world(Polygon([(6, 6), (18, 16), (18, 6), (6, 16)]))  # over building A
    fp = _footprints(tmp_path, [bow, _world(box(24, 8, 34, 20))])
    out = tmp_path / output
    res = runner.invoke(cli, ["reconstruct", str(block / "t.laz"), "--footprints", str(fp),
                              "--lod", "1.2", "--lod", "2.2", "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "1 failed" in res.output and "self-intersecting" in res.output
    report = validate_file(out)
    assert report.valid, (report.schema_errors, report.invalid_objects)


def test_loop_footprint_is_repaired_and_says_so(runner, block, tmp_path):
    import json

    from shapely.geometry import Polygon

    from lidar2city.cli.main import cli
    from lidar2city.tools.validate import validate_file

    # building A's outline with a small loop at a corner (a digitising slip)
    loop = _world(Polygon([(6, 6), (18, 6), (18, 16), (18.6, 16.6), (18, 17), (17.6, 16.5),
                           (18, 16), (6, 16)]))
    fp = _footprints(tmp_path, [loop])
    out = tmp_path / "l.city.json"
    res = runner.invoke(cli, ["reconstruct", str(block / "t.laz"), "--footprints", str(fp),
                              "-o", str(out)])
    assert res.exit_code == 0, res.output
    attrs = json.loads(out.read_text())["CityObjects"]["f0"]["attributes"]
    assert attrs["status"] == "ok" and "kept the largest of 2 parts" in attrs["footprint_note"]
    assert validate_file(out).valid


def test_multipart_footprint_writes_building_parts_that_validate(runner, block, tmp_path):
    import json

    from shapely.geometry import MultiPolygon

    from lidar2city.cli.main import cli
    from lidar2city.tools.validate import validate_file

    two = _world(MultiPolygon([box(6, 6, 18, 16), box(24, 8, 34, 20)]))
    fp = _footprints(tmp_path, [two])
    out = tmp_path / "m.city.json"
    res = runner.invoke(cli, ["reconstruct", str(block / "t.laz"), "--footprints", str(fp),
                              "--lod", "1.2", "--lod", "2.2", "-o", str(out)])
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text())
    assert "MultiSolid" not in out.read_text()
    assert {o["type"] for o in doc["CityObjects"].values()} == {"Building", "BuildingPart"}
    report = validate_file(out)
    assert report.valid, (report.schema_errors, report.invalid_objects)


def test_validate_names_the_rule_not_the_geometry(runner, block, tmp_path):
    import json

    from lidar2city.cli.main import cli

    out = tmp_path / "v.city.json"
    res = runner.invoke(cli, ["reconstruct", str(block / "t.laz"), "--footprints",
                              str(block / "f.gpkg"), "-o", str(out)])
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text())
    g = doc["CityObjects"]["A"]["geometry"][0]
    g["type"], g["boundaries"] = "MultiSolid", [g["boundaries"]]
    g["semantics"]["values"] = [g["semantics"]["values"]]
    out.write_text(json.dumps(doc))
    res = runner.invoke(cli, ["validate", str(out)])
    assert res.exit_code == 1
    line = next(ln for ln in res.output.splitlines() if "CityObjects/A/geometry/0" in ln)
    assert "'MultiSolid' is not one of the types allowed here" in line and "Solid" in line
    assert "[[" not in line and len(line) < 200


def test_validate_survives_broken_semantics(runner, block, tmp_path):
    import json

    from lidar2city.cli.main import cli

    out = tmp_path / "s.city.json"
    res = runner.invoke(cli, ["reconstruct", str(block / "t.laz"), "--footprints",
                              str(block / "f.gpkg"), "-o", str(out)])
    doc = json.loads(out.read_text())
    doc["CityObjects"]["A"]["geometry"][0]["semantics"]["values"][0] = "x"
    doc["CityObjects"]["B"]["geometry"][0]["boundaries"][0][0] = [[10 ** 9, 0, 1]]
    out.write_text(json.dumps(doc))
    res = runner.invoke(cli, ["validate", str(out)])
    assert res.exit_code == 1 and (res.exception is None or isinstance(res.exception, SystemExit))
    assert "INVALID" in res.output and "Traceback" not in res.output


# --- 3: OBJ with several LoDs ------------------------------------------------------------------

def test_obj_holds_every_lod_asked(runner, block, tmp_path):
    from lidar2city.cli.main import cli
    from lidar2city.io.obj import read_obj

    out = tmp_path / "x.obj"
    res = runner.invoke(cli, ["reconstruct", str(block / "t.laz"), "--footprints",
                              str(block / "f.gpkg"), "--lod", "1.2", "--lod", "1.3", "--lod", "2.2",
                              "-o", str(out)])
    assert res.exit_code == 0, res.output
    _, objects = read_obj(out)
    assert {"A_lod12", "B_lod12", "A_lod22", "B_lod22", "A_lod13-part1", "B_lod13-part1"} <= set(objects)
    assert out.read_text().startswith("# lidar2city LoD1.2+1.3+2.2 buildings")


# --- 7: the only footprint is empty ------------------------------------------------------------

def test_only_footprint_empty_says_what_is_wrong(runner, block, tmp_path):
    from shapely.geometry import Polygon

    from lidar2city.cli.main import cli

    fp = _footprints(tmp_path, [Polygon()])
    res = runner.invoke(cli, ["reconstruct", str(block / "t.laz"), "--footprints", str(fp),
                              "-o", str(tmp_path / "e.city.json")])
    line = _error_line(res)
    assert "none of its 1 footprint(s) is a usable polygon: empty geometry" in line
    assert "building point" not in line


# --- 8: the CityJSON schemas are shipped -------------------------------------------------------

def test_validate_checks_the_schema_without_any_data_folder(runner, block, tmp_path, monkeypatch):
    from lidar2city.cli.main import cli

    monkeypatch.setenv("LIDAR2CITY_DATA", str(tmp_path / "nowhere"))
    monkeypatch.delenv("LIDAR2CITY_CITYJSON_SCHEMAS", raising=False)
    out = tmp_path / "v.city.json"
    res = runner.invoke(cli, ["reconstruct", str(block / "t.laz"), "--footprints",
                              str(block / "f.gpkg"), "-o", str(out)])
    assert res.exit_code == 0, res.output
    res = runner.invoke(cli, ["validate", str(out)])
    assert res.exit_code == 0 and "VALID - schema valid" in res.output, res.output


def test_shipped_schemas_are_the_package_data():
    import tomllib
    from pathlib import Path

    from lidar2city.validate.schema import SHIPPED, find_schema_dir

    assert find_schema_dir() == SHIPPED
    names = {p.name for p in SHIPPED.glob("*.json")}
    assert {"cityjson.schema.json", "cityjsonfeature.schema.json", "cityobjects.schema.json",
            "geomprimitives.schema.json"} <= names
    root = Path(__file__).resolve().parents[2]
    data = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    assert any("schemas-2.0.2" in pattern for pattern in data["lidar2city"])


@pytest.mark.slow
def test_demo_checks_the_schema_without_any_data_folder(tmp_path):
    env = dict(os.environ, LIDAR2CITY_DATA=str(tmp_path / "nowhere"))
    env.pop("LIDAR2CITY_CITYJSON_SCHEMAS", None)
    proc = subprocess.run([sys.executable, "-m", "lidar2city.cli.main", "demo", "-o",
                           str(tmp_path / "demo")], capture_output=True, text=True, env=env,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert "CityJSON schema valid" in proc.stdout


# --- 9: a raw tile's small buildings, with footprints ------------------------------------------

def test_claim_footprint_points_only_for_footprints_without_building_points():
    from lidar2city.footprints.points import claim_footprint_points

    xy = np.array([[1.0, 1.0], [1.2, 1.0], [1.4, 1.0], [11.0, 1.0], [11.5, 1.0], [30.0, 30.0]])
    classes = np.array([1, 5, 2, 6, 1, 1])
    out = claim_footprint_points(xy, classes, [box(0, 0, 2, 2), box(10, 0, 12, 2), None],
                                 min_points=1)
    # the shed's vegetation and other points become building, its ground stays ground;
    # the building the classifier found, and every point outside footprints, are untouched
    assert out.tolist() == [6, 6, 2, 6, 1, 1]
    assert classes.tolist() == [1, 5, 2, 6, 1, 1]


@pytest.mark.slow
def test_wiped_delft_small_buildings_get_their_points(data, tmp_path, runner):
    """Delft with its classes wiped: every BGT footprint gets its points (8 used to get none)."""
    import json

    import laspy

    from lidar2city.cli.main import cli

    las = laspy.read(data / "delft" / "ahn3_cropped_1.laz")
    las.classification = np.ones(len(las.points), dtype=np.uint8)
    raw = tmp_path / "raw.laz"
    las.write(str(raw))
    out = tmp_path / "r.city.json"
    res = runner.invoke(cli, ["reconstruct", str(raw), "--crs", "EPSG:7415", "--footprints",
                              str(data / "delft" / "footprints_bgt.gpkg"), "-o", str(out)])
    assert res.exit_code == 0, res.output
    attrs = [o["attributes"] for o in json.loads(out.read_text())["CityObjects"].values()]
    assert len(attrs) == 132
    assert [a.get("reason") for a in attrs if a["status"] != "ok"] == []
    assert min(a["point_count"] for a in attrs) >= 10


# --- 10: no PAM side files, defaults shown, one name per thing ---------------------------------

def _all_commands():
    import click

    from lidar2city.cli.main import cli

    ctx = click.Context(cli)

    def walk(group, prefix):
        for name in group.list_commands(ctx):
            cmd = group.get_command(ctx, name)
            if isinstance(cmd, click.Group):
                yield from walk(cmd, [*prefix, name])
            else:
                yield [*prefix, name], cmd

    return list(walk(cli, []))


def test_every_default_is_shown_as_default(runner):
    import click

    from lidar2city.cli.main import cli

    missing = []
    for path, cmd in _all_commands():
        for p in cmd.params:
            if not isinstance(p, click.Option) or p.is_flag or p.name == "help":
                continue
            has_default = p.default not in (None, ()) and p.required is False and \
                type(p.default).__name__ != "Sentinel"
            prose = "default" in (p.help or "").lower()
            if (has_default or prose) and not p.show_default:
                missing.append(f"{' '.join(path)} {p.opts[-1]}")
        res = runner.invoke(cli, [*path, "-h"])
        assert res.exit_code == 0, res.output
    assert missing == []


def test_ground_method_is_one_name_with_its_choices(runner):
    from lidar2city.cli.main import cli

    for path in (["ground"], ["classify"]):
        text = runner.invoke(cli, [*path, "-h"]).output
        assert "--ground-method" in text and "pmf" in text and "smrf" in text, text
        assert re.search(r"\[default: \(?smrf", " ".join(text.split())), text
    text = " ".join(runner.invoke(cli, ["reconstruct", "-h"]).output.split())
    assert re.search(r"\[default: \(?1\.2, or lod1\.lods of --config\)?\]", text), text


def test_reading_a_geopackage_leaves_no_aux_xml(block, tmp_path):
    """A GeoPackage with dataset metadata (as ``footprints`` writes it) read by evaluate."""
    import shutil

    from lidar2city.io.vector import VectorLayer, write_layers
    from lidar2city.tools.evaluate import evaluate_footprints

    pred, ref = tmp_path / "pred.gpkg", tmp_path / "ref.gpkg"
    shutil.copy(block / "f.gpkg", ref)
    from pyproj import CRS

    write_layers(pred, [VectorLayer("footprints", [box(6, 6, 18, 16)], {"id": ["A"]})],
                 origin=(85000.0, 447000.0), crs=CRS.from_epsg(28992),
                 metadata={"lidar2city_version": "x"})
    evaluate_footprints(pred, ref)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pred.gpkg", "ref.gpkg"]


@pytest.mark.slow
@pytest.mark.parametrize("executor", ["fork", "dask"])
def test_interrupt_with_dask_workers_leaves_journal_only(block, tmp_path, executor):
    """SIGINT to ``reconstruct --workers 2`` (CityJSONSeq, streamed through a spool): exit 130
    in one line; the output, its temporary name and the spool are gone, the journal (meant
    for --resume) is kept, and no worker process outlives the run; with the workers
    forked from the run's process (the default here), run as the command's default
    (``--workers auto``, its threshold lowered so that it forks 2), and on a Dask cluster
    of ``--workers 2``."""
    from lidar2city.tools.engine import LOCAL_EXECUTOR_ENV

    env = {**os.environ, LOCAL_EXECUTOR_ENV: executor}
    import psutil

    from lidar2city.io.las import read_points, write_points
    from lidar2city.io.vector import write_polygons

    # the block repeated on a 4 x 4 grid: 32 buildings in blocks of 50 m
    cloud = read_points(block / "t.laz")
    shifts = [(40.0 * i, 40.0 * j) for i in range(4) for j in range(4)]
    xyz = np.concatenate([cloud.xyz + [dx, dy, 0.0] for dx, dy in shifts])
    big = type(cloud)(xyz, cloud.origin, cloud.crs, cloud.xy_unit, cloud.z_unit,
                      {k: np.tile(v, len(shifts)) for k, v in cloud.attributes.items()})
    src = tmp_path / "big.laz"
    write_points(src, big)
    # the fixture's footprints, local to its origin (85000, 447000), repeated likewise
    geoms = [box(x0 + dx, y0 + dy, x1 + dx, y1 + dy) for dx, dy in shifts
             for x0, y0, x1, y1 in ((6, 6, 18, 16), (24, 8, 34, 20))]
    write_polygons(tmp_path / "fp.gpkg", geoms, {"id": [f"f{i}" for i in range(len(geoms))]},
                   origin=np.array([85000.0, 447000.0]), crs=cloud.crs)
    out = tmp_path / "out"
    out.mkdir()
    args = [sys.executable, "-m", "lidar2city.cli.main", "reconstruct", str(src), "--footprints",
            str(tmp_path / "fp.gpkg"), "--workers", "2", "--block-size", "50",
            "-o", str(out / "x.city.jsonl")]
    if executor == "fork":  # the default command, which forks 2 workers here
        code = ("import sys; import lidar2city.tools.reconstruct as R; "
                "R.AUTO_LEAST_SECONDS.update(fork=1e-6); R.usable_cores = lambda: 2; "
                "from lidar2city.cli.main import main; sys.exit(main())")
        args = [sys.executable, "-c", code, "-v", *args[3:]]
        args[args.index("--workers"):args.index("--workers") + 2] = []
    t0 = time.perf_counter()
    first = subprocess.run(args, check=True, capture_output=True, text=True, timeout=600,
                           env=env)
    full = time.perf_counter() - t0
    assert _left(out) == ["x.city.jsonl"]
    assert executor != "fork" or "--workers auto: 2 " in first.stderr, first.stderr
    (out / "x.city.jsonl").unlink()
    interrupted = 0
    # the first timing can be slower than the runs after it on a busy machine (both then end
    # before their signal): earlier signals are tried while no run has been interrupted
    for k, frac in enumerate((0.5, 0.8, 0.3, 0.15)):
        if k >= 2 and interrupted:
            break
        proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                env=env)
        time.sleep(frac * full)
        children = psutil.Process(proc.pid).children(recursive=True)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
        _, alive = psutil.wait_procs(children, timeout=30)
        assert not alive, [p.cmdline() for p in alive]
        if proc.returncode in (0, -signal.SIGINT):
            # finished before the signal, or caught while the interpreter was shutting
            # down after the run: a complete run, its output kept
            assert "Traceback" not in err and _left(out) == ["x.city.jsonl"], err
        else:
            assert proc.returncode == 130, (frac, proc.returncode, err)
            interrupted += 1
            # the cluster's semaphores are released before the exit: multiprocessing's
            # resource tracker has nothing left to warn of, the error line is the last line
            lines = err.strip().splitlines()
            assert "Traceback" not in err and "leaked" not in err, err
            assert lines[-1].startswith("Error: interrupted"), err
            assert set(_left(out)) <= {"x.city.jsonl.journal"}, (frac, err)
            journal = out / "x.city.jsonl.journal"
            if journal.exists():
                assert not [p.name for p in journal.iterdir() if ".tmp" in p.name]
                # the message says what is kept and how to go on from it
                assert str(journal) in lines[-1] and "--resume" in lines[-1], err
        for p in out.iterdir():
            shutil.rmtree(p) if p.is_dir() else p.unlink()
    assert interrupted, "every run ended before its signal"


def test_footprints_with_touching_holes_give_files_that_validate(runner, block, tmp_path):
    """Valid outlines whose hole meets the outer ring, or two holes meeting at a point:
    every building modelled and the file validates (the plain prisms would be 303)."""
    from shapely.geometry import Polygon

    from lidar2city.cli.main import cli
    from lidar2city.io.las import read_points
    from lidar2city.io.vector import write_polygons

    fps = [Polygon([(6, 6), (18, 6), (18, 16), (6, 16), (6, 11)], [[(6, 11), (9, 9), (9, 13)]]),
           Polygon([(24, 8), (34, 8), (34, 20), (24, 20)],
                   [[(26, 10), (29, 14), (26, 14)], [(29, 14), (32, 18), (32, 14)]])]
    assert all(p.is_valid for p in fps)
    write_polygons(tmp_path / "holes.gpkg", fps, {"id": ["A", "B"]},
                   origin=np.array([85000.0, 447000.0]), crs=read_points(block / "t.laz").crs)
    for out in (tmp_path / "h.city.json", tmp_path / "h.city.jsonl"):
        res = runner.invoke(cli, ["reconstruct", str(block / "t.laz"), "--footprints",
                                  str(tmp_path / "holes.gpkg"), "--lod", "1.2", "--lod", "1.3",
                                  "-o", str(out)])
        assert res.exit_code == 0, res.output
        res = runner.invoke(cli, ["validate", str(out)])
        assert res.exit_code == 0, res.output


@pytest.mark.parametrize("args", [
    ["classify", "{t}", "-o", "{t}"],
    ["ground", "{t}", "-o", "{o}", "--dtm", "{t}"],
    ["rasterize", "{t}", "-o", "{t}"],
    ["footprints", "{t}", "-o", "{t}"],
    ["reconstruct", "{t}", "--format", "cityjson", "-o", "{t}"],
    ["reconstruct", "{t}", "--footprints", "{f}", "--format", "gpkg", "-o", "{f}"],
])
def test_an_output_that_is_an_input_is_refused(runner, block, tmp_path, args):
    """``classify x.laz -o x.laz`` or a --format that lets an output land on the tile
    would replace the user's data: one line before any work, the input untouched."""
    from lidar2city.cli.main import cli

    shutil.copy(block / "t.laz", tmp_path / "t.laz")
    shutil.copy(block / "f.gpkg", tmp_path / "f.gpkg")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    names = {"t": tmp_path / "t.laz", "f": tmp_path / "f.gpkg", "o": tmp_path / "o.laz"}
    res = runner.invoke(cli, [a.format(**names) for a in args])
    assert "is also an input" in _error_line(res)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def test_classified_tile_footprint_without_building_points_gets_its_points(tmp_path, runner):
    """Our own ground + classify on a raw Delft crop called 6 of 78 BGT footprints (8 m2
    garden sheds, a 22 m2 annexe) vegetation / other, and reconstruct on the classified
    tile trusted those classes: 'no points'. A footprint without building points now
    gets its unclassified and vegetation points (0, 1, 3, 4, 5) on classified tiles too;
    other classes (water, bridges, the vendor's own) are never claimed."""
    import json

    import shapely

    from lidar2city.cli.main import cli
    from lidar2city.io.las import write_points
    from lidar2city.io.vector import write_polygons
    from lidar2city.synthetic import make_town

    town = make_town(size=(60.0, 50.0), density=6.0, seed=3)
    cls = np.asarray(town.cloud.get("classification")).copy()
    xy = town.cloud.xyz[:, :2]
    g = town.footprints.geometries[0]
    inside = shapely.contains_xy(g, xy[:, 0], xy[:, 1]) & (cls == 6)
    cls[inside] = 5  # the classifier took the roof for high vegetation
    write_points(tmp_path / "t.laz", town.cloud.with_attributes(classification=cls))
    write_polygons(tmp_path / "f.gpkg", town.footprints.geometries, {"id": town.footprints.ids},
                   origin=town.cloud.origin, crs=town.cloud.crs)
    out = tmp_path / "m.city.json"
    res = runner.invoke(cli, ["reconstruct", str(tmp_path / "t.laz"), "--footprints",
                              str(tmp_path / "f.gpkg"), "--lod", "1.2", "-o", str(out)])
    assert res.exit_code == 0, res.output
    attrs = json.loads(out.read_text())["CityObjects"][town.footprints.ids[0]]["attributes"]
    assert attrs["status"] == "ok" and attrs["point_count"] >= inside.sum() // 2, attrs


def test_claim_footprint_points_claimable_classes_only():
    from lidar2city.footprints.points import claim_footprint_points

    xy = np.array([[1.0, 1.0], [1.2, 1.0], [1.4, 1.0], [1.6, 1.0], [1.8, 1.0]])
    classes = np.array([1, 5, 9, 26, 3])
    out = claim_footprint_points(xy, classes, [box(0, 0, 2, 2)], min_points=1,
                                 claimable=(0, 1, 3, 4, 5))
    assert out.tolist() == [6, 6, 9, 26, 6]


def test_footprints_outside_the_tiles_are_said(tmp_path, runner, caplog):
    """Footprints wholly outside the tiles were left out with an info-level line only:
    '3 of 3 buildings reconstructed' from a file of 5, and no word on the other two."""
    import logging

    from lidar2city.cli.main import cli
    from lidar2city.io.las import write_points
    from lidar2city.io.vector import write_polygons
    from lidar2city.synthetic import make_town

    town = make_town(size=(60.0, 50.0), density=4.0, seed=3)
    write_points(tmp_path / "t.laz", town.cloud)
    far = [shapely_translate(town.footprints.geometries[0], d) for d in (5000.0, 7000.0)]
    write_polygons(tmp_path / "f.gpkg", [*town.footprints.geometries, *far],
                   {"id": [*town.footprints.ids, "far1", "far2"]},
                   origin=town.cloud.origin, crs=town.cloud.crs)
    with caplog.at_level(logging.WARNING):
        res = runner.invoke(cli, ["reconstruct", str(tmp_path / "t.laz"), "--footprints",
                                  str(tmp_path / "f.gpkg"), "--lod", "1.2",
                                  "-o", str(tmp_path / "m.city.json")])
    assert res.exit_code == 0, res.output
    n = len(town.footprints) + 2
    assert f"2 of {n} footprint(s) outside the point cloud's extent" in caplog.text


def shapely_translate(g, d):
    import shapely

    return shapely.transform(g, lambda c: c + d)


@pytest.mark.parametrize("kind", ["laz", "tif", "cityjson"])
def test_a_tile_raster_or_model_given_as_footprints_is_named(tmp_path, runner, kind):
    """A LAS/LAZ tile, a GeoTIFF or a CityJSON model given as --footprints got GDAL's
    "not recognized as being in a supported file format.; It might help to specify the
    correct driver explicitly by prefixing the file path with '<DRIVER>:'": say what the
    file is and what footprints are."""
    from lidar2city.cli.main import cli
    from lidar2city.io.las import write_points
    from lidar2city.synthetic import make_town

    town = make_town(size=(40.0, 40.0), density=2.0, seed=1)
    tile = tmp_path / "t.laz"
    write_points(tile, town.cloud)
    wrong = {"laz": tile, "tif": tmp_path / "d.tif", "cityjson": tmp_path / "m.city.json"}[kind]
    if kind == "tif":
        wrong.write_bytes(b"II*\x00" + bytes(60))
    elif kind == "cityjson":
        wrong.write_text('{"type": "CityJSON", "version": "2.0", "CityObjects": {}, '
                         '"vertices": []}')
    res = runner.invoke(cli, ["reconstruct", str(tile), "--footprints", str(wrong),
                              "-o", str(tmp_path / "m.obj")])
    line = _error_line(res)
    what = {"laz": "LAS/LAZ point cloud", "tif": "GeoTIFF raster", "cityjson": "CityJSON model"}
    assert what[kind] in line and "footprints are polygons" in line, line


def test_geojson_of_projected_coordinates_without_crs(runner, block, tmp_path, caplog):
    """A GeoJSON without a 'crs' member is WGS 84 to GDAL (RFC 7946): projected
    footprints written that way were reprojected from 'degrees' into NaN and refused
    ('none of its 2 footprint(s) is a usable polygon: coordinates not finite'). Their
    coordinates cannot be degrees: they are taken to have no CRS, with a warning."""
    import json

    import shapely

    from lidar2city.cli.main import cli

    def world(g):
        return json.loads(shapely.to_geojson(shapely.transform(g, lambda c: c + (85000.0, 447000.0))))

    feats = [{"type": "Feature", "properties": {"id": k}, "geometry": world(g)}
             for k, g in (("A", box(6, 6, 18, 16)), ("B", box(24, 8, 34, 20)))]
    gj = tmp_path / "f.geojson"
    gj.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    out = tmp_path / "m.city.json"
    res = runner.invoke(cli, ["reconstruct", str(block / "t.laz"), "--footprints", str(gj),
                              "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "2 of 2 buildings reconstructed" in res.output
    assert "are not degrees" in caplog.text


def test_a_finished_run_ignores_ctrl_c_while_its_process_ends(monkeypatch):
    """Ctrl-C after the run's outputs are complete, while the interpreter ends: the
    handler of before the run, Python's, turned it into click's 'Aborted!' with
    status 1 (seen in CI at 95 % of a classify run). A process of its own (the
    console script, ``python -m``) ignores it then; in a host program (CliRunner)
    the handlers of before are put back."""
    from lidar2city.cli import main as cli_main

    before = signal.getsignal(signal.SIGINT)
    try:
        cli_main._restore_handlers({signal.SIGINT: signal.default_int_handler}, finished=True)
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
        monkeypatch.setattr(cli_main, "_STANDALONE", [True])
        cli_main._restore_handlers({signal.SIGINT: signal.default_int_handler}, finished=True)
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, before)


# --- session 10: outputs named with an extension their writer does not write -----------------

@pytest.mark.parametrize("args, kind", [
    (["ground", "{t}", "-o", "{d}/g.txt"], ".las, .laz"),
    (["ground", "{t}", "-o", "{d}/g.ply"], ".las, .laz"),
    (["ground", "{t}", "-o", "{d}/g.laz", "--dtm", "{d}/d.png"], ".tif, .tiff"),
    (["classify", "{t}", "-o", "{d}/c.csv"], ".las, .laz"),
    (["rasterize", "{t}", "-o", "{d}/r.png"], ".tif, .tiff"),
    (["footprints", "{t}", "-o", "{d}/f.txt"], ".gpkg"),
    (["footprints", "--dsm", "{t}", "-o", "{d}/f.gpkg", "--figure", "{d}/f.pdf"], ".png"),
])
def test_an_output_extension_its_writer_does_not_write_is_refused(runner, block, tmp_path,
                                                                  args, kind):
    """``ground x.laz -o g.txt`` wrote a LAS file named .txt, ``rasterize -o r.png`` a
    GeoTIFF named .png, ``footprints -o f.txt`` failed after the work with GDAL's
    ``Could not set geometry`` and a raw Python warning: one line before any work now."""
    from lidar2city.cli.main import cli

    res = runner.invoke(cli, [a.format(t=block / "t.laz", d=tmp_path) for a in args])
    line = _error_line(res)
    assert "extension" in line and kind in line, line
    assert _left(tmp_path) == []

# --- session 10: a GeoPackage of several layers as footprints ----------------------------------

def _two_layers(block, path, *, other_geometry):
    """``f.gpkg``'s footprints as the layer ``buildings``, after a first layer ``roads``."""
    import pyogrio
    import shapely

    meta, _, wkb, data = pyogrio.raw.read(str(block / "f.gpkg"))
    other = shapely.to_wkb([other_geometry])
    pyogrio.raw.write(str(path), np.array(other, dtype=object), [np.array(["r1"], dtype=object)],
                      ["id"], layer="roads", crs=meta["crs"],
                      geometry_type=other_geometry.geom_type)
    pyogrio.raw.write(str(path), wkb, data, list(meta["fields"]), layer="buildings",
                      crs=meta["crs"], geometry_type=meta["geometry_type"], append=True)


def test_several_polygon_layers_are_an_error_naming_them(runner, block, tmp_path):
    """A GeoPackage whose first layer is not the footprints' was read at its first layer
    (with pyogrio's raw ``UserWarning`` and its source line on stderr), and the run ended
    in `none of the 1 footprints meets the point cloud's extent`: now the layers are named
    and --layer picks one."""
    from lidar2city.cli.main import cli

    _two_layers(block, tmp_path / "two.gpkg", other_geometry=box(85000, 447000, 85001, 447001))
    args = ["reconstruct", str(block / "t.laz"), "--footprints", str(tmp_path / "two.gpkg")]
    line = _error_line(runner.invoke(cli, [*args, "-o", str(tmp_path / "m.city.json")]))
    assert "roads" in line and "buildings" in line and "--layer" in line, line
    assert not (tmp_path / "m.city.json").exists()
    res = runner.invoke(cli, [*args, "--layer", "buildings", "-o", str(tmp_path / "m.city.json")])
    assert res.exit_code == 0 and "2 of 2 buildings" in res.output, res.output


def test_the_only_polygon_layer_is_taken(runner, block, tmp_path):
    """Footprints beside a layer of points or lines: the polygons are the footprints."""
    from shapely.geometry import Point

    from lidar2city.cli.main import cli

    _two_layers(block, tmp_path / "two.gpkg", other_geometry=Point(85001, 447001))
    res = runner.invoke(cli, ["reconstruct", str(block / "t.laz"), "--footprints",
                              str(tmp_path / "two.gpkg"), "-o", str(tmp_path / "m.city.json")])
    assert res.exit_code == 0 and "2 of 2 buildings" in res.output, res.output
    assert "Warning" not in res.output, res.output

# --- session 10: --crs against the file's own CRS ------------------------------------------------

@pytest.mark.parametrize("command", [["ground", "{t}", "-o", "{d}/g.laz"],
                                     ["info", "{t}"],
                                     ["reconstruct", "{t}", "--footprints", "{f}", "-o",
                                      "{d}/m.city.json"]])
def test_crs_option_replacing_the_files_own_is_said(runner, block, tmp_path, caplog, command):
    """``--crs`` over a tile that declares another CRS relabelled its coordinates without a
    word (Autzen, in Oregon feet, reconstructed as RD New: 2 of 2 buildings, exit 0)."""
    import logging

    from lidar2city.cli.main import cli
    from lidar2city.io import las

    las._RELABELLED.clear()
    args = [a.format(t=block / "t.laz", f=block / "f.gpkg", d=tmp_path) for a in command]
    with caplog.at_level(logging.WARNING):
        res = runner.invoke(cli, [*args, "--crs", "EPSG:32631"])
    assert "t.laz declares the CRS Amersfoort / RD New but is read as WGS 84 / UTM zone 31N" \
        in caplog.text, caplog.text
    caplog.clear()
    with caplog.at_level(logging.WARNING):  # the same CRS (its compound form too): no word
        runner.invoke(cli, [*args, "--crs", "EPSG:7415"])
    assert "declares the CRS" not in caplog.text
    del res



# --- session 10: coordinates stored coarser than a model needs -----------------------------------

@pytest.mark.parametrize("command", [["info", "{t}"], ["ground", "{t}", "-o", "{d}/g.laz"],
                                     ["reconstruct", "{t}", "--footprints", "{f}", "-o",
                                      "{d}/m.city.json"]])
def test_a_coarse_las_scale_is_said(runner, block, tmp_path, caplog, command):
    """A tile written with a header scale of 1 m (every coordinate rounded to the metre) was
    modelled without a word, its roofs and outlines up to 0.5 m off."""
    import logging

    import laspy

    from lidar2city.cli.main import cli
    from lidar2city.io import las as las_io

    src = laspy.read(block / "t.laz")
    header = laspy.LasHeader(point_format=src.header.point_format, version=src.header.version)
    header.offsets, header.scales = src.header.offsets, np.array([1.0, 1.0, 1.0])
    for vlr in src.header.vlrs:
        header.vlrs.append(vlr)
    coarse = laspy.LasData(header)
    coarse.x, coarse.y, coarse.z = src.x, src.y, src.z
    coarse.classification = src.classification
    coarse.write(tmp_path / "coarse.laz")
    las_io._COARSE.clear()
    args = [a.format(t=tmp_path / "coarse.laz", f=block / "f.gpkg", d=tmp_path) for a in command]
    with caplog.at_level(logging.WARNING):
        runner.invoke(cli, args)
    assert "coarse.laz: coordinates stored to 1 m" in caplog.text, caplog.text
    las_io._COARSE.clear()
    caplog.clear()
    with caplog.at_level(logging.WARNING):  # the tile's own 0.001 m: no word
        runner.invoke(cli, [a.format(t=block / "t.laz", f=block / "f.gpkg", d=tmp_path)
                            for a in command])
    assert "stored to" not in caplog.text


# --- session 10: footprints written as a Shapefile -------------------------------------------------

def test_footprints_as_a_shapefile_is_whole(runner, block, tmp_path):
    """``footprints -o f.shp`` renamed the .shp alone: its .shx, .dbf, .prj and .cpg were left
    under hidden temporary names (a file GDAL cannot open: `Unable to open f.shx`), after
    pyogrio's raw RuntimeWarning on the field names cut to 10 characters."""
    from lidar2city.cli.main import cli
    from lidar2city.io.vector import read_footprints

    out = tmp_path / "out"
    out.mkdir()
    res = runner.invoke(cli, ["footprints", str(block / "t.laz"), "-o", str(out / "f.shp")])
    assert res.exit_code == 0, res.output
    assert "Warning" not in res.output, res.output
    assert _left(out) == ["f.cpg", "f.dbf", "f.prj", "f.shp", "f.shx"]
    fps, crs = read_footprints(out / "f.shp")
    assert len(fps) == 2 and crs.to_epsg() == 28992


# --- session 10: a tile of no area on the per-tile commands ----------------------------------------

@pytest.mark.parametrize("command", [["ground", "{t}", "-o", "{d}/g.laz", "--dtm", "{d}/d.tif"],
                                     ["classify", "{t}", "-o", "{d}/c.laz"],
                                     ["rasterize", "{t}", "-o", "{d}/r.tif", "--product", "dtm"]])
@pytest.mark.parametrize("shape", ["one_xy", "line"])
def test_points_covering_no_area_are_an_error_on_every_command(runner, block, tmp_path, command,
                                                               shape):
    """Every point at one XY (or on one line): `reconstruct` said `no area to reconstruct
    buildings in`, but `ground` called 28 % of them ground and wrote a 1 x 1 DTM, `classify`
    called 14,189 of a column of 23,922 high vegetation, `rasterize` wrote a 1 x 2 DTM."""
    from lidar2city.cli.main import cli
    from lidar2city.io.las import read_points, write_points

    cloud = read_points(block / "t.laz")
    xyz = cloud.xyz.copy()
    xyz[:, 0] = 20.0
    if shape == "one_xy":
        xyz[:, 1] = 20.0
    flat = type(cloud)(xyz, cloud.origin, cloud.crs, cloud.xy_unit, cloud.z_unit,
                       dict(cloud.attributes))
    write_points(tmp_path / "flat.laz", flat)
    out = tmp_path / "out"
    out.mkdir()
    res = runner.invoke(cli, [a.format(t=tmp_path / "flat.laz", d=out) for a in command])
    assert "no area to" in _error_line(res)
    assert _left(out) == []


# --- session 10: a footprint with a vertex every centimetre ----------------------------------------

def test_footprint_with_a_vertex_every_centimetre_is_thinned(runner, block, tmp_path, caplog):
    """BGT footprints densified to a vertex every 1 cm (shapely.segmentize: a traced or
    densified outline) gave a wall face per centimetre: the Delft crop of 11 buildings
    took 24.6 s against 2.4 s, its CityJSON 4.8 MB against 52 kB. Their vertices within
    1 mm of a straight line are dropped now, with a note, and the models are the same."""
    import logging

    import pyogrio
    import shapely

    from lidar2city.cli.main import cli

    meta, _, wkb, data = pyogrio.raw.read(str(block / "f.gpkg"))
    dense = shapely.segmentize(shapely.from_wkb(wkb), 0.01)
    pyogrio.raw.write(str(tmp_path / "dense.gpkg"), np.array(shapely.to_wkb(dense), dtype=object),
                      data, list(meta["fields"]), crs=meta["crs"],
                      geometry_type=meta["geometry_type"])
    docs = {}
    for name in ("dense", "plain"):
        src = tmp_path / "dense.gpkg" if name == "dense" else block / "f.gpkg"
        with caplog.at_level(logging.INFO):
            res = runner.invoke(cli, ["reconstruct", str(block / "t.laz"), "--footprints", str(src),
                                      "-o", str(tmp_path / f"{name}.city.json")])
        assert res.exit_code == 0, res.output
        docs[name] = (tmp_path / f"{name}.city.json").read_text()
    assert "vertices closer than" in caplog.text, caplog.text
    import json

    a, b = (json.loads(docs[k]) for k in ("dense", "plain"))
    assert len(a["vertices"]) == len(b["vertices"])
    assert {k: o.get("attributes", {}).get("roof_height") for k, o in a["CityObjects"].items()} \
        == {k: o.get("attributes", {}).get("roof_height") for k, o in b["CityObjects"].items()}


# --- session 10: footprints stored as GeometryCollections ------------------------------------------

def test_geometry_collection_footprints_give_their_polygons(runner, block, tmp_path):
    """A layer of GeometryCollections (an outline with its label point or its centre
    line, as some exports and overlays write them) failed whole: `none of its 2
    footprint(s) is a usable polygon: not a polygon (GeometryCollection)`."""
    import json

    import pyogrio
    import shapely
    from shapely.geometry import GeometryCollection

    from lidar2city.cli.main import cli

    meta, _, wkb, data = pyogrio.raw.read(str(block / "f.gpkg"))
    gcs = [GeometryCollection([g, g.centroid, g.boundary]) for g in shapely.from_wkb(wkb)]
    pyogrio.raw.write(str(tmp_path / "gc.gpkg"), np.array(shapely.to_wkb(gcs), dtype=object),
                      data, list(meta["fields"]), crs=meta["crs"],
                      geometry_type="GeometryCollection")
    res = runner.invoke(cli, ["reconstruct", str(block / "t.laz"), "--footprints",
                              str(tmp_path / "gc.gpkg"), "-o", str(tmp_path / "m.city.json")])
    assert res.exit_code == 0 and "2 of 2 buildings" in res.output, res.output
    notes = [o["attributes"].get("footprint_note", "") for o in
             json.loads((tmp_path / "m.city.json").read_text())["CityObjects"].values()
             if o["type"] == "Building"]
    assert all("GeometryCollection" in n and "2 other part(s)" in n for n in notes), notes
    only_points = [GeometryCollection([g.centroid]) for g in shapely.from_wkb(wkb)]
    pyogrio.raw.write(str(tmp_path / "pts.gpkg"),
                      np.array(shapely.to_wkb(only_points), dtype=object), data,
                      list(meta["fields"]), crs=meta["crs"], geometry_type="GeometryCollection")
    res = runner.invoke(cli, ["reconstruct", str(block / "t.laz"), "--footprints",
                              str(tmp_path / "pts.gpkg"), "-o", str(tmp_path / "p.city.json")])
    assert "not a polygon (GeometryCollection of Point)" in _error_line(res)


@pytest.mark.parametrize("suffix", [".gpkg", ".shp", ".geojson", ".json", ".fgb"])
def test_footprints_written_in_every_vector_format_named(runner, block, tmp_path, suffix):
    """``footprints -o f.json`` ended in a traceback: pyogrio could not pick between
    GeoJSON and JSONFG for .json. Every extension taken is written and read back."""
    from lidar2city.cli.main import cli
    from lidar2city.io.vector import read_footprints

    out = tmp_path / f"f{suffix}"
    res = runner.invoke(cli, ["footprints", str(block / "t.laz"), "-o", str(out)])
    assert res.exit_code == 0, res.output
    fps, crs = read_footprints(out)
    assert len(fps) == 2 and crs.to_epsg() == 28992


@pytest.mark.parametrize("name", ["m.dat", "m.city.json"])
def test_reconstruct_format_gpkg_under_any_name(runner, block, tmp_path, name):
    """``reconstruct --format gpkg -o m.dat`` ran every building, then ended in a traceback
    (pyogrio: `Could not infer driver from path`); `-o m.city.json` in a GDAL error."""
    import contextlib

    from lidar2city.cli.main import cli

    res = runner.invoke(cli, ["reconstruct", str(block / "t.laz"), "--footprints",
                              str(block / "f.gpkg"), "--format", "gpkg", "-o", str(tmp_path / name)])
    assert res.exit_code == 0, res.output
    assert (tmp_path / name).read_bytes()[:16] == b"SQLite format 3\x00"
    import sqlite3

    with contextlib.closing(sqlite3.connect(tmp_path / name)) as con:
        tables = [r[0] for r in con.execute("SELECT table_name FROM gpkg_contents")]
    assert "footprints" in tables, tables
    assert _left(tmp_path) == [name]


def test_crs_option_over_a_folder_checks_every_tile(runner, block, tmp_path, caplog):
    """A folder of a tile without a CRS and one in another CRS, given --crs: the relabelling
    of the second tile was not said (only the first tile was checked)."""
    import logging

    from lidar2city.cli.main import cli
    from lidar2city.io import las
    from lidar2city.io.las import read_points, write_points

    (tmp_path / "tiles").mkdir()
    cloud = read_points(block / "t.laz")
    write_points(tmp_path / "tiles" / "a.laz", type(cloud)(
        cloud.xyz, cloud.origin, None, 1.0, 1.0, dict(cloud.attributes)))
    shutil.copy(block / "t.laz", tmp_path / "tiles" / "b.laz")
    las._RELABELLED.clear()
    with caplog.at_level(logging.WARNING):
        runner.invoke(cli, ["footprints", str(tmp_path / "tiles"), "--crs", "EPSG:32631",
                            "-o", str(tmp_path / "f.gpkg")])
    assert "b.laz declares the CRS Amersfoort / RD New" in caplog.text, caplog.text
