"""The synthetic town as other surveys would have recorded it.

Users bring point clouds from every decade and vendor. :func:`survey_variant`
re-writes a town from :func:`lidar2city.synthetic.make_town` (multi-echo, in
metres) as:

``"multi"``
    the town as made: per-echo ``return_number`` / ``number_of_returns``.
``"pairs"``
    a first/last-pulse survey (ISPRS Stuttgart style): every pulse gives two
    points, all "n of 2"; a pulse that met one surface gives the same point
    twice (with independent range noise); all first pulses are stored before
    all last pulses. ``shuffle=True`` stores them in random order.
``"single"``
    single returns only: the first echo of every pulse, all "1 of 1".
``"no_returns"``
    the town without return fields.
``"feet"``
    the town in US survey feet (x, y and z; EPSG:6880 + NAVD88 height (ftUS)).

:func:`make_survey` also sets the density (``density=1.5`` or ``25`` pts/m2 for
the sparse and dense surveys). Every variant keeps the truth class of every
point in ``attributes['classification']``.

Pure: no files, randomness only through ``seed``.
"""

from __future__ import annotations

import numpy as np

from .datamodel import PointCloud
from .errors import InputError
from .synthetic import SyntheticTown, make_town

__all__ = ["SURVEY_KINDS", "survey_variant", "make_survey", "FEET_CRS"]

SURVEY_KINDS = ("multi", "pairs", "single", "no_returns", "feet")
#: NAD83(2011) / Nebraska (ftUS) + NAVD88 height (ftUS): a feet CRS for x, y and z.
FEET_CRS = "EPSG:6880+6360"
_FT = 1200.0 / 3937.0  # metres per US survey foot
#: Range noise (m) between the first- and last-pulse detectors of one echo.
_PAIR_NOISE = 0.02


def _pulses(cloud: PointCloud):
    """Index of the first echo of every point's pulse.

    ``make_town`` gives a second echo the horizontal position of its first.
    """
    rn = cloud.attributes["return_number"].astype(np.int64)
    xy = cloud.xyz[:, :2]
    first = np.flatnonzero(rn == 1)
    second = np.flatnonzero(rn == 2)
    # match each second echo to the first echo at the same x, y
    keys = np.concatenate([xy[first], xy[second]])
    _, inv = np.unique(keys, axis=0, return_inverse=True)
    inv = inv.ravel()
    owner = np.full(inv.max() + 1, -1, np.int64)
    owner[inv[:len(first)]] = first
    head = np.arange(len(rn))
    head[second] = owner[inv[len(first):]]
    if (head[second] < 0).any():  # pragma: no cover - make_town invariant
        raise InputError("a second echo has no first echo at its position")
    return head


def survey_variant(town: SyntheticTown, kind: str, *, seed: int = 0,
                   shuffle: bool = False) -> PointCloud:
    """The town's points as survey ``kind`` would record them.

    Parameters
    ----------
    town : SyntheticTown
        From :func:`lidar2city.synthetic.make_town`.
    kind : str
        One of :data:`SURVEY_KINDS`.
    seed : int
        Seed of the range noise of duplicated echoes and of ``shuffle``.
    shuffle : bool
        Store the points in random order (``"pairs"`` only: then pairs must be
        found by position, not by file order).

    Returns
    -------
    PointCloud
        With truth ``classification`` and the variant's return fields.

    Raises
    ------
    InputError
        On an unknown kind.

    Examples
    --------
    >>> from lidar2city.synthetic import make_town
    >>> town = make_town(size=(60, 50), density=2, seed=1)
    >>> pairs = survey_variant(town, "pairs")
    >>> set(pairs.attributes["number_of_returns"].tolist())
    {2}
    """
    if kind not in SURVEY_KINDS:
        raise InputError(f"kind must be one of {', '.join(SURVEY_KINDS)}, got {kind!r}")
    cloud = town.cloud
    a = cloud.attributes
    if kind == "multi":
        return cloud
    if kind == "no_returns":
        return PointCloud(cloud.xyz, cloud.origin, cloud.crs, cloud.xy_unit, cloud.z_unit,
                          {"classification": a["classification"]})
    if kind == "feet":
        from .crs import parse_crs, unit_factors

        crs = parse_crs(FEET_CRS)
        xy_unit, z_unit = unit_factors(crs)
        # the same scene placed in Nebraska, in feet: origin in CRS units
        origin = np.array([1_600_000.0, 500_000.0, 1_000.0])
        return PointCloud(cloud.xyz, origin, crs, xy_unit, z_unit, dict(a))
    rn = a["return_number"]
    first = np.flatnonzero(rn == 1)
    if kind == "single":
        ones = np.ones(len(first), np.uint8)
        return PointCloud(cloud.xyz[first], cloud.origin, cloud.crs, cloud.xy_unit, cloud.z_unit,
                          {"classification": a["classification"][first],
                           "return_number": ones, "number_of_returns": ones.copy()})
    # first/last pairs: the last pulse is the last echo of the pulse (the
    # point itself for one-echo pulses, re-measured with range noise)
    rng = np.random.default_rng(seed)
    head = _pulses(cloud)
    last_of = first.copy()
    pos = np.full(len(rn), -1, np.int64)
    pos[first] = np.arange(len(first))
    second = np.flatnonzero(rn == 2)
    last_of[pos[head[second]]] = second
    last_xyz = cloud.xyz[last_of].copy()
    one_echo = last_of == first
    last_xyz[one_echo, 2] += rng.normal(0, _PAIR_NOISE, int(one_echo.sum()))
    xyz = np.vstack([cloud.xyz[first], last_xyz])
    cls = np.concatenate([a["classification"][first], a["classification"][last_of]])
    m = len(first)
    ret = np.concatenate([np.ones(m, np.uint8), np.full(m, 2, np.uint8)])
    nret = np.full(2 * m, 2, np.uint8)
    if shuffle:
        order = rng.permutation(2 * m)
        xyz, cls, ret, nret = xyz[order], cls[order], ret[order], nret[order]
    return PointCloud(xyz, cloud.origin, cloud.crs, cloud.xy_unit, cloud.z_unit,
                      {"classification": cls, "return_number": ret, "number_of_returns": nret})


def make_survey(kind: str, *, density: float = 10.0, size=(200.0, 150.0), seed: int = 0,
                shuffle: bool = False, **town) -> PointCloud:
    """:func:`make_town` at ``density`` (first echoes per m2), recorded as survey ``kind``.

    Extra keyword arguments go to :func:`make_town`.
    """
    return survey_variant(make_town(size=size, density=density, seed=seed, **town), kind,
                          seed=seed, shuffle=shuffle)
