"""Write outputs under a temporary name and rename them on success.

Every output of the package goes through :func:`atomic_path`, which also keeps
a registry of what the running process is writing (temporary files) and, while
a run is open (:func:`begin_run`), what it has finished writing. The command
line removes both when a run fails or is interrupted
(:func:`remove_run_outputs`), so an interrupted run leaves nothing behind.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
from pathlib import Path

from ..errors import FileFormatError, Lidar2CityError

__all__ = ["atomic_path", "check_input_file", "check_output_path", "make_output_dir",
           "begin_run", "end_run", "remove_run_outputs", "scratch_path", "keep_for_resume",
           "kept_for_resume", "new_scratch_file", "remove_stale_scratch"]

#: temporary files being written by this process
_PENDING: set = set()
#: final outputs (files, then folders created) of the open run; None when no run is open
_RUN: dict | None = None

#: error types raised by the writers' libraries for an OS-level failure (matched by the
#: module that defines them, so that none of those libraries is imported here)
_WRITER_MODULES = ("rasterio", "pyogrio", "lazrs", "laspy", "fiona")


def begin_run() -> None:
    """Start recording the outputs finished from now on (see :func:`remove_run_outputs`)."""
    global _RUN
    _RUN = {"files": [], "dirs": [], "kept": []}


def end_run() -> None:
    """Stop recording outputs: what was written is kept."""
    global _RUN
    _RUN = None


def keep_for_resume(path) -> None:
    """Record ``path`` (a run's journal) as what a failed or interrupted run leaves
    behind on purpose, so that the message can name it (:func:`kept_for_resume`)."""
    if _RUN is not None:
        _RUN["kept"].append(str(path))


def kept_for_resume() -> list[str]:
    """The paths the open run keeps for ``--resume`` (:func:`keep_for_resume`)."""
    return list(_RUN["kept"]) if _RUN is not None else []


def remove_run_outputs() -> list[str]:
    """Remove the temporary files being written and every output of the open run.

    Returns the paths removed (folders created by the run are removed when
    they are left empty). Safe to call from a signal handler.
    """
    removed = []
    for p in list(_PENDING):
        with contextlib.suppress(OSError):
            os.unlink(p)
            removed.append(str(p))
    _PENDING.clear()
    if _RUN is not None:
        for p in reversed(_RUN["files"]):
            with contextlib.suppress(OSError):
                os.unlink(p)
                removed.append(str(p))
        for d in reversed(_RUN["dirs"]):
            with contextlib.suppress(OSError):
                os.rmdir(d)
                removed.append(str(d))
        _RUN["files"].clear()
        _RUN["dirs"].clear()
    return removed


@contextlib.contextmanager
def scratch_path(path):
    """Yield ``path``, a scratch file (never an output) removed at the end of the block.

    While the block runs the file is registered as being written, so that a
    failed or interrupted run removes it too (:func:`remove_run_outputs`).
    """
    path = Path(path)
    _PENDING.add(path)
    try:
        yield path
    finally:
        with contextlib.suppress(OSError):
            os.unlink(path)
        _PENDING.discard(path)


def new_scratch_file(prefix: str, suffix: str) -> str:
    """An empty scratch file in the temporary folder, named by this host and process.

    The name is ``{prefix}{host}-{pid}-{random}{suffix}``, so that a later run
    can tell the files of a run killed outright (``kill -9``: no clean-up ran)
    from those of a live one, and it removes the former first
    (:func:`remove_stale_scratch`). The caller removes the file
    (:func:`scratch_path`).
    """
    import tempfile

    remove_stale_scratch(prefix, suffix)
    fd, name = tempfile.mkstemp(prefix=f"{prefix}{_host()}-{os.getpid()}-", suffix=suffix)
    os.close(fd)
    return name


def remove_stale_scratch(prefix: str, suffix: str) -> list[str]:
    """Remove the scratch files of :func:`new_scratch_file` whose process has ended.

    Only files named by this host and a process id that no longer runs are
    removed: never one of a live run (of any user), of another host sharing the
    folder, or without a process id. Returns the paths removed.
    """
    import tempfile

    folder = tempfile.gettempdir()
    head = f"{prefix}{_host()}-"
    removed = []
    try:
        names = os.listdir(folder)
    except OSError:
        return removed
    for name in sorted(names):
        if not (name.startswith(head) and name.endswith(suffix)):
            continue
        pid = name[len(head):].split("-", 1)[0]
        if not pid.isdigit() or _alive(int(pid)):
            continue
        path = os.path.join(folder, name)
        with contextlib.suppress(OSError):
            os.unlink(path)
            removed.append(path)
    return removed


def _host() -> str:
    import socket

    return socket.gethostname().replace(os.sep, "_") or "localhost"


def _alive(pid: int) -> bool:
    """Whether process ``pid`` runs (on this host); another user's process counts."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # PermissionError: it runs, as someone else
        return True
    return True


def _reason(exc) -> str:
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def _is_write_failure(exc) -> bool:
    """An OS-level or writer-library failure (not one of ours, not an interrupt)."""
    if isinstance(exc, Lidar2CityError) or not isinstance(exc, Exception):
        return False
    if isinstance(exc, OSError):
        return True
    return type(exc).__module__.split(".")[0] in _WRITER_MODULES


def check_output_path(path) -> Path:
    """Check that ``path`` can be written, before any work is done.

    The folder must exist, be a folder and accept a new file (tried, so that
    read-only mounts and permissions are caught whoever runs); ``path`` itself
    must not be a folder.

    Raises
    ------
    FileFormatError
        With the reason, naming the path.
    """
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise FileFormatError(f"output {str(path)!r} is a folder, not a file")
    if not parent.exists():
        # a file on the way ("out.txt/x.laz") is reported as such
        up = parent
        while not up.exists() and up != up.parent:
            up = up.parent
        if up.exists() and not up.is_dir():
            raise FileFormatError(f"cannot write {str(path)!r}: {str(up)!r} is a file, not a folder")
        raise FileFormatError(f"output folder {str(parent)!r} does not exist")
    if not parent.is_dir():
        raise FileFormatError(f"cannot write {str(path)!r}: {str(parent)!r} is a file, not a folder")
    probe = parent / f".lidar2city-probe{os.getpid()}-{threading.get_ident()}"
    # registered before it is made: an interrupt (the CLI's handler removes what is
    # being written, then exits) between its creation and removal leaves nothing
    _PENDING.add(probe)
    try:
        try:
            fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        except OSError as exc:
            raise FileFormatError(f"cannot write to {str(parent)!r}: {_reason(exc)}") from None
        os.close(fd)
        with contextlib.suppress(OSError):
            os.unlink(probe)
    finally:
        _PENDING.discard(probe)
    return path


def make_output_dir(path) -> Path:
    """Create the output folder ``path`` (and its parents) if needed, and check it is writable.

    Folders created are recorded in the open run (removed if it fails).

    Raises
    ------
    FileFormatError
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise FileFormatError(f"output {str(path)!r} is a file, not a folder")
    missing = []
    up = path
    while not up.exists() and up != up.parent:
        missing.append(up)
        up = up.parent
    if up.exists() and not up.is_dir():
        raise FileFormatError(f"cannot create {str(path)!r}: {str(up)!r} is a file, not a folder")
    for d in reversed(missing):
        try:
            d.mkdir()
        except FileExistsError:
            continue
        except OSError as exc:
            raise FileFormatError(f"cannot create the folder {str(d)!r}: {_reason(exc)}") from None
        if _RUN is not None:
            _RUN["dirs"].append(str(d))
    check_output_path(path / "x")
    return path


def _temp_name(path: Path, parent: Path) -> Path:
    if path.name.endswith(".city.json") or path.name.endswith(".city.jsonl"):
        return parent / f".tmp{os.getpid()}.{path.name}"
    return parent / f".{path.stem}.tmp{os.getpid()}{''.join(path.suffixes[-1:])}"


#: files a format writes beside the one named, by the named one's extension
SIDECARS = {".shp": (".shx", ".dbf", ".prj", ".cpg")}


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path``; rename it to ``path`` if the block succeeds.

    On any exception the temporary file is removed, so no half-written output
    is ever left under the final name. The temporary name keeps the final
    suffixes so format drivers that look at the extension still work.

    Raises
    ------
    FileFormatError
        When the folder does not exist or cannot be written, and for every
        OS-level failure while writing (permission, disk full, a writer
        library's I/O error), naming the output and the reason.
    """
    path = Path(path)
    check_output_path(path)
    parent = path.parent if str(path.parent) else Path(".")
    tmp = _temp_name(path, parent)
    # the files a driver writes beside the one named (a Shapefile's .shx, .dbf...): renamed
    # with it, the named one last, and removed with it
    sidecars = [(tmp.with_suffix(s), path.with_suffix(s))
                for s in SIDECARS.get(path.suffix.lower(), ())]
    pending = [tmp, *(t for t, _ in sidecars)]
    _PENDING.update(pending)
    try:
        yield tmp
        for t, final in sidecars:
            if t.exists():
                _commit(t, final)
        _commit(tmp, path)
    except BaseException as exc:
        for t in pending:
            with contextlib.suppress(OSError):
                os.unlink(t)
        if _is_write_failure(exc):
            raise FileFormatError(f"cannot write {str(path)!r}: {_reason(exc)}") from exc
        raise
    finally:
        _PENDING.difference_update(pending)


def _commit(tmp: Path, path: Path) -> None:
    """Rename ``tmp`` to ``path`` and record it, with SIGINT held off in between (main thread)."""
    main = (threading.current_thread() is threading.main_thread()
            and hasattr(signal, "pthread_sigmask"))  # not on Windows
    if main:
        old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    try:
        os.replace(tmp, path)
        if _RUN is not None:
            _RUN["files"].append(str(path))
    finally:
        if main:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)


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
