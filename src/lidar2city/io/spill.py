"""Items held out of order, kept in an unlinked scratch file instead of memory.

A streamed run writes its buildings in the footprint file's order while its
blocks finish in grid order: a building whose predecessors are not all done
waits. When the file is not in spatial order most of an area's buildings wait
at some point, so what waits grows with the area; :class:`SpillFile` keeps
them pickled on disk (an anonymous temporary file, gone when closed or when
the process dies) and only their offsets in memory.
"""

from __future__ import annotations

import pickle
import tempfile

__all__ = ["SpillFile"]


class SpillFile:
    """``put(key, item)`` / ``pop(key)`` of picklable items, held on disk.

    Examples
    --------
    >>> s = SpillFile()
    >>> s.put(3, ("text", {"a": 1}))
    >>> 3 in s, len(s), s.pop(3), len(s)
    (True, 1, ('text', {'a': 1}), 0)
    >>> s.close()
    """

    def __init__(self):
        self._file = None
        self._where = {}  # key -> (offset, length)
        self._end = 0

    def put(self, key, item) -> None:
        """Keep ``item`` under ``key`` (a key already held is replaced)."""
        if self._file is None:
            self._file = tempfile.TemporaryFile(prefix="lidar2city-spill-")
        data = pickle.dumps(item, protocol=pickle.HIGHEST_PROTOCOL)
        self._file.seek(self._end)
        self._file.write(data)
        self._where[key] = (self._end, len(data))
        self._end += len(data)

    def pop(self, key):
        """The item under ``key``, no longer held (KeyError when none)."""
        at, n = self._where.pop(key)
        self._file.seek(at)
        item = pickle.loads(self._file.read(n))
        if not self._where:  # nothing held: the file's space is reused from its start
            self._end = 0
            self._file.truncate(0)
        return item

    def __contains__(self, key) -> bool:
        return key in self._where

    def __len__(self) -> int:
        return len(self._where)

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None
        self._where.clear()
        self._end = 0
