"""reconstruct on one tile vs the same area cut into tiles: same bytes, time, memory.

Usage: ``PYTHONPATH=src python benchmarks/bench_tiling.py [DATA_DIR] [--traced]``

The Delft AHN3 tile is cut into 2 x 2 tiles and into 3 strips (written with
their own LAS offsets, given in shuffled order). Each set is reconstructed
(LoD1.2 + LoD2.2 with the BGT footprints) with several block sizes, each run in
a fresh process so that its peak memory (max RSS) is its own. The output's
MD5 must not depend on the tiling (it may depend on the block size: a block's
raw-tile classification sees the block's box). ``--traced`` adds the runs
without footprints (traced per block), which take over a minute each.

Measured 2026-11-21 (2-core shared machine), see the README's table.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

CHILD = r"""
import json, resource, sys, time
from lidar2city.tools.reconstruct import reconstruct
args = json.loads(sys.argv[1])
t0 = time.perf_counter()
s = reconstruct(args["inputs"], args["out"], footprints=args["fp"], crs="EPSG:28992",
                lods=("1.2", "2.2"), block_size=args["block"])
print(json.dumps({"seconds": time.perf_counter() - t0, "done": s.done, "total": s.total,
                  "invalid": s.invalid,
                  "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def main():
    argv = [a for a in sys.argv[1:] if not a.startswith("--")]
    traced = "--traced" in sys.argv
    root = Path(argv[0] if argv else os.environ.get(
        "LIDAR2CITY_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))
    import numpy as np

    from lidar2city.io.las import read_las, write_points

    tile = root / "delft" / "ahn3_cropped_1.laz"
    fp = root / "delft" / "footprints_bgt.gpkg"
    cloud = read_las(tile, crs="EPSG:28992").point_cloud()
    world = cloud.to_world(cloud.xyz)
    o = cloud.origin
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        sets = {"one tile": [str(tile)]}
        four = []
        for i, sx in enumerate((world[:, 0] < o[0] + 92.0, world[:, 0] >= o[0] + 92.0)):
            for j, sy in enumerate((world[:, 1] < o[1] + 88.0, world[:, 1] >= o[1] + 88.0)):
                p = tmp / f"q{i}{j}.laz"
                write_points(p, cloud.subset(sx & sy))
                four.append(str(p))
        sets["2 x 2 tiles"] = four[::-1]
        cuts = np.searchsorted([o[0] + 62.0, o[0] + 132.0], world[:, 0], side="right")
        strips = []
        for k in range(3):
            p = tmp / f"s{k}.laz"
            write_points(p, cloud.subset(cuts == k))
            strips.append(str(p))
        sets["3 strips"] = [strips[1], strips[2], strips[0]]
        modes = [("footprints", str(fp))] + ([("traced", None)] if traced else [])
        env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1] / "src"))
        for mode, fpath in modes:
            for block in (1000.0, 100.0):
                digests = {}
                for name, inputs in sets.items():
                    out = tmp / "m.city.json"
                    arg = json.dumps({"inputs": inputs, "out": str(out), "fp": fpath, "block": block})
                    res = subprocess.run([sys.executable, "-c", CHILD, arg], capture_output=True,
                                         text=True, env=env, check=True)
                    r = json.loads(res.stdout.strip().splitlines()[-1])
                    digests[name] = hashlib.md5(out.read_bytes()).hexdigest()
                    print(f"{mode:10s} block {block:6.0f} m  {name:12s}  {r['done']}/{r['total']} "
                          f"buildings, {r['invalid']} invalid, {r['seconds']:5.1f} s, "
                          f"max RSS {r['rss_mb']:.0f} MB, md5 {digests[name][:12]}")
                same = len(set(digests.values())) == 1
                print(f"  -> {'identical' if same else 'DIFFERENT'} output for the "
                      f"{len(digests)} tilings")


if __name__ == "__main__":
    main()
