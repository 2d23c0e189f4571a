"""``lidar2city view MODEL [--points TILE...] [--footprints F] [--port P] [--host H]``."""

from __future__ import annotations

import click

from ._options import crs_option


@click.command("view")
@click.argument("model", type=click.Path(dir_okay=False))
@click.option("--points", "points", multiple=True, type=click.Path(dir_okay=False),
              help="A LAS/LAZ tile of the model (repeatable): shown, and needed for editing.")
@click.option("--footprints", default=None, type=click.Path(dir_okay=False),
              help="The footprint file given to reconstruct (original outlines for edits).")
@click.option("--id-field", default=None, help="Footprint field holding the building id.")
@click.option("--edits", default=None, type=click.Path(dir_okay=False),
              show_default="MODEL.edits.json",
              help="EDITS.json accepted edits are appended to.")
@click.option("-o", "--output", default=None, type=click.Path(dir_okay=False),
              show_default="MODEL, replaced atomically",
              help="Write the corrected model here.")
@click.option("--port", default=8080, show_default=True, type=click.IntRange(1, 65535))
@click.option("--host", default="127.0.0.1", show_default=True,
              help="Address to listen on; 0.0.0.0 exposes the viewer (and editing) to the "
                   "network.")
@click.option("--max-points", default=200_000, show_default=True, type=click.IntRange(min=0),
              help="Points shown at most (evenly subsampled).")
@click.option("--no-browser", is_flag=True, help="Do not open a browser.")
@crs_option
def command(model, points, footprints, id_field, edits, output, port, host, max_points,
            no_browser, crs):
    """Open MODEL (CityJSON from reconstruct) in a local web viewer that edits and refits.

    Buildings at each LoD coloured by RMSE, roof type, status, validity or
    height; the points (subsampled); a building's attributes on click; the
    worst buildings to step through. With --points: refit a building as a
    primitive (box, gable, hip, shed, prism; least squares or from a placed
    primitive) or move / add / delete outline vertices and re-run its
    reconstruction; Accept writes the model atomically (it always validates)
    and appends the edit to EDITS.json for `reconstruct --edits`.
    """
    import signal
    import time
    import webbrowser

    from ..viewer.app import Viewer

    viewer = Viewer(model, points=points, footprints=footprints, edits=edits, output=output,
                    host=host, port=port, max_points=max_points, crs=crs, id_field=id_field)
    url = viewer.start()
    click.echo(f"lidar2city viewer at {url} (Ctrl+C to stop)", err=True)
    if not no_browser:
        webbrowser.open(url)
    # Ctrl+C is how a viewer is closed, not an interrupted run: the root command's handler
    # (which reports "interrupted" and exits 130) gives way to a plain KeyboardInterrupt here;
    # saves are atomic (temporary name, rename), so stopping between them leaves the model whole
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        click.echo("viewer stopped", err=True)
    finally:
        signal.signal(signal.SIGINT, previous)
        viewer.stop()
