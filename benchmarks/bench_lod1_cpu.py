"""CPU of the LoD1.2 / LoD1.3 stage on the Delft tile, this tree against another, in pairs.

Usage: ``python benchmarks/bench_lod1_cpu.py [DATA_DIR] [--other SRC] [--rounds 5] [--repeat 3]
[--lod22] [--profile] [--imports]`` (default $LIDAR2CITY_DATA or ../shared/data; SRC: the ``src`` folder of
another checkout, e.g. /work/wt/base/src)

In a fresh process per tree, the tile is read and its 132 BGT footprints are
matched to it; then :func:`lidar2city.tools.reconstruct.reconstruct_buildings`
builds LoD1.2 + 1.3 for every footprint (one warm-up pass, so imports and first
calls are not measured, then ``--repeat`` passes; ``--lod22``: with LoD2.2 too)
and the process CPU seconds (``time.process_time``) of the best pass are
reported, with an MD5 of every result (attributes but the run time, solids and
LoD1.3 parts) to show whether the two trees build the same models. The trees
run alternately, ``--rounds`` times (A B A B ...): the pairs' CPU ratios A/B
and their median are printed with the load average before and after.

``--profile``: instead, per round and tree, the issue's command (``reconstruct`` of the
tile with its footprints, LoD 1.2 + 1.3 + 2.2, one process) runs under cProfile timed
in process CPU seconds, and the cumulative CPU of the LoD1 stage's functions and of
the run's serial start is printed (the profiler inflates them, ~2x: compare trees), with
the number of modules the run imported and whether it loaded GDAL (pyogrio).
``--imports``: instead, per tree, the least CPU of ``--rounds`` fresh processes importing
what a run with footprints imports before its first building (``lidar2city.tools.reconstruct``
and ``lidar2city.lod.lod1``; numpy, shapely and scipy imported first, as a run has them
anyway), and how many modules that import adds.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r'''
import hashlib, json, sys, time
import numpy as np
from lidar2city.io.las import read_points
from lidar2city.lod.lod1 import Lod1Config
from lidar2city.roof.building import Lod22Config
from lidar2city.tools.reconstruct import load_footprints, reconstruct_buildings

d, repeat, lod22 = sys.argv[1], int(sys.argv[2]), sys.argv[3] == "1"
cloud = read_points(d + "/ahn3_cropped_1.laz", crs="EPSG:28992")
fps = load_footprints(d + "/footprints_bgt.gpkg", cloud)
cfg = Lod1Config(lods=("1.2", "1.3"))
extra = Lod22Config() if lod22 else None


def digest(results):
    h = hashlib.md5()
    for r in results:
        a = {k: v for k, v in r.attributes.items() if not k.endswith("_time")}
        h.update(repr((r.id, r.status, r.reason, sorted(a.items()))).encode())
        for key in sorted(r.solids):
            s = r.solids[key]
            for t in (s if isinstance(s, list) else [s]):
                h.update(np.ascontiguousarray(t.vertices).tobytes())
                for f in t.surfaces:
                    h.update(f.semantic.encode())
                    for ring in f.rings:
                        h.update(np.asarray(ring, dtype=np.int64).tobytes())
        for key in sorted(r.parts):
            for t in r.parts[key]:
                h.update(np.ascontiguousarray(t.vertices).tobytes())
    return h.hexdigest()


reconstruct_buildings(cloud, fps, config=cfg, lod22=extra)  # warm-up: imports, caches
cpu = []
for _ in range(repeat):
    t0 = time.process_time()
    res = reconstruct_buildings(cloud, fps, config=cfg, lod22=extra)
    cpu.append(time.process_time() - t0)
print(json.dumps({"cpu": min(cpu), "n": len(res), "md5": digest(res),
                  "rmse13": float(np.median([r.attributes["rmse_lod13"] for r in res
                                             if "rmse_lod13" in r.attributes])),
                  "valid": sum(bool(r.attributes.get("valid")) for r in res)}))
'''


PROFILED = r'''
import cProfile, json, pstats, sys, time
from lidar2city.cli.main import cli
d, out = sys.argv[1], sys.argv[2]
pr = cProfile.Profile(time.process_time)
pr.enable()
cli.main(["reconstruct", d + "/ahn3_cropped_1.laz", "--footprints", d + "/footprints_bgt.gpkg",
          "--lod", "1.2", "--lod", "1.3", "--lod", "2.2", "-o", out], standalone_mode=False)
pr.disable()
st = pstats.Stats(pr)
cum = {}
for (f, _, name), v in st.stats.items():
    key = f.replace("\\", "/").split("lidar2city/")[-1] + ":" + name
    cum[key] = cum.get(key, 0.0) + v[3]
print(json.dumps({"total": st.total_tt, "cum": cum, "modules": len(sys.modules),
                  "gdal": "pyogrio" in sys.modules}))
'''

#: the functions whose cumulative CPU ``--profile`` prints (module path: name)
STAGE = ("lod/lod1.py:reconstruct_building", "lod/lod1.py:_lod13", "lod/lod13.py:height_parts",
         "lod/lod13.py:_height_labels", "lod/lod1.py:_rmse", "lod/lod1.py:_codes",
         "roof/building.py:part_floor", "tools/reconstruct.py:plan_reconstruct",
         "io/las.py:scan_tiles", "io/vector.py:vector_crs", "io/vector.py:read_footprints",
         "io/las.py:read_tile")


def profiled(src, d) -> dict:
    import tempfile

    env = dict(os.environ, PYTHONPATH=str(src), OMP_NUM_THREADS="1")
    with tempfile.TemporaryDirectory() as tmp:
        out = subprocess.run([sys.executable, "-c", PROFILED, str(d), tmp + "/out.city.json"],
                             env=env, check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


IMPORTS = r'''
import json, sys, time
import numpy, scipy, shapely  # noqa: F401
n0, t0 = len(sys.modules), time.process_time()
import lidar2city.lod.lod1, lidar2city.tools.reconstruct  # noqa: F401
print(json.dumps({"cpu": time.process_time() - t0, "modules": len(sys.modules) - n0}))
'''


def imports(src) -> dict:
    env = dict(os.environ, PYTHONPATH=str(src))
    out = subprocess.run([sys.executable, "-c", IMPORTS], env=env, check=True,
                         capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def data_dir(arg):
    if arg:
        return Path(arg)
    if os.environ.get("LIDAR2CITY_DATA"):
        return Path(os.environ["LIDAR2CITY_DATA"])
    return ROOT.parent / "shared" / "data"


def run(src, d, repeat, lod22) -> dict:
    env = dict(os.environ, PYTHONPATH=str(src), OMP_NUM_THREADS="1")
    out = subprocess.run([sys.executable, "-c", CHILD, str(d), str(repeat), "1" if lod22 else "0"],
                         env=env, check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _load() -> str:
    return " ".join(f"{v:.2f}" for v in os.getloadavg())


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="?")
    ap.add_argument("--other", help="the src folder of the tree to compare with")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--lod22", action="store_true", help="LoD2.2 too")
    ap.add_argument("--profile", action="store_true", help="the stage's cProfile CPU")
    ap.add_argument("--imports", action="store_true", help="the imports before a building")
    a = ap.parse_args()
    d = data_dir(a.data) / "delft"
    mine = ROOT / "src"
    print(f"load average before: {_load()} ({os.cpu_count()} cores)", flush=True)
    if a.imports:
        for name, src in [("this tree", mine)] + ([("other", Path(a.other))] if a.other else []):
            got = [imports(src) for _ in range(max(1, a.rounds))]
            print(f"{name}: least {1000 * min(g['cpu'] for g in got):.1f} CPU ms of "
                  f"{len(got)} processes, {got[0]['modules']} modules")
        print(f"load average after: {_load()}")
        return
    if a.profile:
        trees = [("this tree", mine)] + ([("other", Path(a.other))] if a.other else [])
        got = {name: [] for name, _ in trees}
        for _ in range(max(1, a.rounds)):
            for name, src in trees:
                got[name].append(profiled(src, d))
        for key in ("total",) + STAGE:
            cells = []
            for name, _ in trees:
                v = [g["total"] if key == "total" else g["cum"].get(key, 0.0) for g in got[name]]
                cells.append(f"{name} {statistics.median(v):7.3f}")
            print(f"{key:40s} " + "  ".join(cells) + "  (CPU s under cProfile, median)")
        print("modules imported by the run: " + "  ".join(
            f"{name} {got[name][0]['modules']} (GDAL / pyogrio "
            f"{'loaded' if got[name][0]['gdal'] else 'not loaded'})" for name, _ in trees))
        print(f"load average after: {_load()}")
        return
    ratios = []
    for k in range(max(1, a.rounds)):
        ra = run(mine, d, a.repeat, a.lod22)
        line = (f"round {k + 1}: this tree {ra['cpu']:.3f} CPU s ({1000 * ra['cpu'] / ra['n']:.2f} "
                f"ms a building), md5 {ra['md5'][:8]}, LoD1.3 median RMSE {ra['rmse13']:.4f} m, "
                f"valid {ra['valid']}/{ra['n']}")
        if a.other:
            rb = run(a.other, d, a.repeat, a.lod22)
            ratios.append(ra["cpu"] / rb["cpu"])
            line += (f"; other {rb['cpu']:.3f} CPU s, md5 {rb['md5'][:8]}, RMSE {rb['rmse13']:.4f}"
                     f" m, valid {rb['valid']}/{rb['n']}; ratio {ratios[-1]:.3f}"
                     f" ({'same' if ra['md5'] == rb['md5'] else 'DIFFERENT'} models)")
        print(line, flush=True)
    if ratios:
        print(f"CPU ratio this tree / other, median of {len(ratios)} pairs: "
              f"{statistics.median(ratios):.3f}")
    print(f"load average after: {_load()}")


if __name__ == "__main__":
    main()
