"""``classify``: a LAS/LAZ tile in, the same points with ASPRS classes out."""

from __future__ import annotations

import dataclasses
import logging
import time

import numpy as np

from ..datamodel import ASPRS
from ..errors import EmptyInputError
from ..io.las import read_las, with_neighbours, write_las

logger = logging.getLogger(__name__)

__all__ = ["classify_file", "classify_config"]


def classify_config(source=None):
    """The ``[classify]`` section of a run config (TOML path or dict) as a :class:`ClassifyConfig`.

    Other sections are validated by :func:`lidar2city.config.load_config`.
    """
    from ..config import stage_config

    return stage_config("classify", source)


def _ground(cloud, *, ground_from_file: bool, method: str):
    if ground_from_file:
        cls = cloud.get("classification")
        if cls is None or not (cls == ASPRS.GROUND).any():
            raise EmptyInputError(
                "--ground-from-file: the input has no ground (class 2) points to reuse")
        return cls == ASPRS.GROUND
    from ..ground import ground_mask

    ground = np.asarray(ground_mask(cloud.xyz, method=method), dtype=bool)
    if not ground.any():
        raise EmptyInputError("the ground filter found no ground point in the input")
    return ground


#: ASPRS classes a vendor marks noise (low point 7; high noise 18, LAS 1.4): never
#: reclassified
NOISE_CLASSES = (7, 18)


def classify_cloud(cloud, *, ground_from_file: bool = False, ground_method: str = "smrf",
                   config=None) -> np.ndarray:
    """ASPRS classes of every point of a :class:`PointCloud`: ground filter, then classification.

    The cloud's returns and colours are used when present. This is what
    ``classify``, ``footprints`` and ``reconstruct`` run on a raw tile.
    """
    from ..classify import classify_points
    from ..classify.outliers import far_points

    cfg = config if config is not None else classify_config(None)
    given = cloud.get("classification")
    noise = np.isin(given, NOISE_CLASSES) if given is not None else None
    if noise is not None and noise.any():  # the vendor's noise labels are kept
        if noise.all():
            raise EmptyInputError("every point is classified noise (7 or 18): nothing to classify")
        logger.info("%d point(s) classified noise (7 or 18) in the input: kept as noise",
                    int(noise.sum()))
        out = np.array(given, dtype=np.uint8, copy=True)
        out[~noise] = classify_cloud(cloud.subset(~noise), ground_from_file=ground_from_file,
                                     ground_method=ground_method, config=cfg)
        return out
    far = far_points(cloud.xyz[:, :2])
    if far.any():  # stray returns far away: noise, and the survey classified without them
        logger.warning("%d point(s) far from the rest of the survey: classified noise (7)",
                       int(far.sum()))
        out = np.full(len(cloud), ASPRS.NOISE, dtype=np.uint8)
        out[~far] = classify_cloud(cloud.subset(~far), ground_from_file=ground_from_file,
                                   ground_method=ground_method, config=cfg)
        return out
    ground = _ground(cloud, ground_from_file=ground_from_file, method=ground_method)
    rgb = None
    if all(k in cloud.attributes for k in ("red", "green", "blue")):
        rgb = np.column_stack([cloud.attributes[k] for k in ("red", "green", "blue")])
        if not rgb.any():
            rgb = None  # formats with colour fields left at zero
    return classify_points(
        cloud.xyz, ground,
        return_number=cloud.get("return_number"),
        number_of_returns=cloud.get("number_of_returns"),
        intensity=cloud.get("intensity"),
        rgb=rgb, config=cfg,
    )


def classify_file(src, dst, *, crs=None, ground_from_file: bool = False,
                  ground_method: str = "smrf", config=None, neighbours=(), buffer=50.0) -> dict:
    """Classify every point of ``src`` and write them all, with every attribute, to ``dst``.

    Parameters
    ----------
    src, dst : str or Path
        Input and output LAS/LAZ files (the output format follows its extension;
        written under a temporary name and renamed on success).
    crs : str, optional
        CRS overriding or supplying the file's own (needed for the unit of a
        file without CRS only when it is not in metres).
    ground_from_file : bool
        Reuse the input's class 2 as the ground instead of filtering it.
    ground_method : str
        Method of :func:`lidar2city.ground.ground_mask` otherwise.
    config : ClassifyConfig, dict or path of a run TOML, optional
    neighbours : sequence of paths
        Adjacent tiles whose points within ``buffer`` metres are classified
        with the input (:func:`lidar2city.io.las.with_neighbours`); only the
        input's points are written.
    buffer : float
        Width (m) of that strip.

    Returns
    -------
    dict
        ``points``, ``classes`` (code -> count), ``seconds``, ``config``.

    Raises
    ------
    FileFormatError, EmptyInputError, InputError, ConfigError
    """
    cfg = classify_config(config)
    t0 = time.perf_counter()
    tile = read_las(src, crs=crs)
    cloud = tile.point_cloud()
    cloud.require_area(repr(str(src)), "classify")
    wide = with_neighbours(cloud, neighbours, buffer=buffer, crs=crs)
    classes = classify_cloud(wide, ground_from_file=ground_from_file,
                             ground_method=ground_method, config=cfg)[:len(cloud)]
    write_las(dst, tile, classification=classes)
    values, counts = np.unique(classes, return_counts=True)
    summary = {
        "points": len(cloud),
        "classes": {int(v): int(c) for v, c in zip(values, counts, strict=True)},
        "seconds": round(time.perf_counter() - t0, 3),
        "config": dataclasses.asdict(cfg),
    }
    logger.info("classified %s -> %s in %.1f s", src, dst, summary["seconds"])
    return summary
