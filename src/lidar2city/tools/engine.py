"""Executors: run one task function over many items, in this process or on Dask.

``executor.map(fn, items, *args, run_hook=None)`` yields
``(item_index, result_or_exception)`` as tasks finish, in any order; the caller puts results back in its own fixed
order, so nothing else knows which executor ran them. A task that raises is
tried once more; one that fails twice is yielded as its exception (the run
goes on). With Dask, a worker that dies is replaced and its task rerun on
another worker; a task that kills two workers comes back as ``KilledWorker``.

- :class:`InProcess` (``workers=1``, the default): tasks one after the other.
- :class:`lidar2city.tools.forked.ForkExecutor` (``workers=N`` on this machine,
  where the system forks: :func:`make_executor`, :func:`local_executor`): this
  process and ``N - 1`` processes forked from it when the items are handed out,
  inheriting what it has imported, planned and decoded.
- :class:`DaskExecutor`: a ``dask.distributed`` ``LocalCluster`` of ``workers``
  processes (one thread each), or an existing cluster given by its scheduler
  address (started with ``dask scheduler`` / ``dask worker``). A cluster task
  is a run of consecutive items (:func:`runs_of`), so a worker's items are
  neighbours that share their inputs (a block's tiles); each worker is dealt a
  contiguous share of the runs (:func:`shares_of`) and each run is told the
  share's next runs, so those inputs pass from run to run.
  The cluster starts in the background when the executor is entered; its
  worker processes are forked from a server that imported Dask and the task
  modules once (:data:`START_METHOD`, started first: :func:`_start_forkserver`),
  which ends with the last local cluster.
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import multiprocessing
import os
import sys
import threading
import time
from collections import deque

from ..errors import DependencyError, InputError

logger = logging.getLogger(__name__)

__all__ = ["InProcess", "DaskExecutor", "make_executor", "runs_of", "shares_of", "RETRIES",
           "kill_forkserver", "START_METHOD", "start_worker_server", "worker_modules",
           "CONNECT_TIMEOUT", "local_executor", "LOCAL_EXECUTOR_ENV",
           "RUNS_PER_WORKER", "RUN_MAX_COST", "AHEAD_RUNS"]

#: times a failed task is tried again before its failure is reported
RETRIES = 1
#: seconds to wait for a scheduler address to answer
CONNECT_TIMEOUT = 15


class InProcess:
    """Run tasks in this process, in order."""

    workers = 1
    #: seconds it took to start the executor (a cluster's processes)
    startup_seconds = 0.0
    #: worker processes of this machine, which read this process's temporary
    #: files (a local cluster's): none here
    local_workers = False

    def process_cpu(self) -> dict:
        """CPU seconds of each worker process so far (start-up and imports included):
        none here, the tasks run in the caller's process."""
        return {}

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def ready(self):
        """Ready at once (see :meth:`DaskExecutor.ready`)."""
        return self

    def map(self, fn, items, *args, run_hook=None, costs=None, ahead=(), balance=False):
        """``fn(item, *args)`` for every item in turn: ``(index, result or exception)``.

        ``run_hook(items, ahead)``, when given, is called once with the items this
        process will run in turn and returns ``after(k)``, called after the
        ``k``-th of them (e.g. to keep only the inputs the next items share);
        ``ahead``: the items the process is expected to run after these (a
        cluster worker's next runs), whose inputs may be kept too.
        ``costs`` (one number per item) tells a cluster how to cut the items
        into runs of equal work; here they are all one run. ``balance``: a
        cluster hands the items out one by one, in order, to whichever worker
        is free (see :meth:`DaskExecutor.map`); here nothing changes.
        """
        items = list(items)
        after = run_hook(items, list(ahead)) if run_hook is not None and items else None
        try:
            for i, item in enumerate(items):
                for attempt in range(RETRIES + 1):
                    try:
                        out = fn(item, *args)
                    except Exception as exc:  # noqa: BLE001 - reported per task, the run goes on
                        logger.warning("task %d failed (attempt %d): %s", i, attempt + 1, exc)
                        out = exc
                        continue
                    break
                if after is not None:
                    after(i)
                yield i, out
        finally:
            if after is not None:  # the end of the run, or a consumer that stopped
                after(len(items) - 1)

    def describe(self) -> str:
        return "in-process"


