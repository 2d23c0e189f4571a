"""Executors: run one task function over many items, in this process or on Dask.

``executor.map(fn, items, *args)`` yields ``(item_index, result_or_exception)``
as tasks finish, in any order; the caller puts results back in its own fixed
order, so nothing else knows which executor ran them. A task that raises is
tried once more; one that fails twice is yielded as its exception (the run
goes on). With Dask, a worker that dies is replaced and its task rerun on
another worker; a task that kills two workers comes back as ``KilledWorker``.

- :class:`InProcess` (``workers=1``, the default): tasks one after the other.
- :class:`DaskExecutor`: a ``dask.distributed`` ``LocalCluster`` of ``workers``
  processes (one thread each), or an existing cluster given by its scheduler
  address (started with ``dask scheduler`` / ``dask worker``). A cluster task
  is a run of consecutive items (:func:`runs_of`), so a worker's items are
  neighbours that share their inputs (a block's tiles).
"""

from __future__ import annotations

import logging

from ..errors import DependencyError, InputError

logger = logging.getLogger(__name__)

__all__ = ["InProcess", "DaskExecutor", "make_executor", "runs_of", "RETRIES", "CONNECT_TIMEOUT",
           "RUNS_PER_WORKER"]

#: times a failed task is tried again before its failure is reported
RETRIES = 1
#: seconds to wait for a scheduler address to answer
CONNECT_TIMEOUT = 15


class InProcess:
    """Run tasks in this process, in order."""

    workers = 1

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def map(self, fn, items, *args):
        for i, item in enumerate(items):
            for attempt in range(RETRIES + 1):
                try:
                    out = fn(item, *args)
                except Exception as exc:  # noqa: BLE001 - reported per task, the run goes on
                    logger.warning("task %d failed (attempt %d): %s", i, attempt + 1, exc)
                    out = exc
                    continue
                break
            yield i, out

    def describe(self) -> str:
        return "in-process"


class DaskExecutor:
    """Run tasks on a Dask cluster: a local one of ``workers`` processes, or ``scheduler``'s."""

    def __init__(self, workers: int | None = None, scheduler: str | None = None):
        try:
            import distributed  # noqa: F401
        except ImportError:  # pragma: no cover - a core dependency
            raise DependencyError("--workers / --scheduler need dask.distributed: "
                                  "pip install 'dask[distributed]'") from None
        self.scheduler = scheduler
        self.workers = workers
        self._cluster = None
        self._client = None

    def __enter__(self):
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
        # a task that kills two workers is reported, not retried for ever; one thread per
        # worker process, LAZ decoding included (lazrs decodes on a rayon pool of all cores)
        environ = {**dask.config.get("distributed.nanny.pre-spawn-environ", {}),
                   "RAYON_NUM_THREADS": 1, "NUMBA_NUM_THREADS": 1}
        with dask.config.set({"distributed.scheduler.allowed-failures": RETRIES,
                              "distributed.worker.daemon": False,
                              "distributed.nanny.pre-spawn-environ": environ}):
            self._cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1,
                                         processes=True, dashboard_address="127.0.0.1:0",
                                         host="127.0.0.1", silence_logs=logging.ERROR)
            self._client = Client(self._cluster, set_as_default=False)
        return self

    def __exit__(self, *exc):
        if self._client is not None:
            self._client.close()
        if self._cluster is not None:
            self._cluster.close()
        self._dlog.setLevel(self._dlog_level)
        return False

    def map(self, fn, items, *args):
        from distributed import as_completed

        items = list(items)
        if not items:
            return
        # run-wide arguments sent once to every worker, not once per task
        shared = [self._client.scatter(a, broadcast=True, hash=False) for a in args]
        runs = runs_of(len(items), self.workers)
        futures = self._client.map(_run_many, [items[a:b] for a, b in runs],
                                   *[[a] * len(runs) for a in shared], fn=fn, pure=False,
                                   retries=RETRIES)
        where = {f.key: r for f, r in zip(futures, runs, strict=True)}
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

    def describe(self) -> str:
        return (f"Dask scheduler {self.scheduler} ({self.workers} workers)" if self.scheduler
                else f"Dask LocalCluster of {self.workers} workers")


#: runs per worker: enough for the workers to finish together, few enough for
#: each run to be a long stretch of neighbouring items
RUNS_PER_WORKER = 4


def runs_of(n: int, workers: int) -> list:
    """``(start, stop)`` of the runs of consecutive items the cluster's tasks take.

    Items given in a spatial order (the planner's blocks, row by row) share
    their inputs with their neighbours (the tiles a block reads): a worker that
    takes a run of consecutive items decodes each tile about once, where items
    dealt one by one to alternate workers make every worker decode every tile.
    About ``RUNS_PER_WORKER`` runs per worker, of equal length.
    """
    count = max(1, min(n, RUNS_PER_WORKER * max(1, int(workers or 1))))
    cuts = [n * k // count for k in range(count + 1)]
    return [(a, b) for a, b in zip(cuts[:-1], cuts[1:], strict=True) if b > a]


def _run_many(items, *args, fn):
    """One cluster task: ``fn`` over a run of items in turn, each tried as in
    :class:`InProcess`; ``[(offset in the run, result or exception)]``."""
    return list(InProcess().map(fn, items, *args))


def make_executor(workers: int = 1, scheduler: str | None = None):
    """The executor for ``--workers N`` / ``--scheduler ADDRESS`` (use it as a context manager)."""
    if scheduler is not None:
        return DaskExecutor(scheduler=scheduler)
    if int(workers) < 1:
        raise InputError(f"workers must be at least 1, got {workers}")
    return InProcess() if int(workers) == 1 else DaskExecutor(workers=int(workers))
