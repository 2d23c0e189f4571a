"""Classification accuracy: confusion matrix, per-class precision / recall / F1, kappa.

Predicted and reference classes are first mapped to common categories, since
production labels rarely match ASPRS one to one: AHN's class 1 is
"unclassified (vegetation and other)", ASPRS splits vegetation into 3/4/5.
A mapping sends each class code to a category name; codes it does not name
fall into ``other`` (or are ignored when listed in ``ignore``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError

__all__ = [
    "ASPRS_MAPPING",
    "ClassificationScores",
    "map_classes",
    "confusion_matrix",
    "classification_scores",
]

#: ASPRS codes -> categories for building / vegetation evaluation.
ASPRS_MAPPING: dict[int, str] = {2: "ground", 3: "vegetation", 4: "vegetation",
                                 5: "vegetation", 6: "building"}


@dataclass(frozen=True)
class ClassificationScores:
    """Scores of a classification against a reference.

    Attributes
    ----------
    categories : tuple of str
        Category names, the order of the matrix rows / columns.
    confusion : ndarray, shape (C, C), int64
        ``confusion[i, j]`` = points of reference category i predicted as j.
    precision, recall, f1 : dict of str to float
        Per category (NaN where undefined: no prediction / no reference).
    overall_accuracy : float
    kappa : float
        Cohen's kappa (Cohen 1960).
    """

    categories: tuple
    confusion: np.ndarray
    precision: dict
    recall: dict
    f1: dict
    overall_accuracy: float
    kappa: float

    def as_dict(self) -> dict:
        """Plain-Python form (for JSON)."""
        return {
            "categories": list(self.categories),
            "confusion": self.confusion.tolist(),
            "precision": dict(self.precision),
            "recall": dict(self.recall),
            "f1": dict(self.f1),
            "overall_accuracy": self.overall_accuracy,
            "kappa": self.kappa,
        }


def map_classes(codes, mapping: dict, *, default: str = "other") -> np.ndarray:
    """Category name per code (object array), ``default`` for unmapped codes."""
    codes = np.asarray(codes)
    out = np.full(codes.shape, default, dtype=object)
    for code, name in mapping.items():
        out[codes == code] = name
    return out


def confusion_matrix(reference, predicted, categories) -> np.ndarray:
    """Counts ``[i, j]`` of reference category ``categories[i]`` predicted as ``categories[j]``.

    Labels not in ``categories`` are left out.
    """
    reference = np.asarray(reference)
    predicted = np.asarray(predicted)
    if reference.shape != predicted.shape:
        raise InputError(f"reference has shape {reference.shape}, predicted {predicted.shape}")
    c = len(categories)
    ri = np.full(reference.shape, -1, dtype=np.int64)
    pi = np.full(predicted.shape, -1, dtype=np.int64)
    for i, cat in enumerate(categories):
        ri[reference == cat] = i
        pi[predicted == cat] = i
    ok = (ri >= 0) & (pi >= 0)
    return np.bincount(ri[ok] * c + pi[ok], minlength=c * c).reshape(c, c).astype(np.int64)


def _codes_to_category(codes, mapping, ignore, default):
    codes = np.asarray(codes)
    if codes.ndim != 1:
        raise InputError(f"class arrays must be 1-D, got shape {codes.shape}")
    if not np.issubdtype(codes.dtype, np.integer):
        raise InputError(f"class codes must be integers, got dtype {codes.dtype}")
    names = sorted(set(mapping.values()) | {default})
    lut_keys = np.array(sorted(mapping), dtype=np.int64)
    idx = np.full(len(codes), names.index(default), dtype=np.int64)
    if len(lut_keys):
        pos = np.searchsorted(lut_keys, codes)
        pos = np.clip(pos, 0, len(lut_keys) - 1)
        hit = lut_keys[pos] == codes
        mapped = np.array([names.index(mapping[int(k)]) for k in lut_keys])
        idx[hit] = mapped[pos[hit]]
    ignored = np.isin(codes, list(ignore)) if ignore else np.zeros(len(codes), bool)
    return names, idx, ignored


def classification_scores(reference, predicted, *, mapping=None, predicted_mapping=None,
                          ignore=(), default: str = "other") -> ClassificationScores:
    """Compare predicted to reference classes.

    Parameters
    ----------
    reference, predicted : ndarray of int, shape (N,)
        Class codes.
    mapping : dict of int to str, optional
        Reference code -> category; :data:`ASPRS_MAPPING` by default.
    predicted_mapping : dict of int to str, optional
        Predicted code -> category; ``mapping`` by default.
    ignore : iterable of int
        Reference codes left out of every score (e.g. AHN 26 civil
        structures, 9 water, 7 noise when the reference has no noise).
    default : str
        Category of codes not in the mapping.

    Returns
    -------
    ClassificationScores

    Raises
    ------
    InputError
        On mismatched shapes or non-integer codes.

    Notes
    -----
    Precision ``TP / (TP + FP)``, recall ``TP / (TP + FN)``, F1 their
    harmonic mean; kappa ``(p_o - p_e) / (1 - p_e)`` with ``p_e`` from the
    row and column totals (Cohen 1960).

    Examples
    --------
    >>> s = classification_scores(np.array([6, 6, 2, 5]), np.array([6, 2, 2, 5]))
    >>> round(s.f1["building"], 3), round(s.recall["ground"], 3)
    (0.667, 1.0)
    """
    mapping = ASPRS_MAPPING if mapping is None else dict(mapping)
    predicted_mapping = mapping if predicted_mapping is None else dict(predicted_mapping)
    reference = np.asarray(reference)
    predicted = np.asarray(predicted)
    if reference.shape != predicted.shape:
        raise InputError(f"reference has shape {reference.shape}, predicted {predicted.shape}")
    rnames, ridx, ignored = _codes_to_category(reference, mapping, ignore, default)
    pnames, pidx, _ = _codes_to_category(predicted, predicted_mapping, (), default)
    categories = tuple(sorted(set(rnames) | set(pnames)))
    rmap = np.array([categories.index(x) for x in rnames])
    pmap = np.array([categories.index(x) for x in pnames])
    keep = ~ignored
    r = rmap[ridx[keep]] if keep.any() else np.zeros(0, np.int64)
    p = pmap[pidx[keep]] if keep.any() else np.zeros(0, np.int64)
    c = len(categories)
    cm = np.bincount(r * c + p, minlength=c * c).reshape(c, c).astype(np.int64)
    tp = np.diag(cm).astype(np.float64)
    pred_tot = cm.sum(axis=0).astype(np.float64)
    ref_tot = cm.sum(axis=1).astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        prec = tp / pred_tot
        rec = tp / ref_tot
        f1 = 2 * tp / (pred_tot + ref_tot)
    total = cm.sum()
    if total:
        po = tp.sum() / total
        pe = float((pred_tot * ref_tot).sum()) / float(total) ** 2
        kappa = (po - pe) / (1 - pe) if pe < 1 else 1.0
    else:
        po = kappa = float("nan")
    return ClassificationScores(
        categories, cm,
        {k: float(v) for k, v in zip(categories, prec, strict=True)},
        {k: float(v) for k, v in zip(categories, rec, strict=True)},
        {k: float(v) for k, v in zip(categories, f1, strict=True)},
        float(po), float(kappa),
    )
