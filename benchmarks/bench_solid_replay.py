"""CPU of the LoD2.2 partition-to-solid stage (``_finish_solid``: refinement, short edges,
fixes, the solid and its repairs; and ``check_solid`` as LoD2.2 calls it), replayed on the
Delft tile's recorded calls: this tree against other trees (issue 13).

Usage: python benchmarks/bench_solid_replay.py [OTHER_SRC ...] [--data DIR] [--traced]
[--repeat N] [--rounds R] [--cache FILE]
(OTHER_SRC: the ``src`` folder of another checkout, e.g. /work/wt/base/src; DIR default
$LIDAR2CITY_DATA or ../shared/data)

First runs ``reconstruct`` of the Delft tile (LoD 1.2 + 1.3 + 2.2, with the 132 BGT
footprints, or ``--traced`` without them) once in a child process with this tree and
records the arguments of every call of ``roof.building._finish_solid`` and of
``check_solid`` made from ``roof.building`` (the written solid of each building, the
restored-facet and fixed solids; kept in ``--cache``, made again when missing). Then, in
a fresh process of each tree in turn (A B A B ..., ``--rounds`` times), replays each
stage's calls in their order ``--repeat`` times and takes the least CPU
(``time.process_time``) of one pass. The parts below are timed by wrappers on their
module attributes in the same passes (inclusive times; a part missing from a tree is
left out; the wrappers cost ~1 us a call alike in every tree). Prints per tree and stage
the least CPU, the parts' CPU of that pass, this tree's CPU over each other tree's, and a
digest of the stage's answers (solids' vertices and rings, faces' WKB, labels, planes,
issues): the same digest, the same answers to the bit.

Caches of earlier calls (``check_solid``'s verdicts of the last 8 solids, ``solid_mesh``'s
last 4 meshes) hold across the calls of a pass as in a run; the calls are unpickled anew
for every pass, so no solid object is met twice. Only CPU seconds compare on a shared
machine.
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

ROOT = Path(__file__).resolve().parents[1]
STAGES = ("_finish_solid", "check_solid")
#: module (under lidar2city) : function, timed inclusive of what it calls
PARTS = (
    "roof.refine:refine_partition", "roof.refine:edge_types", "roof.arrangement:collapse_short_edges",
    "roof.building:_variant_solid", "roof.building:_clean_faces", "roof.building:_fix_low_faces",
    "roof.building:_fix_high_faces", "roof.building:_manifold_solid", "roof.solid:partition_edges",
    "roof.solid:partition_solid", "lod.mesh:solid_mesh", "validate.solid:_self_intersections",
    "validate.solid:_simple_faces_checks", "validate.solid:_edge_checks",
)


def capture(data: Path, out: Path, traced: bool):
    """Record the stages' calls of one Delft reconstruct (child process)."""
    import lidar2city.roof.building as building
    from lidar2city.cli.main import cli

    calls = {name: [] for name in STAGES}

    def recorder(name, f):
        def g(*a, **k):
            calls[name].append(pickle.dumps((a, k)))  # before the call: it may change them
            return f(*a, **k)
        return g

    for name in STAGES:
        setattr(building, name, recorder(name, getattr(building, name)))
    d = data / "delft"
    given = [] if traced else ["--footprints", str(d / "footprints_bgt.gpkg")]
    with tempfile.TemporaryDirectory() as tmp:
        cli.main(["reconstruct", str(d / "ahn3_cropped_1.laz"), *given, "--lod", "1.2", "--lod",
                  "1.3", "--lod", "2.2", "--workers", "1", "-o", str(Path(tmp) / "out.city.json")],
                 standalone_mode=False)
    with open(out, "wb") as f:
        pickle.dump(calls, f)


def _digest(out, h):
    import numpy as np
    import shapely

    if isinstance(out, np.ndarray):
        h.update(str(out.dtype).encode())
        h.update(np.ascontiguousarray(out).tobytes())
    elif isinstance(out, shapely.Geometry):
        h.update(shapely.to_wkb(out))
    elif hasattr(out, "vertices") and hasattr(out, "surfaces"):  # a Solid
        _digest(np.asarray(out.vertices), h)
        for s in out.surfaces:
            _digest([np.asarray(r) for r in getattr(s, "rings", s)], h)
            h.update(repr(getattr(s, "semantic", None)).encode())
    elif isinstance(out, (list, tuple)):
        h.update(b"(%d" % len(out))
        for o in out:
            _digest(o, h)
    elif isinstance(out, dict):
        for k, v in out.items():
            h.update(repr(k).encode())
            _digest(v, h)
    else:
        h.update(repr(out).encode())


