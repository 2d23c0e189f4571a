"""Write outputs under a temporary name and rename them on success."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

from ..errors import FileFormatError

__all__ = ["atomic_path", "check_input_file"]


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path``; rename it to ``path`` if the block succeeds.

    On any exception the temporary file is removed, so no half-written output
    is ever left under the final name. The temporary name keeps the final
    suffixes so format drivers that look at the extension still work.
    """
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.exists():
        raise FileFormatError(f"output folder {str(parent)!r} does not exist")
    tmp = parent / f".{path.stem}.tmp{os.getpid()}{''.join(path.suffixes[-1:])}"
    if path.name.endswith(".city.json") or path.name.endswith(".city.jsonl"):
        tmp = parent / f".tmp{os.getpid()}.{path.name}"
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def check_input_file(path) -> Path:
    """Return ``path`` as a Path, raising :class:`FileFormatError` if it is not a readable file."""
    p = Path(path)
    if not p.exists():
        raise FileFormatError(f"{str(p)!r}: no such file")
    if p.is_dir():
        raise FileFormatError(f"{str(p)!r} is a folder, not a file")
    if not os.access(p, os.R_OK):
        raise FileFormatError(f"{str(p)!r} is not readable")
    return p
