"""``lidar2city``: the root command, logging options and error reporting."""

from __future__ import annotations

import logging
import sys

import click

from ._lazy import LazyGroup

__all__ = ["cli"]


class _RootGroup(LazyGroup):
    """Turns lidar2city errors into one-line messages and a non-zero exit."""

    def invoke(self, ctx):
        from ..errors import Lidar2CityError

        try:
            return super().invoke(ctx)
        except Lidar2CityError as exc:
            click.echo(f"Error: {exc}", err=True)
            ctx.exit(1)
        except MemoryError:
            click.echo("Error: out of memory; process fewer or smaller tiles", err=True)
            ctx.exit(1)


def _version() -> str:
    from .. import __version__

    return __version__


@click.group(cls=_RootGroup, exclude=("main",), context_settings={"help_option_names": ["-h", "--help"]})
@click.option("-v", "--verbose", count=True, help="More log output (-vv for debug).")
@click.option("-q", "--quiet", is_flag=True, help="Only errors.")
@click.version_option(version=_version(), prog_name="lidar2city")
def cli(verbose, quiet):
    """Airborne LiDAR to 3D city models.

    Typical use: `lidar2city demo`, `lidar2city info TILE.laz`,
    `lidar2city reconstruct TILE.laz --footprints F.gpkg -o out.city.json`.
    """
    level = logging.ERROR if quiet else (logging.WARNING, logging.INFO, logging.DEBUG)[min(verbose, 2)]
    logging.basicConfig(level=level, stream=sys.stderr,
                        format="%(levelname)s %(name)s: %(message)s")


if __name__ == "__main__":  # pragma: no cover
    cli()
