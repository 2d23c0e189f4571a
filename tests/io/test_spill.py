"""SpillFile: items held out of order on disk, returned as they were put."""

from types import SimpleNamespace

import numpy as np
import pytest

from lidar2city.io.spill import SpillFile


def test_items_come_back_as_put_in_any_order():
    s = SpillFile()
    items = {k: (f"feature {k}" * (k + 1), {"a": k, "z": np.arange(k)}) for k in range(6)}
    for k in (4, 1, 5, 2):
        s.put(k, items[k])
    assert len(s) == 4 and 4 in s and 3 not in s
    for k in (2, 5):
        got = s.pop(k)
        assert got[0] == items[k][0] and np.array_equal(got[1]["z"], items[k][1]["z"])
    s.put(3, items[3])  # appended after what was popped: nothing overwritten
    assert [s.pop(k)[1]["a"] for k in (1, 3, 4)] == [1, 3, 4]
    assert len(s) == 0
    with pytest.raises(KeyError):
        s.pop(4)
    s.put(0, items[0])  # the emptied file is used again from its start
    assert s.pop(0)[0] == items[0][0]
    s.close()
    s.close()  # twice: nothing left to close


def test_in_order_holds_waiting_encoded_results_on_disk():
    """A streamed run's results that wait for earlier footprints are spilled, and come
    out in the footprints' order, the same as held in memory."""
    from lidar2city.datamodel import BuildingResult, Footprints
    from lidar2city.tools.reconstruct import InOrder
    from lidar2city.tools.task import BlockOutput

    plan = SimpleNamespace(points=False, traced=False, parts=False, lods=("1.2",))

    def block(index, positions, encoded):
        results = [BuildingResult(f"f{p}", attributes={"footprint_id": f"f{p}"}) for p in positions]
        fps = Footprints([None] * len(positions), [f"f{p}" for p in positions],
                         {"_index": list(positions), "name": [f"n{p}" for p in positions]})
        text = [(f"text {p}", (0.0, 0.0, 0.0, 1.0, 1.0, 1.0)) for p in positions] if encoded else None
        return BlockOutput(index, results, fps, True, encoded=text)

    for encoded in (True, False):
        order = InOrder(plan)
        got = []
        got += order.add(block(1, [3, 1], encoded))  # 0 not done: both wait
        assert not got
        assert (len(order.spilled) == 2 and not order.pending) if encoded else (
            len(order.pending) == 2 and order.spilled is None)
        got += order.add(block(2, [4], encoded))
        got += order.add(block(0, [2, 0], encoded))  # 0 .. 4 all known
        assert [r.id for r, _, _ in got] == ["f0", "f1", "f2", "f3", "f4"]
        assert [f["name"] for _, f, _ in got] == ["n0", "n1", "n2", "n3", "n4"]
        assert [e[0] if e else None for _, _, e in got] == (
            [f"text {p}" for p in range(5)] if encoded else [None] * 5)
        order.check()
        order.close()
