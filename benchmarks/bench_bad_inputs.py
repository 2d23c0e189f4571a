"""Bad inputs of session 10, made from the shared data: what each command says and writes.

Usage: ``PYTHONPATH=src python benchmarks/bench_bad_inputs.py [DATA_DIR]``

Every input is made in a temporary folder from the Delft tile, its BGT footprints and
its DSM (and Autzen's tile); each command runs in a subprocess and its exit status and
last stderr lines are printed, with the files it left. The rows of the README's "Bad
inputs" table from this session quote these lines:

1. the 50 m x 50 m crop (x 84900-84950, y 447500-447550, its 11 BGT footprints) at
   LoD 1.2 + 1.3 + 2.2 with the footprints as they are and segmentized to a vertex
   every 1 cm: CPU seconds of the subprocess (``resource.getrusage(RUSAGE_CHILDREN)``),
   the CityJSON's size and vertex count;
2. the Delft DSM with nodata NaN and two 50 x 50 pixel blocks: NaN and -9999
   (``reconstruct --dsm`` with the BGT footprints);
3. the crop written with a header scale of 1 m; 4. the footprints after a first layer
   of roads (and BGT's terrain file), and as GeometryCollections; 5. ``footprints -o f.shp``; 6. the crop's
   points moved to one XY on ``ground``, ``classify``, ``rasterize``; 7. outputs named
   ``.txt`` / ``.png``; 8. Autzen (Oregon feet) given ``--crs EPSG:28992``; 9. the DSM
   labelled EPSG:4326.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

BOX = (84900.0, 447500.0, 84950.0, 447550.0)


def _children_cpu():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run(label, args, cwd):
    """Run ``lidar2city ARGS`` in ``cwd``; print status, stderr's last lines, CPU s."""
    t0 = _children_cpu()
    res = subprocess.run([sys.executable, "-m", "lidar2city.cli.main", *args], cwd=cwd,
                         capture_output=True, text=True, env=os.environ.copy())
    cpu = _children_cpu() - t0
    said = [ln for ln in (res.stderr + res.stdout).splitlines() if ln.strip()]
    print(f"{label}: exit {res.returncode}, {cpu:.2f} CPU s")
    shown = [ln for ln in said[:-2] if ln.startswith(("WARNING", "Error"))] + said[-2:]
    for ln in shown:
        print(f"    {ln[:300]}")
    return res, cpu


def make_inputs(data, d):
    import laspy
    import pyogrio
    import rasterio
    import shapely

    tile = laspy.read(data / "delft" / "ahn3_cropped_1.laz")
    x, y = np.asarray(tile.x), np.asarray(tile.y)
    m = (x > BOX[0]) & (x < BOX[2]) & (y > BOX[1]) & (y < BOX[3])
    crop = laspy.LasData(tile.header)
    crop.points = tile.points[m].copy()
    crop.update_header()
    crop.write(d / "crop.laz")
    crop = laspy.read(d / "crop.laz")
    meta, _, wkb, fields = pyogrio.raw.read(str(data / "delft" / "footprints_bgt.gpkg"))
    g = shapely.from_wkb(wkb)
    keep = shapely.within(g, shapely.box(*BOX))
    f = [a[keep] for a in fields]
    names = list(meta["fields"])

    def write(name, geoms, **kw):
        pyogrio.raw.write(str(d / name), np.array(shapely.to_wkb(geoms), dtype=object), f, names,
                          crs=meta["crs"], geometry_type=meta["geometry_type"], **kw)

    write("fp.gpkg", g[keep])
    write("dense.gpkg", shapely.segmentize(g[keep], 0.01))
    pyogrio.raw.write(str(d / "two.gpkg"), np.array([shapely.box(*BOX).wkb], dtype=object),
                      [np.array(["r1"], dtype=object)], ["id"], layer="roads", crs=meta["crs"],
                      geometry_type="Polygon")
    write("two.gpkg", g[keep], layer="buildings", append=True)
    gcs = [shapely.GeometryCollection([p, p.centroid, p.boundary]) for p in g[keep]]
    pyogrio.raw.write(str(d / "gc.gpkg"), np.array(shapely.to_wkb(gcs), dtype=object), f, names,
                      crs=meta["crs"], geometry_type="GeometryCollection")
    # header scale 1 m
    h = laspy.LasHeader(point_format=crop.header.point_format, version=crop.header.version)
    h.offsets, h.scales = crop.header.offsets, np.array([1.0, 1.0, 1.0])
    coarse = laspy.LasData(h)
    coarse.x, coarse.y, coarse.z = crop.x, crop.y, crop.z
    coarse.classification = crop.classification
    coarse.write(d / "scale1.laz")
    # every point at one XY
    one = laspy.LasData(crop.header, points=crop.points.copy())
    one.x = np.full(len(one), 84920.0)
    one.y = np.full(len(one), 447520.0)
    one.write(d / "onexy.laz")
    # DSMs: NaN nodata with -9999 gaps; labelled in degrees
    with rasterio.open(data / "delft" / "dsm_50cm.tif") as src:
        a, profile = src.read(1), src.profile
    b = a.copy()
    b[:50, :50] = np.nan
    b[100:150, 100:150] = -9999.0
    with rasterio.open(d / "dsm_nan.tif", "w", **{**profile, "nodata": np.nan}) as dst:
        dst.write(b, 1)
    geo = {**profile, "crs": "EPSG:4326",
           "transform": rasterio.Affine(0.000007, 0, 4.35, 0, -0.000007, 52.01)}
    with rasterio.open(d / "dsm_geo.tif", "w", **geo) as dst:
        dst.write(a, 1)


