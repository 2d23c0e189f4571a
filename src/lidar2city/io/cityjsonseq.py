"""A streaming CityJSONSeq writer: buildings are written as they come, in the caller's order.

The bytes are those of :func:`lidar2city.io.cityjson.write_cityjsonseq` for the
same results. Features go to a spool file beside the output as they are
added (nothing is kept in memory); the header line, which carries the extent
of all buildings, is written on :meth:`CityJSONSeqWriter.close`, followed by
the spooled features, under a temporary name renamed at the end.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np

from ._atomic import _reason, atomic_path, scratch_path
from .cityjson import _extent, _header, cityjson_features

__all__ = ["CityJSONSeqWriter", "encode_feature"]


def encode_feature(result, attributes=None, *, scale=0.001, xy_unit=1.0, z_unit=1.0):
    """One building's CityJSONSeq line(s) and its local extent, as
    :meth:`CityJSONSeqWriter.add` writes them: ``(text, extent or None)``.

    Pure: a worker may encode its buildings and the writer append the text
    (:meth:`CityJSONSeqWriter.add_encoded`), with the same bytes.
    """
    extra = {k: [v] for k, v in (attributes or {}).items()}
    text = "".join(json.dumps(feat, separators=(",", ":")) + "\n"
                   for feat in cityjson_features([result], scale=scale, xy_unit=xy_unit,
                                                 z_unit=z_unit, attributes=extra))
    return text, _extent([result])


class CityJSONSeqWriter:
    """Write building results one by one to a ``.city.jsonl`` file.

    Parameters
    ----------
    path : path
    origin, crs, xy_unit, z_unit, scale, configuration, title
        As :func:`lidar2city.io.cityjson.cityjson_document`.

    Examples
    --------
    >>> with CityJSONSeqWriter(path, origin=origin, crs=crs) as w:  # doctest: +SKIP
    ...     for result in results:
    ...         w.add(result)
    """

    def __init__(self, path, *, origin, crs=None, xy_unit=1.0, z_unit=1.0, scale=0.001,
                 configuration=None, title=None):
        from ..errors import FileFormatError

        self.path = Path(path)
        parent = self.path.parent if str(self.path.parent) else Path(".")
        if not parent.is_dir():
            raise FileFormatError(f"output folder {str(parent)!r} does not exist")
        self._head = dict(origin=origin, crs=crs, xy_unit=xy_unit, z_unit=z_unit, scale=scale,
                          configuration=configuration, title=title)
        self._lo, self._hi = np.full(3, np.inf), np.full(3, -np.inf)
        # a scratch file: removed by close/abort, and by a failed or interrupted run
        self._scratch = scratch_path(parent / f".{self.path.name}.features.tmp{os.getpid()}")
        self._spool_path = self._scratch.__enter__()
        self._spool = open(self._spool_path, "w", encoding="utf-8")
        self.count = 0

    def add(self, result, attributes=None) -> None:
        """Append one building (``attributes``: extra fields, name -> value)."""
        h = self._head
        self.add_encoded(*encode_feature(result, attributes, scale=h["scale"],
                                         xy_unit=h["xy_unit"], z_unit=h["z_unit"]))

    def add_encoded(self, text, extent) -> None:
        """Append one building already encoded by :func:`encode_feature` (with this
        writer's ``scale``, ``xy_unit`` and ``z_unit``)."""
        if extent is not None:
            self._lo = np.minimum(self._lo, extent[:3])
            self._hi = np.maximum(self._hi, extent[3:])
        try:
            self._spool.write(text)
        except OSError as exc:  # disk full while spooling: the output is what fails
            from ..errors import FileFormatError

            raise FileFormatError(f"cannot write {str(self.path)!r}: {_reason(exc)}") from exc
        self.count += 1

    def close(self) -> None:
        """Write the header and the features to the output (atomically)."""
        try:
            self._spool.close()  # flushes the last features
        except OSError as exc:
            from ..errors import FileFormatError

            self.abort()
            raise FileFormatError(f"cannot write {str(self.path)!r}: {_reason(exc)}") from exc
        h = dict(self._head)
        extent = (np.concatenate([self._lo, self._hi]) if np.all(np.isfinite(self._lo))
                  else None)
        head = _header(h.pop("origin"), h.pop("crs"), h.pop("xy_unit"), h.pop("z_unit"),
                       scale=h["scale"], extent_local=extent, configuration=h["configuration"],
                       title=h["title"])
        head["CityObjects"] = {}
        head["vertices"] = []
        try:
            with atomic_path(self.path) as tmp, open(tmp, "w", encoding="utf-8") as f:
                f.write(json.dumps(head, separators=(",", ":")) + "\n")
                with open(self._spool_path, encoding="utf-8") as body:
                    shutil.copyfileobj(body, f, 1 << 20)
        finally:
            self.abort()

    def abort(self) -> None:
        """Drop what was spooled (nothing is written)."""
        self._spool.close()
        if self._scratch is not None:
            self._scratch.__exit__(None, None, None)  # removes the spool
            self._scratch = None

    def __enter__(self):
        return self

    def __exit__(self, exc_type, *exc):
        if exc_type is None:
            self.close()
        else:
            self.abort()
        return False
