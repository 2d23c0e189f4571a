"""Speed and memory of ``reconstruct`` on the Delft tile, against the laspy read floor.

Usage: python benchmarks/bench_speed.py [DATA_DIR] [--runs N] [--no-traced | --traced-only] [--keep-env]
[--workers W]
(default $LIDAR2CITY_DATA or ../shared/data; 3 runs; the command's own --workers default,
``auto``, unless ``--workers W`` is given: ``--workers 1`` measures one process)

Every figure is a whole process as a user runs it, measured from outside
(wall time with time.perf_counter; peak RSS and user + system CPU seconds from
os.wait4's resource usage of that child), and the time is given as a ratio to a
baseline measured in the same call: a fresh Python reading the same tile with
``laspy.read``. Baseline and reconstruct runs alternate and the ratio is taken
pair by pair, so it holds when the machine's speed drifts; CPU seconds are
printed beside wall times because on a shared machine they drift less.
Prints, against issue 13's targets:

* ``reconstruct --lod 1.2 --lod 1.3 --lod 2.2`` with the 132 BGT footprints:
  time / laspy floor (target <= 9) and peak RSS (target <= 200 MB);
* LoD1.3 median RMSE of that output, scored as benchmarks/bench_lod1.py does
  (target <= 0.46 m);
* ``reconstruct`` without footprints (traced from the points): time, CPU
  seconds and their ratios to a laspy floor run just before, and peak RSS
  (targets <= 10 s, <= 300 MB), one run; then the LoD2.2 and LoD1.2 RMSE of
  that output against the tile's points;
* the MD5 of the LoD1.2 + LoD2.2 output, to check that a change kept the bytes.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run(cmd, env) -> tuple[float, float, float]:
    """``(wall seconds, peak RSS in MB, user + system CPU seconds)`` of one child process
    (fails loudly)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode(errors="replace")
    proc.stderr.close()
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(map(str, cmd))} failed ({proc.returncode}):\n{err}")
    return wall, usage.ru_maxrss / 1024.0, usage.ru_utime + usage.ru_stime  # Linux: kilobytes


def data_dir(arg):
    if arg:
        return Path(arg)
    if os.environ.get("LIDAR2CITY_DATA"):
        return Path(os.environ["LIDAR2CITY_DATA"])
    return next((p / "shared" / "data" for p in (ROOT.parent, ROOT.parent.parent)
                 if (p / "shared" / "data").exists()), ROOT.parent / "shared" / "data")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="?")
    ap.add_argument("--runs", type=int, default=3)
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument("--no-traced", action="store_true", help="skip the no-footprints run")
    mode.add_argument("--traced-only", action="store_true",
                      help="only the no-footprints run (--runs of them, each after a floor run)")
    ap.add_argument("--keep-env", action="store_true",
                    help="run with the environment as it is (PYTHONDONTWRITEBYTECODE kept: "
                         "without a __pycache__, lidar2city compiles in every run)")
    ap.add_argument("--workers", default=None,
                    help="reconstruct's --workers (default: none given, the command's default)")
    args = ap.parse_args()
    d = data_dir(args.data) / "delft"
    laz, fps = d / "ahn3_cropped_1.laz", d / "footprints_bgt.gpkg"
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    # the warm-up runs below cache the bytecode, as an installed package has it (laspy's,
    # the floor's, was compiled when it was installed): with PYTHONDONTWRITEBYTECODE set,
    # every run would compile lidar2city's ~50 modules again (~0.2 CPU s); --keep-env
    # runs with the environment as it is
    if not args.keep_env:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
    tmp = Path(tempfile.mkdtemp())
    py = sys.executable
    floor = [py, "-c", f"import laspy; laspy.read({str(laz)!r})"]
    base = [py, "-m", "lidar2city.cli.main", "reconstruct", str(laz), "--crs", "EPSG:7415"]
    if args.workers is not None:
        base += ["--workers", args.workers]
    print(f"reconstruct --workers {args.workers or '(default)'}")
    out = tmp / "delft.city.json"
    full = base + ["--footprints", str(fps), "--lod", "1.2", "--lod", "1.3", "--lod", "2.2",
                   "-o", str(out)]

    run(floor, env)  # warm the file cache and the bytecode
    if args.traced_only:
        traced_runs(base, floor, env, tmp, laz, max(1, args.runs))
        return
    run(full, env)
    floors, fulls, ratios = [], [], []
    for _ in range(max(1, args.runs)):
        a = run(floor, env)
        b = run(full, env)
        floors.append(a)
        fulls.append(b)
        ratios.append(b[0] / a[0])
    f_t = statistics.median(t for t, _, _ in floors)
    f_m = statistics.median(m for _, m, _ in floors)
    f_c = statistics.median(c for _, _, c in floors)
    r_t = statistics.median(t for t, _, _ in fulls)
    r_m = max(m for _, m, _ in fulls)
    r_c = statistics.median(c for _, _, c in fulls)
    print(f"laspy read floor (fresh python, laspy.read of the tile): median {f_t:.2f} s, "
          f"{f_c:.2f} CPU s, peak RSS {f_m:.0f} MB ({len(floors)} runs)")
    print(f"reconstruct LoD1.2+1.3+2.2, 132 footprints: median {r_t:.2f} s, {r_c:.2f} CPU s "
          f"(CPU / floor CPU {r_c / f_c:.1f}x); "
          f"time / laspy floor median {statistics.median(ratios):.1f}x "
          f"(pairs: {', '.join(f'{r:.1f}' for r in ratios)}) [target <= 9x]")
    print(f"reconstruct LoD1.2+1.3+2.2, 132 footprints: peak RSS {r_m:.0f} MB "
          f"(largest of {len(fulls)} runs; {r_m / f_m:.1f}x the laspy floor's {f_m:.0f} MB) "
          f"[target <= 200 MB]")

    sys.path.insert(0, str(ROOT / "src"))
    from lidar2city.tools.evaluate_model import evaluate_model
    from lidar2city.tools.validate import validate_file

    _, s13 = evaluate_model(out, [laz], crs="EPSG:7415", footprints=fps, id_field="gml_id",
                            lod="1.3")
    rep = validate_file(out).summary()
    print(f"LoD1.3 median RMSE {s13['rmse_median']:.3f} m (mean {s13['rmse_mean']:.3f} m, "
          f"{s13['measured']} measured, valid {s13['valid']}/{s13['buildings']}) [target <= 0.46 m]; "
          f"file: schema {rep['schema']}, {rep['invalid']} invalid solids")

    o22 = tmp / "delft_12_22.city.json"
    run(base + ["--footprints", str(fps), "--lod", "1.2", "--lod", "2.2", "-o", str(o22)], env)
    print(f"LoD1.2+2.2 output MD5 {hashlib.md5(o22.read_bytes()).hexdigest()}")

    if not args.no_traced:
        traced_runs(base, floor, env, tmp, laz, 1)


