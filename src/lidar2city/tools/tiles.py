"""Folder-of-tiles jobs: one task per tile with its neighbours, on the same executors.

``ground`` and ``classify`` take a folder (or glob) of tiles and an output
folder: the tiles' headers give each tile its neighbours (the tiles whose
bounds come within ``buffer`` metres of it), and each tile is one task, run by
:mod:`lidar2city.tools.engine` (in process, on a local Dask cluster or on an
existing one). A tile that fails gets its reason; the others go on.
"""

from __future__ import annotations

import functools
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import FileFormatError, InputError, Lidar2CityError

logger = logging.getLogger(__name__)

__all__ = ["TileTask", "TilesSummary", "plan_tiles", "run_tiles"]


@dataclass(frozen=True)
class TileTask:
    """One tile to process: its path, its output path and its neighbours' paths."""

    path: str
    output: str
    neighbours: tuple
    extra: dict = field(default_factory=dict)


@dataclass
class TilesSummary:
    """What a folder run did: per tile its job's summary or the reason it failed."""

    output: str
    done: dict = field(default_factory=dict)
    failed: dict = field(default_factory=dict)
    seconds: float = 0.0

    def lines(self) -> list:
        out = [f"{len(self.done)} of {len(self.done) + len(self.failed)} tiles done, "
               f"{len(self.failed)} failed, in {self.seconds:.1f} s -> {self.output}"]
        out += [f"  failed: {Path(k).name}: {v}" for k, v in sorted(self.failed.items())]
        return out


def plan_tiles(inputs, output_folder, *, crs=None, buffer=50.0, suffix=None,
               extra=None) -> list:
    """A :class:`TileTask` per tile of ``inputs`` (folder, glob or files), in name order.

    ``suffix`` replaces each output's extension (default: the tile's own);
    ``extra`` maps a keyword of the job to an output folder: each task gets
    ``{keyword: folder / (tile stem + that folder's suffix)}`` (e.g. a DTM per tile).

    Raises
    ------
    CRSError
        Tiles with different CRSs.
    FileFormatError
        An output folder whose parent does not exist.
    """
    import numpy as np

    from ..io.las import scan_tiles
    from ..io.tiles import tile_paths

    tiles = scan_tiles(tile_paths(inputs), crs=crs, allow_empty=True)
    out = Path(output_folder)
    folders = [out] + [Path(p) for p, _ in (extra or {}).values()]
    for d in folders:
        if d.exists() and not d.is_dir():
            raise FileFormatError(f"{str(d)!r} is a file; give an output folder for a folder "
                                  "of tiles")
        if not d.parent.is_dir():
            raise FileFormatError(f"output folder {str(d.parent)!r} does not exist")
    mins = np.array([t.mins[:2] for t in tiles])
    maxs = np.array([t.maxs[:2] for t in tiles])
    tasks = []
    for k, t in enumerate(tiles):
        pad = buffer / (1.0 if t.crs is None else _xy_unit(t.crs))
        near = ((mins[:, 0] <= t.maxs[0] + pad) & (maxs[:, 0] >= t.mins[0] - pad)
                & (mins[:, 1] <= t.maxs[1] + pad) & (maxs[:, 1] >= t.mins[1] - pad))
        near[k] = False
        neighbours = tuple(tiles[i].path for i in np.flatnonzero(near) if tiles[i].count)
        p = Path(t.path)
        name = p.name if suffix is None else p.stem + suffix
        if (out / name).resolve() == p.resolve():
            raise InputError(f"the output folder holds the input {str(p)!r}: choose another "
                             "output folder")
        more = {kw: str(Path(folder) / (p.stem + sfx)) for kw, (folder, sfx) in
                (extra or {}).items()}
        tasks.append(TileTask(t.path, str(out / name), neighbours, more))
    return tasks


def _xy_unit(crs) -> float:
    from ..crs import unit_factors

    return unit_factors(crs)[0]


def _run_tile(task: TileTask, job):
    """The task of a folder run: ``job(tile, output, neighbours=..., **extra)``."""
    return job(task.path, task.output, neighbours=task.neighbours, **task.extra)


def run_tiles(job, tasks, output_folder, *, workers=1, scheduler=None, progress=None,
              **options) -> TilesSummary:
    """Run ``job`` (e.g. :func:`lidar2city.tools.ground.ground_file`) on every tile task.

    ``job(path, output, neighbours=..., **extra, **options)`` must be importable
    (it is sent to the workers by name). ``progress(done, total)`` after each tile.
    """
    from .engine import make_executor

    t0 = time.perf_counter()
    Path(output_folder).mkdir(exist_ok=True)
    for t in tasks:
        for v in t.extra.values():
            Path(v).parent.mkdir(exist_ok=True)
    summary = TilesSummary(str(output_folder))
    fn = functools.partial(job, **options)
    with make_executor(workers, scheduler) as executor:
        for n, (i, out) in enumerate(executor.map(_run_tile, tasks, fn), start=1):
            path = tasks[i].path
            if isinstance(out, BaseException):
                msg = str(out).splitlines()[0] if str(out) else type(out).__name__
                summary.failed[path] = (msg if isinstance(out, Lidar2CityError)
                                        else f"{type(out).__name__}: {msg}")
            else:
                summary.done[path] = out
            if progress is not None:
                progress(n, len(tasks))
    summary.seconds = time.perf_counter() - t0
    return summary
