"""A huge footprint its points cover (an industrial hall): CPU seconds per phase.

Usage: ``PYTHONPATH=src python benchmarks/bench_huge_footprint.py [--lods 1.2,1.3,2.2] [--profile]``

The case of ``bench_coverage.py`` section 4: a synthetic 300 m x 300 m footprint,
0.3 pts/m2 of roof points whose heights are random per 6 m block (8-14 m, seed 0),
ground points in two strips just outside it. It is written as a LAS tile
(EPSG:28992 offsets) with a GeoJSON footprint and reconstructed through
:func:`lidar2city.tools.reconstruct.reconstruct` (in this process) at LoD 1.2,
1.2 + 1.3 and 1.2 + 1.3 + 2.2. For each run: CPU seconds (``resource.getrusage``),
those spent in the main phases (each wrapped, CPU time accumulated: the LoD1.3 height
raster ``height_parts``, the prism RMSE ``_rmse``, the prisms' solid checks
``lod1._codes``, the LoD2.2 roof ``reconstruct_lod22``), the LoD1.3 parts, the
building's validity and the MD5 of the CityJSON written (same bytes before and after a
speed-up). ``--profile`` also prints the top 15 functions of the last run by
cumulative time (cProfile).
"""

from __future__ import annotations

import argparse
import cProfile
import hashlib
import json
import pstats
import resource
import tempfile
from pathlib import Path

import numpy as np

W, DENSITY, X0, Y0 = 300.0, 0.3, 85000.0, 447000.0


def _cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def hall_points(w: float = W, density: float = DENSITY, seed: int = 0):
    """(roof xyz, ground xyz) of the synthetic hall, local metres (as bench_coverage.py)."""
    rng = np.random.default_rng(seed)
    n = int(w * w * density)
    xy = rng.uniform(0, w, (n, 2))
    blocks = (xy[:, 0] // 6).astype(int) * 1000 + (xy[:, 1] // 6).astype(int)
    z = 8 + rng.uniform(0, 6, 10**6)[blocks]
    g = rng.uniform(-5, w + 5, (4000, 2))
    g[:, 1] = np.where(rng.random(4000) < 0.5, -2.0, w + 2)
    return np.column_stack([xy, z]), np.column_stack([g, np.zeros(len(g))])


def write_hall(tmp: Path):
    """The hall as ``hall.las`` + ``hall.geojson`` in ``tmp``."""
    import laspy

    roof, ground = hall_points()
    xyz = np.vstack([roof, ground]) + [X0, Y0, 0.0]
    h = laspy.LasHeader(point_format=1, version="1.2")
    h.scales = np.array([0.001, 0.001, 0.001])
    h.offsets = np.floor(xyz.min(axis=0))
    las = laspy.LasData(h)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    las.classification = np.r_[np.full(len(roof), 6), np.full(len(ground), 2)].astype(np.uint8)
    las.write(tmp / "hall.las")
    ring = [[X0, Y0], [X0 + W, Y0], [X0 + W, Y0 + W], [X0, Y0 + W], [X0, Y0]]
    (tmp / "hall.geojson").write_text(json.dumps({"type": "FeatureCollection", "features": [{
        "type": "Feature", "properties": {"id": "hall"},
        "geometry": {"type": "Polygon", "coordinates": [ring]}}]}))


PHASES = (("height_parts", "lidar2city.lod.lod1", "height_parts"),
          ("prism RMSE", "lidar2city.lod.lod1", "_rmse"),
          ("solid checks", "lidar2city.lod.lod1", "_codes"),
          ("LoD2.2 roof", "lidar2city.roof.building", "reconstruct_lod22"))


def _timed(spent, name, fn):
    def wrapper(*a, **kw):
        t0 = _cpu()
        try:
            return fn(*a, **kw)
        finally:
            spent[name] = spent.get(name, 0.0) + _cpu() - t0
    return wrapper


def run(tmp: Path, lods, *, profile: bool = False):
    import importlib

    from lidar2city.tools.reconstruct import reconstruct

    spent: dict[str, float] = {}
    saved = []
    for name, mod, attr in PHASES:
        m = importlib.import_module(mod)
        if hasattr(m, attr):
            saved.append((m, attr, getattr(m, attr)))
            setattr(m, attr, _timed(spent, name, getattr(m, attr)))
    out = tmp / ("hall_" + "_".join(lods) + ".city.json")
    prof = cProfile.Profile() if profile else None
    try:
        t0 = _cpu()
        if prof:
            prof.enable()
        reconstruct([tmp / "hall.las"], out, footprints=tmp / "hall.geojson",
                    crs="EPSG:28992", lods=tuple(lods))
        if prof:
            prof.disable()
        total = _cpu() - t0
    finally:
        for m, attr, fn in saved:
            setattr(m, attr, fn)
    data = out.read_bytes()
    attrs = json.loads(data)["CityObjects"]["hall"].get("attributes", {})
    phases = ", ".join(f"{k} {v:.2f}" for k, v in spent.items())
    print(f"LoD {' + '.join(lods):15s} {total:6.2f} CPU s ({phases}); "
          f"lod13_parts {attrs.get('lod13_parts')}, valid {attrs.get('valid')}, "
          f"md5 {hashlib.md5(data).hexdigest()}")
    if prof:
        pstats.Stats(prof).sort_stats("cumulative").print_stats(15)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lods", default=None, help="one run of these LoDs (comma separated)")
    ap.add_argument("--profile", action="store_true")
    args = ap.parse_args()
    import lidar2city.metrics.model  # noqa: F401  (imports outside the timed runs)
    import lidar2city.roof.building  # noqa: F401
    import lidar2city.tools.reconstruct  # noqa: F401

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        write_hall(tmp)
        runs = [args.lods.split(",")] if args.lods else [["1.2"], ["1.2", "1.3"],
                                                         ["1.2", "1.3", "2.2"]]
        for lods in runs:
            run(tmp, lods, profile=args.profile)


if __name__ == "__main__":
    main()