def main(data: Path):
    with tempfile.TemporaryDirectory(prefix="bench_bad_inputs") as tmp:
        d = Path(tmp)
        make_inputs(data, d)
        delft = data / "delft"
        lods = ["--lod", "1.2", "--lod", "1.3", "--lod", "2.2"]
        print("1. a vertex every 1 cm")
        for name in ("fp", "dense"):
            out = d / f"{name}.city.json"
            _, cpu = run(f"  {name}.gpkg", ["reconstruct", "crop.laz", "--crs", "EPSG:28992",
                                           "--footprints", f"{name}.gpkg", *lods, "-o", out.name],
                         d)
            import json

            doc = json.loads(out.read_text())
            print(f"    -> {out.stat().st_size / 1e3:.0f} kB, {len(doc['vertices'])} vertices")
        print("2. DSM: nodata NaN, gaps of -9999")
        run("  reconstruct --dsm", ["reconstruct", "--dsm", "dsm_nan.tif", "--dtm",
                                    str(delft / "dtm_50cm.tif"), "--footprints",
                                    str(delft / "footprints_bgt.gpkg"), "-o", "nan.city.json"], d)
        print("3. header scale 1 m")
        run("  reconstruct", ["reconstruct", "scale1.laz", "--crs", "EPSG:28992", "--footprints",
                              "fp.gpkg", "-o", "s1.city.json"], d)
        print("4. several layers")
        run("  roads + buildings", ["reconstruct", "crop.laz", "--footprints", "two.gpkg",
                                    "-o", "two.city.json"], d)
        run("  BGT terrain", ["reconstruct", "crop.laz", "--footprints",
                              str(delft / "bgt_terrain.gpkg"), "-o", "t.city.json"], d)
        run("  GeometryCollections (outline, centroid, boundary)",
            ["reconstruct", "crop.laz", "--footprints", "gc.gpkg", "-o", "gc.city.json"], d)
        import json

        notes = {o["attributes"].get("footprint_note") for o in json.loads(
            (d / "gc.city.json").read_text())["CityObjects"].values() if o["type"] == "Building"}
        print(f"    footprint_note: {sorted(notes)}")
        print("5. a Shapefile output")
        (d / "shp").mkdir()
        run("  footprints -o f.shp", ["footprints", "crop.laz", "--crs", "EPSG:28992", "-o",
                                      "shp/f.shp"], d)
        print(f"    left: {sorted(p.name for p in (d / 'shp').iterdir())}")
        print("6. every point at one XY")
        (d / "one").mkdir()
        for cmd in (["ground", "onexy.laz", "-o", "one/g.laz", "--dtm", "one/d.tif"],
                    ["classify", "onexy.laz", "-o", "one/c.laz"],
                    ["rasterize", "onexy.laz", "--crs", "EPSG:28992", "-o", "one/r.tif"]):
            run(f"  {cmd[0]}", cmd, d)
        print(f"    left: {sorted(p.name for p in (d / 'one').iterdir())}")
        print("7. output extensions")
        for cmd in (["ground", "crop.laz", "-o", "g.txt"],
                    ["rasterize", "crop.laz", "--crs", "EPSG:28992", "-o", "r.png"],
                    ["footprints", "crop.laz", "-o", "f.txt"]):
            run(f"  {cmd[0]} -o {cmd[-1]}", cmd, d)
        print("8. --crs over a tile's own CRS")
        run("  info autzen --crs EPSG:28992", ["info", str(data / "misc" / "autzen_trim.laz"),
                                               "--crs", "EPSG:28992"], d)
        print("9. a DSM in degrees")
        run("  footprints --dsm", ["footprints", "--dsm", "dsm_geo.tif", "-o", "g.gpkg"], d)


if __name__ == "__main__":
    default = Path(os.environ.get("LIDAR2CITY_DATA", Path(__file__).resolve().parents[2]
                                  / "shared" / "data"))
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else default)
