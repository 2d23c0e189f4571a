"""reconstruct on an area 4 and 16 times the Delft tile: does it keep its ratio to the laspy floor?

Usage: ``PYTHONPATH=src python benchmarks/bench_scale.py [DATA_DIR] [--sizes 1,2,4]
[--workers 1,2] [--format cityjson,cityjsonseq] [--keep DIR] [--other SRC] [--rounds N]``

The larger area is n x n copies of the shared Delft AHN3 tile laid side by side,
each shifted by a whole number of metres just over the tile's extent (192 m in
x, 229 m in y: the copies leave a gap of 0.3 / 0.5 m, about a point spacing,
and cross the 1 km block lines as real tiles do). Every copy is its own LAZ
file, written with laspy with the tile's point format, scales and offsets; its
integer coordinates are the tile's plus the shift / scale, so every point is
exactly the tile's point moved. The 132 BGT footprints are shifted likewise
into one GeoPackage with unique ids (``identificatiebagpnd`` + copy x 1e16,
``gml_id`` + ``-copy``). 1 x 1 is the tile itself with its own footprints.

Each size is run in a fresh process as a user runs it: ``lidar2city
reconstruct TILES... --footprints FP --lod 1.2 --lod 1.3 --lod 2.2 -o OUT``
(the default 1 km blocks), with ``--workers 1`` and ``--workers 2``, to a
CityJSON file (which holds every feature until it writes the one shared vertex
list) and to CityJSONSeq (streamed feature by feature). Before each run, the
floor: a fresh Python reading every tile of that size with ``laspy.read``.
Measured from outside (``/usr/bin/time``: CPU and peak RSS of the child and
the processes it waited for; wall with time.perf_counter). Printed per run: buildings, wall and
CPU seconds, ratio to the floor run just before it (wall and CPU), CPU ms per
building, peak RSS (the largest process: with 2 workers a Dask worker or the
client) and the machine's load average.

``--other SRC``: each run is made with another tree's source (e.g. main's
``src``) and then with this tree's, in turn, ``--rounds`` times; every run
prints its output's MD5 (the same bytes on 1 and 2 workers, and in both trees
when neither changed the output), and each pair its ratios this / other (wall,
CPU), with their medians over the rounds at the end. ``--keep DIR``: an area
already built there is reused.

Then the output is checked against the tile's own model: every building of
every copy, moved back by its shift, must have the same geometry (to the
output's 1 mm quantisation) and the same attributes (ids aside) as the 1 x 1
run's. Buildings that differ are listed with their copy (a building at a copy's
edge may see the neighbouring copy's points within its ground ring).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHIFT = (192.0, 229.0)  # metres, just over the tile's 191.7 m x 228.5 m
ID_STEP = 10**16
ID_FIELDS = ("identificatiebagpnd", "gml_id", "footprint_id")


def data_dir(arg):
    if arg:
        return Path(arg)
    return Path(os.environ.get("LIDAR2CITY_DATA", ROOT.parent / "shared" / "data"))


def run(cmd, env) -> tuple[float, float, float]:
    """``(wall s, peak RSS MB of the largest process, user + system CPU s)`` of a child
    and everything it waited for, as ``/usr/bin/time`` reports them (a child of this
    script would carry over this script's peak RSS, which holds parsed outputs)."""
    with tempfile.NamedTemporaryFile("r", suffix=".time") as rep:
        t0 = time.perf_counter()
        proc = subprocess.run(["/usr/bin/time", "-o", rep.name, "-f", "%U %S %M", *cmd],
                              env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        wall = time.perf_counter() - t0
        if proc.returncode != 0:
            raise SystemExit(f"{' '.join(map(str, cmd))} failed:\n"
                             f"{proc.stderr.decode(errors='replace')}")
        user, system, kb = rep.read().split()[-3:]
    return wall, float(kb) / 1024.0, float(user) + float(system)


def make_area(tile: Path, fp: Path, n: int, folder: Path, *, reuse: bool = False) -> tuple[list, Path]:
    """n x n shifted copies of ``tile`` (LAZ each) and of the footprints (one GPKG);
    ``reuse``: those already in ``folder`` (all of them) are taken as they are."""
    names = [folder / f"delft_{i}_{j}.laz" for i in range(n) for j in range(n)]
    if reuse and (folder / "footprints.gpkg").exists() and all(p.exists() for p in names):
        return [str(p) for p in names], folder / "footprints.gpkg"
    import laspy
    from pyogrio.raw import read, write

    las = laspy.read(tile)
    sx, sy = las.header.scales[:2]
    meta, _, wkb, values = read(fp)
    import shapely

    geoms = shapely.from_wkb(wkb)
    fields = list(meta["fields"])
    tiles, all_geoms, cols = [], [], {f: [] for f in fields}
    for i in range(n):
        for j in range(n):
            k = i * n + j
            dx, dy = i * SHIFT[0], j * SHIFT[1]
            path = folder / f"delft_{i}_{j}.laz"
            out = laspy.LasData(las.header.copy() if hasattr(las.header, "copy") else las.header)
            out.points = las.points.copy()
            out.X = las.X + int(round(dx / sx))
            out.Y = las.Y + int(round(dy / sy))
            out.update_header()
            out.write(path)
            tiles.append(str(path))
            all_geoms.append(shapely.transform(geoms, lambda c, d=(dx, dy): c + d))
            for f, v in zip(fields, values, strict=True):
                if f == "identificatiebagpnd":
                    v = v + k * ID_STEP
                elif f == "gml_id":
                    v = np.array([f"{s}-{k}" for s in v], dtype=object)
                cols[f].append(v)
    out_fp = folder / "footprints.gpkg"
    write(out_fp, shapely.to_wkb(np.concatenate(all_geoms)),
          [np.concatenate(cols[f]) for f in fields], fields, layer="buildings",
          crs=meta["crs"], geometry_type="Polygon", driver="GPKG")
    return tiles, out_fp


def _buildings(path: Path, fmt: str) -> dict:
    """``{building id: (attributes, [(lod, type, boundaries as mm integer xyz, semantics)])}``
    with each LoD1.3 part folded into its building."""
    if fmt == "cityjson":
        doc = json.loads(path.read_text())
        docs = [(doc["transform"], doc["vertices"], doc["CityObjects"])]
    else:
        lines = path.read_text().splitlines()
        head = json.loads(lines[0])
        docs = [(head["transform"], f["vertices"], f["CityObjects"])
                for f in map(json.loads, lines[1:])]
    out = {}
    for tr, verts, objs in docs:
        scale = np.asarray(tr["scale"])
        v = np.asarray(verts, dtype=np.int64)
        # to integer millimetres in world coordinates (scale 0.001, whole-metre translate)
        v = v * np.rint(scale / 0.001).astype(np.int64) + np.rint(
            np.asarray(tr["translate"]) / 0.001).astype(np.int64)
        for oid, o in objs.items():
            key = o.get("parents", [oid])[0]
            attrs, geoms = out.setdefault(key, ({}, []))
            if "parents" not in o:
                attrs.update({a: b for a, b in o.get("attributes", {}).items()
                              if a not in ID_FIELDS})
            for g in o.get("geometry", []):
                geoms.append((oid.replace(key, "", 1), g["lod"], g["type"],
                              _resolve(g["boundaries"], v), json.dumps(g.get("semantics"))))
    return out


def _resolve(b, v):
    if isinstance(b, int):
        return v[b]
    return [_resolve(x, v) for x in b]


def _moved(geoms, d):
    def mv(b):
        if isinstance(b, np.ndarray):
            return tuple((b - d).tolist())
        return [mv(x) for x in b]
    return [(s, lod, t, mv(b), sem) for s, lod, t, b, sem in geoms]


def _plain(geoms):
    return _moved(geoms, np.zeros(3, dtype=np.int64))


def compare(ref: dict, got: dict, n: int, bag_ids: dict) -> tuple[int, int, list]:
    """(identical buildings, buildings, [(copy, id, what differs)])."""
    same, diffs = 0, []
    ref_plain = {k: (a, _plain(g)) for k, (a, g) in ref.items()}
    for key, (attrs, geoms) in got.items():
        bag = bag_ids.get(key)
        if bag is None:
            diffs.append((None, key, "unknown id"))
            continue
        k, orig = divmod(bag, ID_STEP)
        i, j = divmod(k, n)
        d = np.array([round(i * SHIFT[0] * 1000), round(j * SHIFT[1] * 1000), 0])
        r = ref_plain.get(str(orig))
        if r is None:
            diffs.append(((i, j), str(orig), "not in the tile's model"))
            continue
        ga = _moved([(s.replace(key, "", 1), *rest) for s, *rest in geoms], d)
        what = []
        if ga != r[1]:
            what.append("geometry")
        ad = sorted(a for a in set(attrs) | set(r[0]) if attrs.get(a) != r[0].get(a))
        if ad:
            what.append("attributes " + ",".join(ad))
        if what:
            diffs.append(((i, j), str(orig), "; ".join(what)))
        else:
            same += 1
    return same, len(got), diffs


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="?")
    ap.add_argument("--sizes", default="1,2,4", help="n of the n x n copies")
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--format", default="cityjson,cityjsonseq",
                    help="output formats (cityjsonseq streams; cityjson holds every feature)")
    ap.add_argument("--no-check", action="store_true", help="skip the per-building comparison")
    ap.add_argument("--keep", help="build the tiles in this folder and keep them (reused when "
                                   "there)")
    ap.add_argument("--other", help="another tree's src folder: each run made with it, then "
                                    "with this tree's, in turn")
    ap.add_argument("--rounds", type=int, default=1, help="rounds of every run (pairs with "
                                                          "--other)")
    args = ap.parse_args()
    d = data_dir(args.data) / "delft"
    tile, fp = d / "ahn3_cropped_1.laz", d / "footprints_bgt.gpkg"
    sizes = [int(s) for s in args.sizes.split(",")]
    workers = [int(w) for w in args.workers.split(",")]
    fmts = args.format.split(",")
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # bytecode cached as in an installed package
    trees = [("this", env)]
    if args.other:
        trees = [("other", dict(env, PYTHONPATH=str(Path(args.other).resolve()))), *trees]
    ratios = {}
    py = sys.executable
    tmp = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="bench_scale_"))
    tmp.mkdir(parents=True, exist_ok=True)
    ext = {"cityjson": ".city.json", "cityjsonseq": ".city.jsonl"}
    ref = {}
    for n in sorted(set(sizes) | ({1} if not args.no_check else set())):
        if n == 1:
            tiles, fps = [str(tile)], fp
        else:
            folder = tmp / f"area{n}"
            folder.mkdir(exist_ok=True)
            tiles, fps = make_area(tile, fp, n, folder, reuse=bool(args.keep))
        bag_ids = {}
        if n > 1 and not args.no_check:
            from pyogrio.raw import read
            meta, _, _, vals = read(fps, columns=["identificatiebagpnd"], read_geometry=False)
            bag_ids = {str(v): int(v) for v in vals[0]}
        floor = [py, "-c", "import laspy, sys\nfor p in sys.argv[1:]: laspy.read(p)", *tiles]
        run(floor, env)  # warm the file cache and the bytecode
        for fmt in fmts:
            for w in workers:
                if n not in sizes and w != workers[0]:
                    continue
                for rnd in range(max(1, args.rounds)):
                    pair = {}
                    for tree, tenv in trees:
                        got = one_run(args, py, tmp, ext, fmt, n, w, tiles, fps, floor, tenv,
                                      tree if len(trees) > 1 else "")
                        pair[tree] = got[:2]
                        if tree == "this" and rnd == 0:
                            check(args, ref, fmt, n, got[2], bag_ids)
                    if len(trees) > 1:
                        rw = pair["this"][0] / pair["other"][0]
                        rc = pair["this"][1] / pair["other"][1]
                        ratios.setdefault((n, fmt, w), []).append((rw, rc))
                        print(f"    pair {rnd + 1}: this / other wall {rw:.3f}, CPU {rc:.3f}",
                              flush=True)
    for (n, fmt, w), rs in ratios.items():
        import statistics

        print(f"{n}x{n} {fmt} workers {w}: this / other over {len(rs)} pair(s): wall median "
              f"{statistics.median(r[0] for r in rs):.3f} "
              f"({', '.join(f'{r[0]:.3f}' for r in rs)}), CPU median "
              f"{statistics.median(r[1] for r in rs):.3f} ({', '.join(f'{r[1]:.3f}' for r in rs)})")


