"""An executor whose workers are forked from this process when the items are handed out.

:class:`ForkExecutor` (``--workers N`` on this machine, where the platform forks):
at :meth:`ForkExecutor.map`, after this process has imported, planned and
read what the items share (a tile decoded once, :func:`lidar2city.tools.task.hold_tiles`),
``N - 1`` children are forked from it (multiprocessing's ``fork`` context).
They inherit the items, the run-wide arguments and every decoded array
copy-on-write: nothing is imported, sent or read again, where a Dask
cluster's workers start, import, receive the plan and decode the tile first
(measured in ``benchmarks/bench_engine_tile.py``). Each child runs the runs
of items this process sends it (indices over a pipe) and sends back their
results (pickled); this process runs its own share meanwhile, as
:meth:`lidar2city.tools.engine.DaskExecutor._map_shared` does, and hands out
the runs in the same way: no side waits while the other has runs left.
The caller puts the results in its fixed order: the bytes are those of one
process.

A child that dies, or whose results cannot be sent, has its run re-run here
(a batch never dies on one building); a task that raises is tried again as in
:class:`~lidar2city.tools.engine.InProcess`. The children ignore SIGINT (a
terminal's Ctrl-C reaches the whole process group): this process's handler
removes the partial output and kills them (``multiprocessing.active_children``,
:func:`lidar2city.cli.main._stop_workers`); a child whose parent is gone sees
its pipe closed and ends. Threads alive at the fork are not in the children:
LAZ is decoded there on the calling thread (lazrs's thread pool, created by
this process's decoding, has no threads in a child:
:func:`lidar2city.io.las.laz_backend`), OpenBLAS re-creates its own, and no
Dask runs in this process.
"""

from __future__ import annotations

import contextlib
import gc
import logging
import multiprocessing
import os
import pickle
import queue
import signal
import sys
import threading

logger = logging.getLogger(__name__)

__all__ = ["ForkExecutor", "CAN_FORK"]

#: whether the workers are forked here: on Linux only. macOS forks, but its system
#: libraries (Accelerate, the Objective-C runtime) are not safe in a child forked
#: from a process that used them, which is why Python starts macOS processes by
#: spawning; elsewhere a local run of several workers is a Dask cluster
#: (:func:`lidar2city.tools.engine.make_executor`)
CAN_FORK = (sys.platform.startswith("linux") and hasattr(os, "fork")
            and "fork" in multiprocessing.get_all_start_methods())

#: set when this process is stopping (an interrupt, :func:`lidar2city.cli.main._stop_workers`):
#: a child that ends from then on was killed by it, no failure to report or run again
STOPPING = threading.Event()

#: the signals a child must not take from this process's handlers between its fork
#: and its own set-up (blocked around the fork, inherited blocked by the child)
_SIGNALS = {signal.SIGINT, signal.SIGTERM}


