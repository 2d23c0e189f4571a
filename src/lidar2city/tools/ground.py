"""``ground`` and ``evaluate ground``: file-level ground filtering and its evaluation."""

from __future__ import annotations

import dataclasses
import logging
import time

import numpy as np

from ..datamodel import ASPRS
from ..errors import EmptyInputError, InputError

logger = logging.getLogger(__name__)

__all__ = ["ground_config", "ground_file", "evaluate_ground_files"]


def ground_config(config=None, **overrides):
    """The resolved :class:`~lidar2city.ground.GroundConfig`.

    Parameters
    ----------
    config : str, Path, dict, GroundConfig or None
        A run TOML file or dict of sections (its ``[ground]`` table is used;
        the other tables' names are checked, their values left to their own
        stages), or a config.
    **overrides
        Options set explicitly (e.g. from the command line); ``None`` values
        are ignored.

    Raises
    ------
    ConfigError, FileFormatError
    """
    from ..config import stage_config

    return stage_config("ground", config, **overrides)


def ground_file(input_path, output_path, *, dtm_path=None, config=None, method=None,
                dtm_cell=None, crs=None, neighbours=(), buffer=50.0) -> dict:
    """Classify a LAS/LAZ tile into ground (ASPRS 2) and the rest (1); optionally write a DTM.

    Every input point is written with all its attributes; only the
    classification changes. Both outputs are written under temporary names
    and renamed once complete; nothing is written when an error is raised.

    Parameters
    ----------
    input_path, output_path : str or Path
        LAS/LAZ in and out (format from the output extension).
    dtm_path : str or Path, optional
        GeoTIFF of the terrain interpolated from the ground points (holes
        filled), in the input CRS.
    config : see :func:`ground_config`
    method : str, optional
        Overrides ``ground.method``.
    dtm_cell : float, optional
        Overrides ``ground.dtm_cell`` (metres).
    crs : str, optional
        CRS of the input (overrides the file's).
    neighbours : sequence of paths
        Adjacent tiles: their points within ``buffer`` metres of the input are
        filtered with it (:func:`lidar2city.io.las.with_neighbours`), so the
        input's border points see the terrain beyond it; only the input's
        points are written.
    buffer : float
        Width (m) of the strip taken from the neighbours.

    Returns
    -------
    dict
        ``points``, ``ground``, ``method``, ``config`` (resolved), ``seconds``
        and, with a DTM, ``dtm_shape`` and ``dtm_cell``.

    Raises
    ------
    FileFormatError
        Missing or unreadable input, missing output folder.
    EmptyInputError
        No points, or no ground found.
    InputError
        NaN coordinates, bad options.
    """
    from ..ground import dtm_from_ground, ground_mask
    from ..ground.outliers import far_points
    from ..io.las import read_las, with_neighbours

    cfg = ground_config(config, method=method, dtm_cell=dtm_cell)
    t0 = time.perf_counter()
    tile = read_las(input_path, crs=crs)
    cloud = tile.point_cloud()
    cloud.require_area(repr(tile.path), "filter the ground in")
    wide = with_neighbours(cloud, neighbours, buffer=buffer, crs=crs)
    far = far_points(wide.xyz[:, :2])
    if far.any():  # stray returns far away: not ground, and the survey filtered without them
        logger.warning("%d point(s) far from the survey left out of the ground filter "
                       "(class 1)", int(far.sum()))
        mask = np.zeros(len(wide), dtype=bool)
        mask[~far] = ground_mask(wide.xyz[~far], method=cfg.method, **cfg.method_params())
        mask = mask[:len(cloud)]
    else:
        mask = ground_mask(wide.xyz, method=cfg.method, **cfg.method_params())[:len(cloud)]
    n_ground = int(mask.sum())
    if n_ground == 0:
        raise EmptyInputError(f"{tile.path!r}: no ground point found (method {cfg.method})")
    classification = np.where(mask, ASPRS.GROUND, ASPRS.UNCLASSIFIED).astype(np.uint8)
    summary = {"points": len(cloud), "ground": n_ground, "method": cfg.method,
               "config": dataclasses.asdict(cfg)}
    if dtm_path is not None:
        from ..io.raster import Raster, write_raster

        if cloud.crs is None:
            logger.warning("%s has no CRS: the DTM is written without one (pass --crs)",
                           tile.path)
        near = ~far[:len(cloud)]  # the DTM covers the survey, not its stray returns
        dtm = (dtm_from_ground(cloud.xyz[near], mask[near], cell=cfg.dtm_cell) if far.any()
               else dtm_from_ground(cloud.xyz, mask, cell=cfg.dtm_cell))
        write_raster(dtm_path, Raster(dtm.world_heights(cloud.origin[2], cloud.z_unit),
                                      dtm.world_transform(cloud.origin, cloud.xy_unit), cloud.crs))
        summary.update(dtm_shape=list(dtm.shape), dtm_cell=cfg.dtm_cell)
    from ..io.las import write_las

    write_las(output_path, tile, classification=classification)
    summary["seconds"] = round(time.perf_counter() - t0, 3)
    logger.info("%s: %d of %d points ground (%s)", tile.path, n_ground, len(cloud), cfg.method)
    return summary


def evaluate_ground_files(pred_path, reference_path, *, check_coordinates: bool = True) -> dict:
    """ISPRS ground-filter errors of a classified file against a reference file.

    Ground is ASPRS class 2 in both (the ISPRS reference samples label bare
    earth 2 and objects 0). Points are matched by order.

    Returns
    -------
    dict
        See :func:`lidar2city.metrics.ground.ground_errors`.

    Raises
    ------
    InputError
        Different point counts, or (``check_coordinates``) points in another order.
    FileFormatError
        Missing or unreadable files.
    """
    from ..io.las import read_las
    from ..metrics.ground import ground_errors

    pred = read_las(pred_path).data
    ref = read_las(reference_path).data
    n_pred, n_ref = len(pred.points), len(ref.points)
    if n_pred != n_ref:
        raise InputError(f"the prediction has {n_pred:,} points but the reference {n_ref:,}: "
                         "not the same point set")
    if n_ref == 0:
        raise EmptyInputError("the reference holds no points")
    if check_coordinates:
        for axis in ("x", "y", "z"):
            a = np.asarray(getattr(pred, axis))
            b = np.asarray(getattr(ref, axis))
            tol = max(float(pred.header.scales["xyz".index(axis)]),
                      float(ref.header.scales["xyz".index(axis)]))
            if not np.allclose(a, b, rtol=0.0, atol=tol):
                raise InputError(f"prediction and reference points differ in {axis}: "
                                 "not the same points in the same order")
    ref_ground = np.asarray(ref.classification) == ASPRS.GROUND
    if not ref_ground.any():  # e.g. a raw tile given as the reference: the scores mean nothing
        classes = ", ".join(str(int(c)) for c in np.unique(np.asarray(ref.classification))[:8])
        logger.warning("the reference %s labels no point ground (class 2; its classes: %s): "
                       "type I is undefined and every point called ground counts as an error; "
                       "a reference labels bare earth 2 (the ISPRS samples: 2 and 0)",
                       reference_path, classes)
    return ground_errors(np.asarray(pred.classification) == ASPRS.GROUND, ref_ground)
