"""``lidar2city``: the root command, logging options and error reporting."""

from __future__ import annotations

import atexit
import contextlib
import gc
import logging
import os
import signal
import sys
import threading

import click

from ._lazy import LazyGroup

__all__ = ["cli", "main"]

#: set by :func:`main`: this process runs one command and ends
_STANDALONE: list = []


class _RootGroup(LazyGroup):
    """Turns lidar2city errors into one-line messages and a non-zero exit.

    A run records its outputs (:mod:`lidar2city.io._atomic`): when it fails or
    is interrupted (SIGINT, SIGTERM) everything it wrote is removed. An
    interrupt ends the process at once with status 130 (143 for SIGTERM),
    without unwinding: worker threads of the compression and JIT libraries
    are never torn down half-way, so no traceback and no crash.
    """

    def invoke(self, ctx):
        from ..errors import Lidar2CityError
        from ..io import _atomic

        _atomic.begin_run()
        previous = _install_interrupt_handlers()
        thresholds = gc.get_threshold()
        # a run makes millions of short-lived arrays and geometries, freed by reference
        # counting; with the default threshold (700) the cycle collector ran ~370 times
        # in a reconstruct of the Delft tile (~2 % of its CPU), every 10,000 26 times
        # (0.045 CPU s: it walks the modules the buildings import, scipy's thousands of
        # objects, before they grow old), every 50,000 14 times (0.031 s; same peak memory)
        gc.set_threshold(max(thresholds[0], _GC_THRESHOLD), *thresholds[1:])
        _freeze_at_exit()
        try:
            return super().invoke(ctx)
        except Lidar2CityError as exc:
            _fail(ctx, str(exc))
        except MemoryError:
            _fail(ctx, "out of memory; process fewer or smaller tiles")
        except BrokenPipeError:  # the reader of our output went away (`| head`): not an error
            with contextlib.suppress(Exception):
                os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            ctx.exit(1)
        except OSError as exc:  # an OS-level failure no tool turned into one of ours
            logging.getLogger(__name__).debug("OS error", exc_info=True)
            where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
            _fail(ctx, f"{where}{exc.strerror or exc}")
        finally:
            gc.set_threshold(*thresholds)
            _restore_handlers(previous, finished=True)
            _atomic.end_run()


#: allocations between two collections of the youngest generation during a run (a
#: local cluster's workers run with the same: ``lidar2city.tools.engine.GC_THRESHOLD``)
_GC_THRESHOLD = 50_000

_frozen_at_exit = []


def _freeze_at_exit():
    """At the interpreter's exit, move every object to the collector's permanent
    generation (:func:`gc.freeze`), once per process.

    Python ends by clearing its modules and collecting the cycles that held them
    (functions and their globals, classes, the imported libraries' objects): ~0.06
    CPU s of a reconstruct's ~4 (0.10-0.15 s before, 0.06 after, on the Delft tile),
    work whose only result is memory the operating system takes back anyway. Every
    output is closed and every ``atexit`` hook registered before this one still runs
    after it (they run last-in first-out); only that final collection finds nothing.
    """
    if not _frozen_at_exit:
        _frozen_at_exit.append(True)
        atexit.register(gc.freeze)


def _fail(ctx, message):
    from ..io._atomic import remove_run_outputs

    remove_run_outputs()
    click.echo(f"Error: {message}", err=True)
    ctx.exit(1)


def _on_interrupt(signum, frame):  # pragma: no cover - exercised in a subprocess
    from ..io._atomic import kept_for_resume, remove_run_outputs

    removed = remove_run_outputs()
    _stop_workers()
    note = f"; {len(removed)} partial output(s) removed" if removed else ""
    # a journal is named as kept before it is made (io.journal imported by then): kept
    # when complete, removed when the interrupt came while it was being made
    journal = sys.modules.get("lidar2city.io.journal")
    kept = [p for p in kept_for_resume() if journal is not None and journal.settle_interrupted(p)]
    if kept:  # the blocks finished are in the journal: say how to go on from them
        note += f"; the journal {kept[0]} is kept: run the same command with --resume to go on"
    with contextlib.suppress(Exception):
        os.write(2, f"\nError: interrupted{note}\n".encode())
    os._exit(130 if signum == signal.SIGINT else 143)