class ForkExecutor:
    """Run tasks here and in ``workers - 1`` processes forked from this one at each
    :meth:`map` (see the module's doc)."""

    #: workers of this machine that read this process's temporary files: they
    #: need none, they inherit its memory (:attr:`inherits`)
    local_workers = False
    #: the workers inherit this process's memory as it is when :meth:`map` is called
    inherits = True
    startup_seconds = 0.0

    def __init__(self, workers: int, preload=()):
        if not CAN_FORK:  # pragma: no cover - make_executor never asks for it there
            raise RuntimeError("this platform does not fork")
        self.workers = int(workers)
        #: modules the tasks import, imported here before the first fork (:func:`_preload`)
        self.preload = tuple(preload)
        self._cpu: dict = {}

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def ready(self):
        return self

    def describe(self) -> str:
        return f"{self.workers - 1} forked process(es) and this one"

    def process_cpu(self) -> dict:
        """CPU seconds each child spent, by ``host:pid`` (children of the maps so far)."""
        return dict(self._cpu)

    def map(self, fn, items, *args, run_hook=None, costs=None, ahead=(), balance=False):
        """As :meth:`lidar2city.tools.engine.InProcess.map`: ``(index, result or
        exception)`` as they finish. The items are handed out one by one: from
        contiguous shares of equal ``costs``, this process's run backward, a side
        whose share is done taking from the far end of another's (:func:`_dealing`);
        ``balance``: one queue of single items in order, taken from its front by
        every side. A single item, or a single worker, runs here without a fork."""
        from .engine import InProcess, RunDealer

        items = list(items)
        if not items:
            return
        n = len(items)
        runs = [(i, i + 1) for i in range(n)]
        children = min(self.workers - 1, n - 1)
        if children < 1:
            yield from InProcess().map(fn, items, *args, run_hook=run_hook, ahead=ahead)
            return
        if balance:
            dealer = RunDealer(n, children, balance=True)
        else:
            dealer = RunDealer(n, children, **_dealing(n, self.workers, costs))
        # runs of children that died go back to the dealer's rerun: run here
        lock, rerun, results = dealer.lock, dealer.rerun, queue.SimpleQueue()

        def take_mine():
            r, ahead = dealer.mine()
            return r, [x for q in ahead for x in items[slice(*runs[q])]]

        take_theirs = dealer.theirs  # a child is sent run indices: it holds the items

        # what this process holds at the fork is moved out of its collector's reach
        # while the children share it (:func:`_frozen`): its collections during the map
        # neither walk those objects nor write to, and so copy, the pages they share
        frozen = _frozen()
        # and the heap's free pages given back to the system: a page the two sides
        # share and one of them allocates into is copied, and the other keeps its
        # stale copy; given back, it is one fresh page of the side that uses it
        from .task import give_back_memory

        give_back_memory()
        try:
            _preload(self.preload)
            procs, conns = _fork_children(children, fn, items, args, runs, run_hook)
        except BaseException:
            frozen()  # no child to share with: the objects go back to the collector
            raise
        threads = []

        def feed(k):
            conn, r = conns[k], None
            try:
                while True:
                    r, nxt = take_theirs(k)
                    if r is None:
                        conn.send(None)
                        cpu = conn.recv()  # its CPU seconds, as it ends
                        with lock:
                            self._cpu[cpu[0]] = self._cpu.get(cpu[0], 0.0) + cpu[1]
                        return
                    conn.send((r, nxt))
                    got = conn.recv()
                    try:
                        if got[0] != "sent":
                            raise RuntimeError(got[1])
                        outs = pickle.loads(got[1])
                    except Exception as exc:  # noqa: BLE001 - its results lost: run here
                        logger.warning("a forked worker's results of items %d to %d did not "
                                       "come back (%s): run again here", *runs[r], exc)
                        with lock:
                            rerun.append(r)
                    else:
                        results.put((runs[r][0], outs))
                    r = None
            except (EOFError, OSError) as exc:  # the child died (or was killed)
                if r is not None and not STOPPING.is_set():  # (not by this process's stop)
                    logger.warning("a forked worker ended (%s) with items %d to %d: run "
                                   "again here", type(exc).__name__, *runs[r])
                    with lock:
                        rerun.append(r)
            except BaseException as exc:  # noqa: BLE001 - raised in the caller's thread
                results.put(exc)
            finally:
                results.put(None)  # this feeder is done (and wakes the caller)

        try:
            for k in range(children):
                t = threading.Thread(target=feed, args=(k,), name=f"lidar2city-fork-feed-{k}",
                                     daemon=True)
                t.start()
                threads.append(t)
            done = 0

            def drain(block):
                nonlocal done
                while done < children:
                    try:
                        got = results.get(block=block)
                    except queue.Empty:
                        return
                    if got is None:
                        done += 1
                        if block:
                            return  # a run may have come back: look for it
                        continue
                    if isinstance(got, BaseException):
                        raise got
                    a, outs = got
                    for j, out in outs:
                        yield a + j, out
                    if block:
                        return

            while True:
                r, nxt = take_mine()
                if r is None:
                    if done >= children:
                        with lock:
                            if not rerun:
                                break
                        continue
                    yield from drain(True)
                    continue
                a, b = runs[r]
                for j, out in InProcess().map(fn, items[a:b], *args, run_hook=run_hook,
                                              ahead=nxt):
                    yield a + j, out
                    yield from drain(False)
            yield from drain(False)
            if run_hook is not None:
                # the runs this process kept inputs ahead for may have gone to a child:
                # keep only what the caller's next items read, as InProcess.map ends
                after = run_hook([], list(ahead))
                if after is not None:
                    after(-1)
        finally:
            _end_children(procs, conns, threads)
            frozen()


