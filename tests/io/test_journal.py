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


def test_a_journal_interrupted_while_it_was_made_is_removed_not_named(tmp_path):
    """The interrupt handler names a kept journal only when ``--resume`` can go on from
    it: a folder the interrupt caught before its run file was written is removed (a
    later --resume would refuse it as another run's), one not made yet is not named,
    and a complete one is kept."""
    from lidar2city.io.journal import settle_interrupted

    out = tmp_path / "m.city.jsonl"
    folder = journal_path(out)
    assert not settle_interrupted(folder)  # named as kept, not made yet
    folder.mkdir()
    assert not settle_interrupted(folder) and not folder.exists()
    Journal.open(out, "k1", 3)
    assert settle_interrupted(folder) and folder.is_dir()
