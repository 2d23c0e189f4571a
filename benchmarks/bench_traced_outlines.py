"""A traced block's outlines regularised by all the workers or in its first pass, in pairs.

Usage: ``python benchmarks/bench_traced_outlines.py [DATA_DIR] [--areas tile,clip,copies]
[--pairs 3] [--workers 2] [--src OTHER_SRC]``
(default $LIDAR2CITY_DATA or ../shared/data)

``reconstruct`` without footprints (LoD 1.2 + 1.3 + 2.2, ``--workers 2``: forked
workers) traces each block first when the blocks are fewer than the workers'
runs; a block with at least ``lidar2city.tools.task.STAGED_LEAST`` outlines has
them regularised in pieces by all the workers, then assembled, instead of in its
first pass by one worker while the other waits (issue 13, session 16). Per area,
this tree's command as typed ("staged") and the same tree with every block
regularised in its first pass ("one pass": ``STAGED_LEAST`` set above any block's
outlines, the plan of before) are run in turn (A B A B ..., one warm-up each),
each a fresh process; ``--src OTHER_SRC`` adds a third run of another tree
(e.g. main's) in each round. Printed per run: wall and user + system CPU
seconds (os.wait4: the command and the workers it forked), the output's MD5;
then per area the medians of the staged / one-pass ratios and whether every
run wrote the same bytes. ``--least N`` runs "staged" with ``STAGED_LEAST = N``
(``1``: every block staged, however few its outlines).

Areas: ``tile``, the Delft tile (one block, 80 traced footprints); ``clip``, a
75 m x 75 m corner of it (a small traced input, about ten footprints: below
``STAGED_LEAST``, so both modes should run the same plan); ``copies``, 2 x 2
shifted copies of the tile (``bench_scale.make_area``: four LAZ files in one or
a few blocks, each a first pass of its own).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_speed import ROOT, data_dir  # noqa: E402
from bench_speed_pairs import run  # noqa: E402

CHILD = r'''
import sys
from lidar2city.tools import task
least = int(sys.argv[1])
if least > 0:
    task.STAGED_LEAST = least
from lidar2city.cli.main import main
sys.argv = ["lidar2city", *sys.argv[2:]]
main()
'''


def make_clip(tile: Path, folder: Path, size: float = 75.0) -> list:
    """The ``size`` x ``size`` m corner of ``tile`` at its minimum x, y (one LAZ)."""
    import laspy

    las = laspy.read(tile)
    x0, y0 = float(las.x.min()), float(las.y.min())
    keep = (las.x < x0 + size) & (las.y < y0 + size)
    out = laspy.LasData(las.header)
    out.points = las.points[keep]
    out.update_header()
    path = folder / "clip.laz"
    out.write(path)
    return [str(path)]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="?")
    ap.add_argument("--areas", default="tile,clip,copies")
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--workers", default="2")
    ap.add_argument("--least", type=int, default=0,
                    help="STAGED_LEAST of the staged runs (default the tree's)")
    ap.add_argument("--src", help="another tree's src folder, run third in each round")
    a = ap.parse_args()
    d = data_dir(a.data) / "delft"
    tile = d / "ahn3_cropped_1.laz"
    tmp = Path(tempfile.mkdtemp(prefix="bench_traced_outlines_"))
    (tmp / "child.py").write_text(CHILD)
    py = sys.executable
    envs = {}
    for name, src in (("staged", ROOT / "src"), ("one pass", ROOT / "src"),
                      *((("other", Path(a.src).resolve()),) if a.src else ())):
        env = dict(os.environ, PYTHONPATH=str(src))
        env.pop("PYTHONDONTWRITEBYTECODE", None)  # bytecode cached, as an install has it
        envs[name] = env
    least = {"staged": a.least, "one pass": 10**9, "other": 0}
    print(f"load average before: {' '.join(f'{v:.2f}' for v in os.getloadavg())} "
          f"({os.cpu_count()} cores)", flush=True)
    for area in a.areas.split(","):
        if area == "tile":
            tiles = [str(tile)]
        elif area == "clip":
            tiles = make_clip(tile, tmp)
        elif area == "copies":
            from bench_scale import make_area

            folder = tmp / "copies"
            folder.mkdir(exist_ok=True)
            tiles, _ = make_area(tile, d / "footprints_bgt.gpkg", 2, folder)
        else:
            raise SystemExit(f"unknown area {area!r}")
        got = {name: [] for name in envs}
        digests = set()
        for k in range(a.pairs + 1):  # the first round warms the caches, not counted
            for name, env in envs.items():
                out = tmp / f"{area}-{name.replace(' ', '_')}.city.json"
                cmd = [py, str(tmp / "child.py"), str(least[name]), "reconstruct", *tiles,
                       "--crs", "EPSG:7415", "--lod", "1.2", "--lod", "1.3", "--lod", "2.2",
                       "-q", "-o", str(out), "--workers", a.workers]
                wall, cpu = run(cmd, env)
                digest = hashlib.md5(out.read_bytes()).hexdigest()
                n = sum(o["type"] == "Building"
                        for o in json.loads(out.read_text())["CityObjects"].values())
                digests.add(digest)
                if k:
                    got[name].append((wall, cpu))
                print(f"{area} {'warm-up' if not k else f'round {k}'} {name}: {wall:.2f} s, "
                      f"{cpu:.2f} CPU s, {n} buildings, MD5 {digest}, load "
                      f"{os.getloadavg()[0]:.2f}", flush=True)
        for name, rows in got.items():
            print(f"{area} {name}: median {statistics.median(w for w, _ in rows):.2f} s, "
                  f"{statistics.median(c for _, c in rows):.2f} CPU s")
        for other in [n for n in got if n != "staged"]:
            w = [s[0] / o[0] for s, o in zip(got["staged"], got[other], strict=True)]
            c = [s[1] / o[1] for s, o in zip(got["staged"], got[other], strict=True)]
            print(f"{area} staged / {other}: wall median {statistics.median(w):.3f} "
                  f"({', '.join(f'{v:.3f}' for v in w)}), CPU median {statistics.median(c):.3f} "
                  f"({', '.join(f'{v:.3f}' for v in c)})")
        same = len(digests) == 1
        print(f"{area}: {'the same bytes in every run' if same else 'DIFFERENT BYTES: '}"
              f"{'' if same else ', '.join(sorted(digests))}", flush=True)
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
