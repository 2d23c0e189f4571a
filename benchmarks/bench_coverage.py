"""Footprints unlike their points: a 1 km2 polygon over a crop, a 1 m x 1 m crop.

Usage: ``PYTHONPATH=src python benchmarks/bench_coverage.py [DATA_DIR]``

1. A 100 m x 120 m crop of the Delft AHN3 tile (x 84850-84950, y 447450-447570)
   with one 1 km x 1 km footprint laid over it, reconstructed at LoD 1.2 + 1.3
   + 2.2 (in this process): the CPU seconds of the run (``resource.getrusage``),
   and what the building got (``low_coverage``, ``lod22_fallback``).
2. The share of each BGT footprint within reach of its building points
   (:func:`lidar2city.lod.coverage.reach_coverage`, the rule's measure) on the
   whole tile and on the crop of ``bench_surveys.py`` thinned at random (seed 0)
   to 2 and 1 pts/m2 and to 2 pts/m2 in scan lines 1.4 m apart: the smallest
   share and how many fall under :data:`lidar2city.lod.lod1.MIN_COVERAGE`;
   then the LoD1.2 run on each thinned crop: buildings modelled.
4. A synthetic 300 m x 300 m footprint covered by points (0.3 pts/m2, roof heights random
   per 6 m block, seed 0) at LoD1.2 + 1.3: CPU seconds with the LoD1.3 raster capped
   (:data:`lidar2city.lod.lod1.LOD13_MAX_CELLS`) and without the cap.
3. A 1 m x 1 m crop (x 84923-84924, y 447499-447500, inside a 69 m2 footprint) with the BGT footprints:
   what each footprint got.
"""

from __future__ import annotations

import json
import resource
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_surveys import X0, X1, Y0, Y1, _footprints, _scan_lines, _write_like  # noqa: E402


def _cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _crop(tile, box, path):
    import laspy

    x, y = np.asarray(tile.x), np.asarray(tile.y)
    m = (x >= box[0]) & (x < box[2]) & (y >= box[1]) & (y < box[3])
    out = laspy.LasData(tile.header)
    out.points = tile.points[m].copy()
    out.write(path)
    return laspy.read(path)


def _buildings(path):
    d = json.loads(Path(path).read_text())
    return {k: o.get("attributes", {}) for k, o in d["CityObjects"].items()
            if o["type"] == "Building"}


def _shares(las, gpkg):
    import pyogrio.raw
    import shapely

    from lidar2city.lod.coverage import reach_coverage

    _, _, wkb, _ = pyogrio.raw.read(str(gpkg))
    b = np.asarray(las.classification) == 6
    xy = np.column_stack([np.asarray(las.x)[b], np.asarray(las.y)[b]])
    out = []
    for g in shapely.from_wkb(wkb):
        inside = xy[shapely.contains_xy(g, xy[:, 0], xy[:, 1])]
        out.append(reach_coverage(g, inside)[0] if len(inside) else float("nan"))
    return np.array(out)


