"""CPU of LoD1.3's height regions (``lod.lod13._height_labels``) and of its parts, replayed
on the Delft tile's recorded calls: this tree against other trees (issue 13).

Usage: python benchmarks/bench_lod13_kernels.py [OTHER_SRC ...] [--data DIR] [--repeat N]
[--rounds R] [--cache FILE]
(OTHER_SRC: the ``src`` folder of another checkout, e.g. /work/wt/base/src; DIR default
$LIDAR2CITY_DATA or ../shared/data)

First builds LoD1.2 + 1.3 for the Delft tile's 132 BGT footprints once in a child process
with this tree (:func:`lidar2city.tools.reconstruct.reconstruct_buildings`) and records the
arguments of every ``_height_labels`` call (kept in ``--cache``, made again when missing).
Then, in a fresh process of each tree in turn (A B A B ..., ``--rounds`` times), replays
them ``--repeat`` times and takes the least CPU (``time.process_time``) of one pass; in the
same passes the parts below are timed by wrappers put on the module's attributes
(inclusive; a part missing from a tree is left out). Prints per tree the least pass and its
parts, this tree's CPU over each other tree's (whole replay and per part), and a digest of
the label rasters per tree (the same digest: the same regions to the bit).

Wall-clock timers are not used: on a shared machine only CPU seconds compare.
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from replay_common import (  # noqa: E402
    data_dir, least_pass, recording, replay_parser, time_parts)

ROOT = Path(__file__).resolve().parents[1]
#: parts of ``_height_labels`` timed inclusive (names in ``lidar2city.lod.lod13``)
PARTS = ("_touched_cells", "_cell_medians", "_merge_by_height", "_merge_small",
         "_neighbour_pairs")


def capture(data: Path, out: Path):
    """Record the ``_height_labels`` calls of LoD1.2 + 1.3 on Delft (child process)."""
    import lidar2city.lod.lod13 as lod13
    from lidar2city.io.las import read_points
    from lidar2city.lod.lod1 import Lod1Config
    from lidar2city.tools.reconstruct import load_footprints, reconstruct_buildings

    d = data / "delft"
    cloud = read_points(str(d / "ahn3_cropped_1.laz"), crs="EPSG:28992")
    fps = load_footprints(str(d / "footprints_bgt.gpkg"), cloud)
    calls = recording(lod13, ["_height_labels"])["_height_labels"]
    reconstruct_buildings(cloud, fps, config=Lod1Config(lods=("1.2", "1.3")))
    with open(out, "wb") as fh:
        pickle.dump(calls, fh)


def _label_digest(res, h):
    import numpy as np

    for labels, x0, y_top in res:
        h.update(np.ascontiguousarray(labels, dtype=np.int64).tobytes())
        h.update(repr((float(x0), float(y_top))).encode())


def timed(cache: Path, repeat: int, result: Path):
    """Least CPU of a replay and its parts' CPU in that pass, and the labels' digest (child)."""
    import collections

    import scipy.ndimage  # noqa: F401 - the pipeline's imports, not timed
    import shapely  # noqa: F401

    import lidar2city.lod.lod13 as lod13

    acc: collections.Counter = collections.Counter()
    time_parts([f"lod.lod13:{name}" for name in PARTS], ("lod.lod13",), acc)
    with open(cache, "rb") as fh:
        raw = pickle.load(fh)
    best, parts, digest = least_pass(lod13._height_labels, raw, repeat, acc, _label_digest)
    with open(result, "wb") as fh:
        pickle.dump((best, parts, digest, len(raw)), fh)


def _child(src, *args):
    env = dict(os.environ, PYTHONPATH=str(src), OMP_NUM_THREADS="1")
    subprocess.run([sys.executable, __file__, "--child", *map(str, args)], env=env, check=True)


def main():
    ap = replay_parser(__doc__, traced=False)
    args = ap.parse_args()
    if args.child:
        kind, a, b = args.child
        if kind == "capture":
            capture(Path(a), Path(b))
        else:
            cache, repeat, result = a.split("|")
            timed(Path(cache), int(repeat), Path(result))
            del b
        return
    data = data_dir(args.data)
    trees = [ROOT / "src", *map(Path, args.others)]
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        cache = Path(args.cache) if args.cache else Path(tmp) / "calls.pkl"
        if not cache.exists():
            _child(trees[0], "capture", data, cache)
        runs: dict = {i: [] for i in range(len(trees))}
        for r in range(args.rounds):
            for i, src in enumerate(trees):
                out = Path(tmp) / f"r{r}t{i}.pkl"
                _child(src, "timed", f"{cache}|{args.repeat}|{out}", "-")
                with open(out, "rb") as fh:
                    runs[i].append(pickle.load(fh))
    load1 = os.getloadavg()[0]
    print(f"Delft, LoD1.3 height regions replayed, least CPU s of {args.repeat} passes x "
          f"{args.rounds} rounds per tree; load {load0:.1f} -> {load1:.1f}")
    least = {i: min(runs[i], key=lambda t: t[0]) for i in runs}
    for i, src in enumerate(trees):
        cpu, parts, digest, n = least[i]
        head = f"[{i}] {src}: _height_labels {n} calls {cpu:.3f}"
        if i:
            head += f" ([0] / [{i}] = {least[0][0] / cpu:.3f})"
        print(head + f"  digest {digest[:12]}")
        for name in PARTS:
            if name in parts:
                ratio = ""
                if i and name in least[0][1] and parts[name] > 0:
                    ratio = f"  ([0] / [{i}] = {least[0][1][name] / parts[name]:.3f})"
                print(f"      {name:<20} {parts[name]:.3f}{ratio}")
    print("same labels in every tree:", len({least[i][2] for i in least}) == 1)


if __name__ == "__main__":
    main()
