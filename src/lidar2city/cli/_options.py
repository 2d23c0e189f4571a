"""Options and helpers shared by several subcommands."""

from __future__ import annotations

import time

import click

__all__ = ["check_output", "check_not_input", "check_suffix", "POINTS_SUFFIXES", "RASTER_SUFFIXES",
           "VECTOR_SUFFIXES", "crs_option", "engine_options", "EngineProgress",
           "neighbours_options", "output_option", "progress", "progress_callback", "run_on_tiles"]

crs_option = click.option(
    "--crs", default=None, metavar="CRS",
    help="CRS of the input (EPSG:xxxx, WKT or PROJ); overrides or supplies the file's own.",
)


def neighbours_options(f):
    """``--neighbour`` (repeatable) and ``--buffer``: adjacent tiles filtered with the input."""
    f = click.option("--buffer", type=click.FloatRange(min=0.0), default=50.0, show_default=True,
                     help="Width (m) of the strip of the neighbouring tiles taken.")(f)
    return click.option("--neighbour", "neighbours", multiple=True,
                        type=click.Path(dir_okay=False),
                        help="An adjacent tile (repeatable): its points near INPUT are "
                             "processed with it so that INPUT's border sees beyond it; only "
                             "INPUT's points are written.")(f)


def check_output(ctx, param, value):
    """click callback of output file options: a folder that cannot be written fails at once,
    in one line, before any work is done."""
    if value is not None:
        from ..io._atomic import check_output_path

        check_output_path(value)
    return value


def check_not_input(outputs, *inputs) -> None:
    """An output path that is also one of the input files is an error before any work:
    the run would replace the user's data (``classify x.laz -o x.laz``,
    ``reconstruct x.laz --format cityjson -o x.laz``)."""
    from pathlib import Path

    from ..errors import InputError

    given = set()
    for i in inputs:
        for p in ([i] if isinstance(i, (str, Path)) else i or ()):
            if p is not None and Path(p).is_file():
                given.add(Path(p).resolve())
    for o in [outputs] if isinstance(outputs, (str, Path)) else outputs:
        if o is not None and Path(o).resolve() in given:
            raise InputError(f"output {str(o)!r} is also an input: give the output another name")


#: output extensions the writers write, by kind of output (anything else is refused)
POINTS_SUFFIXES = (".las", ".laz")
RASTER_SUFFIXES = (".tif", ".tiff")
VECTOR_SUFFIXES = (".gpkg", ".shp", ".geojson", ".json", ".fgb")


def check_suffix(path, suffixes, what) -> None:
    """An output file whose extension its writer does not write is an error before any
    work: the LAS writer would put a LAS file under ``g.txt``, GDAL a GeoTIFF under
    ``r.png``, and OGR fail at the end (``Could not set geometry``) on ``f.txt``."""
    from pathlib import Path

    from ..errors import InputError

    if path is not None and Path(path).suffix.lower() not in suffixes:
        raise InputError(f"output {str(path)!r}: {what} are written as {', '.join(suffixes)}: "
                         "give the output one of these extensions")


class _Workers(click.ParamType):
    """``--workers``: a whole number >= 1, or ``auto``."""

    name = "N|auto"

    def convert(self, value, param, ctx):
        if value == "auto":
            return value
        try:
            n = int(value)
        except (TypeError, ValueError):
            self.fail(f"{value!r} is neither a whole number nor 'auto'", param, ctx)
        if n < 1:
            self.fail(f"{n} is not >= 1 (or 'auto')", param, ctx)
        return n


def engine_options(f=None, *, auto=False):
    """``--workers`` and ``--scheduler``: where the tasks (blocks or tiles) run;
    ``auto``: ``--workers`` also takes ``auto`` (the command picks the count), its
    default (:func:`lidar2city.tools.reconstruct.auto_workers`)."""
    if f is None:
        return lambda g: engine_options(g, auto=auto)
    f = click.option("--scheduler", default=None, metavar="ADDRESS",
                     help="Run the tasks on an existing Dask cluster (tcp://HOST:8786, started "
                          "with `dask scheduler` and `dask worker`); its workers must see the "
                          "input paths.")(f)
    if auto:
        return click.option("--workers", type=_Workers(), default="auto", show_default=True,
                            help="Worker processes: 1 runs the tasks in this process, N > 1 in "
                                 "it and N - 1 processes forked from it (a local Dask cluster "
                                 "where the system does not fork; same output bytes); "
                                 "auto: one per ~1.5 CPU seconds of expected work, at most "
                                 "the usable cores (Delft's 640,000 points with LoD2.2: 2), "
                                 "1 for a small input or where forking is not safe.")(f)
    return click.option("--workers", type=click.IntRange(min=1), default=1, show_default=True,
                        help="Worker processes: 1 runs the tasks in this process, N > 1 in it "
                             "and N - 1 processes forked from it (a local Dask cluster where "
                             "the system does not fork; same output bytes).")(f)


