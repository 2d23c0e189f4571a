"""LoD2.2 roofs on the Delft tile: fit (RMSE, coverage), validity, type IV use, speed.

Usage: python benchmarks/bench_lod22.py [DATA_DIR]   (default $LIDAR2CITY_DATA or ../shared/data)
       python benchmarks/bench_lod22.py --types [DATA_DIR]   (the City3D roof types only)

Reconstructs the 132 BGT footprints of the shared AHN3 tile at LoD1.2 and LoD2.2
(the AHN classes: 6 building, 2 ground) and measures, with the code that
`lidar2city evaluate model` uses, the 3-D distance of the building points
inside each footprint to each model's surface (point to mesh, as roofer's
rf_rmse); "under a roof" is the share of those points whose vertical line
meets a roof face. Then the whole-process time of the CLI, and the synthetic
town of the demo against its truth.

With ``--types``, only the 60 City3D clouds, each roof's type and plane count
scored against the reference labelled by eye in
``benchmarks/data/city3d_roof_reference.csv``: per reference type, our type
right / wrong, the median excess of our roof planes over the reference's, and
the median RMSE.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


REFERENCE = ROOT / "benchmarks" / "data" / "city3d_roof_reference.csv"


def data_dir() -> Path:
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    if args:
        return Path(args[0])
    if os.environ.get("LIDAR2CITY_DATA"):
        return Path(os.environ["LIDAR2CITY_DATA"])
    return ROOT.parent / "shared" / "data"


def under_roof(pts, solids):
    import shapely

    roofs = []
    for s in solids:
        for surf in s.surfaces:
            if surf.semantic == "RoofSurface":
                v = s.vertices
                roofs.append(shapely.Polygon(v[surf.rings[0], :2], [v[h, :2] for h in surf.rings[1:]]))
    if not roofs or not len(pts):
        return 0.0
    u = shapely.union_all(roofs).buffer(1e-6)
    return float(np.mean(shapely.contains_xy(u, pts[:, 0], pts[:, 1])))


def main():
    import shapely

    sys.path.insert(0, str(ROOT / "src"))
    from lidar2city.io.las import read_points
    from lidar2city.io.vector import read_footprints
    from lidar2city.lod.lod1 import Lod1Config
    from lidar2city.metrics.model import model_rmse
    from lidar2city.roof.building import Lod22Config
    from lidar2city.tools.reconstruct import reconstruct_buildings
    from lidar2city.validate.solid import check_solid

    d = data_dir() / "delft"
    laz, fpath = d / "ahn3_cropped_1.laz", d / "footprints_bgt.gpkg"
    cloud = read_points(laz, crs="EPSG:7415")
    fps, _ = read_footprints(fpath, origin=cloud.origin[:2], target_crs=cloud.crs)
    cls = cloud.get("classification")
    t0 = time.process_time()
    results = reconstruct_buildings(cloud, fps, config=Lod1Config(lods=("1.2",)), lod22=Lod22Config())
    cpu = time.process_time() - t0
    bxyz = cloud.xyz[cls == 6]
    rm12, rm22, cover, valid, fallback, type4, times = [], [], [], 0, 0, [], []
    kinds = {}
    for g, r in zip(fps.geometries, results, strict=True):
        pts = bxyz[shapely.contains_xy(g, bxyz[:, 0], bxyz[:, 1])]
        s12 = r.solids["1.2"]
        s22 = r.solids["2.2"]
        s12 = s12 if isinstance(s12, list) else [s12]
        s22 = s22 if isinstance(s22, list) else [s22]
        rm12.append(model_rmse(pts, s12))
        rm22.append(model_rmse(pts, s22))
        cover.append(under_roof(pts, s22))
        valid += all(not check_solid(s) for s in s22)
        fallback += "lod22_fallback" in r.attributes
        type4.append(r.attributes.get("type_iv", 0))
        times.append(r.attributes.get("lod22_time", 0.0))
        kinds[r.attributes.get("roof_type", "-")] = kinds.get(r.attributes.get("roof_type", "-"), 0) + 1
    n = len(results)
    rm12, rm22 = np.array(rm12), np.array(rm22)
    print(f"Delft shared tile, {n} BGT footprints (AHN3 class 6 points inside each)")
    print(f"  LoD2.2 RMSE  median {np.median(rm22):.3f} m  mean {rm22.mean():.3f} m  p90 {np.percentile(rm22, 90):.3f} m")
    print(f"  LoD1.2 RMSE  median {np.median(rm12):.3f} m  mean {rm12.mean():.3f} m  p90 {np.percentile(rm12, 90):.3f} m")
    print(f"  points under a roof face: median {100 * np.median(cover):.1f} %, all buildings >= 95 %: "
          f"{int(np.sum(np.array(cover) >= 0.95))}/{n}")
    print(f"  valid LoD2.2 solids {valid}/{n}, LoD1.2 fallbacks {fallback}")
    print(f"  roof types {dict(sorted(kinds.items()))}")
    t4 = np.array(type4)
    print(f"  buildings needing type IV reductions: {int(np.sum(t4 > 0))}/{n} "
          f"({100 * np.mean(t4 == 0):.1f} % needed none)")
    print(f"  LoD2.2 time per building: median {1000 * np.median(times):.1f} ms, mean "
          f"{1000 * np.mean(times):.1f} ms -> {1 / np.mean(times):.1f} buildings/s; whole batch CPU {cpu:.2f} s")
    out = Path(tempfile.mkdtemp()) / "delft_lod22.city.json"
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    cmd = [sys.executable, "-m", "lidar2city.cli.main", "reconstruct", str(laz), "--crs", "EPSG:7415",
           "--footprints", str(fpath), "--lod", "1.2", "--lod", "2.2", "-o", str(out)]
    t0 = time.perf_counter()
    run = subprocess.run(cmd, check=True, env=env, capture_output=True, text=True)
    print(f"  CLI whole process (LoD1.2 + LoD2.2, read, write CityJSON): {time.perf_counter() - t0:.2f} s")
    # the command's own summary, with its LoD1.2 fallbacks: the command reads the tile block
    # by block (points in canonical order), the loop above the tile read whole, and a roof
    # near a fallback can go either way
    print("  CLI summary:" + "".join(f"\n    {ln.strip()}" for ln in run.stderr.splitlines()
                                     if "buildings reconstructed" in ln or "LoD2.2:" in ln))
    res = subprocess.run([sys.executable, "-m", "lidar2city.cli.main", "validate", str(out)],
                         env=env, capture_output=True, text=True)
    print("  validate: " + (res.stdout.strip().splitlines() or ["?"])[-1])
    city3d(data_dir() / "city3d" / "building_instances")


def city3d(folder):
    """The City3D single-building clouds: footprint derived from the points (snake-regularised),
    floor at the lowest point (they hold no ground)."""
    import shapely

    from lidar2city.footprints import extract_footprints
    from lidar2city.io.ply import read_ply
    from lidar2city.metrics.model import model_rmse
    from lidar2city.roof.building import reconstruct_lod22
    from lidar2city.validate.solid import check_solid

    files = sorted(folder.glob("*.ply"), key=lambda p: int(p.stem))
    rms, valid, t0, ours = [], 0, time.perf_counter(), {}
    for f in files:
        pc = read_ply(f)
        fps = extract_footprints(pc.xyz, np.full(len(pc), 6), regularize="snake")
        fp = shapely.union_all([x.polygon for x in fps])
        res = reconstruct_lod22(fp, pc.xyz, float(pc.xyz[:, 2].min()))
        valid += all(not check_solid(s) for s in res.solids)
        inside = shapely.contains_xy(fp, pc.xyz[:, 0], pc.xyz[:, 1])
        rms.append(model_rmse(pc.xyz[inside], res.solids))
        ours[f.stem] = (res.attributes["roof_type"], res.attributes["roof_planes"], rms[-1])
    print(f"City3D single buildings ({len(files)}; footprints derived, floor = lowest point): "
          f"valid {valid}/{len(files)}, RMSE median {np.median(rms):.3f} m, p90 "
          f"{np.percentile(rms, 90):.3f} m, {time.perf_counter() - t0:.1f} s")
    return ours


def delft_planes():
    """The Delft tile's roof plane counts and types (no reference there: the distribution)."""
    from lidar2city.io.las import read_points
    from lidar2city.io.vector import read_footprints
    from lidar2city.lod.lod1 import Lod1Config
    from lidar2city.roof.building import Lod22Config
    from lidar2city.tools.reconstruct import reconstruct_buildings

    d = data_dir() / "delft"
    cloud = read_points(d / "ahn3_cropped_1.laz", crs="EPSG:7415")
    fps, _ = read_footprints(d / "footprints_bgt.gpkg", origin=cloud.origin[:2], target_crs=cloud.crs)
    res = reconstruct_buildings(cloud, fps, config=Lod1Config(lods=("1.2",)), lod22=Lod22Config())
    n = np.array([r.attributes.get("roof_planes", 0) for r in res])
    types = {}
    for r in res:
        types[r.attributes.get("roof_type", "-")] = types.get(r.attributes.get("roof_type", "-"), 0) + 1
    hist = {(str(a) if b == a else f"{a}+" if b is None else f"{a}-{b}"): int(np.sum((n >= a) & (n <= (b or n.max()))))
            for a, b in ((1, 1), (2, 2), (3, 4), (5, 8), (9, 16), (17, None))}
    print(f"Delft tile ({len(res)} buildings, no reference): roof planes median {np.median(n):.0f}, "
          f"buildings by plane count {hist}; types {dict(sorted(types.items()))}")