def timed(cache: Path, repeat: int, result: Path):
    """Least CPU per stage and its parts' CPU in that pass, and the answers' digests (child)."""
    import collections
    import hashlib
    import importlib
    import time

    import scipy.ndimage  # noqa: F401 - the pipeline's imports, not timed
    import scipy.spatial  # noqa: F401
    import shapely  # noqa: F401

    import lidar2city.roof.building as building

    acc: collections.Counter = collections.Counter()
    mods = [importlib.import_module(f"lidar2city.{m}") for m in
            ("roof.building", "roof.refine", "roof.arrangement", "roof.solid", "lod.mesh",
             "validate.solid")]
    stage_fns = {name: getattr(building, name) for name in STAGES}
    for item in PARTS:
        mname, fname = item.split(":")
        try:
            mod = importlib.import_module(f"lidar2city.{mname}")
        except ImportError:
            continue
        f = getattr(mod, fname, None)
        if f is None:
            continue

        def wrap(f=f, key=fname):
            def g(*a, **k):
                t = time.process_time()
                try:
                    return f(*a, **k)
                finally:
                    acc[key] += time.process_time() - t
            return g

        g = wrap()
        for m in mods:  # every module that calls it by this name
            if getattr(m, fname, None) is f:
                setattr(m, fname, g)
    with open(cache, "rb") as fh:
        raw = pickle.load(fh)
    out = {}
    for name in STAGES:
        f = stage_fns[name]
        best, parts, digest = float("inf"), {}, None
        for _ in range(repeat):
            calls = [pickle.loads(c) for c in raw[name]]
            acc.clear()
            t = time.process_time()
            res = [f(*a, **k) for a, k in calls]
            cpu = time.process_time() - t
            if cpu < best:
                best, parts = cpu, dict(acc)
            if digest is None:
                h = hashlib.md5()
                _digest(res, h)
                digest = h.hexdigest()
        out[name] = (best, parts, digest, len(raw[name]))
    with open(result, "wb") as fh:
        pickle.dump(out, fh)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("others", nargs="*", help="src folders of other trees to compare with")
    ap.add_argument("--data")
    ap.add_argument("--traced", action="store_true", help="the run without footprints")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--cache")
    ap.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        mode, a, b = args.child
        if mode == "capture":
            capture(Path(a), Path(b), args.traced)
        else:
            timed(Path(a), args.repeat, Path(b))
        return
    data = Path(args.data or os.environ.get("LIDAR2CITY_DATA") or ROOT.parent / "shared" / "data")
    kind = "traced" if args.traced else "footprints"
    cache = Path(args.cache or Path(tempfile.gettempdir()) / f"solid_replay_{kind}.pkl")
    me = str(Path(__file__).resolve())
    trees = [str(ROOT / "src"), *[str(Path(o).resolve()) for o in args.others]]

    def child(src, *argv):
        env = dict(os.environ, PYTHONPATH=src)
        subprocess.run([sys.executable, me, *(["--traced"] if args.traced else []),
                        "--repeat", str(args.repeat), "--child", *argv], env=env, check=True,
                       stdout=subprocess.DEVNULL)

    if not cache.exists():
        child(trees[0], "capture", str(data), str(cache))
    best: dict = {}
    loads = [os.getloadavg()[0]]
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.rounds):
            for i, src in enumerate(trees):
                res = Path(tmp) / f"{i}_{r}.pkl"
                child(src, "timed", str(cache), str(res))
                loads.append(os.getloadavg()[0])
                with open(res, "rb") as fh:
                    got = pickle.load(fh)
                for name, (cpu, parts, digest, n) in got.items():
                    old = best.get((i, name))
                    if old is None or cpu < old[0]:
                        best[(i, name)] = (cpu, parts, digest, n)
    print(f"Delft, {kind}: partition to solid replayed, least CPU s of {args.repeat} passes x "
          f"{args.rounds} rounds per tree; load {min(loads):.1f}-{max(loads):.1f}")
    for i, src in enumerate(trees):
        total = sum(best[(i, s)][0] for s in STAGES)
        print(f"[{i}] {src}: stages {total:.3f} CPU s"
              + ("" if i == 0 else f"; [0] / [{i}] = {sum(best[(0, s)][0] for s in STAGES) / total:.3f}"))
        for s in STAGES:
            cpu, parts, digest, n = best[(i, s)]
            ratio = "" if i == 0 else f" ([0] / [{i}] = {best[(0, s)][0] / cpu:.3f})"
            print(f"  {s}: {n} calls {cpu:.3f}{ratio}  digest {digest[:12]}")
            for p, t in sorted(parts.items(), key=lambda kv: -kv[1]):
                print(f"      {p:24s} {t:.3f}")
    same = all(best[(i, s)][2] == best[(0, s)][2] for i in range(len(trees)) for s in STAGES)
    print("same outputs in every tree:", same)
    if len(trees) > 1:
        print("stage CPU of [0] over the others' (median over trees):",
              {s: round(statistics.median(best[(0, s)][0] / best[(i, s)][0]
                                          for i in range(1, len(trees))), 3) for s in STAGES})


if __name__ == "__main__":
    main()
