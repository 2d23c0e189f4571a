"""LoD1 on the Delft tile: RMSE against 3dfier's LoD1, validity, schema, run time.

Usage: python benchmarks/bench_lod1.py [DATA_DIR]   (default $LIDAR2CITY_DATA or ../shared/data)

Runs the CLI as a separate process (whole-process time, as a user sees it),
then measures ours and 3dfier's output with the same code: the AHN building
points (class 6) inside each BGT footprint, 3-D distance to the building's
triangulated model (3dfier's building matched by its BGT gml_id).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main():
    if len(sys.argv) > 1:
        data = Path(sys.argv[1])
    elif os.environ.get("LIDAR2CITY_DATA"):
        data = Path(os.environ["LIDAR2CITY_DATA"])
    else:
        data = next((p / "shared" / "data" for p in (ROOT.parent, ROOT.parent.parent)
                     if (p / "shared" / "data").exists()), ROOT.parent / "shared" / "data")
    d = data / "delft"
    laz, fps, peer = d / "ahn3_cropped_1.laz", d / "footprints_bgt.gpkg", d / "peer_3dfier_lod1.city.json"
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    out = Path(tempfile.mkdtemp()) / "delft_lod12.city.json"
    cmd = [sys.executable, "-m", "lidar2city.cli.main", "reconstruct", str(laz), "--crs", "EPSG:7415",
           "--footprints", str(fps), "-o", str(out)]
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, env=env, capture_output=True)
        times.append(time.perf_counter() - t0)
    print(f"reconstruct LoD1.2, 132 footprints, whole process: best {min(times):.2f} s "
          f"(runs: {', '.join(f'{t:.2f}' for t in times)})")

    sys.path.insert(0, str(ROOT / "src"))
    from lidar2city.tools.evaluate_model import evaluate_model
    from lidar2city.tools.validate import validate_file

    rep = validate_file(out)
    s = rep.summary()
    print(f"ours: schema {s['schema']}; {s['objects']} objects, {s['invalid']} invalid solids")

    def line(name, summary):
        print(f"{name:<28} measured {summary['measured']:>3}  RMSE median {summary['rmse_median']:.3f} m"
              f"  mean {summary['rmse_mean']:.3f} m  p90 {summary['rmse_p90']:.3f} m  "
              f"valid {summary['valid']}/{summary['buildings']}")

    _, ours = evaluate_model(out, [laz], crs="EPSG:7415", footprints=fps, id_field="gml_id")
    _, theirs = evaluate_model(peer, [laz], crs="EPSG:7415", footprints=fps, id_field="gml_id")
    line("lidar2city LoD1.2 (p70)", ours)
    line("3dfier LoD1 (p90)", theirs)
    for stat in ("mean", "median", 90):
        cfg = out.with_name(f"cfg_{stat}.toml")
        value = f'"{stat}"' if isinstance(stat, str) else stat
        cfg.write_text(f"[lod1]\nroof_statistic = {value}\n")
        o = out.with_name(f"delft_{stat}.city.json")
        subprocess.run(cmd[:-2] + ["-o", str(o), "--config", str(cfg)], check=True, env=env,
                       capture_output=True)
        _, summ = evaluate_model(o, [laz], crs="EPSG:7415", footprints=fps, id_field="gml_id")
        line(f"lidar2city LoD1.2 ({stat})", summ)
    o13 = out.with_name("delft_lod13.city.json")
    t0 = time.perf_counter()
    subprocess.run(cmd[:-2] + ["-o", str(o13), "--lod", "1.3"], check=True, env=env,
                   capture_output=True)
    t13 = time.perf_counter() - t0
    _, s13 = evaluate_model(o13, [laz], crs="EPSG:7415", footprints=fps, id_field="gml_id")
    r13 = validate_file(o13).summary()
    line("lidar2city LoD1.3", s13)
    print(f"LoD1.3: {t13:.2f} s whole process; schema {r13['schema']}; {r13['objects']} objects "
          f"(buildings + parts), {r13['invalid']} invalid")


if __name__ == "__main__":
    main()