def run_on_tiles(job, input, output, *, neighbours, workers, scheduler, extra=None, suffix=None,
                 buffer=50.0, crs=None, **options):
    """The folder-of-tiles mode of a per-tile command (``ground``, ``classify``).

    The outputs (``output`` and the folders of ``extra``) are checked first: as
    files that can be written when ``input`` is one file, else created as folders.

    Returns False when ``input`` is one file (the command's own mode), else runs
    ``job`` on every tile, prints its summary and exits non-zero when a tile failed.
    """
    from ..errors import InputError
    from ..io._atomic import check_output_path, make_output_dir
    from ..io.tiles import is_tile_set

    outputs = [output, *(v[0] for v in (extra or {}).values() if v[0] is not None)]
    if not is_tile_set(input):
        if workers != 1 or scheduler is not None:
            raise InputError("--workers and --scheduler apply to a folder or glob of tiles")
        for path in outputs:  # one file each: fails at once, in one line, before any work
            check_output_path(path)
        check_suffix(output, POINTS_SUFFIXES, "points")
        for path, _ in (extra or {}).values():
            check_suffix(path, RASTER_SUFFIXES, "rasters")
        return False
    if neighbours:
        raise InputError("with a folder of tiles the neighbours are found from the tiles; "
                         "drop --neighbour")
    if workers != 1 and scheduler is not None:
        raise InputError("give either --workers (a local cluster) or --scheduler, not both")
    for path in outputs:  # folders of tiles
        make_output_dir(path)
    from ..tools.tiles import plan_tiles, run_tiles

    tasks = plan_tiles(input, output, crs=crs, buffer=buffer, suffix=suffix, extra=extra)
    with EngineProgress("tiles") as bar:
        summary = run_tiles(job, tasks, output, workers=workers, scheduler=scheduler,
                            progress=bar.blocks, buffer=buffer, crs=crs, **options)
    for line in summary.lines():
        click.echo(line, err=True)
    if summary.failed:
        raise click.exceptions.Exit(1)
    return True


def output_option(**kwargs):
    kwargs.setdefault("callback", check_output)
    return click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
                        help="Output file.", **kwargs)


def progress(iterable=None, *, length=None, label="", quiet=False, item_show_func=None):
    """A click progress bar shown on a terminal only (never in pipes or CI logs)."""
    import sys

    if quiet or not sys.stderr.isatty():
        class _Null:
            def __enter__(self):
                return self

            def __exit__(self, *a):
                return False

            def update(self, n, current_item=None):
                pass

            def __iter__(self):
                return iter(iterable)

        return _Null()
    return click.progressbar(iterable, length=length, label=label, file=sys.stderr,
                             item_show_func=item_show_func)


def progress_callback(bar):
    """A ``callback(done, total)`` for the library's jobs that advances ``bar`` to ``done``."""
    state = {"done": 0}

    def callback(done, total):
        bar.length = total
        bar.update(done - state["done"])
        state["done"] = done

    return callback


class EngineProgress:
    """Bars over the tasks of a run (blocks or tiles) and what they make (buildings,
    footprints), drawn with rich on a terminal only; nothing otherwise (pipes, CI
    logs, ``quiet``), where the command prints its one-line summary at the end.

    ``blocks(done, total)`` after each task; ``items(done, total)`` with
    ``total`` None while the number is not known (traced footprints).
    """

    #: the least time between two drawings of the bars (seconds); the last count is
    #: always drawn
    EVERY = 0.1

    def __init__(self, tasks="blocks", items=None, *, quiet=False):
        import sys

        self.labels = (tasks, items)
        self.live = not quiet and sys.stderr.isatty()
        self._bar = None
        self._ids = {}

    def __enter__(self):
        if self.live:
            from rich.console import Console
            from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,
                                       TimeElapsedColumn, TimeRemainingColumn)

            # drawn when a count changes, not by rich's refresh thread: a process with
            # no other thread can fork its workers (``--workers auto`` forks none beside
            # another thread, whose locks a child would inherit held)
            self._bar = Progress(TextColumn("{task.description:>10}"), BarColumn(),
                                 MofNCompleteColumn(), TimeElapsedColumn(), TimeRemainingColumn(),
                                 console=Console(stderr=True), transient=False,
                                 auto_refresh=False)
            self._bar.start()
            self._drawn = 0.0
        return self

    def __exit__(self, *exc):
        if self._bar is not None:
            self._bar.stop()
        return False

    def _set(self, which, done, total):
        if self._bar is None:
            return
        if which not in self._ids:
            self._ids[which] = self._bar.add_task(self.labels[which], total=total)
        self._bar.update(self._ids[which], completed=done, total=total)
        now = time.monotonic()
        if now - self._drawn >= self.EVERY or done == total:
            self._drawn = now
            self._bar.refresh()

    def blocks(self, done, total):
        self._set(0, done, total)

    def items(self, done, total):
        if self.labels[1] is not None:
            self._set(1, done, total)