def _stop_workers():  # pragma: no cover - exercised in a subprocess
    """Kill the worker processes this process started (a local Dask cluster's): ended by
    os._exit they would outlive it for a while and log their lost connection."""
    mp = sys.modules.get("multiprocessing")
    if mp is None:
        return
    forked = sys.modules.get("lidar2city.tools.forked")
    if forked is not None:  # its children, killed below, are no failure to run again
        forked.STOPPING.set()
    engine = sys.modules.get("lidar2city.tools.engine")
    if engine is not None:
        # no semaphore made from now on (the queues of a worker a nanny starts in place
        # of one killed below) is left to the resource tracker to warn of
        with contextlib.suppress(Exception):
            engine.close_semaphores()
        # first the server workers are forked from: no worker restarted
        with contextlib.suppress(Exception):
            engine.kill_forkserver()
    with contextlib.suppress(Exception):
        for child in mp.active_children():
            with contextlib.suppress(Exception):
                child.kill()
    _release_semaphores()


def _release_semaphores():  # pragma: no cover - exercised in a subprocess
    """Unlink the named semaphores the cluster's nannies made in this process (their
    queues' locks): os._exit skips multiprocessing's exit hooks, so the resource
    tracker would unlink them itself and warn of "leaked semaphore objects"."""
    engine = sys.modules.get("lidar2city.tools.engine")
    if engine is not None:
        with contextlib.suppress(Exception):
            engine.release_semaphores()


def _install_interrupt_handlers():
    if threading.current_thread() is not threading.main_thread():
        return {}
    previous = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        previous[sig] = signal.signal(sig, _on_interrupt)
    return previous


def _restore_handlers(previous, *, finished=False):
    """Put the handlers of before the run back; in a process of its own
    (:func:`main`) a finished run ignores SIGINT instead while the interpreter
    ends: its outputs are complete and kept, and a Ctrl-C then must not turn
    it into click's "Aborted!" with status 1."""
    for sig, handler in previous.items():
        if finished and _STANDALONE and sig == signal.SIGINT:
            handler = signal.SIG_IGN
        signal.signal(sig, handler)


def _version() -> str:
    from .. import __version__

    return __version__


@click.group(cls=_RootGroup, exclude=("main",), context_settings={"help_option_names": ["-h", "--help"]})
@click.option("-v", "--verbose", count=True, help="More log output (-vv for debug).")
@click.option("-q", "--quiet", is_flag=True, help="Only errors.")
@click.version_option(version=_version(), prog_name="lidar2city")
def cli(verbose, quiet):
    """Airborne LiDAR to 3D city models.

    Typical use: `lidar2city demo`, `lidar2city info TILE.laz`,
    `lidar2city reconstruct TILE.laz --footprints F.gpkg -o out.city.json`.
    """
    level = logging.ERROR if quiet else (logging.WARNING, logging.INFO, logging.DEBUG)[min(verbose, 2)]
    logging.basicConfig(level=level, stream=sys.stderr,
                        format="%(levelname)s %(name)s: %(message)s")


def main():  # pragma: no cover - the console script, exercised in subprocesses
    """The ``lidar2city`` command: :func:`cli` in a process of its own."""
    _STANDALONE.append(True)
    return cli()


if __name__ == "__main__":  # pragma: no cover - ``python -m lidar2city.cli.main``
    # the package's module, not this copy run as __main__: one copy of the run's state
    # (_STANDALONE), which the subcommands import from it
    from lidar2city.cli.main import main as _main

    _main()
