"""Roof wireframes: corners and edges of roof-face outlines, their cleanliness and F1 scores.

A roof face's outline (its rings, lifted onto the face's plane) *turns* at a
vertex when the 3-D directions of its two edges differ by more than
``turn_deg`` (10 degrees); such vertices are the roof **corners**; the outline
between two consecutive corners is one **edge** (vertices where it runs on
straight, e.g. where a neighbour's edge ends, do not split it). The wireframe
of a roof is the set of distinct corners and edges of all its faces.

Two cleanliness figures (issue 12): corners per building (distinct plan
positions) and the share of roof-face edge length in edges shorter than
``short`` (0.5 m); for this share every vertex of a face's ring splits it (as a
viewer draws it) and every face counts its own edges, so a shared edge counts
twice, for everyone alike. Against a
reference wireframe: corner and edge precision / recall / F1 with one-to-one
matches within a 3-D tolerance (an edge matches when both its ends are within
the tolerance of the reference edge's ends, in either order).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Wireframe", "roof_wireframe", "faces_wireframe", "roof_cleanliness", "wireframe_scores",
           "pooled_scores"]


@dataclass(frozen=True, eq=False)
class Wireframe:
    """Corners (C, 3), edges (E, 2, 3) and the lengths of all faces' ring segments (L,) of a roof."""

    corners: np.ndarray
    edges: np.ndarray
    face_edge_lengths: np.ndarray


def _ring_edges(ring, turn_cos):
    """Corners (k, 3), corner-to-corner edges (k, 2, 3) and segment lengths of a closed 3-D ring (m, 3)."""
    r = np.asarray(ring, dtype=np.float64)
    step = np.linalg.norm(np.roll(r, -1, axis=0) - r, axis=1)
    keep = step > 1e-9
    r, seg = r[keep], step[keep]
    if len(r) < 3:
        return np.empty((0, 3)), np.empty((0, 2, 3)), seg
    d_out = np.roll(r, -1, axis=0) - r
    d_out /= np.linalg.norm(d_out, axis=1, keepdims=True)
    d_in = np.roll(d_out, 1, axis=0)
    corner = np.einsum("ij,ij->i", d_in, d_out) < turn_cos
    c = r[corner]
    if len(c) < 2:
        return c, np.empty((0, 2, 3)), seg
    return c, np.stack([c, np.roll(c, -1, axis=0)], axis=1), seg


def _cluster(points, tol):
    """Representative (cluster mean) of each point (N, 3), clusters = points linked within ``tol``."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    pairs = cKDTree(points).query_pairs(tol, output_type="ndarray")
    if not len(pairs):
        return points
    g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(points), len(points)))
    n, comp = connected_components(g, directed=False)
    mean = np.zeros((n, 3))
    np.add.at(mean, comp, points)
    return (mean / np.bincount(comp, minlength=n)[:, None])[comp]


def faces_wireframe(faces, *, turn_deg=10.0, merge=0.1) -> Wireframe:
    """The wireframe of roof faces given as lists of 3-D rings (each (m, 3), not closed).

    Corners closer than ``merge`` (m, 3-D) are one corner, at their mean: fitted
    planes meeting at a junction agree there within centimetres, not exactly, and
    a viewer sees one corner.
    """
    turn_cos = np.cos(np.radians(turn_deg))
    corners, edges, lengths = [], [], []
    for rings in faces:
        for ring in rings:
            c, e, seg = _ring_edges(ring, turn_cos)
            corners.append(c)
            edges.append(e)
            lengths.append(seg)
    if not corners:
        return Wireframe(np.empty((0, 3)), np.empty((0, 2, 3)), np.empty(0))
    c = np.concatenate(corners)
    e = np.concatenate(edges)
    if merge and len(c):
        rep = _cluster(np.concatenate([c, e.reshape(-1, 3)]), merge)
        c, e = rep[:len(c)], rep[len(c):].reshape(-1, 2, 3)
        e = e[np.linalg.norm(e[:, 1] - e[:, 0], axis=1) > 1e-9]
    # distinct corners and edges (mm keys; an edge is unordered)
    ck = np.round(c * 1000).astype(np.int64)
    _, first = np.unique(ck, axis=0, return_index=True)
    c = c[np.sort(first)]
    if len(e):
        ek = np.round(e * 1000).astype(np.int64).reshape(len(e), 6)
        a, b = ek[:, :3], ek[:, 3:]
        less = (a[:, 0] < b[:, 0]) | ((a[:, 0] == b[:, 0]) & ((a[:, 1] < b[:, 1]) | (
            (a[:, 1] == b[:, 1]) & (a[:, 2] <= b[:, 2]))))
        canon = np.where(less[:, None], ek, np.column_stack([b, a]))
        _, first = np.unique(canon, axis=0, return_index=True)
        e = e[np.sort(first)]
    return Wireframe(c, e, np.concatenate(lengths))


def roof_wireframe(solids, *, turn_deg=10.0) -> Wireframe:
    """The wireframe of the RoofSurfaces of one building's solids (a Solid or a list)."""
    solids = solids if isinstance(solids, list | tuple) else [solids]
    faces = []
    for s in solids:
        v = np.asarray(s.vertices)
        for surf in s.surfaces:
            if surf.semantic == "RoofSurface":
                faces.append([v[np.asarray(r)] for r in surf.rings])
    return faces_wireframe(faces, turn_deg=turn_deg)


