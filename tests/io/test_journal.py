"""The run journal beside an output (``--resume``)."""

from __future__ import annotations

from lidar2city.io import _atomic
from lidar2city.io.journal import Journal, journal_path


def test_an_open_run_keeps_its_journal_by_name(tmp_path):
    """An interrupted run removes its outputs but keeps its journal, and its message names
    it: the journal is registered as kept for --resume while the run is open."""
    out = tmp_path / "m.city.jsonl"
    _atomic.begin_run()
    try:
        Journal.open(out, "k1", 3)
        assert _atomic.kept_for_resume() == [str(journal_path(out))]
        assert _atomic.remove_run_outputs() == [] and journal_path(out).is_dir()
    finally:
        _atomic.end_run()
    assert _atomic.kept_for_resume() == []
