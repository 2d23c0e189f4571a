"""The journal of a block-by-block run: which blocks are done, and their results.

A folder beside the output (``OUT.journal``) holds ``run.json`` (a hash of
the run's inputs and options, and its number of blocks) and one pickle per
finished block (``block-000012.pickle``). Every file is written under a
temporary name and renamed, so a run killed at any moment (even by SIGKILL)
leaves only whole blocks; a resumed run loads them, runs the others and
writes the same bytes as an uninterrupted run. The journal is removed once
the output is in place.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import pickle
import shutil
from pathlib import Path

from ..errors import FileFormatError, InputError
from ._atomic import keep_for_resume, scratch_path

logger = logging.getLogger(__name__)

__all__ = ["Journal", "journal_path", "run_key", "file_stamp", "settle_interrupted"]

_RUN = "run.json"


def journal_path(output) -> Path:
    """The journal folder of ``output``: ``OUT.journal`` beside it."""
    output = Path(output)
    return output.with_name(output.name + ".journal")


def file_stamp(path) -> list:
    """What identifies an input file's content cheaply: absolute path, size, mtime."""
    p = Path(path).resolve()
    st = p.stat()
    return [str(p), st.st_size, st.st_mtime_ns]


def run_key(description: dict) -> str:
    """A hash of a JSON-able description of a run's inputs and options."""
    text = json.dumps(description, sort_keys=True, default=str, separators=(",", ":"))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def settle_interrupted(folder) -> bool:
    """Whether ``folder``, a journal an interrupted run keeps (:func:`keep_for_resume`),
    is one ``--resume`` can go on from; a folder interrupted before its run file was
    written is removed (it could only be refused as another run's). Safe in a signal
    handler."""
    folder = str(folder)
    if not os.path.isdir(folder):
        return False
    if os.path.isfile(os.path.join(folder, _RUN)):
        return True
    shutil.rmtree(folder, ignore_errors=True)
    return False


def _write_atomic(path: Path, data: bytes) -> None:
    # the journal is kept after a failure (for --resume): its blocks are not run outputs,
    # only the block being written is a partial file to remove on an interrupt
    with scratch_path(path.with_name(f".{path.name}.tmp{os.getpid()}")) as tmp:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)


class Journal:
    """The finished blocks of a run (use :meth:`open`).

    Parameters
    ----------
    folder : Path
    key : str
        The run's hash (:func:`run_key`).
    """

    def __init__(self, folder: Path, key: str):
        self.folder = Path(folder)
        self.key = key

    @classmethod
    def open(cls, output, key: str, blocks: int, *, resume: bool = False) -> Journal:
        """The journal of ``output`` for the run ``key``.

        With ``resume`` the blocks already written by an earlier run of the same
        inputs and options are kept; without it an earlier journal of the same
        run is cleared (a fresh start).

        Raises
        ------
        InputError
            When a journal of other inputs or options is there.
        """
        folder = journal_path(output)
        old = None
        if folder.exists():
            try:
                old = json.loads((folder / _RUN).read_text(encoding="utf-8")).get("key")
            except (OSError, ValueError, AttributeError):
                old = None
            if old != key:
                if resume:
                    raise InputError(f"the journal {str(folder)!r} is of another run (other "
                                     "inputs or options): it cannot be resumed with these; run "
                                     "without --resume to a new output, or delete it")
                raise InputError(f"a journal of another run (other inputs or options) is beside "
                                 f"the output: {str(folder)!r}; finish that run with --resume, "
                                 "write to a new output, or delete it")
        elif resume:
            logger.warning("nothing to resume: no journal %s; starting from the first block",
                           folder)
        journal = cls(folder, key)
        if old is not None and not resume:
            logger.info("an earlier journal of this run is cleared (no --resume)")
            journal.remove()
        if not folder.parent.is_dir():
            raise FileFormatError(f"output folder {str(folder.parent)!r} does not exist")
        # named as kept before it is made: an interrupt while it is being made finds it
        # (:func:`settle_interrupted`) and either names it or removes it
        keep_for_resume(folder)
        try:
            folder.mkdir(exist_ok=True)
            if not (folder / _RUN).exists():
                _write_atomic(folder / _RUN, json.dumps({"key": key, "blocks": blocks}).encode())
        except OSError as exc:
            with contextlib.suppress(OSError):  # an empty journal is no use to --resume
                folder.rmdir()
            raise FileFormatError(f"cannot write the journal {str(folder)!r}: "
                                  f"{exc.strerror or exc}") from None
        return journal

    def _block(self, index: int) -> Path:
        return self.folder / f"block-{index:06d}.pickle"

    def done(self) -> list:
        """Indices of the blocks finished, sorted."""
        out = []
        for p in self.folder.glob("block-*.pickle"):
            with contextlib.suppress(ValueError):
                out.append(int(p.stem.split("-")[1]))
        return sorted(out)

    def load(self, index: int):
        """The saved output of block ``index``."""
        try:
            with open(self._block(index), "rb") as f:
                return pickle.load(f)
        except Exception as exc:  # noqa: BLE001 - any unreadable block is run again
            logger.warning("journal block %d unreadable (%s): it is run again", index, exc)
            with contextlib.suppress(OSError):
                self._block(index).unlink()
            return None

    def save(self, index: int, output) -> None:
        """Record block ``index`` as finished with ``output``."""
        try:
            _write_atomic(self._block(index),
                          pickle.dumps(output, protocol=pickle.HIGHEST_PROTOCOL))
        except OSError as exc:
            raise FileFormatError(f"cannot write the journal {str(self.folder)!r}: "
                                  f"{exc.strerror or exc}") from None

    def remove(self) -> None:
        """Delete the journal (the run is complete)."""
        shutil.rmtree(self.folder, ignore_errors=True)
