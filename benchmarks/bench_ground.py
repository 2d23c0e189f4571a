"""Ground filtering benchmark: ISPRS errors per sample and whole-process speed ratio.

Usage::

    python benchmarks/bench_ground.py [--data DIR] [--repeat 3] [--no-speed] [--loo]

Prints, for every ISPRS reference sample in ``DIR/isprs/reference`` and each
method with its default parameters, type I / type II / total error and
Cohen's kappa (Sithole & Vosselman 2004), and their means, then the total
error of each method on the synthetic terrains of
:mod:`lidar2city.synthetic_terrain` (1 m and 2.5 m spacing). Then times
``lidar2city ground`` on ``DIR/isprs/sites/CSite4_orig-utm.laz`` as a fresh
process against plainly reading and writing the same file with laspy (best
of ``--repeat`` runs each) and prints the ratio, for each method and for
``smrf_vote`` with its ``veto`` off, with ``above`` 3 m, with ``connect`` 3, the
ring, the wall anchor 3 and without the wall anchor and ``above`` (the default until
session 16) (:data:`SPEED_VARIANTS`), with the load average and the threads the filter's
grid passes would take at that load (two on an idle two-core machine, one on a
busy one).

``--loo`` adds the leave-one-sample-out check of SMRF, smrf_refined and
smrf_segments (the same grid for the three) and of ptd (its iteration angle
and seed cell; ``--loo-methods ptd`` runs only the named ones): for each
ISPRS sample, the parameter set of a coarse grid (:data:`LOO_GRID`) that
minimises the mean total error over the six other samples plus the
synthetic terrains (their mean counted as one more sample) is scored on the
held-out sample; it prints the held-out errors, their mean and maximum, and
the set chosen on all seven (compare with the defaults); beside each
held-out error, the range of held-out errors of the sets whose objective on
the six others is within :data:`NEAR_TIE` of the chosen one (how much the
choice rests on near-ties). A few minutes.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

import itertools  # noqa: E402

from lidar2city.ground import GROUND_METHODS, GroundConfig  # noqa: E402
from lidar2city.metrics.ground import ground_errors  # noqa: E402
from lidar2city.synthetic_terrain import TERRAIN_KINDS, make_terrain  # noqa: E402

#: parameter grid of the leave-one-out check, per method.
LOO_GRID = {
    "smrf": {"slope": (0.1, 0.15, 0.2), "window": (16.0, 24.0, 32.0),
             "scalar": (0.75, 1.25, 2.0), "threshold": (0.3, 0.5, 0.7)},
    "smrf_refined": {"slope": (0.1, 0.15, 0.2), "window": (16.0, 24.0, 32.0),
                     "scalar": (0.75, 1.25, 2.0), "threshold": (0.3, 0.5, 0.7)},
    "smrf_segments": {"slope": (0.1, 0.15, 0.2), "window": (16.0, 24.0, 32.0),
                      "scalar": (0.75, 1.25, 2.0), "threshold": (0.3, 0.5, 0.7)},
    # progressive TIN densification: its iteration angle and seed cell (issue 18, session 11)
    "ptd": {"iteration_angle": (10.0, 20.0, 30.0), "seed_cell": (20.0, 40.0)},
}


#: objective margin (fraction) within which the leave-one-out check reports the near-ties.
NEAR_TIE = 0.0002


def arg_parser(doc):
    """The scripts' argument parser, with ``--data`` (default ``LIDAR2CITY_DATA``)."""
    default = Path(os.environ.get("LIDAR2CITY_DATA", ROOT.parent / "shared" / "data"))
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--data", type=Path, default=default)
    return ap


def reference_paths(data):
    """The ISPRS reference samples under ``data``, or exit saying there are none."""
    refs = sorted((data / "isprs" / "reference").glob("samp*.laz"))
    if not refs:
        sys.exit(f"no ISPRS reference samples under {data}")
    return refs


def load(path):
    import laspy

    las = laspy.read(path)
    xyz = np.column_stack([las.x, las.y, las.z])
    xyz -= np.floor(xyz.min(axis=0))
    return xyz, np.asarray(las.classification) == 2


