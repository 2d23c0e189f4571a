"""Building / vegetation separation: ASPRS classes from a ground mask.

:func:`classify_points` is the stage function (config stage ``classify``,
:class:`ClassifyConfig`); heights above ground come from
:func:`lidar2city.ground.dtm_from_ground`; :func:`local_shape` and :func:`planar_regions` are the
feature and region-growing building blocks; :func:`survey_cues` reads the
return fields the way the survey wrote them (multi-echo, first/last-pulse
pairs, single returns, absent or inconsistent).
"""

from .core import ClassifyConfig, classify_points, greenness
from .cues import SurveyCues, survey_cues
from .features import LocalShape, local_shape, point_spacing
from .regions import Regions, planar_regions, region_planes

__all__ = [
    "ClassifyConfig",
    "classify_points",
    "greenness",
    "SurveyCues",
    "survey_cues",
    "LocalShape",
    "local_shape",
    "point_spacing",
    "Regions",
    "planar_regions",
    "region_planes",
]
