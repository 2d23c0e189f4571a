"""Benchmark of the viewer and of editing on the shared Delft tile (issue 15 targets).

Prints:

- the server's start (model + all points read, scene and GUI sent on connection);
- page-ready: seconds from a headless chromium's navigation to the first
  screenshot showing the buildings (SwiftShader software WebGL), with the CPU
  seconds chromium used, and the same for a bare viser page holding one box in
  the same run (the floor any viser page pays on this machine: the ratio is
  less sensitive to the machine's load than the seconds);
- edit time: one refit of a building (automatic primitive, a chosen gable, and
  a re-run from a moved outline) as the viewer does it, median and max over
  buildings after one warm-up;
- reproduction: those edits accepted, then ``reconstruct --edits`` re-run;
  the largest vertex difference over the edited buildings and whether the two
  files are byte-identical.

Run: ``PYTHONPATH=src python benchmarks/bench_viewer.py [--model M.city.json] [--quick]``
(without ``--model`` the Delft model is reconstructed first, ~1 min).
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
        reconstruct([TILE], path, footprints=FOOTPRINTS, lods=("1.2", "2.2"), crs="EPSG:7415")
    return path


def page_ready(viewer, screenshot=None):
    from lidar2city.viewer.browser import capture_when_drawn, find_chromium

    if find_chromium() is None:
        print("page-ready: chromium not installed, not measured")
        return
    import viser

    png, sec, ok = capture_when_drawn(f"http://127.0.0.1:{viewer.port}", timeout=90.0,
                                      width=1100, height=700)
    cpu = capture_when_drawn.last_cpu
    if screenshot:  # the README's picture, as a small palette PNG
        from io import BytesIO

        from PIL import Image

        Image.open(BytesIO(png)).convert("RGB").quantize(
            256, dither=Image.Dither.NONE).save(screenshot, optimize=True)
    bare = viser.ViserServer(host="127.0.0.1", port=_port(), verbose=False)
    bare.scene.add_box("/box", color=(200, 30, 30), dimensions=(40.0, 40.0, 40.0))
    bare.initial_camera.position = (120.0, 120.0, 120.0)
    bare.initial_camera.look_at = (0.0, 0.0, 0.0)
    try:
        _, sec0, ok0 = capture_when_drawn(f"http://127.0.0.1:{bare.get_port()}", timeout=90.0,
                                          width=1100, height=700)
        cpu0 = capture_when_drawn.last_cpu
    finally:
        bare.stop()
    print(f"page-ready (Delft model + {viewer.points_handle.points.shape[0]} points): "
          f"{sec:.2f} s wall, chromium {cpu:.1f} CPU s, drawn={ok}")
    print(f"page-ready (bare viser page, one box):           {sec0:.2f} s wall, chromium "
          f"{cpu0:.1f} CPU s, drawn={ok0}")
    print(f"page-ready ratio Delft / bare viser page: {sec / sec0:.2f} (wall), "
          f"{cpu / cpu0:.2f} (CPU)")


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

    done = []
    for bid in ids:
        viewer.select(bid)
        if viewer.refit_primitive("auto") is not None and viewer.accept() is not None:
            done.append(bid)
    if ids:
        viewer.select(ids[-1])
        viewer.start_outline()
        c = viewer.outline.mean(axis=0)
        d = viewer.outline[1] - c
        viewer.move_vertex(1, viewer.outline[1] + 0.5 * d / np.linalg.norm(d))
        if viewer.rebuild_from_outline() is not None and viewer.accept() is not None:
            done.append(ids[-1])
    rerun = folder / "rerun.city.json"
    reconstruct([TILE], rerun, footprints=FOOTPRINTS, lods=("1.2", "2.2"), crs="EPSG:7415",
                edits=viewer.edits_path)
    a, b = read_cityjson(viewer.path), read_cityjson(rerun)
    worst = 0.0
    for bid in set(done):
        for lod in ("1.2", "2.2"):
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
    args = ap.parse_args()
    from lidar2city.viewer.app import Viewer

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        model = _model(folder, args.model)
        t0 = time.perf_counter()
        viewer = Viewer(model, points=[TILE], crs="EPSG:7415", port=_port())
        viewer.start(compute_rmse=False)
        print(f"server start (model + {len(viewer.cloud)} points read, scene built): "
              f"{time.perf_counter() - t0:.2f} s")
        try:
            page_ready(viewer, args.screenshot)
            viewer._compute_all_rmse()
            ids = [b for b, _ in viewer.worst_order()][: 4 if args.quick else 12]
            edit_times(viewer, ids)
            reproduction(viewer, folder, ids[:3])
        finally:
            viewer.stop()


if __name__ == "__main__":
    main()