class DaskExecutor:
    """Run tasks on a Dask cluster: a local one of ``workers`` processes, or ``scheduler``'s."""

    def __init__(self, workers: int | None = None, scheduler: str | None = None,
                 preload=(), client_computes: bool = False):
        import importlib.util

        # found, not imported: Dask is imported by the thread that starts the cluster
        if importlib.util.find_spec("distributed") is None:  # pragma: no cover - a core dependency
            raise DependencyError("--workers / --scheduler need dask.distributed: "
                                  "pip install 'dask[distributed]'")
        self.scheduler = scheduler
        self.workers = workers
        self.preload = tuple(preload)
        #: a local cluster of ``workers - 1`` processes, this process computing
        #: the rest (:meth:`_map_shared`)
        self.client_computes = bool(client_computes and scheduler is None
                                    and int(workers or 1) > 1)
        self._cluster = None
        self._client = None
        self._starting = None
        self._error = None
        self._dlog = None
        self._local = False
        self.startup_seconds = 0.0

    def __enter__(self):
        """Start the cluster (or connect to it) in the background: the caller plans
        its work meanwhile; the first :meth:`map` waits for it (and raises its
        error, e.g. a scheduler that does not answer).

        For a local cluster the server its workers are forked from is started
        first (:func:`_start_forkserver`), so that it imports Dask and the
        task modules (``preload``) on another core while this process imports
        Dask and starts the scheduler."""
        t0 = time.perf_counter()
        self._error = None
        if self.scheduler is None:
            with _LOCAL_LOCK:
                _LOCAL_CLUSTERS[0] += 1
            self._local = True
            # the cluster's start (scheduler, nannies, each worker's registration) and,
            # later, the handing out of runs take the interpreter lock from this
            # process's planning or computing within SWITCH_INTERVAL, not Python's 5 ms
            self._interval = sys.getswitchinterval()
            sys.setswitchinterval(min(self._interval, SWITCH_INTERVAL))
            _track_semaphores()
            try:
                _start_forkserver(self.preload)
            except Exception as exc:  # noqa: BLE001 - Dask starts it as it would have
                logger.debug("the worker server did not start early: %s", exc)

        def start():
            try:
                self._start()
                # the workers import the task modules now, not in their first task;
                # those of our own cluster end without tearing their interpreter down.
                # Workers forked from the server have both (its preload; a forked
                # process ends so): no round trip to them before the first task
                if self.scheduler is not None or START_METHOD != "forkserver":
                    self._client.run(_warm, self.scheduler is None)
            except BaseException as exc:  # noqa: BLE001 - raised by ready()
                self._error = exc
            finally:
                self.startup_seconds = time.perf_counter() - t0

        self._starting = threading.Thread(target=start, name="lidar2city-dask-start",
                                          daemon=True)
        self._starting.start()
        return self

    @property
    def local_workers(self) -> bool:
        """Whether the workers are processes of this machine, which read this process's
        temporary files (a local cluster's; an existing cluster's may be anywhere)."""
        return self.scheduler is None

    def ready(self):
        """Wait for the cluster started by ``__enter__``; raise its start's error."""
        if self._starting is not None:
            self._starting.join()
            self._starting = None
        if self._error is not None:
            err, self._error = self._error, None
            raise err
        return self

    def process_cpu(self) -> dict:
        """CPU seconds of each worker process so far (start-up and imports included),
        by worker address (none when the cluster did not start)."""
        self.ready()
        if self._client is None:
            return {}
        return dict(sorted(self._client.run(_process_cpu).items()))

    def _start(self):
        import dask
        from distributed import Client, LocalCluster

        # distributed logs at INFO on its own handlers, tracebacks of connections it closes
        # itself included: only its warnings reach the user unless our log is at debug
        self._dlog = logging.getLogger("distributed")
        self._dlog_level = self._dlog.level
        if logging.getLogger("lidar2city").getEffectiveLevel() > logging.DEBUG:
            self._dlog.setLevel(logging.WARNING)

        if self.scheduler is not None:
            try:
                self._client = Client(self.scheduler, timeout=f"{CONNECT_TIMEOUT}s",
                                      set_as_default=False)
            except (OSError, TimeoutError, ValueError) as exc:
                raise InputError(f"no Dask scheduler answers at {self.scheduler!r} within "
                                 f"{CONNECT_TIMEOUT} s ({type(exc).__name__}); start one with "
                                 "`dask scheduler` and `dask worker ADDRESS`") from None
            self.workers = len(self._client.scheduler_info().get("workers", {}))
            return self
        # a task that kills two workers is reported, not retried for ever
        with dask.config.set({"distributed.scheduler.allowed-failures": RETRIES,
                              "distributed.worker.daemon": False,
                              "distributed.worker.multiprocessing-method": START_METHOD,
                              "distributed.nanny.pre-spawn-environ": _worker_environ(),
                              **QUIET_CLUSTER}):
            self._cluster = LocalCluster(n_workers=self.workers - self.client_computes,
                                         threads_per_worker=1,
                                         processes=True, dashboard_address="127.0.0.1:0",
                                         host="127.0.0.1", silence_logs=logging.ERROR)
            self._client = Client(self._cluster, set_as_default=False)
        return self

    def __exit__(self, *exc):
        if self._starting is not None:  # the caller is done before the cluster was needed
            self._starting.join()
            self._starting = None
        try:
            self._close()
        finally:
            if self._error is not None and exc[0] is None:  # a start that failed unseen
                raise self._error
        return False

    def _close(self):
        if self._client is not None:
            self._client.close()
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None
        if self._local:
            self._local = False
            sys.setswitchinterval(self._interval)
            with _LOCAL_LOCK:
                _LOCAL_CLUSTERS[0] -= 1
                last = _LOCAL_CLUSTERS[0] == 0
            if last:  # not while another cluster has workers forked from the server
                _stop_forkserver()
        if self._dlog is not None:
            self._dlog.setLevel(self._dlog_level)

    def map(self, fn, items, *args, run_hook=None, costs=None, balance=False):
        """As :meth:`InProcess.map`; a cluster task is a run of consecutive items
        (:func:`runs_of`, of equal total ``costs`` when given), and ``run_hook``
        is called on the worker per run.

        ``balance``: every item is a task of its own, tied to no worker, handed
        out in the items' order to whichever worker is free (Dask queues
        them on the scheduler): a few items of uneven work that share their
        inputs (the parts of one block, heaviest first) end about together.
        Each is told the next :data:`AHEAD_RUNS` items, whose inputs it keeps.

        The runs are dealt to the workers in contiguous shares (:func:`shares_of`):
        each worker is asked to run its share's runs in order (Dask may still move
        a run to an idle worker near the end, or to another when one dies), and
        each run is told the share's next runs (``ahead``, :data:`AHEAD_RUNS`), so
        a worker keeps the inputs its next runs share with this one instead of
        reading them again.
        """
        from distributed import as_completed

        items = list(items)
        if not items:
            return
        if self.client_computes:
            yield from self._map_shared(fn, items, args, run_hook, costs, balance)
            return
        self.ready()
        # run-wide arguments sent once to every worker, not once per task
        shared = [self._client.scatter(a, broadcast=True, hash=False) for a in args]
        futures, where = [], {}
        if balance:
            for i in range(len(items)):
                fut = self._client.submit(_run_many, items[i:i + 1], *shared, fn=fn,
                                          run_hook=run_hook, own=self.scheduler is None,
                                          ahead=items[i + 1:i + 1 + AHEAD_RUNS], pure=False,
                                          retries=RETRIES, priority=len(items) - i)
                futures.append(fut)
                where[fut.key] = (i, i + 1)
        runs = [] if balance else runs_of(len(items), self.workers, costs)
        names = sorted(self._client.scheduler_info().get("workers", {}))
        shares = shares_of(len(runs), max(1, len(names)))
        for rank, (k, r) in enumerate(_dealt(shares)):
            a, b = runs[r]
            # the share's next runs (the tiles they read are kept for them), not all
            # the rest: what a task carries stays bounded whatever the area
            nxt = min(r + AHEAD_RUNS, shares[k][1] - 1)
            ahead = items[b:runs[nxt][1]] if nxt > r else []
            # earlier submitted, higher priority: each worker's runs start in order
            fut = self._client.submit(_run_many, items[a:b], *shared, fn=fn, run_hook=run_hook,
                                      ahead=ahead, own=self.scheduler is None, pure=False,
                                      retries=RETRIES,
                                      priority=len(runs) - rank,
                                      workers=[names[k]] if names else None,
                                      allow_other_workers=True)
            futures.append(fut)
            where[fut.key] = (a, b)
        try:
            with self._client.as_current():
                completed = as_completed(futures)
            for fut in completed:
                start, stop = where[fut.key]
                try:
                    outs = fut.result()
                except Exception as exc:  # noqa: BLE001 - reported per task, the run goes on
                    logger.warning("tasks %d to %d failed on the cluster: %s", start, stop - 1,
                                   exc)
                    outs = [(j, exc) for j in range(stop - start)]
                fut.release()
                for j, out in outs:
                    yield start + j, out
        finally:
            for f in futures:
                f.cancel()

    def _map_shared(self, fn, items, args, run_hook, costs, balance):
        """:meth:`map` with this process computing too (:attr:`client_computes`).

        The runs are cut and dealt as for ``workers`` processes (:func:`runs_of`,
        :func:`shares_of`): the cluster's ``workers - 1`` processes get the first
        shares, this process the last, which it runs in order as :class:`InProcess`
        does from the moment it is asked, while the cluster may still be starting.
        A thread hands the cluster's workers their runs once it is up, one at a
        time each (the front of its share), and collects their results. So no
        run waits on a busy side while the other is idle: a worker whose share
        is done gets the last run of this process's share, and this process,
        its share done, takes the last run of the largest share not yet handed
        out. A cluster that fails to start leaves every run to this process (a
        warning). ``balance``: one queue of single items in order, taken from its
        front by both sides. Results and retries as :meth:`map`.
        """
        import queue

        from distributed import as_completed

        n = len(items)
        runs = [(i, i + 1) for i in range(n)] if balance else runs_of(n, self.workers, costs)
        dealer = RunDealer(len(runs), self.workers - 1, balance=balance)
        lock, results, stop = dealer.lock, queue.SimpleQueue(), threading.Event()
        futures, end, finished = {}, object(), []

        def items_of(rs):
            return [x for r in rs for x in items[slice(*runs[r])]]

        def take_mine():
            r, ahead = dealer.mine()
            return r, items_of(ahead)

        def take_theirs(k):
            r, ahead = dealer.theirs(k)
            return r, items_of(ahead)

        def feed():
            try:
                try:
                    self.ready()
                except Exception as exc:  # noqa: BLE001 - this process runs every run itself
                    logger.warning("the local cluster did not start (%s: %s): this process "
                                   "runs every task", type(exc).__name__, exc)
                if self._client is None:
                    return
                shared = [self._client.scatter(a, broadcast=True, hash=False) for a in args]
                names = sorted(self._client.scheduler_info().get("workers", {}))
                with self._client.as_current():
                    done = as_completed()

                def give(k):
                    r, ahead = take_theirs(k)
                    if r is None:
                        return
                    a, b = runs[r]
                    # a worker of several is asked for its share's runs (its tiles kept
                    # from run to run); one alone is asked for none: a dead one's run
                    # waits for its successor (a restriction to it would wait for ever)
                    fut = self._client.submit(
                        _run_many, items[a:b], *shared, fn=fn, run_hook=run_hook, ahead=ahead,
                        own=True, pure=False, retries=RETRIES, priority=n - a,
                        workers=[names[k]] if len(names) > 1 else None,
                        allow_other_workers=len(names) > 1)
                    with lock:
                        futures[fut.key] = (fut, a, b, k)
                    done.add(fut)

                for k in range(max(1, len(names))):
                    give(k)
                for fut in done:
                    with lock:
                        _, a, b, k = futures.pop(fut.key)
                    try:
                        outs = fut.result()
                    except Exception as exc:  # noqa: BLE001 - reported per task, the run goes on
                        logger.warning("tasks %d to %d failed on the cluster: %s", a, b - 1, exc)
                        outs = [(j, exc) for j in range(b - a)]
                    fut.release()
                    results.put((a, outs))
                    if stop.is_set():
                        break
                    give(k)
            except BaseException as exc:  # noqa: BLE001 - raised in the caller's thread
                results.put(exc)
            finally:
                results.put(end)

        def drain(block):
            while not finished:
                try:
                    got = results.get(block=block)
                except queue.Empty:
                    return
                if got is end:
                    finished.append(True)
                    return
                if isinstance(got, BaseException):
                    raise got
                a, outs = got
                for j, out in outs:
                    yield a + j, out

        feeder = threading.Thread(target=feed, name="lidar2city-dask-feed", daemon=True)
        feeder.start()
        try:
            while True:
                r, ahead = take_mine()
                if r is None:
                    break
                a, b = runs[r]
                for j, out in InProcess().map(fn, items[a:b], *args, run_hook=run_hook,
                                              ahead=ahead):
                    yield a + j, out
                    yield from drain(False)
            while not finished:
                yield from drain(True)
        finally:
            stop.set()
            with lock:
                pending = [v[0] for v in futures.values()]
            for fut in pending:
                fut.cancel()
            feeder.join(timeout=5)

    def describe(self) -> str:
        if self.client_computes:
            return f"Dask LocalCluster of {self.workers - 1} worker(s) and this process"
        if self.scheduler is not None:  # its workers are counted once it answers
            self.ready()
        return (f"Dask scheduler {self.scheduler} ({self.workers} workers)" if self.scheduler
                else f"Dask LocalCluster of {self.workers} workers")