def _dealing(n: int, workers: int, costs=None) -> dict:
    """How :meth:`ForkExecutor.map` deals ``n`` items of ``costs`` (not ``balance``):
    the keywords of its :class:`~lidar2city.tools.engine.RunDealer` of single items.

    Each side gets a contiguous share of the items of about equal total cost
    (:func:`~lidar2city.tools.engine.shares_of`), runs them one by one, and, its
    share done, takes single items from the far end of another's: a side waits
    at the end for at most the one item the other is running. Runs of several
    items dealt in shares of equal numbers of runs (as a cluster's tasks are,
    :func:`~lidar2city.tools.engine.runs_of`) could leave it a whole run: on
    4 x 4 copies of the Delft tile (20 blocks of 250 m, 15-226 buildings each) the
    child's share of runs held 1,201 buildings and this process's 911, and the
    child ran its last run of 2 blocks (15 CPU s) while this process waited
    (``benchmarks/bench_scale_timeline.py``). This process runs its share
    backward (:class:`RunDealer`'s ``backward``), so the two sides meet where
    their shares meet and a side's next item neighbours its last; the items told
    ahead of an item (whose tiles it keeps) reach as far as those of the runs
    of :func:`runs_of` did (:data:`~lidar2city.tools.engine.AHEAD_RUNS` runs),
    so that a tile a row of blocks leaves to the next row is still decoded once
    a side."""
    from .engine import runs_of

    groups = [0] * n
    for g, (a, b) in enumerate(runs_of(n, workers, costs)):
        groups[a:b] = [g] * (b - a)
    return {"costs": None if costs is None else list(costs), "groups": groups,
            "backward": True}


def _preload(modules) -> None:
    """Import ``modules`` (the tasks' own: :func:`lidar2city.tools.engine.worker_modules`)
    here, before the children are forked, so that they inherit them: imported by
    the tasks after the fork, each process paid for them in its first run
    (Delft with footprints: 291 modules, scipy's among them, ~0.35 CPU s a process,
    ``benchmarks/bench_engine_tile_timeline.py``). Wall time is the same on an idle
    machine (the import moves from the two processes' first runs to before the
    fork); the CPU seconds of the run fall by one process's imports. A module that
    cannot be imported is left to the task (which reports it as its own failure)."""
    import importlib

    for name in modules:
        if name in sys.modules:
            continue
        try:
            importlib.import_module(name)
        except Exception as exc:  # noqa: BLE001 - the task that needs it says so
            logger.debug("preloading %s before the fork failed: %s", name, exc)


def _frozen():
    """Move every object this process's collector tracks to its permanent generation
    (:func:`gc.freeze`), as Python's documentation advises before a fork; returns the
    function that moves them back (:func:`gc.unfreeze`), for when the children are gone.

    A collection in this process while its children run (every ``gc`` threshold's
    allocations of its own share of the items) walks every object it tracks and writes
    to each one's header: each page of the parent's objects written so is copied,
    though neither side needed a copy. Frozen, they are not walked: a cycle made
    before the fork is collected only after the map (at most what the map leaves).
    Objects already frozen (a caller's own freeze) stay frozen: only the ones moved
    here are let go.
    """
    if gc.get_freeze_count():  # someone else's freeze: leave the permanent generation alone
        return lambda: None
    gc.freeze()
    return gc.unfreeze


