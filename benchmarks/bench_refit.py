"""Refit time of single buildings in an edit session (what the viewer and ``edit`` wait for).

Run::

    lidar2city reconstruct $LIDAR2CITY_DATA/delft/ahn3_cropped_1.laz --lod 1.2 --lod 1.3 --lod 2.2 \\
        --crs EPSG:7415 -o /tmp/t.city.json
    PYTHONPATH=src python benchmarks/bench_refit.py --model /tmp/t.city.json [--building b4 --building b1]

Opens the model once (as the viewer does), makes one warm-up refit, then
times each building's automatic primitive, gable primitive and outline
re-run (its own footprint) ``--repeat`` times and prints the median wall
and CPU seconds (CPU: this process, all threads) of each, and the time to
build the updated document of a refit (``replace_building``). With
``--copies N`` the model is also enlarged N times (its objects copied side
by side) and the updated document of the first building's automatic refit
timed on it (a large area's accept). Nothing is written.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path


def _timed(fn):
    from lidar2city.errors import FitError

    w, c = time.perf_counter(), time.process_time()
    try:
        out = fn()
    except FitError as exc:  # a refused refit (a gable on a flat roof) is timed too
        out = exc
    return out, time.perf_counter() - w, time.process_time() - c


def main() -> None:
    from lidar2city.tools.edit import EditSession

    data = Path(os.environ.get("LIDAR2CITY_DATA", "data"))
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", required=True, help="a Delft model written by lidar2city reconstruct")
    ap.add_argument("--points", default=str(data / "delft" / "ahn3_cropped_1.laz"))
    ap.add_argument("--building", action="append", default=None, help="building id (repeatable; default b4, b1)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--copies", type=int, default=0, help="also time the updated document on an N-times model")
    args = ap.parse_args()
    session = EditSession(args.model, [args.points])
    buildings = args.building or ["b4", "b1"]
    session.refit(session.make_edit(buildings[0], primitive="box"))  # warm-up: imports, first tile read
    for bid in buildings:
        kinds = {"auto": {"primitive": "auto"}, "gable": {"primitive": "gable"},
                 "outline": {"footprint": session.footprint(bid)}}
        for name, kw in kinds.items():
            edit = session.make_edit(bid, **kw)
            walls, cpus = [], []
            for _ in range(args.repeat):
                result, w, c = _timed(lambda edit=edit: session.refit(edit))
                walls.append(w)
                cpus.append(c)
            line = (f"refit {bid} {name}: median wall {statistics.median(walls):.2f} s, "
                    f"CPU {statistics.median(cpus):.2f} s (of {args.repeat})")
            if isinstance(result, Exception):
                line += f" [refused: {str(result).split(': ')[-1]}]"
            elif name == "auto":
                _, w, c = _timed(lambda result=result: session.updated_document(result))
                line += f"; updated document {w:.2f} s wall, {c:.2f} s CPU"
            print(line, flush=True)
    if args.copies > 1:
        result = session.refit(session.make_edit(buildings[0], primitive="auto"))
        session.doc = _enlarged(session.doc, args.copies)
        n = sum(o.get("type") == "Building" for o in session.doc["CityObjects"].values())
        times = [_timed(lambda: session.updated_document(result))[1:] for _ in range(args.repeat)]
        print(f"updated document, model x{args.copies} ({n} buildings, {len(session.doc['vertices'])} vertices): "
              f"median wall {statistics.median(t[0] for t in times):.2f} s, "
              f"CPU {statistics.median(t[1] for t in times):.2f} s (of {args.repeat})", flush=True)


def _enlarged(doc: dict, copies: int) -> dict:
    """``doc`` with its objects copied ``copies`` times side by side (the originals kept as
    copy 0, their ids unchanged; copy k's ids suffixed ``_k``)."""
    import json

    import numpy as np

    verts = np.asarray(doc["vertices"], dtype=np.int64)
    span = int(verts[:, 0].max() - verts[:, 0].min()) + 1
    objects, allv = {}, []
    for k in range(copies):
        allv.append(verts + [k * span, 0, 0])
        text = json.dumps(doc["CityObjects"])
        for oid, obj in json.loads(text).items():
            sfx = f"_{k}" if k else ""
            for rel in ("children", "parents"):
                if rel in obj:
                    obj[rel] = [c + sfx for c in obj[rel]]
            for g in obj.get("geometry", []):
                g["boundaries"] = _shift(g["boundaries"], k * len(verts))
            objects[oid + sfx] = obj
    return dict(doc, CityObjects=objects, vertices=np.vstack(allv).tolist())


def _shift(b, offset):
    return [_shift(x, offset) for x in b] if isinstance(b, list) else b + offset


if __name__ == "__main__":
    main()