def roof_cleanliness(wireframe: Wireframe, *, short=0.5) -> tuple[int, float, float]:
    """``(corners, short_length, total_length)`` of one roof.

    ``corners`` counts distinct plan positions (mm) of corners, as seen from
    above; the lengths are over the faces' ring segments as drawn (every vertex
    splits a ring, even where it runs on straight): the length in segments
    shorter than ``short`` (m) and in all of them.
    """
    L = wireframe.face_edge_lengths
    n = len(np.unique(np.round(wireframe.corners[:, :2] * 1000).astype(np.int64), axis=0))
    return n, float(L[L < short].sum()), float(L.sum())


def _prf(matched, n_pred, n_ref):
    p = matched / n_pred if n_pred else 0.0
    r = matched / n_ref if n_ref else 0.0
    return p, r, (2 * p * r / (p + r) if p + r else 0.0)


def wireframe_scores(pred: Wireframe, ref: Wireframe, *, tolerance=0.5) -> dict:
    """Corner and edge precision, recall and F1 of a predicted wireframe against a reference.

    Returns a dict with ``corner_precision``, ``corner_recall``, ``corner_f1``,
    ``edge_precision``, ``edge_recall``, ``edge_f1`` and the counts
    ``corners_matched``, ``corners_pred``, ``corners_ref``, ``edges_matched``,
    ``edges_pred``, ``edges_ref`` (sum counts over buildings to pool them).
    """
    from scipy.optimize import linear_sum_assignment

    from .corners import match_corners

    ic, _, _ = match_corners(pred.corners, ref.corners, tolerance=tolerance)
    out = {"corners_matched": len(ic), "corners_pred": len(pred.corners), "corners_ref": len(ref.corners)}
    pe, re_ = pred.edges, ref.edges
    n_match = 0
    if len(pe) and len(re_):
        def dist(a, b):
            return np.linalg.norm(a[:, None, :] - b[None, :, :], axis=-1)

        same = np.maximum(dist(pe[:, 0], re_[:, 0]), dist(pe[:, 1], re_[:, 1]))
        flip = np.maximum(dist(pe[:, 0], re_[:, 1]), dist(pe[:, 1], re_[:, 0]))
        d = np.minimum(same, flip)
        big = tolerance * (min(len(pe), len(re_)) + 1) + 1.0
        ip, ir = linear_sum_assignment(np.where(d <= tolerance, d, big))
        n_match = int(np.sum(d[ip, ir] <= tolerance))
    out.update(edges_matched=n_match, edges_pred=len(pe), edges_ref=len(re_))
    return {**pooled_scores(out), **out}


def pooled_scores(counts: dict) -> dict:
    """Precision / recall / F1 from (summed) match counts as returned by :func:`wireframe_scores`."""
    cp, cr, cf = _prf(counts["corners_matched"], counts["corners_pred"], counts["corners_ref"])
    ep, er, ef = _prf(counts["edges_matched"], counts["edges_pred"], counts["edges_ref"])
    return dict(corner_precision=cp, corner_recall=cr, corner_f1=cf,
                edge_precision=ep, edge_recall=er, edge_f1=ef)
