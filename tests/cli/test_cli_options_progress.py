"""cli._options.progress_callback: the shared adapter from job callbacks to a progress bar."""

from lidar2city.cli._options import progress_callback


class _Bar:
    length = 1

    def __init__(self):
        self.steps = []

    def update(self, n):
        self.steps.append(n)


def test_progress_callback_advances_the_bar_by_the_difference():
    bar = _Bar()
    cb = progress_callback(bar)
    cb(1, 5)
    cb(4, 5)
    cb(5, 5)
    assert bar.length == 5 and bar.steps == [1, 3, 1]


def test_engine_progress_on_a_terminal_starts_no_thread(monkeypatch):
    """The bars on a terminal are drawn when a count changes, by no refresh thread of
    rich's: ``--workers auto`` forks no worker beside another thread (session 15: on a
    terminal the default run stayed in one process for rich's refresh thread)."""
    import io
    import threading

    from lidar2city.cli import _options

    before = set(threading.enumerate())
    bar = _options.EngineProgress("blocks", "buildings")
    bar.live = True  # as on a terminal
    monkeypatch.setattr("sys.stderr", io.StringIO())
    with bar:
        assert set(threading.enumerate()) == before
        for done in range(5):
            bar.blocks(done, 4)
            bar.items(done * 3, None)
        assert set(threading.enumerate()) == before
    assert bar._bar is not None and bar._bar.tasks[0].completed == 4
