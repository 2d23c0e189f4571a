"""What a cloud can tell: inspect the return and intensity fields before trusting them.

Surveys code their pulses differently. Modern multi-echo scanners write
``return_number`` / ``number_of_returns`` per echo; single-echo surveys write
``1 of 1`` everywhere (no cue); old first/last-pulse surveys (ISPRS Stuttgart,
1990s-2000s) store every pulse twice, a first-pulse and a last-pulse point,
both saying "n of 2" even where the pulse met one surface and both points
coincide. Taken at face value the last kind marks every roof as a
multi-return target, i.e. vegetation.

:func:`survey_cues` inspects the fields and returns, per point, the cues the
classifier may use:

* **multi-echo** (``number_of_returns`` varies, some ``1 of 1``): used as written.
* **first/last pairs** (every point "n of 2", and many last-pulse points
  repeat a first-pulse point): each pulse's two points are paired (by file
  order when the first and last pulses are stored as two aligned blocks,
  else by the nearest last-pulse point within a coincidence tolerance). Equal
  first and last (one surface: roofs, ground, walls) make the first-pulse point a
  duplicate, left out of the geometry and given its partner's class; a
  first pulse with a distinct last pulse (below it: canopy, edges) is a
  "first of two echoes", the last pulse a "last of two".
* **single returns, constant, absent or inconsistent fields** (every point
  the same "n of m"; nearly all points multi-echo but no pairs; return number
  0 or above the number of returns): no return cue at all.

Intensity is inspected (absent, constant, informative) and reported; the
classifier does not decide on it.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

logger = logging.getLogger(__name__)

__all__ = ["SurveyCues", "survey_cues"]

#: Largest height difference (m) between the first and last pulse of one echo
#: (range noise of the two detectors); larger is two surfaces.
ECHO_DZ = 0.3
#: Share of points that must be "n of 2"-style before pairing is tried.
_PAIRED_SHARE = 0.9
#: Share of last-pulse points repeating a first-pulse point for the pairs reading.
_COINCIDENT_SHARE = 0.3


@dataclass(frozen=True, eq=False)
class SurveyCues:
    """Return cues of a cloud as the classifier should read them.

    Attributes
    ----------
    returns : str
        ``"multi"`` (per-echo returns), ``"pairs"`` (first/last-pulse pairs),
        ``"single"`` (all 1 of 1), ``"constant"`` (every point the same
        "n of m", or nearly all multi-echo without pairs), ``"absent"`` or
        ``"inconsistent"`` (return number 0 or above the number of returns).
    multi : ndarray of bool, shape (N,)
        The point's pulse met several surfaces.
    not_last : ndarray of bool, shape (N,)
        The point is an echo with another echo of its pulse below it.
    duplicate : ndarray of bool, shape (N,)
        The point repeats another point of the same echo (``partner``).
    partner : ndarray of int64, shape (N,)
        For a duplicate, the index of the point it repeats; ``-1`` otherwise.
    intensity : str
        ``"absent"``, ``"constant"`` or ``"informative"``.
    notes : tuple of str
        What was found, for the log.
    """

    returns: str
    multi: np.ndarray
    not_last: np.ndarray
    duplicate: np.ndarray
    partner: np.ndarray
    intensity: str
    notes: tuple

    @property
    def has_returns(self) -> bool:
        """Whether the return cue says anything (some points are multi-echo)."""
        return self.returns in ("multi", "pairs") and bool(self.multi.any())


def _pair_by_order(xyz, first, last, tol):
    """First/last pulses stored as two aligned blocks (all first, then all last)?

    Returns the partner (last-pulse index) of each first-pulse index, or None.
    """
    fi, li = np.flatnonzero(first), np.flatnonzero(last)
    if len(fi) != len(li) or len(fi) == 0:
        return None
    # pulses where both detectors saw one surface coincide exactly: the median
    # pair of aligned blocks is such a pulse
    d = np.hypot(*(xyz[fi, :2] - xyz[li, :2]).T)
    if np.median(d) > tol:
        return None
    return fi, li


def _pair_by_neighbour(xyz, first, last, tol):
    """Each first-pulse point with a last-pulse point within ``tol`` horizontally, mutual nearest.

    Horizontal only: the two detectors' range noise separates an echo's two
    points vertically (the caller tests the height difference).
    """
    from scipy.spatial import cKDTree

    fi, li = np.flatnonzero(first), np.flatnonzero(last)
    if len(fi) == 0 or len(li) == 0:
        return fi[:0], li[:0]
    d, j = cKDTree(xyz[li, :2]).query(xyz[fi, :2], k=1, distance_upper_bound=tol, workers=-1)
    ok = np.isfinite(d)
    fi, cand = fi[ok], li[j[ok]]
    # mutual: the last-pulse point's nearest first-pulse point is this one
    _, back = cKDTree(xyz[fi, :2]).query(xyz[cand, :2], k=1, workers=-1)
    keep = back == np.arange(len(fi))
    return fi[keep], cand[keep]


def survey_cues(xyz, *, return_number=None, number_of_returns=None, intensity=None,
                spacing: float | None = None) -> SurveyCues:
    """Inspect return and intensity fields and read them for classification.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
        Coordinates in metres.
    return_number, number_of_returns : ndarray, shape (N,), optional
        The LAS return fields.
    intensity : ndarray, shape (N,), optional
        Only inspected and reported.
    spacing : float, optional
        Mean point spacing (m), measured when omitted; scales the
        coincidence tolerance of first/last pairs.

    Returns
    -------
    SurveyCues

    Examples
    --------
    >>> import numpy as np
    >>> xyz = np.zeros((4, 3)); xyz[:, 0] = [0, 1, 0, 1]
    >>> c = survey_cues(xyz, return_number=np.array([1, 1, 2, 2]),
    ...                 number_of_returns=np.array([2, 2, 2, 2]))
    >>> c.returns, c.duplicate.tolist()
    ('pairs', [True, True, False, False])
    """
    from .features import point_spacing

    xyz = np.asarray(xyz, dtype=np.float64)
    n = len(xyz)
    none = np.zeros(n, bool)
    partner = np.full(n, -1, np.int64)
    notes = []
    if intensity is None:
        inten = "absent"
    else:
        iv = np.asarray(intensity)
        inten = "constant" if n == 0 or iv.min() == iv.max() else "informative"
    notes.append(f"intensity {inten}")

    if return_number is None or number_of_returns is None or n == 0:
        notes.append("return fields absent: no return cue")
        return SurveyCues("absent", none, none.copy(), none.copy(), partner, inten, tuple(notes))
    rn = np.asarray(return_number).astype(np.int64)
    nr = np.asarray(number_of_returns).astype(np.int64)
    bad = (rn < 1) | (nr < 1) | (rn > nr)
    if bad.mean() > 0.01:
        notes.append(f"return fields inconsistent on {bad.mean():.0%} of the points: no return cue")
        return SurveyCues("inconsistent", none, none.copy(), none.copy(), partner, inten,
                          tuple(notes))
    if not (nr > 1).any():
        notes.append("single returns only (all 1 of 1): no return cue")
        return SurveyCues("single", none, none.copy(), none.copy(), partner, inten, tuple(notes))
    if rn.min() == rn.max() and nr.min() == nr.max():
        notes.append(f"every point says return {rn[0]} of {nr[0]}: no return cue")
        return SurveyCues("constant", none, none.copy(), none.copy(), partner, inten, tuple(notes))
    multi = (nr > 1) & ~bad
    not_last = (rn < nr) & ~bad
    if multi.mean() < _PAIRED_SHARE:
        notes.append(f"multi-echo returns ({multi.mean():.0%} of the points in multi-echo pulses)")
        return SurveyCues("multi", multi, not_last, none.copy(), partner, inten, tuple(notes))

    # nearly every point claims a multi-echo pulse: first/last-pulse pairs?
    if spacing is None:
        spacing = point_spacing(xyz[:, :2])
    tol = max(0.05, 0.15 * spacing)
    first = (rn < nr) & ~bad
    last = (rn == nr) & ~bad
    pairs = _pair_by_order(xyz, first, last, tol)
    how = "file order"
    if pairs is None:
        pairs = _pair_by_neighbour(xyz, first, last, tol)
        how = "nearest neighbour"
    fi, li = pairs
    same = np.abs(xyz[fi, 2] - xyz[li, 2]) <= ECHO_DZ
    same &= np.hypot(*(xyz[fi, :2] - xyz[li, :2]).T) <= tol
    share = same.sum() / max(last.sum(), 1)
    if share < _COINCIDENT_SHARE:
        # nearly every pulse multi-echo, roofs included, is no survey: the
        # fields were coded otherwise (all "2 of 2", last pulses only...)
        notes.append(f"{multi.mean():.0%} of the points claim a multi-echo pulse but only "
                     f"{share:.0%} pair as first/last pulses: returns uninformative, no return cue")
        return SurveyCues("constant", none, none.copy(), none.copy(), partner, inten, tuple(notes))
    duplicate = none.copy()
    duplicate[fi[same]] = True
    partner[fi[same]] = li[same]
    # one echo: neither point is multi; two distinct echoes: the first is not last
    multi = multi.copy()
    not_last = not_last.copy()
    multi[fi[same]] = multi[li[same]] = False
    not_last[fi[same]] = False
    notes.append(f"first/last-pulse pairs (paired by {how}): {share:.0%} of the pulses give one "
                 f"echo (first = last within {ECHO_DZ:g} m), the first pulse dropped as a duplicate; "
                 f"{int(multi.sum())} points in two-echo pulses")
    return SurveyCues("pairs", multi, not_last, duplicate, partner, inten, tuple(notes))