def _fork_children(count, fn, items, args, runs, run_hook):
    """Fork ``count`` children (:func:`_child`); ``(processes, this side's pipe ends)``."""
    ctx = multiprocessing.get_context("fork")
    procs, conns = [], []
    mask = threading.current_thread() is threading.main_thread()
    try:
        for _ in range(count):
            here, there = ctx.Pipe()
            if mask:
                signal.pthread_sigmask(signal.SIG_BLOCK, _SIGNALS)
            try:
                p = ctx.Process(target=_child, args=(there, list(conns) + [here], fn, items,
                                                     args, runs, run_hook),
                                name="lidar2city-fork", daemon=True)
                p.start()
            finally:
                if mask:
                    signal.pthread_sigmask(signal.SIG_UNBLOCK, _SIGNALS)
            there.close()  # the child's end: closed here, its death is seen as EOF
            procs.append(p)
            conns.append(here)
    except BaseException:
        _end_children(procs, conns, [])
        raise
    return procs, conns


def _end_children(procs, conns, threads) -> None:
    """End the children and their feeders; no process is left behind. A child whose
    feeder still runs (the caller stopped early: an error, an interrupt) is killed;
    one told to end is waited for."""
    early = len(threads) < len(procs) or any(t.is_alive() for t in threads)
    for p in procs:
        if early and p.exitcode is None:
            with contextlib.suppress(OSError):
                p.kill()
    for t in threads:
        t.join(timeout=5)
    for p in procs:
        p.join(timeout=10)
        if p.exitcode is None:  # pragma: no cover - a child that did not end when told
            with contextlib.suppress(OSError):
                p.kill()
            p.join(timeout=5)
    for c in conns:
        with contextlib.suppress(OSError):
            c.close()


def _child(conn, others, fn, items, args, runs, run_hook):  # pragma: no cover - in a child
    """A forked worker: run the runs this process's parent sends (``(run, ahead runs)``;
    None: end), sending each run's results pickled, then its CPU seconds. Ends with
    ``os._exit``: nothing of the parent's (its exit handlers, its outputs) is run or
    touched here."""
    import socket

    from .engine import InProcess

    code = 0
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles a Ctrl-C
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, _SIGNALS)
        for c in others:  # the parent's ends of the pipes: its death closes ours
            c.close()
        # what the parent holds is never walked by this child's collections (whose
        # writes would copy the pages it shares with the parent)
        gc.freeze()
        while True:
            got = conn.recv()
            if got is None:
                break
            r, nxt = got
            a, b = runs[r]
            ahead = [x for q in nxt for x in items[slice(*runs[q])]]
            outs = list(InProcess().map(fn, items[a:b], *args, run_hook=run_hook, ahead=ahead))
            try:
                data = pickle.dumps(outs, protocol=pickle.HIGHEST_PROTOCOL)
            except Exception as exc:  # noqa: BLE001 - the parent runs them again
                conn.send(("failed", f"{type(exc).__name__}: {exc}"))
                continue
            conn.send(("sent", data))
        t = os.times()
        conn.send((f"{socket.gethostname()}:{os.getpid()}", t.user + t.system))
    except (EOFError, OSError):  # the parent is gone or stopped: end
        code = 1
    except BaseException:  # noqa: BLE001 - the parent runs the run again
        logger.exception("a forked worker failed")
        code = 1
    finally:
        with contextlib.suppress(Exception):
            conn.close()
        for stream in ("stdout", "stderr"):
            with contextlib.suppress(Exception):
                getattr(__import__("sys"), stream).flush()
        os._exit(code)