def accuracy(samples):
    means = {}
    for method in sorted(GROUND_METHODS):
        params = GroundConfig(method=method).method_params()
        print(f"\n{method} (defaults: {', '.join(f'{k}={v}' for k, v in params.items())})")
        print(f"{'sample':<8} {'points':>7} {'type I %':>9} {'type II %':>10} {'total %':>8} "
              f"{'kappa %':>8} {'s':>6}")
        rows = []
        for name, (xyz, ref) in samples.items():
            t = time.perf_counter()
            pred = GROUND_METHODS[method](xyz, **params)
            dt = time.perf_counter() - t
            e = ground_errors(pred, ref)
            rows.append([e["type_i"], e["type_ii"], e["total"], e["kappa"]])
            print(f"{name:<8} {len(xyz):>7} {100 * e['type_i']:>9.2f} {100 * e['type_ii']:>10.2f} "
                  f"{100 * e['total']:>8.2f} {100 * e['kappa']:>8.2f} {dt:>6.2f}")
        m = 100 * np.mean(rows, axis=0)
        means[method] = m
        print(f"{'mean':<8} {'':>7} {m[0]:>9.2f} {m[1]:>10.2f} {m[2]:>8.2f} {m[3]:>8.2f}")
    return means


def synthetic_scenes():
    return {f"{kind}@{spacing:g}m": make_terrain(kind, spacing=spacing, seed=1)
            for kind in TERRAIN_KINDS for spacing in (1.0, 2.5)}


def synthetic(scenes):
    print("\nsynthetic terrains (total error %, defaults)")
    methods = sorted(GROUND_METHODS)
    print(f"{'scene':<20} " + " ".join(f"{m:>13}" for m in methods))
    totals = {m: [] for m in methods}
    for name, scene in scenes.items():
        for m in methods:
            pred = GROUND_METHODS[m](scene.xyz, **GroundConfig(method=m).method_params())
            totals[m].append(ground_errors(pred, scene.ground)["total"])
        print(f"{name:<20} " + " ".join(f"{100 * totals[m][-1]:>13.2f}" for m in methods))
    print(f"{'mean':<20} " + " ".join(f"{100 * np.mean(totals[m]):>13.2f}" for m in methods))


def leave_one_out(samples, scenes, methods=tuple(LOO_GRID)):
    for method in methods:
        grid = LOO_GRID[method]
        leave_one_out_method(method, GROUND_METHODS[method],
                             GroundConfig(method=method).method_params(), grid, samples, scenes)


def leave_one_out_method(method, fn, base, grid, samples, scenes):
    """Print the leave-one-sample-out check of ``fn(xyz, **params)`` over ``grid``."""
    keys = list(grid)
    table = []
    for values in itertools.product(*(grid[k] for k in keys)):
        params = dict(base, **dict(zip(keys, values)))
        real = {n: ground_errors(fn(xyz, **params), ref)["total"]
                for n, (xyz, ref) in samples.items()}
        syn = np.mean([ground_errors(fn(s.xyz, **params), s.ground)["total"]
                       for s in scenes.values()])
        table.append((dict(zip(keys, values)), real, syn))

    def objective(row, held_out):
        return np.mean([v for n, v in row[1].items() if n != held_out] + [row[2]])

    print(f"\nleave-one-out, {method} ({len(table)} parameter sets; chosen on the other six "
          f"samples + synthetic terrains)")
    held = []
    for name in samples:
        best = min(table, key=lambda row: objective(row, name))
        held.append(best[1][name])
        # how much the choice decides: held-out errors of the near-ties on the six
        near = [row[1][name] for row in table
                if objective(row, name) <= objective(best, name) + NEAR_TIE]
        print(f"{name:<8} held-out total {100 * best[1][name]:5.2f} %  chosen "
              f"{', '.join(f'{k}={v}' for k, v in best[0].items())}  ({len(near)} sets within "
              f"{100 * NEAR_TIE:g} point: held-out {100 * min(near):.2f}-{100 * max(near):.2f} %)")
    print(f"{method} leave-one-out mean total {100 * np.mean(held):.2f} %, "
          f"max {100 * np.max(held):.2f} %")
    best = min(table, key=lambda row: objective(row, None))
    print(f"{method} chosen on all seven: {', '.join(f'{k}={v}' for k, v in best[0].items())} "
          f"(mean {100 * np.mean(list(best[1].values())):.2f} %, synthetic "
          f"{100 * best[2]:.2f} %)")


