"""The executor whose workers are forked from the running process (``--workers N`` here)."""

import contextlib
import os
import signal
import time
from collections import Counter

import numpy as np
import pytest

from lidar2city.errors import InputError
from lidar2city.tools import engine, task
from lidar2city.tools.forked import CAN_FORK, ForkExecutor

pytestmark = pytest.mark.skipif(not CAN_FORK, reason="this platform does not fork")


def _alive(pid) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


@pytest.mark.parametrize("balance", [False, True])
def test_every_item_comes_back_once_from_this_process_or_a_child(balance):
    me = os.getpid()

    def square_where(i):
        time.sleep(0.01)
        return i * i, os.getpid()

    with ForkExecutor(3) as ex:
        got = list(ex.map(square_where, range(24), costs=[1.0] * 24, balance=balance))
        cpu = ex.process_cpu()
    assert sorted(i for i, _ in got) == list(range(24))
    assert all(v[0] == i * i for i, v in got)
    pids = {pid for _, (_, pid) in got}
    assert me in pids and len(pids) >= 2
    assert len(cpu) == 2 and all(v >= 0 for v in cpu.values())  # both children reported
    assert not [pid for pid in pids - {me} if _alive(pid)]  # reaped


def test_the_sides_meet_where_their_shares_meet_whatever_the_timing():
    """Items of uneven cost are handed out one by one: the child runs a prefix of
    them in order, this process the rest from the last one back, each taking over
    the other's items next to its own; neither is left a whole run of several
    items at the end."""
    me = os.getpid()
    costs = [1, 1, 1, 1, 9, 9, 9, 2, 9, 9, 9, 2, 1, 1, 1]

    def where(i, pause):
        time.sleep(pause * costs[i])
        return os.getpid(), time.monotonic()

    for pause in (0.004,):
        with ForkExecutor(2) as ex:
            got = dict(ex.map(where, range(len(costs)), pause, costs=costs))
        assert sorted(got) == list(range(len(costs)))
        mine = sorted(i for i, (pid, _) in got.items() if pid == me)
        theirs = sorted(i for i, (pid, _) in got.items() if pid != me)
        assert mine and theirs and mine == list(range(theirs[-1] + 1, len(costs)))
        assert theirs == list(range(len(theirs)))
        # this process went backward from the last item, the child forward
        assert sorted(mine, key=lambda i: got[i][1]) == mine[::-1]
        assert sorted(theirs, key=lambda i: got[i][1]) == theirs


def test_shares_of_equal_costs_are_contiguous():
    assert engine.shares_of(6, 2, [1, 1, 1, 1, 1, 1]) == [(0, 3), (3, 6)]
    assert engine.shares_of(5, 2, [10, 1, 1, 1, 1]) == [(0, 1), (1, 5)]
    assert engine.shares_of(4, 3, [0, 0, 0, 0]) == engine.shares_of(4, 3)
    shares = engine.shares_of(20, 3, np.arange(20.0))
    assert shares[0][0] == 0 and shares[-1][1] == 20
    assert all(b == c for (_, b), (c, _) in zip(shares, shares[1:]))


def test_a_backward_dealer_tells_each_side_the_items_it_takes_next():
    """With ``backward`` this process takes its share from the end; ``groups``
    bound the items told ahead; every item goes out once."""
    dealer = engine.RunDealer(10, 1, costs=[1] * 10, groups=[0, 0, 1, 1, 2, 2, 3, 3, 4, 4],
                              backward=True)
    r, ahead = dealer.mine()
    assert r == 9 and ahead == [8, 7, 6, 5]  # groups 4 back to 1 (AHEAD_RUNS 3)
    r, ahead = dealer.theirs(0)
    assert r == 0 and ahead == [1, 2, 3, 4]
    got = [9, 0]
    while (r := dealer.theirs(0)[0]) is not None:
        got.append(r)
    assert sorted(got) == list(range(10))
    assert dealer.mine() == (None, [])


