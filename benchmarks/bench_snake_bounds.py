"""The snake's energy tables with the deviation of the pairs paying the direction energy
bounded below by 0 (``edge_energy_tables(bound=True)``) against the whole tables, on the
Delft tile's own snake solves (issue 13).

Usage: PYTHONPATH=src python benchmarks/bench_snake_bounds.py [DATA_DIR] [--traced] [--repeat N]
(default data $LIDAR2CITY_DATA or ../shared/data, N = 7)

``reconstruct`` (LoD 1.2 + 1.3 + 2.2, the 132 BGT footprints, or ``--traced`` without
them: the footprint snake of the traced outlines too) runs once in this process, one
worker, and records the arguments of every table the snake (``regularize.snake``)
builds with ``bound=True``, and how many edges' tables it built again because the
minimum used a bounded entry (each such edge is solved with its whole table). Then
prints: the solves, edges and candidate pairs, the share of pairs bounded, the solves
and edges solved again, whether every entry not bounded is the very double of the
whole table (and every bounded one at most it), and the CPU of building all the tables
both ways in this process (alternated, least of N passes; ``time.process_time``).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np


def _capture(data: Path, traced: bool):
    import lidar2city.regularize.snake as snake
    from lidar2city.cli.main import cli

    calls, again = [], []
    real = snake.edge_energy_tables

    def recording(*args, **kwargs):
        if kwargs.get("bound"):
            calls.append((args, {k: v for k, v in kwargs.items() if k != "bound"}))
        else:
            again.append(len(args[1]))
        return real(*args, **kwargs)

    tile, fp = data / "delft" / "ahn3_cropped_1.laz", data / "delft" / "footprints_bgt.gpkg"
    snake.edge_energy_tables = recording
    try:
        import tempfile
        with tempfile.TemporaryDirectory() as tmp:
            given = [] if traced else ["--footprints", str(fp)]
            cli.main(["-q", "reconstruct", str(tile), *given, "--lod", "1.2", "--lod", "1.3", "--lod", "2.2",
                      "--workers", "1", "-o", str(Path(tmp) / "out.city.json")], standalone_mode=False)
    except SystemExit:
        pass
    finally:
        snake.edge_energy_tables = real
    return calls, again


def main(argv: list[str]) -> int:
    from lidar2city.snake.energies import edge_energy_tables

    traced = "--traced" in argv
    argv = [a for a in argv if a != "--traced"]
    repeat = 7
    if "--repeat" in argv:
        i = argv.index("--repeat")
        repeat = int(argv[i + 1])
        argv = argv[:i] + argv[i + 2:]
    data = Path(argv[0] if argv else os.environ.get("LIDAR2CITY_DATA", "../shared/data"))
    calls, again = _capture(data, traced)
    pairs = bounded = edges = 0
    exact = True
    for args, kw in calls:
        whole = edge_energy_tables(*args, **kw)
        tables, masks = edge_energy_tables(*args, bound=True, **kw)
        edges += len(whole)
        for t, b, m in zip(whole, tables, masks, strict=True):
            pairs += t.size
            bounded += int(m.sum())
            exact &= bool(b[~m].tobytes() == t[~m].tobytes() and np.all(b[m] <= t[m]))
    best = {False: float("inf"), True: float("inf")}
    for _ in range(repeat):
        for bound in (False, True):
            t = time.process_time()
            for args, kw in calls:
                edge_energy_tables(*args, bound=bound, **kw)
            best[bound] = min(best[bound], time.process_time() - t)
    what = "traced" if traced else "with the 132 BGT footprints"
    print(f"Delft {what}: {len(calls)} snake solves, {edges} edges, {pairs} candidate pairs; load "
          f"{os.getloadavg()[0]:.1f}")
    print(f"  pairs bounded (deviation not sampled): {bounded / pairs:.3f}; solved again: "
          f"{len(again)} solves, {sum(again)} edges with their whole tables")
    print(f"  entries not bounded the same doubles, bounded ones at most the whole: {exact}")
    print(f"  tables CPU s (least of {repeat}, alternated): whole {best[False]:.3f}, bounded {best[True]:.3f}, "
          f"ratio {best[True] / best[False]:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