def traced_runs(base, floor, env, tmp, laz, runs):
    """The no-footprints reconstruct ``runs`` times, each after a laspy floor run (the
    median of each figure printed when more than one), then the RMSE of its output."""
    sys.path.insert(0, str(ROOT / "src"))
    from lidar2city.tools.evaluate_model import evaluate_model

    traced = tmp / "traced.city.json"
    rows = []
    for _ in range(runs):
        a = run(floor, env)
        b = run(base + ["--lod", "1.2", "--lod", "1.3", "--lod", "2.2", "-o", str(traced)], env)
        rows.append((*b, a[0], a[2]))
    t, m, c, f_t, f_c = (statistics.median(col) for col in zip(*rows, strict=True))
    m = max(r[1] for r in rows)
    runs_note = "" if runs == 1 else (f"; median of {runs} runs, CPU s each: "
                                      + ", ".join(f"{r[2]:.1f}" for r in rows))
    print(f"reconstruct without footprints (traced), LoD1.2+1.3+2.2: {t:.1f} s, {c:.1f} CPU s "
          f"(time / laspy floor {t / f_t:.0f}x, CPU / floor CPU {c / f_c:.0f}x, floor "
          f"{f_t:.2f} s, {f_c:.2f} CPU s, same run{runs_note}), peak RSS {m:.0f} MB "
          f"[targets <= 10 s, <= 300 MB]; output MD5 {hashlib.md5(traced.read_bytes()).hexdigest()}")
    _, s22 = evaluate_model(traced, [laz], crs="EPSG:7415", lod="2.2")
    _, s12 = evaluate_model(traced, [laz], crs="EPSG:7415", lod="1.2")
    print(f"  traced: {s22['buildings']} buildings; LoD2.2 RMSE median {s22['rmse_median']:.3f} m, "
          f"mean {s22['rmse_mean']:.3f} m, p90 {s22['rmse_p90']:.3f} m; LoD1.2 RMSE median "
          f"{s12['rmse_median']:.3f} m, mean {s12['rmse_mean']:.3f} m; "
          f"valid {s22['valid']}/{s22['buildings']}")


if __name__ == "__main__":
    main()