#: seconds a thread of a local cluster's client holds the interpreter lock while
#: another waits for it (Python's default: 0.005): the cluster's event loop (its
#: start, a worker's registration, a result) and the thread that hands a worker
#: its next run (:meth:`DaskExecutor._map_shared`) wait at most this long for the
#: planning or computing thread
SWITCH_INTERVAL = 0.001

#: runs per worker: a worker's runs are one contiguous share whose inputs pass
#: from run to run (:func:`shares_of`), so runs cost no extra reading; several
#: per worker let an idle worker take a short run off a slow one at the end
RUNS_PER_WORKER = 4

#: the runs of its share a run is told of (their items travel with the task):
#: the tiles a run decodes are kept for these too, so a strip of tiles that a
#: row of blocks leaves to the next row is decoded once even when a run is
#: shorter than a row
AHEAD_RUNS = 3

#: the most work one cluster task takes (in ``costs`` units: buildings for
#: blocks of footprints, else items): a task returns its items' results
#: together when it ends, so without a cap a worker would hold the results of
#: 1 / (RUNS_PER_WORKER x workers) of the whole area, unbounded for a country.
#: 1000 buildings of LoD2.2 are a few tens of MB; a run of them still spans
#: tens of blocks, so each tile is decoded about once (a run boundary costs
#: one extra decoding of the tiles its two sides share)
RUN_MAX_COST = 1000

