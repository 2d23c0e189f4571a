"""Tile lists: files, folders and glob patterns of LAS/LAZ tiles."""

from __future__ import annotations

import glob
from pathlib import Path

from ..errors import EmptyInputError, FileFormatError

__all__ = ["TILE_SUFFIXES", "is_tile_set", "tile_paths"]

#: file endings of point cloud tiles found in a folder
TILE_SUFFIXES = (".las", ".laz")


def is_tile_set(path) -> bool:
    """Whether ``path`` names several tiles: a folder or a glob pattern."""
    s = str(path)
    return Path(s).is_dir() or any(c in s for c in "*?[")


def tile_paths(inputs) -> list:
    """The tile files named by ``inputs`` (files, folders, glob patterns), in a fixed order.

    A folder gives its ``.las`` / ``.laz`` files (not its sub-folders), a glob
    pattern its matches, both sorted by name; a file is kept as given.

    Raises
    ------
    EmptyInputError
        A folder or pattern without tiles.
    FileFormatError
        A folder that cannot be listed.
    """
    if isinstance(inputs, (str, bytes, Path)):
        inputs = [inputs]
    out = []
    for item in inputs:
        s = str(item)
        if Path(s).is_dir():
            try:
                found = sorted(str(p) for p in Path(s).iterdir()
                               if p.is_file() and p.suffix.lower() in TILE_SUFFIXES)
            except OSError as exc:
                raise FileFormatError(f"cannot list the folder {s!r}: {exc.strerror}") from None
            if not found:
                raise EmptyInputError(f"the folder {s!r} holds no .las / .laz tile")
            out += found
        elif any(c in s for c in "*?[") and not Path(s).exists():
            found = sorted(p for p in glob.glob(s) if Path(p).is_file())
            if not found:
                raise EmptyInputError(f"no tile matches {s!r}")
            out += found
        else:
            out.append(item)
    return out