def test_one_run_or_one_worker_runs_here_without_a_fork():
    me = os.getpid()
    with ForkExecutor(2) as ex:
        assert dict(ex.map(lambda i: os.getpid(), [7])) == {0: me}
    with ForkExecutor(1) as ex:
        assert set(dict(ex.map(lambda i: os.getpid(), range(5))).values()) == {me}


def test_children_see_what_this_process_held_when_it_handed_the_items_out():
    """Nothing is sent but indices: a child reads the items, the arguments and this
    process's state as they were at the map (copy-on-write)."""
    state = {"big": np.arange(1_000_000)}

    def total(i, offset):
        return int(state["big"][i::7].sum()) + offset

    with ForkExecutor(2) as ex:
        got = dict(ex.map(total, range(7), 5))
    assert got == {i: int(state["big"][i::7].sum()) + 5 for i in range(7)}


def test_this_process_objects_are_frozen_while_its_children_run_then_let_go():
    """Its collections during the map neither walk nor write to (copy) what the
    children share; after it, the objects are the collector's again, and a freeze
    made by someone else is left as it was."""
    import gc

    me = os.getpid()
    assert gc.get_freeze_count() == 0

    def frozen_here(i):
        return os.getpid(), gc.get_freeze_count()

    with ForkExecutor(2) as ex:
        got = dict(ex.map(frozen_here, range(8), costs=[1.0] * 8))
    mine = [n for pid, n in got.values() if pid == me]
    assert mine and all(n > 0 for n in mine)
    assert len({pid for pid, _ in got.values()}) == 2
    assert gc.get_freeze_count() == 0
    gc.freeze()
    try:
        before = gc.get_freeze_count()
        with ForkExecutor(2) as ex:
            assert len(dict(ex.map(frozen_here, range(4), costs=[1.0] * 4))) == 4
        assert gc.get_freeze_count() > before // 2  # (not let go: a frozen object may die)
    finally:
        gc.unfreeze()



def test_a_fork_that_fails_lets_the_objects_go(monkeypatch):
    """A map whose children cannot be forked raises, and leaves nothing frozen."""
    import gc

    from lidar2city.tools import forked

    def no_fork(*a, **k):
        raise OSError("Resource temporarily unavailable")

    monkeypatch.setattr(forked, "_fork_children", no_fork)
    assert gc.get_freeze_count() == 0
    with pytest.raises(OSError, match="unavailable"), ForkExecutor(2) as ex:
        list(ex.map(abs, range(8), costs=[1.0] * 8))
    assert gc.get_freeze_count() == 0

def test_a_dead_childs_run_is_run_again_here(caplog):
    me = os.getpid()

    def square_or_die(i):
        if os.getpid() != me:
            os.kill(os.getpid(), signal.SIGKILL)
        time.sleep(0.01)
        return i * i

    with ForkExecutor(2) as ex:
        got = dict(ex.map(square_or_die, range(8)))
    assert got == {i: i * i for i in range(8)}
    assert "run again here" in caplog.text


def test_results_a_child_cannot_send_are_made_again_here(caplog):
    me = os.getpid()

    def odd(i):
        if os.getpid() != me:
            return lambda: i  # not picklable
        return i

    with ForkExecutor(2) as ex:
        got = dict(ex.map(odd, range(8)))
    assert got == {i: i for i in range(8)}
    assert "did not come back" in caplog.text


def test_a_task_failing_twice_is_its_exception_and_the_rest_goes_on():
    calls = Counter()

    def fragile(i):
        calls[i] += 1  # (counted in this process only)
        if i == 5:
            raise ValueError("no roof")
        return i

    with ForkExecutor(2) as ex:
        got = dict(ex.map(fragile, range(8)))
    assert isinstance(got.pop(5), ValueError) and got == {i: i for i in range(8) if i != 5}


def test_a_consumer_that_stops_early_leaves_no_child():
    def slow(i):
        time.sleep(0.2)
        return os.getpid()

    with ForkExecutor(2) as ex:
        it = ex.map(slow, range(20))
        next(it)
        children = [p.pid for p in __import__("multiprocessing").active_children()]
        it.close()
    assert children
    assert not [pid for pid in children if _alive(pid)]