def one_run(args, py, tmp, ext, fmt, n, w, tiles, fps, floor, env, label) -> tuple:
    """One run of the command after its floor: ``(wall s, CPU s, parsed buildings)``."""
    import hashlib

    out = tmp / f"out{n}_{w}{label}{ext[fmt]}"
    out.unlink(missing_ok=True)  # and an interrupted earlier run's journal
    shutil.rmtree(out.with_name(out.name + ".journal"), ignore_errors=True)
    cmd = [py, "-m", "lidar2city.cli.main", "reconstruct", *tiles, "--crs",
           "EPSG:7415", "--footprints", str(fps), "--lod", "1.2", "--lod", "1.3",
           "--lod", "2.2", "--workers", str(w), "-q", "-o", str(out)]
    f_t, f_m, f_c = run(floor, env)
    t, m, c = run(cmd, env)
    got = _buildings(out, fmt) if not args.no_check else {}
    md5 = hashlib.md5(out.read_bytes()).hexdigest()
    nb = 132 * n * n
    load = os.getloadavg()[0]
    print(f"{n}x{n} ({len(tiles)} tiles, {nb} footprints) {fmt:11s} workers {w}"
          f"{' ' + label if label else ''}: "
          f"{t:6.1f} s, {c:6.1f} CPU s; floor {f_t:.2f} s, {f_c:.2f} CPU s, "
          f"{f_m:.0f} MB; time / floor {t / f_t:4.1f}x, CPU / floor CPU "
          f"{c / f_c:4.1f}x; {1000 * c / nb:.1f} CPU ms per building; "
          f"peak RSS {m:.0f} MB; load {load:.1f}; MD5 {md5}", flush=True)
    return t, c, got


def check(args, ref, fmt, n, got, bag_ids) -> None:
    """The per-building comparison of an n x n output with the tile's own model."""
    if args.no_check:
        return
    if n == 1:
        ref.setdefault(fmt, got)
        return
    nb = 132 * n * n
    same, total, diffs = compare(ref[fmt], got, n, bag_ids)
    print(f"    {same}/{total} buildings the tile's model moved by their copy's "
          f"shift ({nb} footprints)" + (":" if diffs else ""), flush=True)
    if diffs:
        per = Counter(str(cp) for cp, _, _ in diffs)
        geo = sum("geometry" in w for _, _, w in diffs)
        print(f"      by copy {dict(sorted(per.items()))}; {geo} in their geometry")
    for cp, bid, what in diffs[:3]:
        print(f"      copy {cp} {bid}: {what}")


if __name__ == "__main__":
    main()
