"""CPU of the roof plane segmentation (``roof.facets.segment_planes``) alone, this tree against another.

Usage: python benchmarks/bench_facets.py [OTHER_SRC] [DATA_DIR] [--runs N] [--cache FILE]
(OTHER_SRC: the ``src`` folder of another checkout, e.g. /work/wt/base/src; DATA_DIR
default $LIDAR2CITY_DATA or ../shared/data)

First collects the inputs of every ``segment_planes`` call that LoD2.2 makes on the
Delft tile, with the 132 BGT footprints and without them (traced), and on the City3D
building instances of the tests, by running those reconstructions once in a child
process with this tree and recording the calls' point arrays and options (kept in
``--cache``, default a file in the temporary folder, made again when missing).
Then times ``segment_planes`` over all those inputs in a fresh process of each tree
in turn (A B A B ..., CPU seconds by ``time.process_time``, the first pass a
warm-up), and prints per input set (delft, traced, city3d) each tree's CPU, the
median A/B ratio, and how many calls gave the same facets in both trees (labels
equal and planes within 1e-9) with the share of points whose facet differs
(after matching the facets of the two trees by their largest overlap).
"""

from __future__ import annotations

import argparse
import os
import pickle
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SETS = ("delft", "traced", "city3d")
CITY3D = ["0", "1", "5", "12", "23", "37", "48", "59"]


def capture(data: Path, out: Path):
    """Record the inputs of every segment_planes call of the three input sets (child process)."""
    import lidar2city.roof.building as building
    from lidar2city.cli.main import cli

    calls: dict[str, list] = {s: [] for s in SETS}
    current = ["delft"]
    real = building.segment_planes

    def recording(pts, **kw):
        calls[current[0]].append((np.array(pts, dtype=np.float64), dict(kw)))
        return real(pts, **kw)

    building.segment_planes = recording
    d = data / "delft"
    tmp = Path(tempfile.mkdtemp())
    for name, given in (("delft", ["--footprints", str(d / "footprints_bgt.gpkg")]), ("traced", [])):
        current[0] = name
        cli.main(["reconstruct", str(d / "ahn3_cropped_1.laz"), *given, "--lod", "2.2",
                  "-o", str(tmp / f"{name}.city.json")], standalone_mode=False)
    current[0] = "city3d"
    import shapely

    from lidar2city.footprints import extract_footprints
    from lidar2city.io.ply import read_ply
    for name in CITY3D:
        pc = read_ply(data / "city3d" / "building_instances" / f"{name}.ply")
        fps = extract_footprints(pc.xyz, np.full(len(pc), 6), regularize="snake")
        fp = shapely.union_all([f.polygon for f in fps])
        try:
            building.reconstruct_lod22(fp, pc.xyz, float(pc.xyz[:, 2].min()))
        except Exception:  # noqa: BLE001 - only the recorded inputs matter here
            pass
    with open(out, "wb") as f:
        pickle.dump(calls, f)


def timed(cache: Path, result: Path):
    """CPU seconds of segment_planes over every recorded input, and the outputs (child process)."""
    import time

    import scipy.spatial  # noqa: F401 - imported by the pipeline anyway: its import is not timed

    from lidar2city.roof.facets import segment_planes
    with open(cache, "rb") as f:
        calls = pickle.load(f)
    cpu, outs = {}, {}
    for s in SETS:
        t0 = time.process_time()
        outs[s] = [segment_planes(pts, **kw) for pts, kw in calls[s]]
        cpu[s] = time.process_time() - t0
    with open(result, "wb") as f:
        pickle.dump((cpu, outs), f)


def _child(src: Path, *args) -> None:
    env = dict(os.environ, PYTHONPATH=str(src))
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    subprocess.run([sys.executable, __file__, *map(str, args)], env=env, check=True)


def _differing(la, lb) -> int:
    """Points whose facet differs, the facets of b matched to those of a by largest overlap."""
    if len(la) != len(lb):
        return max(len(la), len(lb))
    ka, kb = int(la.max(initial=-1)) + 2, int(lb.max(initial=-1)) + 2
    joint = np.bincount((la + 1) * kb + (lb + 1), minlength=ka * kb).reshape(ka, kb)
    match = joint.argmax(axis=0)  # each facet of b (and -1) to the facet of a it overlaps most
    return int(np.sum(match[lb + 1] != la + 1))


def main():
    if len(sys.argv) > 1 and sys.argv[1] in ("--child-capture", "--child-time"):
        if sys.argv[1] == "--child-capture":
            capture(Path(sys.argv[2]), Path(sys.argv[3]))
        else:
            timed(Path(sys.argv[2]), Path(sys.argv[3]))
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("other", nargs="?", help="the src folder of the tree to compare with")
    ap.add_argument("data", nargs="?")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--cache", default=str(Path(tempfile.gettempdir()) / "lidar2city_facets_inputs.pkl"))
    args = ap.parse_args()
    data = Path(args.data or os.environ.get("LIDAR2CITY_DATA") or ROOT.parent / "shared" / "data")
    cache = Path(args.cache)
    if not cache.exists():
        _child(ROOT / "src", "--child-capture", data, cache)
    with open(cache, "rb") as f:
        calls = pickle.load(f)
    print("inputs: " + ", ".join(f"{s} {len(calls[s])} calls, {sum(len(p) for p, _ in calls[s])} points"
                                 for s in SETS))
    trees = {"A": ROOT / "src"}
    if args.other:
        trees["B"] = Path(args.other).resolve()
    tmp = Path(tempfile.mkdtemp())
    load0 = os.getloadavg()[0]
    cpu: dict = {t: [] for t in trees}
    outs = {}
    for r in range(max(1, args.runs) + 1):  # the first pass warms up (bytecode, file cache)
        for t, src in trees.items():
            res = tmp / f"{t}.pkl"
            _child(src, "--child-time", cache, res)
            with open(res, "rb") as f:
                c, o = pickle.load(f)
            if r:
                cpu[t].append(c)
            outs[t] = o
    print(f"load average {load0:.2f} -> {os.getloadavg()[0]:.2f}; {args.runs} runs each, CPU s (median)")
    for s in SETS + ("all",):
        def tot(c):
            return sum(c.values()) if s == "all" else c[s]
        line = f"{s:7s}" + "".join(f" {t} {statistics.median(tot(c) for c in cpu[t]):7.3f}" for t in trees)
        if "B" in trees:
            ratio = statistics.median(tot(a) / tot(b) for a, b in zip(cpu["A"], cpu["B"], strict=True))
            line += f"  A/B {ratio:.3f}"
            if s != "all":
                same = diff = total = 0
                for (la, pa), (lb, pb) in zip(outs["A"][s], outs["B"][s], strict=True):
                    if (len(la) == len(lb) and np.array_equal(la, lb) and pa.shape == pb.shape
                            and np.allclose(pa, pb, rtol=0, atol=1e-9)):
                        same += 1
                    diff += _differing(la, lb)
                    total += len(la)
                line += (f"  same facets {same}/{len(outs['A'][s])} calls,"
                         f" points on another facet {100 * diff / max(total, 1):.2f} %")
        print(line)


if __name__ == "__main__":
    main()
