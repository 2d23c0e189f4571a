"""Building / vegetation separation: ASPRS classes from a ground mask.

:func:`classify_points` is the stage function (config stage ``classify``,
:class:`ClassifyConfig`); :func:`height_above_ground` grids a DTM from the
ground points; :func:`local_shape` and :func:`planar_regions` are the
feature and region-growing building blocks.
"""

from .core import ClassifyConfig, classify_points, greenness
from .features import LocalShape, local_shape, point_spacing
from .hag import GroundGrid, ground_grid, height_above_ground
from .regions import Regions, planar_regions, region_planes

__all__ = [
    "ClassifyConfig",
    "classify_points",
    "greenness",
    "LocalShape",
    "local_shape",
    "point_spacing",
    "GroundGrid",
    "ground_grid",
    "height_above_ground",
    "Regions",
    "planar_regions",
    "region_planes",
]
