"""Ground-filter errors of Sithole & Vosselman (2004): type I, type II, total, kappa."""

from __future__ import annotations

import numpy as np

from ..errors import InputError

__all__ = ["ground_errors"]


def ground_errors(pred_ground, ref_ground) -> dict:
    """Compare a predicted ground mask with a reference one.

    Parameters
    ----------
    pred_ground, ref_ground : array_like of bool, shape (N,)
        True for ground (predicted and reference).

    Returns
    -------
    dict
        ``type_i`` (reference ground called object / reference ground),
        ``type_ii`` (reference object called ground / reference object),
        ``total`` (misclassified / all), ``kappa`` (Cohen's kappa), as
        fractions (NaN where a denominator is zero), and the confusion
        counts ``ground_ground`` (a), ``ground_object`` (b, type I errors),
        ``object_ground`` (c, type II errors), ``object_object`` (d), ``points``.

    Raises
    ------
    InputError
        If the masks differ in length or are not 1-D.

    References
    ----------
    Sithole, G., Vosselman, G. (2004). Experimental comparison of filter
    algorithms for bare-Earth extraction from airborne laser scanning point
    clouds. ISPRS J. Photogramm. Remote Sens. 59, 85-101 (Table 4).
    Cohen, J. (1960). A coefficient of agreement for nominal scales.

    Examples
    --------
    >>> e = ground_errors([True, True, False, False], [True, False, False, False])
    >>> e["type_i"], round(e["type_ii"], 3), e["total"]
    (0.0, 0.333, 0.25)
    """
    pred = np.asarray(pred_ground)
    ref = np.asarray(ref_ground)
    if pred.ndim != 1 or ref.ndim != 1:
        raise InputError(f"masks must be 1-D, got shapes {pred.shape} and {ref.shape}")
    if len(pred) != len(ref):
        raise InputError(f"the prediction has {len(pred)} points but the reference {len(ref)}")
    pred = pred.astype(bool)
    ref = ref.astype(bool)
    a = int(np.count_nonzero(ref & pred))
    b = int(np.count_nonzero(ref & ~pred))
    c = int(np.count_nonzero(~ref & pred))
    d = int(np.count_nonzero(~ref & ~pred))
    n = a + b + c + d

    def ratio(num, den):
        return num / den if den else float("nan")

    observed = ratio(a + d, n)
    expected = ratio((a + b) * (a + c) + (c + d) * (b + d), n * n)
    if n == 0:
        kappa = float("nan")
    elif expected == 1.0:
        kappa = 1.0 if observed == 1.0 else 0.0
    else:
        kappa = (observed - expected) / (1.0 - expected)
    return {
        "type_i": ratio(b, a + b),
        "type_ii": ratio(c, c + d),
        "total": ratio(b + c, n),
        "kappa": kappa,
        "ground_ground": a,
        "ground_object": b,
        "object_ground": c,
        "object_object": d,
        "points": n,
    }