def test_a_child_decodes_laz_after_this_process_did(tmp_path):
    """lazrs decodes on a thread pool that a forked child has none of: the child
    decodes on its own thread (a decoding handed to the pool would never return),
    the same points."""
    from lidar2city.datamodel import PointCloud
    from lidar2city.io.las import laz_backend, read_tile, write_points

    rng = np.random.default_rng(3)
    xyz = rng.uniform(0, 100, (50_000, 3))
    path = tmp_path / "t.laz"
    write_points(path, PointCloud(xyz, attributes={"classification": np.full(len(xyz), 6, np.uint8)}))
    here = read_tile(path)  # the pool made here
    assert laz_backend() is None

    def decode(i):
        return laz_backend() is not None, read_tile(path).steps.sum(axis=0).tolist()

    with ForkExecutor(2) as ex:
        got = dict(ex.map(decode, range(2)))
    want = here.steps.sum(axis=0).tolist()
    assert all(v[1] == want for v in got.values())
    assert {v[0] for v in got.values()} == {False, True}  # the child's own decoder


def test_held_tiles_are_read_by_the_children_without_decoding(tmp_path):
    from lidar2city.datamodel import PointCloud
    from lidar2city.io.las import scan_tiles, write_points

    rng = np.random.default_rng(4)
    xyz = rng.uniform(0, 100, (20_000, 3))
    path = tmp_path / "t.laz"
    write_points(path, PointCloud(xyz, attributes={"classification": np.full(len(xyz), 6, np.uint8)}))
    tiles = scan_tiles([path])

    def never():
        raise AssertionError("decoded again")

    def read(i):
        return len(task._cache.get(tiles[0], never))

    with contextlib.ExitStack() as stack:
        assert task.hold_tiles(tiles, stack) == 1
        with ForkExecutor(2) as ex:
            assert dict(ex.map(read, range(2))) == {0: 20_000, 1: 20_000}
        task._cache.stop()
    assert not task._cache.held  # let go with the run


def test_workers_n_forks_here_unless_dask_is_asked_for(monkeypatch):
    monkeypatch.delenv(engine.LOCAL_EXECUTOR_ENV, raising=False)
    assert isinstance(engine.make_executor(2), ForkExecutor)
    assert isinstance(engine.make_executor(1), engine.InProcess)
    assert not engine.start_worker_server(2)  # no Dask server started for it
    monkeypatch.setenv(engine.LOCAL_EXECUTOR_ENV, "dask")
    assert isinstance(engine.make_executor(2), engine.DaskExecutor)
    monkeypatch.setenv(engine.LOCAL_EXECUTOR_ENV, "threads")
    with pytest.raises(InputError, match="LIDAR2CITY_LOCAL_EXECUTOR"):
        engine.make_executor(2)


def test_the_tasks_modules_are_imported_here_once_before_the_fork(tmp_path, monkeypatch):
    """``preload``: the modules the tasks import are imported by this process before
    it forks, so that every child inherits them instead of importing them again in
    its first run (each paid for them: ``bench_engine_tile_timeline.py``); one that
    cannot be imported is left to the task, and a map without a fork imports none."""
    import sys

    (tmp_path / "l2c_preload_probe.py").write_text("LOADED = True\n")
    (tmp_path / "l2c_preload_broken.py").write_text("raise ImportError('broken on purpose')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    for name in ("l2c_preload_probe", "l2c_preload_broken"):
        monkeypatch.delitem(sys.modules, name, raising=False)

    def where(i):
        time.sleep(0.01)
        return os.getpid(), "l2c_preload_probe" in sys.modules

    preload = ("l2c_preload_broken", "l2c_preload_probe")
    with ForkExecutor(2, preload=preload) as ex:
        assert dict(ex.map(where, [0]))[0] == (os.getpid(), False)  # no fork: nothing loaded
        assert "l2c_preload_probe" not in sys.modules
        got = dict(ex.map(where, range(16)))
    assert "l2c_preload_probe" in sys.modules and "l2c_preload_broken" not in sys.modules
    pids = {pid for pid, _ in got.values()}
    assert len(pids) == 2 and all(seen for _, seen in got.values())
    assert engine.make_executor(2, preload=preload).preload == preload
