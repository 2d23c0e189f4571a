"""``lidar2city tune``: learn the active-contour weights from reference footprints."""

from __future__ import annotations

import click

from ._options import output_option, progress

_path = click.Path(dir_okay=False)


@click.command("tune")
@click.option("--dsm", required=True, type=_path, help="DSM GeoTIFF (heights in the CRS's vertical unit).")
@click.option("--dtm", type=_path, default=None, show_default="derived from the DSM",
              help="DTM on the DSM grid.")
@click.option("--ortho", type=_path, default=None, help="Orthoimage on the DSM grid (drives the regional term).")
@click.option("--reference", required=True, type=_path, help="Reference building footprints (GPKG or any OGR source).")
@output_option()
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed (the same seed gives the same weights).")
@click.option("--population", type=click.IntRange(min=4), default=30, show_default=True, help="Chromosomes per generation.")
@click.option("--generations", type=click.IntRange(min=0), default=15, show_default=True, help="Maximum generations.")
@click.option("-j", "--jobs", type=click.IntRange(min=1), default=1, show_default=True, help="Processes evaluating fitness.")
@click.option("--objective", type=click.Choice(["cost", "kappa"]), default="cost", show_default=True,
              help="Fitness: (FP + FN) / N pixels (eq. 4), or 1 - kappa.")
@click.option("--config", "config_path", type=_path, default=None, help="Run config TOML; its [active_contour] section sets the other snake parameters.")
@click.option("--figure", type=_path, default=None, help="Also write the cost per generation as a PNG.")
@click.option("--domain", type=click.Choice(["reference", "bbox"]), default="reference", show_default=True,
              help="Pixels scored: around the reference buildings, skipping above-ground objects the "
                   "reference does not hold (incomplete reference), or its whole bounding box (complete).")
@click.option("--scale", type=click.Choice(["log", "linear"]), default="log", show_default=True,
              help="Genes: log10 of the weights (0.01 to 10) or the weights themselves (0 to 3).")
def command(dsm, dtm, ortho, reference, output, seed, population, generations, jobs, objective,
            config_path, figure, domain, scale):
    """Tune the active-contour weights (alpha, beta, gamma, mu, epsilon, anchor) with a genetic algorithm.

    The cost is the share of wrongly classified pixels, (FP + FN) / N, of the
    snake outlines against the reference buildings. Writes the weights as TOML
    for `lidar2city footprints --regularize active-contour --weights W.toml`.
    """
    from ..tools.active_contour import tune

    cfg = None
    if config_path is not None:
        from ..config import build_stage
        from ..contour.outlines import ActiveContourConfig
        from ..io.weights import read_stage_table

        cfg = build_stage("active_contour", read_stage_table(config_path, "active_contour"),
                          cls=ActiveContourConfig)

    with progress(length=generations + 1, label="tuning") as bar:
        def step(record):
            bar.update(1)

        res = tune(dsm, dtm=dtm, ortho=ortho, reference=reference, output=output, seed=seed,
                   population=population, generations=generations, n_jobs=jobs, objective=objective,
                   config=cfg, figure=figure, callback=step, domain=domain, scale=scale)
    for r in res["history"]:
        click.echo(f"generation {r['generation']:3d}  best cost {r['best_cost']:.5f}  "
                   f"mean {r['mean']:.5f}  same {100 * r['same']:.0f} %", err=True)
    w = res["weights"]
    click.echo("weights  " + "  ".join(f"{k}={v:.4f}" for k, v in w.items()))
    click.echo(f"cost     {res['cost']:.5f} (default weights {res['default_cost']:.5f})")
    click.echo(f"written  {output}")