#: how a local cluster starts its worker processes: forked from a server process
#: (Python's ``forkserver``, started by the first cluster of a client process)
#: that has imported Dask and NumPy once, rather than each a fresh interpreter
#: importing them (``spawn``, Dask's default): measured 0.33 -> 0.05
#: CPU-second per worker until it is ready (the server's own imports, ~0.3
#: CPU-second, are paid once), the cluster ready sooner (1.8 -> 0.9 s at load
#: ~5), 116 -> 109 MB peak per worker on 144 tiles; a forked worker also ends
#: without tearing its interpreter down. ``spawn`` where there is no
#: ``forkserver`` (Windows); a worker Dask restarts after a death is spawned.
START_METHOD = ("forkserver" if "forkserver" in multiprocessing.get_all_start_methods()
                else "spawn")

#: Dask settings of a local cluster: no statistical profiler (it samples every
#: thread's stack every 10 ms) and the periodic checks of the event loop, the
#: system and the memory every second or more instead of every 20 / 100 / 500 ms:
#: each wakes the worker's event loop, which takes the interpreter lock from the
#: task (measured: 7 % of a busy task's CPU with the defaults, 1 % with these)
QUIET_CLUSTER = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.worker.memory.monitor-interval": "1s",
}


def runs_of(n: int, workers: int, costs=None, max_cost: float | None = None) -> list:
    """``(start, stop)`` of the runs of consecutive items the cluster's tasks take.

    Items given in a spatial order (the planner's blocks, row by row) share
    their inputs with their neighbours (the tiles a block reads): a worker that
    takes a run of consecutive items decodes each tile about once, where items
    dealt one by one to alternate workers make every worker decode every tile.
    About ``RUNS_PER_WORKER`` runs per worker, of equal length, or of equal
    total ``costs`` (one non-negative number per item, e.g. its buildings) when given;
    more runs (a multiple of ``workers``) when that would give a run more than ``max_cost`` (default
    :data:`RUN_MAX_COST`; an item costs 1 without ``costs``), so that what a
    task holds is bounded whatever the area (a single item may cost more).
    """
    import numpy as np

    max_cost = RUN_MAX_COST if max_cost is None else max_cost
    total = (np.arange(1, n + 1, dtype=np.float64) if costs is None
             else np.cumsum(np.asarray(costs, dtype=np.float64).reshape(n)))
    w = max(1, int(workers or 1))
    want = RUNS_PER_WORKER * w
    if n and total[-1] > 0:
        want = max(want, int(np.ceil(total[-1] / max_cost)))
        want = -(-want // w) * w  # equal numbers of runs for every worker's share
    count = max(1, min(n, want))
    if costs is None:
        cuts = [n * k // count for k in range(count + 1)]
    else:
        cuts = [0]
        for k in range(1, count):
            # the first item past the k-th share, leaving one item at least per run
            at = int(np.searchsorted(total, total[-1] * k / count, side="left")) + 1
            cuts.append(min(max(at, cuts[-1] + 1), n - (count - k)))
        cuts.append(n)
    return [(a, b) for a, b in zip(cuts[:-1], cuts[1:], strict=True) if b > a]


#: local clusters open in this process (their workers come from one forkserver)
_LOCAL_CLUSTERS = [0]
_LOCAL_LOCK = threading.Lock()


def _worker_environ() -> dict:
    """The environment variables a local cluster's worker processes start with
    (Dask's ``distributed.nanny.pre-spawn-environ``): one thread per worker
    process, LAZ decoding included (lazrs decodes on a rayon pool of all
    cores), and no fixed ``MALLOC_TRIM_THRESHOLD_``, which turns off glibc's
    dynamic mmap threshold (every large array would be mapped and faulted in
    afresh, system CPU, not reused)."""
    import dask

    environ = {**dask.config.get("distributed.nanny.pre-spawn-environ", {}),
               "RAYON_NUM_THREADS": 1, "NUMBA_NUM_THREADS": 1}
    environ.pop("MALLOC_TRIM_THRESHOLD_", None)
    return environ


#: what the server local workers are forked from imports before it forks any
#: (besides a caller's ``preload``): Dask's worker and what every task needs
FORKSERVER_PRELOAD = ("distributed", "numpy", "lidar2city.tools.task",
                      "lidar2city.tools.reconstruct")


#: what a block imports (besides :mod:`lidar2city.tools.task`), for a local cluster's
#: workers to have it imported before they are forked (:func:`worker_modules`)
WORKER_MODULES = ("laspy", "lazrs", "shapely", "shapely.ops", "pyproj", "lidar2city.io.las",
                  "lidar2city.io.vector", "lidar2city.lod.lod1", "lidar2city.metrics.model",
                  "lidar2city.validate.solid", "lidar2city._components")
#: what LoD2.2 from the roof topology imports besides (scipy's ~0.25 CPU-second)
LOD22_MODULES = ("scipy.ndimage", "scipy.spatial", "scipy.sparse", "lidar2city.roof.building",
                 "lidar2city.regularize.snake", "lidar2city.lod.roofcheck")


def worker_modules(lods=(), method="roof") -> tuple:
    """The modules the blocks of a run building ``lods`` import
    (:func:`make_executor` ``preload``)."""
    return WORKER_MODULES + (LOD22_MODULES if "2.2" in (lods or ()) and method == "roof"
                             else ())


def start_worker_server(workers, scheduler=None, preload=()) -> bool:
    """Start the server a local cluster of ``workers`` processes forks them from
    (:func:`_start_forkserver`, ``preload`` imported in it) at once, before the
    caller imports and reads what its run needs: the command line calls it
    first thing (~0.13 CPU-second earlier than the cluster itself would, at
    the start of the run), so that the server's imports, the critical path of
    the first worker's start, run on the other core meanwhile; the cluster
    then finds it running. Nothing for one worker, ``auto`` or an existing
    cluster (``scheduler``). Returns whether it was started; a failure is left
    to the cluster's start, which tries again."""
    if scheduler is not None or not isinstance(workers, int) or workers < 2:
        return False
    if local_executor() != "dask":  # the workers are forked from this process: no server
        return False
    try:
        _start_forkserver(preload)
    except Exception as exc:  # noqa: BLE001 - the cluster starts it as it would have
        logger.debug("the worker server did not start early: %s", exc)
        return False
    return True


def _start_forkserver(preload=()) -> None:
    """Start the server local clusters fork their workers from (:data:`START_METHOD`)
    now, with the environment Dask's nannies would give it (:func:`_worker_environ`,
    set in this process as a nanny does) and :data:`FORKSERVER_PRELOAD` +
    ``preload`` imported in it: it imports them on another core while this
    process imports Dask and starts the scheduler and nannies (which then find
    it running), and each worker forked from it has them already. Nothing to
    do without a ``forkserver``, or when it runs (another cluster's)."""
    if START_METHOD != "forkserver":
        return
    from multiprocessing import forkserver

    server = getattr(forkserver, "_forkserver", None)
    if getattr(server, "_forkserver_pid", None) is not None:
        return
    env = {k: os.environ.get(k, str(v)) for k, v in _worker_environ().items() if v is not None}
    if env.get("PYTHONHASHSEED") in (None, "0"):  # as a nanny sets it before it spawns
        env["PYTHONHASHSEED"] = "6640"
    os.environ.update(env)
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(list(dict.fromkeys([*FORKSERVER_PRELOAD, *preload])))
    forkserver.ensure_running()


def _stop_forkserver() -> None:
    """End the server the local cluster's workers were forked from, and reap it, so
    that no process outlives the cluster and its CPU (its workers' included: it
    has reaped them once they ended) is accounted to this process. It is ended
    with SIGTERM, not asked to tear its interpreter down (measured: the close
    0.23 -> 0.05 s at load ~5); Python starts it again if another cluster (or
    anything else in this process) needs it."""
    server = kill_forkserver()
    stop = getattr(server, "_stop", None)
    if stop is not None:  # CPython's: reaps it; elsewhere it ends with this process
        stop()


#: names of the semaphores this process registered with multiprocessing's resource
#: tracker and has not released (:func:`_track_semaphores`)
_SEMAPHORES: set = set()
#: held while a semaphore is registered or the registrations are closed
_SEMAPHORE_LOCK = threading.RLock()
#: set by :func:`close_semaphores` when an interrupted run stops: no semaphore made
#: after it is left to the resource tracker
_SEMAPHORES_CLOSED = [False]
#: names :func:`release_semaphores` unlinked and unregistered itself: a finalizer
#: that unlinked one of them concurrently does not tell the tracker a second time
_RELEASED: set = set()


def _track_semaphores() -> None:
    """Record the semaphores this process registers with multiprocessing's resource
    tracker (a local cluster's nannies make them for their queues, in the thread that
    starts the cluster), so that an interrupted run can release every one of them
    (:func:`release_semaphores`): one registered but not yet given its finalizer when
    the interrupt came was left to the tracker, which warned of a "leaked semaphore"
    after the run's last line. Installed once per process."""
    from multiprocessing import resource_tracker

    if getattr(resource_tracker.register, "_lidar2city", False):
        return
    register, unregister = resource_tracker.register, resource_tracker.unregister

    def tracked_register(name, rtype):
        if rtype != "semaphore":
            return register(name, rtype)
        with _SEMAPHORE_LOCK:
            if _SEMAPHORES_CLOSED[0]:
                # made while the interrupted run stops (a nanny replacing the worker just
                # killed): its name goes at once, the tracker never hears of it
                _unlink_semaphore(name)
                return None
            _SEMAPHORES.add(name)
            return register(name, rtype)

    def tracked_unregister(name, rtype):
        if rtype != "semaphore":
            return unregister(name, rtype)
        # the tracker is told and the name forgotten under the lock: a finalizer in a
        # cluster's thread that had unlinked its semaphore when the interrupt came
        # either finishes telling the tracker before release_semaphores looks, or
        # finds it told already; it is never cut off between forgetting and telling
        # (the tracker then warned of a leaked semaphore it could not unlink) nor
        # tells twice (the tracker then printed a KeyError's traceback)
        # waited for at most a second: a finalizer the collector runs in a thread that
        # holds the tracker's own lock must not wait for ever on a thread that holds
        # this one and waits for the tracker's (it then fails as CPython's would)
        got = _SEMAPHORE_LOCK.acquire(timeout=1.0)
        try:
            if name in _RELEASED:
                return None
            done = unregister(name, rtype)
            _SEMAPHORES.discard(name)
            return done
        finally:
            if got:
                _SEMAPHORE_LOCK.release()

    tracked_register._lidar2city = True
    resource_tracker.register, resource_tracker.unregister = tracked_register, tracked_unregister


def _unlink_semaphore(name) -> None:
    sync = sys.modules.get("multiprocessing.synchronize")
    if sync is not None:
        with contextlib.suppress(Exception):
            sync.sem_unlink(name)


def close_semaphores() -> None:
    """Stop leaving semaphores to the resource tracker: for an interrupted run, before
    it kills its workers, whose nannies would make new queues (six semaphores each)
    for the workers they start in their place; those would be registered after
    :func:`release_semaphores` and warned of as leaked after the run's last line.
    Not undone: the process ends. Safe in a signal handler (the lock is re-entrant and
    waited for at most a second)."""
    got = _SEMAPHORE_LOCK.acquire(timeout=1.0)
    try:
        _SEMAPHORES_CLOSED[0] = True
    finally:
        if got:
            _SEMAPHORE_LOCK.release()


def release_semaphores() -> None:
    """Unlink the named semaphores this process made and still holds (a local cluster's
    nannies' queue locks), and tell the resource tracker: for a run ended by
    ``os._exit``, which skips multiprocessing's exit hooks (the tracker would unlink
    them itself and warn of "leaked semaphore objects"). Safe in a signal handler."""
    util = sys.modules.get("multiprocessing.util")
    sync = sys.modules.get("multiprocessing.synchronize")
    if util is None or sync is None:
        return
    from multiprocessing import resource_tracker

    # a finalizer another thread is running tells the tracker before this looks, or
    # after it, finding the name released (tracked_unregister)
    got = _SEMAPHORE_LOCK.acquire(timeout=1.0)
    try:
        finalizers = []
        for _ in range(10):  # another thread may be adding one: take a stable snapshot
            try:
                finalizers = list(util._finalizer_registry.values())
                break
            except RuntimeError:
                continue
        for finalizer in finalizers:
            if getattr(finalizer, "_callback", None) is sync.SemLock._cleanup:
                with contextlib.suppress(Exception):
                    finalizer()
        # registered, but their finalizer not made yet when the run was stopped, or
        # being run by another thread that has unlinked the semaphore, not yet told
        for name in list(_SEMAPHORES):
            _unlink_semaphore(name)
            with contextlib.suppress(Exception):
                resource_tracker.unregister(name, "semaphore")
            _SEMAPHORES.discard(name)
            _RELEASED.add(name)
    finally:
        if got:
            _SEMAPHORE_LOCK.release()


def kill_forkserver():
    """Send SIGTERM to the server local clusters fork their workers from, if it runs
    (no new worker can be forked from then on; e.g. before an interrupted run kills
    its workers, whose nannies would restart them at once); returns Python's
    handle of the server (None without one)."""
    if START_METHOD != "forkserver":
        return None
    import signal
    from multiprocessing import forkserver

    server = getattr(forkserver, "_forkserver", None)
    pid = getattr(server, "_forkserver_pid", None)
    if pid is not None:
        try:
            os.kill(pid, signal.SIGTERM)
        except OSError:  # already gone
            pass
    return server


def _process_cpu() -> float:
    """CPU seconds of this process (user + system, all its threads)."""
    t = os.times()
    return t.user + t.system


def _warm(exit_fast: bool = False):
    """Import what a worker's tasks use (run on every worker once the cluster is up).

    ``exit_fast`` (a worker process of our own local cluster, never one of an
    external cluster): once the worker has closed and its process runs its
    exit handlers, end it at once (:func:`_exit_now`) instead of tearing down
    its interpreter, which costs ~0.2 CPU-second per worker (measured: 2
    workers 0.4 CPU-s and the cluster's close 0.3 -> 0.03 s) while the
    client waits for the cluster to close. A worker forked from the forkserver
    (:data:`START_METHOD`) ends so anyway; this serves spawned workers.
    """
    from . import reconstruct, task  # noqa: F401

    if exit_fast:
        import atexit

        # registered last, so run first among the exit handlers: the worker has
        # already closed (Dask's own clean-up ran when its nanny stopped it)
        atexit.register(_exit_now)


def _exit_now():
    """End this worker process now, its output streams flushed: nothing it holds
    outlives it (its scratch files are unlinked, its results already sent)."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError, AttributeError):
            pass
    os._exit(0)


def shares_of(runs: int, workers: int, costs=None) -> list:
    """``(first run, stop)`` of each worker's share: ``runs`` cut into ``workers``
    contiguous shares of (nearly) equal numbers of runs, or of about equal total
    ``costs`` (one non-negative number per run) when given: each share ends with
    the run that brings it past its part of the total (a share may then be empty
    when one run costs more than a share)."""
    if costs is None or runs == 0:
        cuts = [runs * k // workers for k in range(workers + 1)]
    else:
        import numpy as np

        total = np.cumsum(np.asarray(costs, dtype=np.float64).reshape(runs))
        if not total[-1] > 0:
            return shares_of(runs, workers)
        at = np.searchsorted(total, total[-1] * np.arange(1, workers) / workers, side="left") + 1
        cuts = [0, *np.clip(at, 0, runs).tolist(), runs]
    return [(a, b) for a, b in zip(cuts[:-1], cuts[1:], strict=True)]


class RunDealer:
    """The runs of a map dealt between this process and ``others`` workers, as
    :meth:`DaskExecutor._map_shared` and :class:`lidar2city.tools.forked.ForkExecutor`
    deal them: the workers get the first contiguous shares (:func:`shares_of`, of
    equal numbers of runs, or of equal total ``costs`` when given), this process
    the last; ``balance``: one queue of single runs in order, taken from its front
    by every side. A side whose share is done takes the last run of another's:
    this process the largest share's not yet handed out, a worker this process's.
    Runs given back (:attr:`rerun`: a worker died with them) go to this process first.

    ``backward``: this process runs its share from its last run to its first, so
    that the sides meet where their shares meet: a worker whose share is done takes
    the run of this process's next to the ones it ran last, and this process, its
    share done, the last run of the share before its own, next to its own first
    (neighbouring runs read the same tiles). ``groups``: the runs told as ahead of
    a run (whose inputs it keeps) are the next ones of its share in the order they
    are handed out whose group (one number per run, e.g. the run of
    :func:`runs_of` a single item falls in) is at most :data:`AHEAD_RUNS` from
    the run's own; default the next :data:`AHEAD_RUNS` runs.
    Safe to call from several threads (:attr:`lock`)."""

    def __init__(self, runs: int, others: int, *, balance: bool = False, costs=None,
                 groups=None, backward: bool = False):
        if balance:
            self._mine, self._theirs = deque(range(runs)), [deque() for _ in range(others)]
        else:
            shares = shares_of(runs, others + 1, costs)
            mine = range(*shares[-1])
            self._mine = deque(reversed(mine) if backward else mine)
            self._theirs = [deque(range(a, b)) for a, b in shares[:-1]]
        self._balance = balance
        self._groups = None if groups is None else list(groups)
        self.rerun = deque()
        self.lock = threading.Lock()

    def _ahead(self, r, order) -> list:
        """The runs told as ahead of ``r``: the first of ``order`` (the runs its side
        takes next, in turn) within :data:`AHEAD_RUNS` groups of it."""
        if self._groups is None:
            return list(itertools.islice(order, AHEAD_RUNS))
        g = self._groups[r]
        return list(itertools.takewhile(lambda q: abs(self._groups[q] - g) <= AHEAD_RUNS,
                                        order))

    def mine(self):
        """``(run, runs after it in this process's share, at most AHEAD_RUNS)``;
        ``(None, [])`` when none is left."""
        with self.lock:
            if self.rerun:
                return self.rerun.popleft(), []
            if self._mine:
                r = self._mine.popleft()
                return r, self._ahead(r, self._mine)
            left = max(self._theirs, key=len, default=None)
            if not left:
                return None, []
            r = left.pop()
            return r, self._ahead(r, reversed(left)) if self._groups is not None else []

    def theirs(self, k: int):
        """The next run of worker ``k``'s share, else the last of this process's (the
        front, with ``balance``), with the runs after it as :meth:`mine`."""
        with self.lock:
            share = self._theirs[k] if k < len(self._theirs) else None
            if share:
                r = share.popleft()
                return r, self._ahead(r, share)
            if not self._mine:
                return None, []
            if self._balance:
                r = self._mine.popleft()
                return r, self._ahead(r, self._mine)
            r = self._mine.pop()
            return r, self._ahead(r, reversed(self._mine)) if self._groups is not None else []


def _dealt(shares) -> list:
    """``(share, run)`` in the order runs are handed out: the first run of every
    share, then the second of every share..."""
    out, depth = [], 0
    while True:
        row = [(k, a + depth) for k, (a, b) in enumerate(shares) if a + depth < b]
        if not row:
            return out
        out += row
        depth += 1


#: allocations between two collections of the youngest generation in a cluster
#: worker, as in a run of one process (``lidar2city.cli.main._GC_THRESHOLD``)
GC_THRESHOLD = 50_000
_WORKER_SET_UP: list = []


def _set_up_worker() -> None:
    """Once per cluster worker process, before its first task: the cycle collector
    as a run in one process has it, every :data:`GC_THRESHOLD` allocations
    instead of Python's 700 (a worker of the Delft tile's parts ran 40
    collections over its 4 parts, the client computing beside it none), and
    what the process holds by then (the modules its server imported, Dask's
    own state) moved out of the collector's reach (:func:`gc.freeze`): a
    collection neither walks those objects again nor writes to, and so
    copies, the pages a forked worker shares with its server."""
    if _WORKER_SET_UP:
        return
    import gc

    _WORKER_SET_UP.append(True)
    thresholds = gc.get_threshold()
    gc.set_threshold(max(thresholds[0], GC_THRESHOLD), *thresholds[1:])
    gc.freeze()


def _run_many(items, *args, fn, run_hook=None, ahead=(), own=False):
    """One cluster task: ``fn`` over a run of items in turn, each tried as in
    :class:`InProcess`; ``[(offset in the run, result or exception)]``. ``own``:
    on a worker of our own local cluster (:func:`_set_up_worker`; an external
    cluster's workers are left as they are)."""
    if own:
        _set_up_worker()
    return list(InProcess().map(fn, items, *args, run_hook=run_hook, ahead=ahead))


def make_executor(workers: int = 1, scheduler: str | None = None, preload=(),
                  client_computes: bool = False):
    """The executor for ``--workers N`` / ``--scheduler ADDRESS`` (use it as a context manager);
    ``preload``: modules a local cluster's workers import before they are forked
    (:func:`_start_forkserver`), or this process before it forks its workers
    (:class:`~lidar2city.tools.forked.ForkExecutor`); ``client_computes``: a local cluster of N - 1
    processes, this one computing too (:meth:`DaskExecutor._map_shared`)."""
    if scheduler is not None:
        return DaskExecutor(scheduler=scheduler)
    if int(workers) < 1:
        raise InputError(f"workers must be at least 1, got {workers}")
    if int(workers) == 1:
        return InProcess()
    if local_executor() == "fork":
        from .forked import ForkExecutor

        return ForkExecutor(int(workers), preload=preload)
    return DaskExecutor(workers=int(workers), preload=preload, client_computes=client_computes)


#: the environment variable that chooses the executor of ``--workers N`` on this
#: machine (:func:`local_executor`)
LOCAL_EXECUTOR_ENV = "LIDAR2CITY_LOCAL_EXECUTOR"
#: the executors ``--workers N`` may run on this machine
LOCAL_EXECUTORS = ("fork", "dask")


def local_executor() -> str:
    """The executor of ``--workers N`` (N > 1) without ``--scheduler``: ``"fork"``,
    workers forked from this process when it hands the blocks out
    (:class:`lidar2city.tools.forked.ForkExecutor`), where the platform forks; else
    ``"dask"``, a Dask ``LocalCluster`` (:class:`DaskExecutor`). The environment
    variable :data:`LOCAL_EXECUTOR_ENV` set to ``dask`` chooses the cluster
    (e.g. to compare them: ``benchmarks/bench_engine_tile.py --executor``)."""
    from .forked import CAN_FORK

    chosen = os.environ.get(LOCAL_EXECUTOR_ENV, "").strip().lower() or "fork"
    if chosen not in LOCAL_EXECUTORS:
        raise InputError(f"{LOCAL_EXECUTOR_ENV} must be one of {', '.join(LOCAL_EXECUTORS)}, "
                         f"got {chosen!r}")
    return chosen if chosen == "dask" or CAN_FORK else "dask"
