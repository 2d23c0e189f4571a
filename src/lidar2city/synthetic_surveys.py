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

:func:`add_canopy` gives the town the vegetation of a modern full-waveform
survey (IGN LiDAR HD style, up to 5-6 echoes): contiguous stands of
overlapping crowns, some smooth-topped, crowns overhanging roofs (the roof
then answers as a later echo of the pulse) and up to ``max_returns`` echoes per
pulse, some of them on smooth dense crowns that stop the pulse (one echo).
:func:`make_survey` also sets the density (``density=1.5`` or ``25`` pts/m2 for
the sparse and dense surveys) and adds that canopy with ``canopy=True``. Every
variant keeps the truth class of every point in ``attributes['classification']``.

Pure: no files, randomness only through ``seed``.
"""

from __future__ import annotations

import numpy as np

from .datamodel import ASPRS, PointCloud
from .errors import InputError
from .synthetic import SyntheticTown, make_town

__all__ = ["SURVEY_KINDS", "survey_variant", "make_survey", "scan_lines", "add_canopy", "FEET_CRS"]

SURVEY_KINDS = ("multi", "pairs", "single", "no_returns", "feet")
#: NAD83(2011) / Nebraska (ftUS) + NAVD88 height (ftUS): a feet CRS for x, y and z.
FEET_CRS = "EPSG:6880+6360"
_FT = 1200.0 / 3937.0  # metres per US survey foot
#: Range noise (m) between the first- and last-pulse detectors of one echo.
_PAIR_NOISE = 0.02


def _pulses(cloud: PointCloud):
    """Index of the first echo of every point's pulse.

    ``make_town`` and :func:`add_canopy` give the later echoes of a pulse the
    horizontal position of its first.
    """
    rn = cloud.attributes["return_number"].astype(np.int64)
    xy = cloud.xyz[:, :2]
    first = np.flatnonzero(rn == 1)
    second = np.flatnonzero(rn >= 2)
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
    last = np.flatnonzero((rn >= 2) & (rn == a["number_of_returns"]))
    last_of[pos[head[last]]] = last
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
                shuffle: bool = False, canopy: bool = False, anisotropy: float = 1.0,
                **town) -> PointCloud:
    """:func:`make_town` at ``density`` (first echoes per m2), recorded as survey ``kind``.

    ``canopy=True`` adds :func:`add_canopy`'s multi-echo stands and overhanging
    crowns first. ``anisotropy > 1`` records the town in scan lines
    (:func:`scan_lines`): lines ``anisotropy`` times farther apart than the
    points along them. Extra keyword arguments go to :func:`make_town`.
    """
    if not anisotropy >= 1:
        raise InputError(f"anisotropy must be >= 1, got {anisotropy!r}")
    # scan lines are cut from a town dense enough to hold a point every along-line step
    t = make_town(size=size, density=density * (1.5 * anisotropy if anisotropy > 1 else 1.0),
                  seed=seed, **town)
    if canopy:
        t = add_canopy(t, seed=seed)
    cloud = survey_variant(t, kind, seed=seed, shuffle=shuffle)
    return scan_lines(cloud, density, anisotropy) if anisotropy > 1 else cloud


def scan_lines(cloud: PointCloud, density: float, anisotropy: float = 8.0) -> PointCloud:
    """The points of ``cloud`` a scanner with strongly anisotropic sampling would record.

    Scan lines run along x, ``sqrt(anisotropy / density)`` apart in y, with one
    point every ``1 / anisotropy`` of that along each (the lowest-index point of
    ``cloud`` in each step of a strip as wide as the step): ``density`` points
    per m2, e.g. 8:1 for a fast scan mirror over a slow platform. ``cloud`` must
    hold ``1.5 x anisotropy x density`` points per m2 or so for every step to
    have a point. Pure; the points keep their attributes (all echoes of a
    pulse lie at its x, y, so pulses stay whole).

    Examples
    --------
    >>> from lidar2city.synthetic import make_town
    >>> town = make_town(size=(60, 50), density=96, seed=1)
    >>> lines = scan_lines(town.cloud, 8.0, 8.0)
    >>> round(len(lines) / (60 * 50), 0)
    8.0
    """
    if not (density > 0 and anisotropy >= 1):
        raise InputError(f"density must be > 0 and anisotropy >= 1, got {density!r}, "
                         f"{anisotropy!r}")
    gap = np.sqrt(anisotropy / density)
    step = gap / anisotropy
    x, y = cloud.xyz[:, 0], cloud.xyz[:, 1]
    on = np.flatnonzero(np.mod(y, gap) < step)
    key = np.floor(y[on] / gap).astype(np.int64) * (1 << 32) + np.floor(x[on] / step).astype(
        np.int64)
    _, first = np.unique(key, return_index=True)
    # whole pulses: every echo at the x, y of a kept point
    _, inv = np.unique(np.concatenate([cloud.xyz[on[first], :2], cloud.xyz[on, :2]]), axis=0,
                       return_inverse=True)
    inv = inv.ravel()
    keep = np.sort(on[np.isin(inv[len(first):], inv[:len(first)])])
    return PointCloud(cloud.xyz[keep], cloud.origin, cloud.crs, cloud.xy_unit, cloud.z_unit,
                      {k: np.asarray(v)[keep] for k, v in cloud.attributes.items()})


def _crowns(rng, town: SyntheticTown, *, cover, overhang, roughness):
    """Crown centres, radii and top heights: stands of overlapping crowns in the
    open space, each crown allowed over a roof by up to ``overhang`` metres."""
    import shapely

    w, h = np.ptp(town.cloud.xyz[:, :2], axis=0)
    fp = shapely.union_all([b.footprint for b in town.buildings])
    free = shapely.geometry.box(2, 2, w - 2, h - 2).difference(fp.buffer(1.0))
    target = cover * free.area
    crowns, area, tries = [], 0.0, 0
    while area < target and tries < 5000:
        tries += 1
        # a stand: a centre in the open, crowns scattered around it
        cx, cy = rng.uniform(2, w - 2), rng.uniform(2, h - 2)
        if not free.contains(shapely.geometry.Point(cx, cy)):
            continue
        stand_r, stand_h = rng.uniform(6, 18), rng.uniform(8, 22)
        for _ in range(int(rng.integers(3, 14))):
            r = rng.uniform(2.0, 6.0)
            x = cx + rng.uniform(-stand_r, stand_r)
            y = cy + rng.uniform(-stand_r, stand_r)
            if not 2 < x < w - 2 or not 2 < y < h - 2:
                continue
            if fp.distance(shapely.geometry.Point(x, y)) < max(r - overhang, 1.0):
                continue
            crowns.append((x, y, r, stand_h * rng.uniform(0.8, 1.2), rng.uniform(*roughness)))
            area += 0.6 * np.pi * r * r
    return np.array(crowns).reshape(-1, 5)


def add_canopy(town: SyntheticTown, *, seed: int = 0, cover: float = 0.3,
               overhang: float = 2.0, max_returns: int = 5,
               opaque: float = 0.35, roughness=(0.15, 0.4)) -> SyntheticTown:
    """The town with the vegetation of a modern multi-echo survey.

    Stands of overlapping ellipsoidal crowns (radius 2-6 m, 6-26 m high, each
    with its own surface roughness drawn from ``roughness``) cover
    about ``cover`` of the open space; crowns may reach over roofs by up to
    ``overhang`` metres. A pulse under a crown returns its first echo on the
    crown; with probability ``opaque`` that is its only echo (a dense crown),
    otherwise it gives 2 to ``max_returns`` echoes, the later ones inside the
    crown and, for half of them, the last on what lies under it (terrain or
    roof, which keeps its class).

    Parameters
    ----------
    town : SyntheticTown
        From :func:`lidar2city.synthetic.make_town`.
    seed : int
        Seed of the crowns and echoes.
    cover : float
        Fraction of the open space (more than 1 m from buildings) under crowns.
    overhang : float
        How far (m) a crown may reach over a roof.
    max_returns : int
        Most echoes per pulse (2 to 15).
    opaque : float
        Share of the pulses on crowns that give one echo only.
    roughness : (float, float)
        Range (m) of the crowns' surface roughness (standard deviation of the
        first echo about the crown's surface). The default's local residuals
        span those measured on real crowns (Delft AHN3, the Nebraska sample);
        smoother crowns look like roofs to geometry alone.

    Returns
    -------
    SyntheticTown
        With the new points (truth classes 3/4/5 by height for vegetation)
        and consistent ``return_number`` / ``number_of_returns``.

    Raises
    ------
    InputError
        On a parameter out of range.

    Examples
    --------
    >>> from lidar2city.synthetic import make_town
    >>> town = add_canopy(make_town(size=(60, 50), density=4, seed=1), seed=1)
    >>> int(town.cloud.attributes["number_of_returns"].max()) <= 5
    True
    """
    import dataclasses

    if not 0 <= cover <= 1 or not 0 <= opaque <= 1 or overhang < 0:
        raise InputError("cover and opaque must be in [0, 1] and overhang >= 0")
    if not 2 <= max_returns <= 15:
        raise InputError(f"max_returns must be in [2, 15], got {max_returns!r}")
    rng = np.random.default_rng([seed, 7])
    cloud = town.cloud
    a = cloud.attributes
    xyz = cloud.xyz
    # pulses that may meet a crown: one-echo pulses on terrain or a roof
    cand = np.flatnonzero((a["number_of_returns"] == 1)
                          & np.isin(a["classification"], (ASPRS.GROUND, ASPRS.BUILDING)))
    top = np.full(len(cand), -np.inf)
    sigma = np.zeros(len(cand))
    gz = town.terrain_z(xyz[cand, :2])
    for x, y, r, height, rough in _crowns(rng, town, cover=cover, overhang=overhang,
                                                    roughness=roughness):
        d2 = ((xyz[cand, 0] - x) ** 2 + (xyz[cand, 1] - y) ** 2) / (r * r)
        near = np.flatnonzero(d2 < 1)
        z0 = float(town.terrain_z(np.array([[x, y]]))[0])
        zc = z0 + height - 0.5 * r + 0.5 * r * np.sqrt(1 - d2[near])
        higher = zc > top[near]
        top[near[higher]] = zc[higher]
        sigma[near[higher]] = rough
    # a crown over a roof must clear it
    hit = np.isfinite(top) & (top > xyz[cand, 2] + 1.5)
    idx, top, sigma, gz = cand[hit], top[hit], sigma[hit], gz[hit]
    m = len(idx)
    first_z = top + rng.normal(0, 1, m) * sigma
    n_echo = np.where(rng.random(m) < opaque, 1, rng.integers(2, max_returns + 1, m))
    reach = (n_echo > 1) & (rng.random(m) < 0.5)  # the last echo is the surface below
    new_xyz = xyz.copy()
    cls = a["classification"].copy()
    rn = a["return_number"].copy()
    nr = a["number_of_returns"].copy()
    below_cls = cls[idx].copy()
    below_z = xyz[idx, 2].copy()
    new_xyz[idx, 2] = first_z
    cls[idx] = ASPRS.HIGH_VEGETATION
    nr[idx] = n_echo
    extra_xyz, extra_cls, extra_rn, extra_nr = [], [], [], []
    for k in range(2, max_returns + 1):
        has = n_echo >= k
        is_last = has & (n_echo == k)
        on_surface = is_last & reach
        # inner echoes spread down the crown, ordered by echo number
        frac = (k - 1) / n_echo[has] + rng.uniform(0, 0.5, int(has.sum())) / n_echo[has]
        lo = np.maximum(below_z[has], gz[has]) + 0.3
        z = np.where(on_surface[has], below_z[has], first_z[has] - frac * (first_z[has] - lo))
        veg_h = z - gz[has]
        c = np.where(on_surface[has], below_cls[has],
                     np.where(veg_h >= 2, ASPRS.HIGH_VEGETATION,
                              np.where(veg_h >= 0.5, ASPRS.MEDIUM_VEGETATION,
                                       ASPRS.LOW_VEGETATION)))
        extra_xyz.append(np.column_stack([xyz[idx[has], :2], z]))
        extra_cls.append(c)
        extra_rn.append(np.full(int(has.sum()), k))
        extra_nr.append(n_echo[has])
    xyz2 = np.vstack([new_xyz, *extra_xyz])
    cls2 = np.concatenate([cls, *extra_cls]).astype(np.uint8)
    rn2 = np.concatenate([rn, *extra_rn]).astype(np.uint8)
    nr2 = np.concatenate([nr, *extra_nr]).astype(np.uint8)
    order = np.lexsort((xyz2[:, 2], xyz2[:, 1], xyz2[:, 0]))
    attrs = {"classification": cls2[order], "return_number": rn2[order],
             "number_of_returns": nr2[order]}
    out = PointCloud(xyz2[order], cloud.origin, cloud.crs, cloud.xy_unit, cloud.z_unit, attrs)
    return dataclasses.replace(town, cloud=out)
