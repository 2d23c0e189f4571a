"""Options and helpers shared by several subcommands."""

from __future__ import annotations

import click

__all__ = ["crs_option", "neighbours_options", "output_option", "progress", "progress_callback"]

crs_option = click.option(
    "--crs", default=None, metavar="CRS",
    help="CRS of the input (EPSG:xxxx, WKT or PROJ); overrides or supplies the file's own.",
)


def neighbours_options(f):
    """``--neighbour`` (repeatable) and ``--buffer``: adjacent tiles filtered with the input."""
    f = click.option("--buffer", type=click.FloatRange(min=0.0), default=50.0, show_default=True,
                     help="Width (m) of the strip of the neighbouring tiles taken.")(f)
    return click.option("--neighbour", "neighbours", multiple=True,
                        type=click.Path(dir_okay=False),
                        help="An adjacent tile (repeatable): its points near INPUT are "
                             "processed with it so that INPUT's border sees beyond it; only "
                             "INPUT's points are written.")(f)


def output_option(**kwargs):
    return click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
                        help="Output file.", **kwargs)


def progress(iterable=None, *, length=None, label="", quiet=False, item_show_func=None):
    """A click progress bar shown on a terminal only (never in pipes or CI logs)."""
    import sys

    if quiet or not sys.stderr.isatty():
        class _Null:
            def __enter__(self):
                return self

            def __exit__(self, *a):
                return False

            def update(self, n, current_item=None):
                pass

            def __iter__(self):
                return iter(iterable)

        return _Null()
    return click.progressbar(iterable, length=length, label=label, file=sys.stderr,
                             item_show_func=item_show_func)


def progress_callback(bar):
    """A ``callback(done, total)`` for the library's jobs that advances ``bar`` to ``done``."""
    state = {"done": 0}

    def callback(done, total):
        bar.length = total
        bar.update(done - state["done"])
        state["done"] = done

    return callback
