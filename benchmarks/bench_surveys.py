"""Surveys unlike Delft, made from it: does reconstruct give the same buildings?

Usage: ``PYTHONPATH=src python benchmarks/bench_surveys.py [DATA_DIR]``

A 100 m x 120 m crop of the Delft AHN3 tile (x 84880-84980, y 447480-447600)
and the 78 BGT footprints wholly inside it are written again as other surveys
would deliver them: LAS 1.4 point formats 6 / 7 / 8, extra-bytes dimensions,
a 0.01 scale, z + 1000 m (a mountain town), coordinates near 0 and near 1e7
(footprints moved with them), a few stray returns 1000 km off, thinned at
random (seed 0) to 8, 4, 2 and 1 pts/m2, and to 2 pts/m2 in scan lines 1.4 m
apart (points 0.35 m apart along them); the crop with its classes wiped, then through
our own ``ground`` + ``classify``; its ground (class 2) left in class 1 (a
buildings-only classification); and the whole Delft tile (132 footprints) with
the stray returns. Each is reconstructed at LoD1.2 + LoD2.2
(in this process, in a temporary folder) and compared with the crop as it is:
buildings modelled / failed / with the LoD1.2 prism standing in for LoD2.2
(and why), the largest difference of ``roof_height`` (LoD1.2),
``ridge_height`` (LoD2.2, the highest vertex) and ``ground_height``, and
whether the file validates; for the crop and the thinned surveys, the RMSE of
the models (LoD2.2, or the LoD1.2 prism standing in) to the crop's building points.
Last, ISPRS samp11 (a sparse UTM survey) without footprints: traced buildings
modelled and failed. ``--sites`` prints only the footprints traced from the
ISPRS sites CSite1 (points 4 m apart) and FSite5 (first/last-pulse pairs, our
own ``classify``): count and area, with the spacing measured from the distinct
positions on squares of twice the spacing, and as before session 10 (all points
on fixed 2 m squares).
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import numpy as np

X0, Y0, X1, Y1 = 84880.0, 447480.0, 84980.0, 447600.0


def _write_like(src, path, *, version="1.2", fmt=1, scale=None, shift=(0.0, 0.0, 0.0),
                extra=False, keep=None, strays=False):
    import laspy

    keep = np.ones(len(src.points), bool) if keep is None else keep
    h = laspy.LasHeader(point_format=fmt, version=version)
    h.scales = np.array(scale or src.header.scales)
    xyz = np.column_stack([np.asarray(src.x), np.asarray(src.y), np.asarray(src.z)])[keep]
    xyz = xyz + shift
    if strays:  # three returns 1000 km east, 1000 km south and 100 km up
        keep = np.r_[np.flatnonzero(keep), 0, 1, 2]
        xyz = np.vstack([xyz, [[X0 + 1e6, Y0, 5.0], [X0, Y0 - 1e6, 5.0], [X0 + 50, Y0 + 50, 1e5]]])
    h.offsets = np.floor(xyz.min(axis=0))
    if extra:
        h.add_extra_dims([laspy.ExtraBytesParams(name="height_above", type=np.float32),
                          laspy.ExtraBytesParams(name="flags3", type="3u1")])
    out = laspy.LasData(h)
    for dim in ("intensity", "return_number", "number_of_returns", "classification", "gps_time"):
        out[dim] = np.asarray(src[dim])[keep]
    out.x, out.y, out.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    if extra:
        out.height_above = xyz[:, 2].astype(np.float32)
    out.write(path)


def _scan_lines(src, draw, density, area, *, anisotropy=4.0, width=0.3):
    """Points of ``src`` kept as a scanner at ``density`` pts/m2 whose scan lines lie
    ``anisotropy`` times farther apart than its points along a line: strips ``width``
    wide (about the crop's own spacing) across y, thinned at random within them."""
    line = np.sqrt(anisotropy / density)
    on = ((np.asarray(src.y) - Y0) % line) < width
    return on & (draw < density * area / max(int(on.sum()), 1))


def _footprints(src_gpkg, path, shift=(0.0, 0.0)):
    import pyogrio.raw
    import shapely

    meta, _, wkb, fields = pyogrio.raw.read(str(src_gpkg))
    g = shapely.from_wkb(wkb)
    inside = shapely.within(g, shapely.box(X0, Y0, X1, Y1))
    g = shapely.transform(g[inside], lambda c: c + shift)
    pyogrio.raw.write(str(path), shapely.to_wkb(g), [np.asarray(f)[inside] for f in fields],
                      list(meta["fields"]), crs="EPSG:28992", geometry_type="Polygon")


def _attributes(path):
    d = json.loads(Path(path).read_text())
    return {k: o.get("attributes", {}) for k, o in d["CityObjects"].items()
            if o["type"] == "Building"}


def main():
    import laspy

    from lidar2city.tools.reconstruct import reconstruct
    from lidar2city.tools.validate import validate_file

    data = Path(sys.argv[1] if len(sys.argv) > 1 else
                Path(__file__).resolve().parents[2] / "shared" / "data")
    tile = laspy.read(data / "delft" / "ahn3_cropped_1.laz")
    m = ((np.asarray(tile.x) >= X0) & (np.asarray(tile.x) < X1)
         & (np.asarray(tile.y) >= Y0) & (np.asarray(tile.y) < Y1))
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        crop = laspy.LasData(tile.header)
        crop.points = tile.points[m].copy()
        crop.write(tmp / "crop.laz")
        crop = laspy.read(tmp / "crop.laz")
        n, area = len(crop.points), (X1 - X0) * (Y1 - Y0)
        rng = np.random.default_rng(0)
        draw = rng.random(n)
        _footprints(data / "delft" / "footprints_bgt.gpkg", tmp / "fp.gpkg")
        variants = {  # name: (tile writer keywords, footprint shift, z shift)
            "crop (LAS 1.2 format 1)": ({}, None, 0.0),
            "LAS 1.4 format 6": ({"version": "1.4", "fmt": 6}, None, 0.0),
            "LAS 1.4 format 7": ({"version": "1.4", "fmt": 7}, None, 0.0),
            "LAS 1.4 format 8": ({"version": "1.4", "fmt": 8}, None, 0.0),
            "extra bytes": ({"extra": True}, None, 0.0),
            "scale 0.01": ({"scale": [0.01, 0.01, 0.01]}, None, 0.0),
            "z + 1000 m": ({"shift": (0.0, 0.0, 1000.0)}, None, 1000.0),
            "near 0": ({"shift": (-X0, -Y0, 0.0)}, (-X0, -Y0), 0.0),
            "near 1e7": ({"shift": (1e7 - X0, 1e7 - Y0, 0.0)}, (1e7 - X0, 1e7 - Y0), 0.0),
            "3 stray returns": ({"strays": True}, None, 0.0),
            "8 pts/m2": ({"keep": draw < 8 * area / n}, None, 0.0),
            "4 pts/m2": ({"keep": draw < 4 * area / n}, None, 0.0),
            "2 pts/m2": ({"keep": draw < 2 * area / n}, None, 0.0),
            "2 pts/m2 in scan lines": ({"keep": _scan_lines(crop, draw, 2.0, area)}, None, 0.0),
            "1 pts/m2": ({"keep": draw < 1 * area / n}, None, 0.0),
            "ours: ground + classify": ({"own_classes": True}, None, 0.0),
            "no ground class": ({"no_ground": True}, None, 0.0),
            "whole tile + 3 strays": ({"strays": True, "whole": True}, None, 0.0),
        }
        base = None
        print(f"crop: {n:,} points ({n / area:.1f} pts/m2); LoD1.2 + LoD2.2 with the BGT "
              "footprints inside it")
        for name, (kw, fshift, dz) in variants.items():
            path = tmp / "v.laz"
            kw = dict(kw)
            own, whole = kw.pop("own_classes", False), kw.pop("whole", False)
            no_ground = kw.pop("no_ground", False)
            _write_like(tile if whole else crop, path, **kw)
            if no_ground:  # a buildings-only classification: the ground left in class 1
                las = laspy.read(path)
                c = np.asarray(las.classification).copy()
                las.classification = np.where(c == 2, 1, c).astype(c.dtype)
                las.write(path)
            if own:  # classes wiped, then our own ground filter and classifier
                from lidar2city.tools.classify import classify_file
                from lidar2city.tools.ground import ground_file

                raw = laspy.read(path)
                raw.classification[:] = 1
                raw.write(tmp / "raw.laz")
                ground_file(tmp / "raw.laz", tmp / "g.laz", crs="EPSG:7415")
                classify_file(tmp / "g.laz", path, crs="EPSG:7415", ground_from_file=True)
            fp = tmp / "fp.gpkg"
            if whole:
                fp = data / "delft" / "footprints_bgt.gpkg"
            if fshift is not None:
                fp = tmp / "fp_shift.gpkg"
                _footprints(data / "delft" / "footprints_bgt.gpkg", fp, fshift)
            out = tmp / "v.city.json"
            s = reconstruct([path], out, footprints=fp, crs="EPSG:7415", lods=("1.2", "2.2"))
            attrs = _attributes(out)
            valid = validate_file(out).valid
            if base is None:
                base = attrs
            why = sorted({a["lod22_fallback"] for a in attrs.values() if "lod22_fallback" in a})
            diffs = []
            for key, shift in (("roof_height", dz), ("ridge_height", dz), ("ground_height", dz)):
                d = [abs(a[key] - shift - base[k][key]) for k, a in attrs.items()
                     if a.get(key) is not None and base.get(k, {}).get(key) is not None]
                diffs.append(max(d) if d else float("nan"))
            rmse = ""
            if "pts/m2" in name or base is attrs:  # the model against the crop's every point
                from lidar2city.tools.evaluate_model import evaluate_model

                _, ev = evaluate_model(out, [tmp / "crop.laz"], crs="EPSG:7415", check=False)
                rmse = (f"; RMSE to the crop's points median {ev['rmse_median']:.3f} m, "
                        f"p90 {ev['rmse_p90']:.3f} m")
            fb = sum("lod22_fallback" in a for a in attrs.values())
            failed = sorted(a.get("reason", "") for a in attrs.values() if a.get("status") != "ok")
            print(f"{name:24s} {s.done}/{s.total} modelled, {s.failed} failed, {fb} LoD1.2 "
                  f"fallback(s); max |d| roof_height {diffs[0]:.3f} m, ridge_height "
                  f"{diffs[1]:.3f} m, ground_height {diffs[2]:.3f} m; "
                  f"{'valid' if valid else 'INVALID'}" + rmse
                  + (f"; {'; '.join(why)}" if why else "")
                  + (f"; failed: {'; '.join(failed)}" if failed else ""))
    sparse_survey_without_footprints(data)


def sparse_survey_without_footprints(data):
    """ISPRS samp11 (Stuttgart, about 1 pts/m2, EPSG:32632, ground labelled 2, the rest
    0): reconstruct without footprints, LoD1.2 + LoD2.2; buildings traced, modelled,
    failed (by reason), and whether the file validates."""
    import collections

    from lidar2city.tools.reconstruct import reconstruct
    from lidar2city.tools.validate import validate_file

    src = data / "isprs" / "reference" / "samp11-utm.laz"
    if not src.exists():
        return
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "s11.city.json"
        s = reconstruct([src], out, lods=("1.2", "2.2"))
        valid = validate_file(out).valid
        why = collections.Counter(a.get("reason", "").split(" (")[0]
                                  for a in _attributes(out).values() if a.get("status") != "ok")
    print(f"samp11, no footprints      {s.done}/{s.total} modelled, {s.failed} failed"
          + "".join(f", {n} x {r}" for r, n in sorted(why.items()))
          + f"; {'valid' if valid else 'INVALID'}")


def sparse_sites_footprints(data):
    """``--sites``: footprints of the raw ISPRS sites CSite1 and FSite5 (our classify),
    on the grid of the spacing measured now and as it was measured before."""
    from lidar2city.footprints import extract_footprints, grid_lengths, point_spacing
    from lidar2city.io.las import read_points
    from lidar2city.tools.classify import classify_cloud

    for name in ("CSite1_red2-utm.laz", "FSite5_orig-utm.laz"):
        src = data / "isprs" / "sites" / name
        if not src.exists():
            continue
        cloud = read_points(src)
        cls = np.asarray(classify_cloud(cloud))
        b = cloud.xyz[cls == 6, :2]
        now, before = point_spacing(b), point_spacing(b, cell=2.0)
        out = []
        for s in (now, before):
            lengths = grid_lengths(s)
            fps = extract_footprints(cloud.xyz, cls, cell=lengths["cell"], sigma=lengths["sigma"],
                                     void_distance=lengths["void_distance"],
                                     simplify=lengths["simplify"],
                                     snake_cell=lengths["snake_cell"])
            out.append(f"{len(fps)} footprints of {sum(f.polygon.area for f in fps):,.0f} m2 "
                       f"(spacing {s:.2f} m)")
        print(f"{name:22s} {len(b):,} building points: {out[0]}; before: {out[1]}")


if __name__ == "__main__":
    _data = Path(__file__).resolve().parents[2] / "shared" / "data"
    _args = [a for a in sys.argv[1:] if a != "--sites"]
    if "--sites" in sys.argv[1:]:
        sparse_sites_footprints(Path(_args[0]) if _args else _data)
    else:
        main()
