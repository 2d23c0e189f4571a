"""Benchmark of the viewer and of editing on the shared Delft tile (issue 15 targets).

Prints:

- the server's start (model + all points read, scene and GUI sent on connection);
- page-ready, read from the page's own clock in headless chromium (SwiftShader
  software WebGL): from the navigation start to the first frame in which every
  building mesh and the points are drawn on a fully opaque canvas (a probe on
  viser's client state, see ``lidar2city.viewer.browser.time_page``); also the
  whole process from chromium's launch (what a user waits for, browser start-up
  included) and chromium's CPU seconds. The same for two bare viser pages holding
  one box, in interleaved runs: with the viewer's plain lights (the floor any
  viser page pays on this machine; the difference is our part) and with viser's
  defaults (its environment map keeps the canvas faint until prefiltered);
- edit time: one refit of a building (automatic primitive, a chosen gable, and
  a re-run from a moved outline) as the viewer does it, median and max over
  buildings after one warm-up;
- frame time: once drawn, the page's milliseconds per rendered frame while the
  camera turns for 3 s with the whole model in view, beside a bare viser page's;
- LoD switch: seconds to show each other LoD the first time (meshed then);
- reproduction: those edits accepted (the seconds of each accept: model checked and
  written, edit appended), then ``reconstruct --edits`` re-run; the largest vertex
  difference over the edited buildings and whether the two files are byte-identical.

The Delft model has LoD1.2, 1.3 and 2.2. With ``--big DIR`` instead: the 144-tile
synthetic area of ``bench_engine.py`` (2,160 buildings, 17.4 M points; made in DIR
once, ~4 min, then reused), viewed without and with its points: server start and
this process's peak memory, page drawn and frame time, LoD switch, the RMSE of one
building, edits and accepts.

Run: ``PYTHONPATH=src python benchmarks/bench_viewer.py [--model M.city.json] [--quick]``
(without ``--model`` the Delft model is reconstructed first, ~1 min), or
``... bench_viewer.py --big DIR``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import socket
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

DATA = Path(os.environ.get("LIDAR2CITY_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))
TILE = DATA / "delft" / "ahn3_cropped_1.laz"
FOOTPRINTS = DATA / "delft" / "footprints_bgt.gpkg"
LODS = ("1.2", "1.3", "2.2")


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _model(folder: Path, given):
    from lidar2city.tools.reconstruct import reconstruct

    path = folder / "delft.city.json"
    if given:
        shutil.copy(given, path)
    else:
        reconstruct([TILE], path, footprints=FOOTPRINTS, lods=LODS, crs="EPSG:7415")
    return path


def _bare_page(plain):
    """A viser server showing one box (with viser's default environment map, or with the
    viewer's plain lights)."""
    import viser

    from lidar2city.viewer.app import _plain_lighting

    bare = viser.ViserServer(host="127.0.0.1", port=_port(), verbose=False)
    if plain:
        _plain_lighting(bare.scene)
    bare.scene.add_box("/box", color=(200, 30, 30), dimensions=(40.0, 40.0, 40.0))
    bare.initial_camera.position = (120.0, 120.0, 120.0)
    bare.initial_camera.look_at = (0.0, 0.0, 0.0)
    return bare


def _median(runs, key):
    vals = [getattr(r, key) for r in runs]
    return None if any(v is None for v in vals) else statistics.median(vals)


def page_ready(viewer, screenshot=None, repeat=1):
    """Page-ready figures of the viewer and of two bare viser pages, interleaved runs."""
    from lidar2city.viewer.browser import find_chromium, time_page

    if find_chromium() is None:
        print("page-ready: chromium not installed, not measured")
        return
    pages = {"reloaded": None, "bare, viewer's lights": True, "bare, viser defaults": False}
    runs = {k: [] for k in pages}
    url = f"http://127.0.0.1:{viewer.port}"
    # the first load as `lidar2city view` serves it: its RMSE of every building is being
    # computed in the background meanwhile (and recolours the buildings when done)
    first = time_page(url, viewer.scene_prefixes(), timeout=90.0, width=1100, height=700)
    if viewer._rmse_thread is not None:
        viewer._rmse_thread.join()
    for _ in range(repeat):
        for label, plain in pages.items():
            server = None if plain is None else _bare_page(plain)
            try:
                page = url if server is None else f"http://127.0.0.1:{server.get_port()}"
                expect = viewer.scene_prefixes() if server is None else ["/box"]
                runs[label].append(time_page(page, expect, timeout=90.0, width=1100,
                                             height=700, settle=2.0 if screenshot else 0.0))
            finally:
                if server is not None:
                    server.stop()
    if screenshot:  # the README's picture, as a small palette PNG
        from io import BytesIO

        from PIL import Image

        Image.open(BytesIO(runs["reloaded"][0].png)).convert("RGB").quantize(
            256, dither=Image.Dither.NONE).save(screenshot, optimize=True)

    def f(v):
        return "not reached" if v is None else f"{v:.2f} s"

    print(f"page-ready (headless chromium, SwiftShader WebGL, 1100x700; page clock = from "
          f"the navigation start, performance.now()); median of {repeat} run(s) each, "
          f"interleaved, after a first load")
    n = viewer.points_handle.points.shape[0] if getattr(viewer, "points_handle", None) else 0
    delft = (f"Delft model ({len(viewer.attrs)} buildings in {len(viewer.scene_nodes()) - 1} "
             f"meshes) + {n} points")
    for label, rs in (("first load, RMSE computed meanwhile", [first]), *runs.items()):
        what = f"{label}, one box" if label.startswith("bare") else f"{delft}, {label}"
        print(f"page-ready [{what}]: drawn {f(_median(rs, 'page_complete'))} page clock "
              f"(client booted {f(_median(rs, 'page_booted'))}, scene nodes filled "
              f"{f(_median(rs, 'page_nodes'))}); whole process from chromium launch "
              f"{f(_median(rs, 'wall_from_launch'))} wall (browser start "
              f"{f(_median(rs, 'wall_browser_start'))}); chromium {_median(rs, 'chromium_cpu'):.1f}"
              f" CPU s; screenshot shows buildings: {all(r.drawn for r in rs)}")
    mine, bare = runs["reloaded"], runs["bare, viewer's lights"]
    ours, floor = _median(mine, "page_complete"), _median(bare, "page_complete")
    if ours is not None and floor is not None:
        print(f"page-ready: our part (the viewer minus the bare page with the same lights) "
              f"{ours - floor:.2f} s page clock (ratio {ours / floor:.2f}), "
              f"{_median(mine, 'chromium_cpu') - _median(bare, 'chromium_cpu'):.1f} chromium CPU s")


def frame_times(viewer, label, spin=3.0):
    """Page milliseconds per frame while the camera turns, the whole model in view: the
    viewer's page and a bare viser page (one box, the same lights) in the same run."""
    from lidar2city.viewer.browser import find_chromium, time_page

    if find_chromium() is None:
        print("frame time: chromium not installed, not measured")
        return
    url = f"http://127.0.0.1:{viewer.port}"
    ours = time_page(url, viewer.scene_prefixes(), timeout=120.0, width=1100, height=700,
                     spin=spin)
    bare = _bare_page(True)
    try:
        floor = time_page(f"http://127.0.0.1:{bare.get_port()}", ["/box"], timeout=90.0,
                          width=1100, height=700, spin=spin)
    finally:
        bare.stop()

    def ms(v):
        return "not measured" if v is None else f"{v:.0f} ms"

    drawn = "not reached" if ours.page_complete is None else f"{ours.page_complete:.2f} s"
    print(f"frame time [{label}]: drawn {drawn} page clock, then {ms(ours.frame_ms)} per frame "
          f"while the camera turns for {spin:.0f} s (bare page, one box: "
          f"{ms(floor.frame_ms)}); screenshot shows buildings: {ours.drawn}")


def lod_switch(viewer):
    """Seconds to show each other LoD the first time (meshed then), then back."""
    took = []
    for lod in [*viewer.lods[:-1], viewer.lods[-1]]:
        t0 = time.perf_counter()
        viewer.lod_choice.value = lod
        viewer._show_lod()
        took.append(f"{lod} {time.perf_counter() - t0:.3f} s")
    print(f"LoD switch (first time each, meshed then): {', '.join(took)}")


def big_area(folder: Path):
    """The 144-tile synthetic area of bench_engine.py (2,160 buildings, 17 M points) at
    LoD1.2 + 2.2, made in ``folder`` once (~4 min), viewed without and with its points."""
    import resource
    import sys

    from lidar2city.tools.reconstruct import reconstruct
    from lidar2city.viewer.app import Viewer

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_engine import make_area

    folder.mkdir(parents=True, exist_ok=True)
    made = folder / "area.city.json"
    if not made.exists():
        tiles, fp = make_area(folder, 12)
        reconstruct(tiles, made, footprints=fp, lods=("1.2", "2.2"), crs="EPSG:7415")
    tiles = sorted(str(p) for p in folder.glob("tile_*.laz"))
    model = folder / "view.city.json"
    shutil.copy(made, model)
    model.with_name("view.edits.json").unlink(missing_ok=True)
    for pts in ([], tiles):
        t0 = time.perf_counter()
        v = Viewer(model, points=pts, crs="EPSG:7415", port=_port())
        v.start(compute_rmse=False)
        what = (f"{len(v.attrs)} buildings, " +
                (f"{v._reader.count} points ({'read per building' if v._lazy else 'held'})"
                 if pts else "no points"))
        print(f"big area [{what}]: server start {time.perf_counter() - t0:.2f} s; peak memory "
              f"of this process {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")
        try:
            frame_times(v, f"big area, {what}")
            lod_switch(v)
            if pts:
                ids = [b for b, _ in v.worst_order()][:4]
                t0 = time.perf_counter()
                for b in ids:
                    v._rmse_of(b, v._world_solids(b, v.lods[-1]))
                print(f"big area: RMSE of one building (points read around it) "
                      f"{(time.perf_counter() - t0) / len(ids):.3f} s")
                edit_times(v, ids)
                reproduction_saves(v, ids[:2])
        finally:
            v.stop()
    print(f"big area: peak memory of this process "
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


def _print_saves(saves):
    if saves:
        print(f"accept (model validated and written, edit appended): median "
              f"{statistics.median(saves):.3f} s, max {max(saves):.3f} s wall over {len(saves)}")


def reproduction_saves(viewer, ids):
    saves = []
    for bid in ids:
        viewer.select(bid)
        if viewer.refit_primitive("auto") is not None:
            t0 = time.perf_counter()
            if viewer.accept() is not None:
                saves.append(time.perf_counter() - t0)
    _print_saves(saves)


def edit_times(viewer, ids):
    """Seconds of refits as the viewer runs them (each undone)."""
    out = {"auto primitive": [], "gable primitive": [], "outline re-run": []}
    cpu = {k: [] for k in out}

    def timed(key, i, action):
        c0 = time.process_time()
        t = action()
        if t is not None and i:  # the first building warms up
            out[key].append(t)
            cpu[key].append(time.process_time() - c0)
        viewer.undo()

    for i, bid in enumerate(ids):
        viewer.select(bid)
        timed("auto primitive", i, lambda: viewer.refit_primitive("auto"))
        timed("gable primitive", i, lambda: viewer.refit_primitive("gable"))
        viewer.start_outline()
        c = viewer.outline.mean(axis=0)
        d = viewer.outline[0] - c
        viewer.move_vertex(0, viewer.outline[0] + 0.4 * d / np.linalg.norm(d))
        timed("outline re-run", i, viewer.rebuild_from_outline)
    for key, ts in out.items():
        if ts:
            print(f"edit ({key}): median {statistics.median(ts):.3f} s, max {max(ts):.3f} s "
                  f"wall over {len(ts)} buildings ({sum(t < 1.0 for t in ts)} under 1 s); "
                  f"CPU median {statistics.median(cpu[key]):.3f} s, max {max(cpu[key]):.3f} s")
        else:
            print(f"edit ({key}): no building could be refitted")


def reproduction(viewer, folder, ids):
    from lidar2city.io.cityjson import read_cityjson
    from lidar2city.tools.reconstruct import reconstruct

    done, saves = [], []

    def accept():
        t0 = time.perf_counter()
        out = viewer.accept()
        saves.append(time.perf_counter() - t0)
        return out

    for bid in ids:
        viewer.select(bid)
        if viewer.refit_primitive("auto") is not None and accept() is not None:
            done.append(bid)
    if ids:
        viewer.select(ids[-1])
        viewer.start_outline()
        c = viewer.outline.mean(axis=0)
        d = viewer.outline[1] - c
        viewer.move_vertex(1, viewer.outline[1] + 0.5 * d / np.linalg.norm(d))
        if viewer.rebuild_from_outline() is not None and accept() is not None:
            done.append(ids[-1])
    _print_saves(saves)
    rerun = folder / "rerun.city.json"
    reconstruct([TILE], rerun, footprints=FOOTPRINTS, lods=LODS, crs="EPSG:7415",
                edits=viewer.edits_path)
    a, b = read_cityjson(viewer.path), read_cityjson(rerun)
    worst = 0.0
    for bid in set(done):
        for lod in LODS:
            va = np.concatenate([s.vertices for s in a.solids(bid, lod=lod)])
            vb = np.concatenate([s.vertices for s in b.solids(bid, lod=lod)])
            worst = max(worst, float(np.abs(va - vb).max()) if va.shape == vb.shape else np.inf)
    same = viewer.path.read_bytes() == rerun.read_bytes()
    print(f"reconstruct --edits: {len(done)} edits on {len(set(done))} buildings re-applied, "
          f"largest vertex difference {worst:.4f} m, files byte-identical: {same}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default=None, help="an existing Delft model (LoD1.2 + 2.2)")
    ap.add_argument("--quick", action="store_true", help="fewer buildings")
    ap.add_argument("--screenshot", default=None, help="write the page's screenshot here")
    ap.add_argument("--big", default=None, metavar="DIR",
                    help="instead: the 144-tile synthetic area (made in DIR once, ~4 min)")
    ap.add_argument("--repeat", type=int, default=None,
                    help="page-ready runs of each page (default 1 with --quick, else 3)")
    args = ap.parse_args()
    from lidar2city.viewer.app import Viewer

    print(f"load average: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    if args.big:
        big_area(Path(args.big))
        return

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        model = _model(folder, args.model)
        t0 = time.perf_counter()
        viewer = Viewer(model, points=[TILE], crs="EPSG:7415", port=_port())
        viewer.start()  # as `lidar2city view` does: RMSEs computed in the background
        print(f"server start (model + {viewer._reader.count} points read, scene built): "
              f"{time.perf_counter() - t0:.2f} s")
        try:
            page_ready(viewer, args.screenshot,
                       repeat=args.repeat or (1 if args.quick else 3))
            viewer._rmse_thread.join()
            frame_times(viewer, "Delft model + points")
            lod_switch(viewer)
            ids = [b for b, _ in viewer.worst_order()][: 4 if args.quick else 12]
            edit_times(viewer, ids)
            reproduction(viewer, folder, ids[:3])
        finally:
            viewer.stop()


if __name__ == "__main__":
    main()