def best_times(cmd, env, repeat):
    """Best wall time and best CPU time (user + system of the child) of ``repeat`` runs."""
    import resource

    wall, cpu = [], []
    for _ in range(repeat):
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t = time.perf_counter()
        subprocess.run(cmd, check=True, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        wall.append(time.perf_counter() - t)
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu.append(r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime)
    return min(wall), min(cpu)


#: ``lidar2city ground`` runs of the speed check besides the methods' defaults: label ->
#: (method, the ``[ground]`` table of a run TOML given with ``--config``).
SPEED_VARIANTS = {"smrf_vote, veto off": ("smrf_vote", "veto = inf"),
                  "smrf_vote, above 3": ("smrf_vote", "above = 3.0"),
                  "smrf_vote, connect 3": ("smrf_vote", "connect = 3"),
                  "smrf_vote, ring 1.25": ("smrf_vote", "ring = 1.25"),
                  "smrf_vote, ring 1.25 dilation": ("smrf_vote", 'ring = 1.25\n'
                                                    'ring_neighbourhood = "dilation"'),
                  "smrf_vote, wall_anchor 3": ("smrf_vote", "wall_anchor = 3.0"),
                  "smrf_vote, no anchor, no above (the default until session 16)": (
                      "smrf_vote", "wall_anchor = 1.0\nabove = inf")}


def speed(site, repeat, methods=("smrf", "smrf_refined", "smrf_segments", "smrf_vote"),
          variants=SPEED_VARIANTS):
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    with tempfile.TemporaryDirectory() as tmp:
        out = str(Path(tmp) / ("out" + site.suffix))
        base_cmd = [sys.executable, "-c",
                    f"import laspy; laspy.read({str(site)!r}).write({out!r})"]
        cli_cmds = {m: [sys.executable, "-m", "lidar2city.cli.main", "ground", str(site), "-o", out,
                        "--method", m] for m in methods}
        for label, (method, table) in variants.items():
            toml = Path(tmp) / f"variant{len(cli_cmds)}.toml"
            toml.write_text(f"[ground]\n{table}\n")
            cli_cmds[label] = cli_cmds.get(method, [
                sys.executable, "-m", "lidar2city.cli.main", "ground", str(site), "-o", out,
                "--method", method]) + ["--config", str(toml)]
        # interleave to share the machine load fairly
        base = (float("inf"),) * 2
        cli = dict.fromkeys(cli_cmds, (float("inf"),) * 2)
        for _ in range(repeat):
            base = tuple(map(min, base, best_times(base_cmd, env, 1)))
            for m, cmd in cli_cmds.items():
                cli[m] = tuple(map(min, cli[m], best_times(cmd, env, 1)))
    from lidar2city.ground._grid import _thread_count

    load = os.getloadavg()[0]
    # the filter's grid passes take the cores the load leaves idle (1 on a busy machine)
    threads = _thread_count()
    for m in cli_cmds:
        how = f"--method {m}" if m in methods else f"({m})"
        print(f"\nspeed on {site.name}: laspy read+write {base[0]:.2f} s, lidar2city ground {how} "
              f"{cli[m][0]:.2f} s, ratio {cli[m][0] / base[0]:.2f} (best of {repeat}); CPU seconds "
              f"{base[1]:.2f} and {cli[m][1]:.2f}, ratio {cli[m][1] / base[1]:.2f} "
              f"(load average {load:.1f}, filter threads {threads})")


def main():
    ap = arg_parser(__doc__)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-speed", action="store_true")
    ap.add_argument("--loo", action="store_true")
    ap.add_argument("--loo-methods", default=",".join(LOO_GRID),
                    help="comma-separated methods of the leave-one-out check (default all)")
    args = ap.parse_args()
    loo_methods = args.loo_methods.split(",")
    if not set(loo_methods) <= set(LOO_GRID):
        ap.error(f"--loo-methods: choose from {', '.join(LOO_GRID)}")
    samples = {p.name.split("-")[0]: load(p) for p in reference_paths(args.data)}
    accuracy(samples)
    scenes = synthetic_scenes()
    synthetic(scenes)
    if args.loo:
        leave_one_out(samples, scenes, loo_methods)
    if not args.no_speed:
        speed(args.data / "isprs" / "sites" / "CSite4_orig-utm.laz", args.repeat)


if __name__ == "__main__":
    main()
