"""Stray returns far from the survey: the handful of points that blow up its extent.

A tile with a few points kilometres away (a gross range error, a point with a
corrupt coordinate) makes every grid over its extent enormous: the ground filter
and the classification grid the whole extent and would ask for a grid of
10^12 cells. :func:`far_points` finds them so that the tools leave them out
(as noise) and filter the survey itself. It lives in :mod:`lidar2city.ground.outliers`
(a ``ground`` run need not import the classification); this module keeps its name.
"""

from __future__ import annotations

from ..ground.outliers import far_points

__all__ = ["far_points"]