def main():
    import laspy

    from lidar2city.lod.lod1 import MIN_COVERAGE
    from lidar2city.tools.reconstruct import reconstruct

    data = Path(sys.argv[1] if len(sys.argv) > 1 else
                Path(__file__).resolve().parents[2] / "shared" / "data")
    tile = laspy.read(data / "delft" / "ahn3_cropped_1.laz")
    bgt = data / "delft" / "footprints_bgt.gpkg"
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        crop = _crop(tile, (84850.0, 447450.0, 84950.0, 447570.0), tmp / "crop.laz")
        big = tmp / "big.geojson"
        big.write_text(json.dumps({"type": "FeatureCollection", "features": [{
            "type": "Feature", "properties": {"id": "big"}, "geometry": {
                "type": "Polygon", "coordinates": [[[84400, 447000], [85400, 447000],
                                                    [85400, 448000], [84400, 448000],
                                                    [84400, 447000]]]}}]}))
        t0 = _cpu()
        reconstruct([tmp / "crop.laz"], tmp / "big.city.json", footprints=big,
                    crs="EPSG:28992", lods=("1.2", "1.3", "2.2"))
        a = _buildings(tmp / "big.city.json")["big"]
        print(f"1 km2 footprint over the {len(crop.points):,}-point crop, LoD 1.2 + 1.3 + 2.2: "
              f"{_cpu() - t0:.2f} CPU s; status {a.get('status', 'ok')}, lod13_parts "
              f"{a.get('lod13_parts')}, low_coverage: {a.get('low_coverage')}; "
              f"lod22_fallback: {a.get('lod22_fallback')}")

        s = _shares(tile, bgt)
        print(f"whole tile, {np.isfinite(s).sum()} footprints with building points: smallest "
              f"share {np.nanmin(s):.3f}, under {MIN_COVERAGE}: {(s < MIN_COVERAGE).sum()}")
        sub = _crop(tile, (X0, Y0, X1, Y1), tmp / "sub.laz")
        _footprints(bgt, tmp / "fp.gpkg")
        n, area = len(sub.points), (X1 - X0) * (Y1 - Y0)
        draw = np.random.default_rng(0).random(n)
        for name, keep in (("2 pts/m2", draw < 2 * area / n), ("1 pts/m2", draw < area / n),
                           ("2 pts/m2 in scan lines", _scan_lines(sub, draw, 2.0, area))):
            _write_like(sub, tmp / "thin.laz", keep=keep)
            s = _shares(laspy.read(tmp / "thin.laz"), tmp / "fp.gpkg")
            r = reconstruct([tmp / "thin.laz"], tmp / "thin.city.json", footprints=tmp / "fp.gpkg",
                            crs="EPSG:7415", lods=("1.2",))
            low = sum("low_coverage" in b for b in _buildings(tmp / "thin.city.json").values())
            print(f"{name:23s} smallest share {np.nanmin(s):.3f}, under {MIN_COVERAGE}: "
                  f"{(s < MIN_COVERAGE).sum()}; LoD1.2 {r.done}/{r.total} modelled, "
                  f"{low} low_coverage")

        _crop(tile, (84923.0, 447499.0, 84924.0, 447500.0), tmp / "tiny.laz")
        try:
            r = reconstruct([tmp / "tiny.laz"], tmp / "tiny.city.json", footprints=bgt,
                            crs="EPSG:28992", lods=("1.2",))
            print(f"1 m x 1 m crop: {r.done}/{r.total} modelled; "
                  + "; ".join(f"{k}: {v.get('reason') or v.get('ground_note') or v.get('roof_height')}"
                              for k, v in _buildings(tmp / "tiny.city.json").items()))
        except Exception as exc:  # noqa: BLE001  (a one-line error is an answer here)
            print(f"1 m x 1 m crop: {type(exc).__name__}: {exc}")

    huge_covered_footprint()


def huge_covered_footprint():
    """Section 4: the LoD1.3 raster cap on a huge footprint its points cover."""
    from shapely.geometry import box

    import lidar2city.lod.lod1 as lod1

    from bench_huge_footprint import hall_points

    w = 300.0
    roof, ground = hall_points(w, 0.3, seed=0)
    cap = lod1.LOD13_MAX_CELLS
    for name, cells in (("capped", cap), ("no cap", 10**12)):
        lod1.LOD13_MAX_CELLS = cells
        t0 = _cpu()
        r = lod1.reconstruct_building(box(0, 0, w, w), roof, ground,
                                      config=lod1.Lod1Config(lods=("1.2", "1.3")))
        print(f"300 m x 300 m covered footprint, LoD1.3 {name}: {_cpu() - t0:.1f} CPU s, "
              f"{r.attributes.get('lod13_parts')} parts, cell "
              f"{lod1.lod13_cell(box(0, 0, w, w), 0.5):.3f} m")
    lod1.LOD13_MAX_CELLS = cap


if __name__ == "__main__":
    main()
