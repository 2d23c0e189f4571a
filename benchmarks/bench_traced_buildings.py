"""Where the no-footprints reconstruct spends its CPU, building by building (issue 13).

Usage: python benchmarks/bench_traced_buildings.py [DATA_DIR] [--top N]
(default data $LIDAR2CITY_DATA or ../shared/data; N = 15)

Runs ``reconstruct`` of the Delft tile without footprints (traced per block,
LoD 1.2 + 1.3 + 2.2) once in this process, with the LoD2.2 phases of every
building timed in CPU seconds (``time.process_time``): plane segmentation, the
boundary lines (label grid, chains, step snake), the arrangement partition,
refining and building the solid, validation, and the whole try of each roof
partition method (``rims`` first, ``arrangement`` without rims when the rims'
shell does not close or validate, ``grid`` last). Prints the run's CPU, the
LoD2.2 total and each phase's, the CPU per m2 and per point by footprint size
class (a cost growing faster than the area or the points shows as a larger
ms/m2 or us/point in the larger classes; the points per m2 vary by block),
where the traced blocks lie against BGT's footprints (inside their hull + 2 m:
on them or off them; outside: blocks the BGT file leaves out), then the N
costliest buildings: area, points, roof faces, CPU by phase and which methods
were tried. The timing wrappers only add their own small cost;
the output is the same file as without them.
"""

from __future__ import annotations

import collections
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

PHASES = ("segment_planes", "roof_lines", "arrangement_partition", "_finish_solid", "check_solid")


def data_dir(args):
    if args:
        return Path(args[0])
    if os.environ.get("LIDAR2CITY_DATA"):
        return Path(os.environ["LIDAR2CITY_DATA"])
    return ROOT.parent / "shared" / "data"


def main(argv):
    top = 15
    if "--top" in argv:
        i = argv.index("--top")
        top = int(argv[i + 1])
        argv = argv[:i] + argv[i + 2:]
    laz = data_dir(argv) / "delft" / "ahn3_cropped_1.laz"

    import lidar2city.roof.building as B
    from lidar2city.cli.main import cli

    now = collections.defaultdict(float)
    rows = []

    def timed(name, f):
        def g(*a, **k):
            t = time.process_time()
            try:
                return f(*a, **k)
            finally:
                now[name] += time.process_time() - t
        return g

    for name in PHASES:
        setattr(B, name, timed(name, getattr(B, name)))
    part = B._part_solid

    def part_timed(method, *a, **k):
        t = time.process_time()
        try:
            out = part(method, *a, **k)
        finally:
            now["try " + method] += time.process_time() - t
        now["faces"] = len(out[1])
        return out

    B._part_solid = part_timed
    whole = B.reconstruct_lod22

    def lod22(footprint, xyz, *a, **k):
        now.clear()
        t = time.process_time()
        try:
            return whole(footprint, xyz, *a, **k)
        finally:
            rows.append((footprint.area, len(xyz), time.process_time() - t, dict(now)))

    B.reconstruct_lod22 = lod22
    import lidar2city.tools.reconstruct as R

    traced = []
    trace = R.footprints_from_points

    def traced_kept(cloud, *a, **k):
        fps = trace(cloud, *a, **k)
        traced.append((cloud, fps.geometries))
        return fps

    R.footprints_from_points = traced_kept
    out = Path(tempfile.mkdtemp()) / "traced.city.json"
    t0 = time.process_time()
    try:
        cli(["reconstruct", str(laz), "--crs", "EPSG:7415", "--lod", "1.2", "--lod", "1.3",
             "--lod", "2.2", "-o", str(out)], standalone_mode=False)
    except SystemExit as exc:
        if exc.code:
            raise
    total = time.process_time() - t0
    roof = sum(r[2] for r in rows)
    area = sum(r[0] for r in rows)
    phases = collections.defaultdict(float)
    for r in rows:
        for k, v in r[3].items():
            if k != "faces":
                phases[k] += v
    print(f"reconstruct without footprints, Delft, in one process: {total:.2f} CPU s; "
          f"LoD2.2 {roof:.2f} CPU s over {len(rows)} buildings, {area:.0f} m2 "
          f"({1000 * roof / max(area, 1e-9):.2f} ms/m2)")
    print("  LoD2.2 by phase (CPU s): " + ", ".join(
        f"{k} {v:.2f}" for k, v in sorted(phases.items(), key=lambda kv: -kv[1])))
    for lo, hi in ((0, 200), (200, 500), (500, 1000), (1000, float("inf"))):
        sel = [r for r in rows if lo <= r[0] < hi]
        if sel:
            a, c, n = sum(r[0] for r in sel), sum(r[2] for r in sel), sum(r[1] for r in sel)
            print(f"  footprints {lo:g}-{hi:g} m2: {len(sel)} buildings, {a:.0f} m2, "
                  f"{c:.2f} CPU s, {1000 * c / a:.2f} ms/m2, {n / a:.1f} points/m2, "
                  f"{1e6 * c / n:.0f} us/point")
    if traced:
        against_bgt(traced, laz.parent / "footprints_bgt.gpkg")
    print(f"  the {min(top, len(rows))} costliest (area m2, points, roof faces, CPU s: "
          "whole / segmentation / lines / arrangement / finish / check; tries)")
    for a, n, c, ph in sorted(rows, key=lambda r: -r[2])[:top]:
        tries = " ".join(f"{k[4:]} {v:.2f}" for k, v in ph.items() if k.startswith("try "))
        print(f"    {a:7.0f} {n:7d} {int(ph.get('faces', 0)):4d}  {c:5.2f} / "
              + " / ".join(f"{ph.get(k, 0.0):.2f}" for k in PHASES) + f"; {tries}")


def against_bgt(traced, bgt_path):
    """Where the traced blocks lie against BGT's footprints (which cover only the tile's two
    central blocks): traced area inside BGT's hull + 2 m and outside it, and inside it the
    area both cover, BGT's area not traced and the traced area off BGT."""
    import shapely

    from lidar2city.io.vector import read_footprints

    cloud = traced[0][0]
    tu = shapely.union_all([g for _, gs in traced for g in gs])
    bgt, _ = read_footprints(bgt_path, origin=cloud.origin[:2], xy_unit=cloud.xy_unit,
                             target_crs=cloud.crs)
    bu = shapely.union_all([g for g in bgt.geometries if g is not None])
    hull = shapely.convex_hull(bu).buffer(2.0)
    inside = tu.intersection(hull)
    print(f"  traced {tu.area:.0f} m2 against BGT's {len(bgt)} footprints, {bu.area:.0f} m2: "
          f"{inside.area:.0f} m2 inside BGT's hull + 2 m ({inside.intersection(bu).area:.0f} m2 "
          f"on BGT, {inside.difference(bu).area:.0f} m2 off it; BGT not traced "
          f"{bu.difference(tu).area:.0f} m2), {tu.difference(hull).area:.0f} m2 outside it "
          "(blocks BGT's file leaves out)")


if __name__ == "__main__":
    main(sys.argv[1:])