def read_reference(path=REFERENCE):
    """``{id: (types, planes, main types)}`` of the roofs labelled by eye ('unsure' left out)."""
    import csv

    rows = [ln for ln in path.read_text().splitlines() if ln and not ln.startswith("#")]
    ref = {}
    for r in csv.DictReader(rows):
        if r["type"] != "unsure":
            ref[r["id"]] = (tuple(r["type"].split("|")), int(r["planes"]), tuple(r["main"].split("|")))
    return ref


def score_types(ours, ref):
    """Per reference type: our type right / wrong, median excess planes, median RMSE."""
    simple = sorted({t[0] for t, *_ in ref.values()}, key=lambda t: (t == "complex", t))
    print(f"City3D roof types against the reference by eye ({len(ref)} labelled, "
          f"{len(ours) - len(ref)} unsure left out; {REFERENCE.name}):")
    print(f"  {'reference':<12} {'n':>3} {'right':>6} {'wrong':>6} {'excess planes (median)':>23} "
          f"{'RMSE median':>12}   ours when wrong")
    for group in [simple[:-1], ["complex"]] if "complex" in simple else [simple]:
        for t in group:
            ids = [i for i, (ts, *_) in ref.items() if ts[0] == t]
            right = [i for i in ids if ours[i][0] in ref[i][0]]
            excess = [ours[i][1] - ref[i][1] for i in ids]
            wrong = ", ".join(f"{i}:{ours[i][0]}" for i in ids if i not in right)
            print(f"  {'|'.join(ref[ids[0]][0]):<12} {len(ids):>3} {len(right):>6} {len(ids) - len(right):>6} "
                  f"{np.median(excess):>+23.1f} {np.median([ours[i][2] for i in ids]):>10.3f} m   {wrong}")
    ids = [i for i, (ts, *_) in ref.items() if ts[0] == "complex"]
    if ids:
        main = sum(ours[i][0] in ref[i][2] for i in ids if ours[i][0] != "complex")
        print(f"  complex roofs typed as their main part's type (dormers, annexes left to 'minor'): "
              f"{main}/{sum(ours[i][0] != 'complex' for i in ids)}")
    ids = [i for i, (ts, *_) in ref.items() if ts[0] != "complex"]
    right = sum(ours[i][0] in ref[i][0] for i in ids)
    print(f"  simple roofs (not complex): type right {right}/{len(ids)}, median excess planes "
          f"{np.median([ours[i][1] - ref[i][1] for i in ids]):+.1f}, RMSE median "
          f"{np.median([ours[i][2] for i in ids]):.3f} m")


if __name__ == "__main__":
    if "--types" in sys.argv:
        sys.path.insert(0, str(ROOT / "src"))
        score_types(city3d(data_dir() / "city3d" / "building_instances"), read_reference())
        delft_planes()
    else:
        main()
