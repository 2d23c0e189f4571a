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
