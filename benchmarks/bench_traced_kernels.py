"""CPU of kernels of the no-footprints reconstruct on the Delft tile (issue 13), replayed:
the LoD1.2 / 1.3 RMSE's point-to-prism distances, the arrangement's cell labels, and
(``--all``) the LoD2.2 plane segmentation, boundary lines, edge refinement, short-edge
collapse and the LoD1.3 height parts, the chain ends lengthened to their first hit
(``extend_to_hits``), and the traced outlines' direction search (``dominant_direction``,
called by the footprint snake).

Usage: python benchmarks/bench_traced_kernels.py [DATA_DIR] [--repeat N] [--src SRC] [--all]
[--footprints] [--only NAME,...]
(default data $LIDAR2CITY_DATA or ../shared/data, N = 5; SRC the ``src`` folder whose
lidar2city is measured, default this checkout's: pass another checkout's to compare;
``--footprints``: the run with the tile's BGT footprints instead of traced ones;
``--only``: just the named kernels, e.g. ``segment_planes,roof_lines,arrangement_partition``)

Runs ``reconstruct`` of the Delft tile without footprints (LoD 1.2 + 1.3 + 2.2) once in
this process, records the arguments of every call of
:func:`lidar2city.lod.prism.prism_distance` (``_layout_distance``, ``_layout_inside_distance``:
the prisms' layouts as built) and of
``lidar2city.roof.arrangement._cell_labels``, then calls each again N times on them and
prints the least CPU (``time.process_time``) of one pass over all the calls: the
kernels' cost per Delft run, little affected by other processes on the machine. It
also prints whether the replays gave what the run gave, and the MD5 of the output
(the bytes must not change when only the kernels' speed does).
"""

from __future__ import annotations

import argparse
import hashlib
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="?")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--src", default=str(ROOT / "src"))
    ap.add_argument("--all", action="store_true", help="also the LoD2.2 and LoD1.3 kernels")
    ap.add_argument("--footprints", action="store_true", help="the run with the BGT footprints")
    ap.add_argument("--only", default="", help="comma-separated kernel names (implies --all)")
    args = ap.parse_args()
    sys.path.insert(0, args.src)
    data = Path(args.data or os.environ.get("LIDAR2CITY_DATA") or ROOT.parent / "shared" / "data")
    laz = data / "delft" / "ahn3_cropped_1.laz"

    import numpy as np
    import shapely

    import lidar2city.lod.lod1 as lod1
    import lidar2city.roof.arrangement as arr
    import lidar2city.regularize.snake as rsnake
    import lidar2city.roof.building as bld
    from lidar2city.cli.main import cli

    # name -> the module whose attribute the run calls it by
    # (LoD1 measures its prisms' distances from the layouts they were built with)
    where = {"_layout_distance": lod1, "_layout_inside_distance": lod1, "_cell_labels": arr}
    if args.all or args.only:
        where.update(segment_planes=bld, roof_lines=bld, arrangement_partition=bld,
                     refine_partition=bld, collapse_short_edges=bld, height_parts=lod1,
                     extend_to_hits=arr, dominant_direction=rsnake)
    if args.only:
        where = {name: where[name] for name in args.only.split(",")}
    calls = {name: [] for name in where}
    kernels = {name: getattr(mod, name) for name, mod in where.items()}

    def recorder(name):
        f = kernels[name]

        def g(*a, **k):
            # the cells as well-known binary: each replay gets them fresh (a kernel may
            # prepare them, which a later pass must not inherit)
            rec = (shapely.to_wkb(np.asarray(a[0], dtype=object)), *a[1:]) if name == "_cell_labels" else a
            out = f(*a, **k)
            # a copy: the caller may change the arrays it was given (the cell labels are)
            calls[name].append((rec, k, _frozen(out)))
            return out
        return g

    for name, mod in where.items():
        setattr(mod, name, recorder(name))
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "traced.city.json"
        try:
            fp = ["--footprints", str(data / "delft" / "footprints_bgt.gpkg")] if args.footprints else []
            cli.main(["reconstruct", str(laz), *fp, "--lod", "1.2", "--lod", "1.3", "--lod", "2.2",
                      "-o", str(out)], standalone_mode=False)
        finally:
            for name, mod in where.items():
                setattr(mod, name, kernels[name])
        md5 = hashlib.md5(out.read_bytes()).hexdigest()

    kind = "BGT footprints" if args.footprints else "traced footprints"
    print(f"lidar2city from {args.src}; Delft reconstruct LoD 1.2+1.3+2.2, {kind}")
    total = 0.0
    for name, f in kernels.items():
        best, identical = float("inf"), True
        for _ in range(args.repeat):
            todo = [((list(shapely.from_wkb(a[0])), *a[1:]) if name == "_cell_labels" else a, k)
                    for a, k, _ in calls[name]]
            t = time.process_time()
            outs = [f(*a, **k) for a, k in todo]
            best = min(best, time.process_time() - t)
            identical &= all(_same(_frozen(o), r)
                             for o, (_, _, r) in zip(outs, calls[name], strict=True))
        total += best
        print(f"{name}: {len(calls[name])} calls, least of {args.repeat} replays {best:.3f} CPU s; "
              f"replays identical to the run: {identical}")
    print(f"all kernels above: {total:.3f} CPU s")
    print(f"output MD5 {md5}")


def _frozen(out):
    """A kernel's answer as compared between runs: arrays copied (the caller may change
    them), geometries as well-known binary, containers item by item."""
    import numpy as np
    import shapely

    if isinstance(out, np.ndarray):
        return np.copy(out)
    if isinstance(out, shapely.Geometry):
        return ("wkb", shapely.to_wkb(out))
    if isinstance(out, (list, tuple)):
        return tuple(_frozen(o) for o in out)
    if isinstance(out, dict):
        return tuple((k, _frozen(v)) for k, v in out.items())
    return out


def _same(a, b) -> bool:
    import numpy as np

    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and np.array_equal(a, b)
    if isinstance(a, tuple):
        return isinstance(b, tuple) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return a == b or (a != a and b != b)  # NaN equals NaN here


if __name__ == "__main__":
    main()
