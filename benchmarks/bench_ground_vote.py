"""The learnt vote of SMRF surfaces (``smrf_vote``): its rule refitted, leave-one-out, speed.

Usage::

    python benchmarks/bench_ground_vote.py [--data DIR] [--repeat 3] [--no-speed] [--pairs]
        [--cues [--only-cues NAME,NAME]] [--uphill] [--ring] [--terrain]
        [--wall-slopes 1,1.5,2,3] [--wall-anchors 1.5,2,2.5,3] [--walls]
        [--roughness] [--above-fixed 4,6,8,inf [--above-anchors off,2,2.5]]
        [--anatomy [PNG_DIR]]
        [--fit-held-out-kinds] [--fit {greedy,coded,bagged,grid,grid-bagged,unit,selected}]
        [--fill SHARE [--fill-where o|f|of]
         [--fill-value nearest|max|min|limited|gated [--fill-gate M]] [--fill-marks]] [--forced-shape] [--fine-edges]
        [--syn-spacings 1,1.5,2,2.5,3,3.5] [--syn-seeds N]

``smrf_vote`` (:mod:`lidar2city.ground.vote_filter`) judges each point from
its tolerance ratios to three provisional surfaces of one SMRF opening
(:func:`~lidar2city.ground.vote_features`: ``smrf_segments``' surface at
slope 0.1, the same at 0.3, plain SMRF's at 0.1) and its distance to the
nearest wall, and (its `veto`) a fourth, ``smrf_segments``' at 0.4. This
script:

1. computes the features of every point of the ISPRS reference samples in
   ``DIR/isprs/reference`` and of the synthetic terrains of
   :mod:`lidar2city.synthetic_terrain` (1 m and 2.5 m spacing);
2. fits the rule by the procedure of ``--fit`` (:data:`FITS`,
   :func:`fit_procedure`), leaving each ISPRS sample out in turn (the whole
   procedure, any bagging or choice among procedures included, runs on the
   six others + the synthetic terrains). The objective is always the
   weighted point error, every sample weighted equally and the synthetic
   terrains together as one more sample. ``unit`` (the default since
   session 17): the three thresholds at SMRF's own test, ratio 1, then the
   wall distance ``clear`` of :data:`CLEAR` that minimises the objective,
   then the ``veto`` of :data:`VETO` (:func:`fit_veto`), then the ``above``
   of :data:`ABOVE` (:func:`fit_above`), the walls anchored as
   ``smrf_vote``'s default (:data:`~lidar2city.ground.VOTE_ANCHOR`).
   ``greedy`` (the default until session 16): first a depth-2 decision tree
   on the three ratios (:func:`fit_rule`, :func:`fit_tree`: each split the
   threshold, among 48 quantiles of the pooled ratios, that minimises the
   objective), thresholds rounded to two decimals, then the same three
   steps; ``coded``: the tree forced to the coded rule's shape, its three
   thresholds chosen together (:func:`fit_coded`); ``bagged``: ``coded``
   on every subset of the training samples that leaves
   :data:`BAG_LEAVE` out, the median of each parameter
   (:func:`fit_bagged`); ``grid`` and ``grid-bagged``: the same with the
   thresholds among :data:`RATIO_GRID` rather than the pooled quantiles
   (which are 0.48, 1.14, 1.91 for ``near`` between 0.3 and 3, and move
   with the training samples); ``selected``: the procedure among the six
   others with the lowest leave-one-out on the training samples, then fitted
   on them (:func:`fit_selected`: the choice of procedure nested too; a few
   minutes). It prints the held-out sample's type I / type II / total error
   with the veto, the total without it and with the veto and ``above``, and
   with the veto and the default ``above``, the rule of each fold, their
   mean and maximum (the leave-one-out figures);
3. fits it on all seven and prints the rule: its thresholds are
   :data:`lidar2city.ground.VOTE_RULE` and its veto
   :data:`lidar2city.ground.VOTE_VETO` (the script says whether they still
   are; with a rule that differs, its errors on the seven, the synthetic
   terrains and the held-out kinds, :func:`fitted_rule_check`);
4. scores ``smrf_vote`` with its defaults, without its veto, without its
   wall anchor and ``above`` (the defaults until session 16) and with
   ``above`` 3 m against ``smrf_segments`` on the seven samples, the
   synthetic terrains and the small tile with a building of
   ``bench_ground_segments.py``, then on the scenes of
   :data:`~lidar2city.synthetic_terrain.HELD_OUT_KINDS` (kept out of every
   fit; with ``--fit-held-out-kinds`` they join the synthetic terrains of
   every fit instead);
5. the bound of any per-point rule over such surfaces: the share of points
   that every one of ``smrf_segments`` at the slopes of :data:`ORACLE_SLOPES`
   and plain SMRF at 0.1 classifies wrongly, per sample;
6. with ``--pairs``, the same leave-one-out with the two SMRF slopes chosen
   too, per fold, among :data:`PAIRS` (the pair whose fitted rule has the
   lowest objective on the six other samples + synthetic terrains): the
   default pair (0.1, 0.3) was chosen among these by looking at all seven
   samples' leave-one-out, so this nested figure is the honest one for the
   whole procedure; printed without and with the ``veto`` (chosen per fold
   too, :func:`fit_veto`), the rule fitted by ``--fit`` ``unit`` or
   ``greedy`` (session 13's nesting: walls not anchored, no ``above``)
   (a few minutes more);
7. with ``--anatomy``, where ``smrf_vote``'s errors are on its two worst
   samples: type I and type II points, the share of them each candidate of
   step 5 has right, the share within 5 m of a wall and their median ratio
   to the strict surface; with a folder, a PNG map of them per sample;
8. with ``--cues``, the leave-one-out of a depth-3 tree over the three
   ratios alone and with one more cue each (the ratio to ``smrf_segments``'
   surface at slope 0.4, the wall distance, the height above the lowest
   point of the 3x3 cells around, how far the point is raised above the
   ground on both sides in its second most raised direction
   (:func:`raised_all_sides`), the cloth simulation filter's call when its
   package is installed, the local roughness of the 16 or 8 nearest points
   about their plane and the vertical spread of a 1.5-spacing column
   (:func:`knn_roughness`, :func:`column_spread`), the tolerance ratio to a TIN densified from the
   points all four surfaces call ground (:func:`seeded_tin_ratio`), how high
   the point's surface patch stands over the ground on its uphill side
   (:func:`uphill_steps`: median and low quantile, against the ground
   inpainted from the points all four surfaces call ground, or against those
   cells only)), the worst sample's error with such trees fitted
   on that sample itself over every cue (the ceiling of the rule family
   there); the cues tried for issue 18 (the first became the veto; see the
   README); a few minutes with the cloth filter; ``--only-cues`` runs only
   the cues named;
9. with ``--uphill``, the leave-one-out of the coded rule (and veto, per
   fold) with points near the lenient surface given back when their patch
   stands at most ``t`` over the ground uphill (:func:`uphill_loo`, ``t``
   chosen per fold), then fitted on all seven and scored on the held-out
   kinds (session 13: not lower; ``benchmarks/HISTORY.md``);
   with ``--ring``, the same with a point of an object patch given back
   when within ``t`` tolerances of the plane of the ground around the
   patch (:func:`~lidar2city.ground.ring_plane.ring_ratios`, ``smrf_vote``'s
   ``ring`` option, alone or also near the lenient surface; the slow
   exact-ring form, :func:`ring_cue_exact`, and the library's form of it,
   ``ring_ratios(..., neighbourhood="dilation")``; with the CPU seconds of
   each cue per sample); with ``--terrain``, the same for session 14's
   terrain-structure give-backs (:func:`terrain_loo`: between agreed ground
   above and below, or near the surface inpainted from it); with
   ``--wall-slopes``, the leave-one-out with the wall-marking slope chosen
   per fold too (:func:`wall_slope_loo`); with ``--wall-anchors``, the same
   with ``smrf_vote``'s ``wall_anchor`` (a wall region counts only when the
   opening also cuts one of its cells at that slope: a building's step, not
   an embankment) chosen per fold among off and the slopes given, and each
   fixed (:func:`wall_anchor_loo`); with ``--walls``, what the wall mark
   holds on each sample and held-out kind (cells mostly reference ground,
   regions, what the anchor leaves out) and the default rule's error with
   the walls as marked, with every wall cell holding reference ground taken
   out (an oracle), and anchored (:func:`wall_anatomy`); with ``--roughness``,
   whether a point-level roughness cue (:func:`knn_roughness`, :func:`column_spread`)
   tells the vegetation the wall anchor frees from the ground it frees, and the
   leave-one-out of the anchor with a roughness veto (:func:`roughness_check`);
   with ``--above-fixed``, the leave-one-out of the rule and veto with ``above``
   fixed at each value given, beside each wall anchor of ``--above-anchors``, and
   with the pair chosen per fold (:func:`above_loo`);
10. ``smrf_vote``'s ``fill`` (session 17; its default
   :data:`~lidar2city.ground.VOTE_FILL`): ``--fill SHARE`` runs all of the
   above with another share (0: off, the default until session 16) and the
   private variants of
   :func:`~lidar2city.ground.segment_filter._segment_surfaces` (``--fill-where``:
   the opening's input, the final surfaces or both; ``--fill-value``: the
   nearest point's height, the higher / lower of it and the harmonic
   inpainting's, the nearest height continued by its slope-limited
   gradient, or the nearest height only where it is more than ``--fill-gate``
   m off the harmonic inpainting's; ``--fill-marks``: the walls marked on the filled opening too),
   and prints the CPU seconds of ``smrf_vote`` with and without the fill on
   the samples where it acts. The scenes of
   :data:`~lidar2city.synthetic_terrain.HELD_OUT_KINDS` are scored at each
   spacing of :data:`~lidar2city.synthetic_terrain.HELD_OUT_SPACINGS`. The
   fitting procedure has options of its own for this check: ``--forced-shape``
   fits the thresholds of the coded rule's shape instead of a free tree,
   ``--fine-edges`` tries thresholds 0.1, 0.15, ... 2 besides the quantiles,
   ``--syn-spacings`` / ``--syn-seeds`` fit on more synthetic terrains;
11. unless ``--no-speed``, times ``lidar2city ground`` with both methods (and
   ``smrf_vote`` without its veto) on ``DIR/isprs/sites/CSite4_orig-utm.laz``
   against reading and writing it with laspy (best of ``--repeat``,
   interleaved).

About a minute plus the speed runs.
"""

from __future__ import annotations

import functools
import os
import sys
import time
from itertools import combinations
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_ground import arg_parser, load, reference_paths, speed, synthetic_scenes  # noqa: E402
from bench_ground_segments import small_tile  # noqa: E402
from lidar2city.ground import (  # noqa: E402
    VETO_SLOPE,
    VOTE_ABOVE,
    VOTE_ANCHOR,
    VOTE_FILL,
    VOTE_RULE,
    VOTE_VETO,
    GroundConfig,
    ptd,
    smrf_segments,
    smrf_vote,
    vote_features,
)
from lidar2city.ground._grid import (  # noqa: E402
    bilinear_weights,
    cell_of,
    dilate_square,
    gradient_magnitude,
    grid_spec,
    inpaint,
    running_extreme,
    sample_bilinear,
)
from lidar2city.ground.smrf_filter import FILL_VALUES, FILL_WHERE  # noqa: E402
from lidar2city.ground.vote_filter import _distance_to  # noqa: E402
from lidar2city.ground.connect_filter import _spacing, surface_patches  # noqa: E402
from lidar2city.ground.ring_plane import ring_ratios  # noqa: E402
from lidar2city.ground.tin_filter import seeded_tin  # noqa: E402
from lidar2city.ground.vote_filter import vote_rule  # noqa: E402
from lidar2city.metrics.ground import ground_errors  # noqa: E402
from lidar2city.synthetic_terrain import (  # noqa: E402
    HELD_OUT_KINDS,
    HELD_OUT_SPACINGS,
    TERRAIN_KINDS,
    make_terrain,
)

NAMES = ("near", "steep", "plain")  # the three ratios, in the order of vote_features
DEPTH = 2
QUANTILES = np.linspace(0.01, 0.99, 48)
#: (strict, lenient) SMRF slope pairs of the ``--pairs`` check.
PAIRS = ((0.1, 0.2), (0.1, 0.25), (0.1, 0.3), (0.1, 0.4), (0.15, 0.3), (0.15, 0.4))
#: slopes of the smrf_segments surfaces of the per-point bound.
ORACLE_SLOPES = (0.1, 0.15, 0.2, 0.3, 0.4)
#: wall distances (m) tried for ``clear``; inf: the lenient surface never decides alone.
CLEAR = (5.0, 8.0, 10.0, 15.0, 20.0, 30.0, np.inf)
#: samples the ``--anatomy`` check looks at (the worst by smrf_vote's total error), and the
#: wall distance (m) it counts errors within.
ANATOMY_WORST = 2
#: the further cues of the ``--cues`` check (the first: the ratio to the fourth surface of
#: ``smrf_vote``'s ``veto`` option, at ``VETO_SLOPE`` 0.4) and the depth of its trees.
CUES = ("segments 0.4 ratio", "wall distance", "height above lowest 3x3",
        "raised on all sides", "cloth (CSF) ground", "seeded TIN ratio", "uphill step",
        "lowest uphill step", "uphill step to ground", "lowest uphill step to ground",
        "roughness 16-NN", "roughness 8-NN", "column spread")
#: reach (m) of the ``raised on all sides`` cue.
RAISED_REACH = 12.0
CUE_DEPTH = 3
#: vetoes (tolerance ratios to the fourth surface) :func:`fit_veto` chooses among.
VETO = (0.6, 0.7, 0.8, 1.0, 1.2, 1.6, np.inf)
#: rises (m) of ``smrf_vote``'s ``above`` option :func:`fit_above` chooses among (inf: off).
ABOVE = (1.0, 2.0, 3.0, 4.0, 6.0, np.inf)
ANATOMY_WALL = 5.0
#: neighbours of :func:`knn_roughness` (the ``--cues`` and ``--roughness`` checks) and the
#: plan reach (point spacings) of :func:`column_spread`.
ROUGH_K = 16
COLUMN_REACH = 1.5
#: ``--roughness``: the wall anchor it frees walls with, and the roughness vetoes (point
#: spacings; a point freed by the anchor stays near its walls when rougher) it tries.
ROUGH_ANCHOR = 3.0
ROUGH_VETOES = (0.2, 0.25, 0.3, 0.35, 0.4, 0.5)
#: the ``above`` (m) scored beside the defaults on the seven samples and the held-out kinds.
ABOVE_SHOWN = 3.0
#: the fitting procedures of ``--fit`` (see the module's docstring, step 2); the default,
#: ``unit``, is the one ``selected`` chooses in every fold and on all seven (session 17).
FITS = ("greedy", "coded", "bagged", "grid", "grid-bagged", "unit", "selected")
BAG_LEAVE = 2
#: the thresholds the ``grid`` procedures choose among (tolerance ratios; SMRF's own test is 1).
RATIO_GRID = np.round(np.arange(0.2, 3.05, 0.1), 2)


def fit_rule(sets, coded=False, grid=None):
    """:data:`VOTE_RULE` fitted on ``sets`` (as :func:`fit_tree`): the tree, then ``clear``.

    Returns the rule (dict, thresholds rounded to two decimals), or None when
    the tree has not the shape of the coded rule (its one-line form is then
    printed by the caller). ``coded``: the tree has the coded rule's shape,
    its three thresholds chosen together (:func:`fit_coded`, among the values of ``grid``
    when given), not greedily.
    """
    ratios = [(f[:, :3], g, w) for f, g, w in sets]
    tree = fit_coded(ratios, grid) if coded else fit_tree(ratios)
    rule = rule_of(tree)
    if rule is None:
        return None, tree
    total = sum(w for _, _, w in sets)

    def objective(clear):
        return sum(w * np.mean(vote_rule(f, **rule, clear=clear) != g) for f, g, w in sets) / total

    return dict(rule, clear=float(min(CLEAR, key=objective))), tree


def fit_sequence(sets, keys, xyz_of, cache, coded=False, grid=None):
    """The whole fit of one procedure on ``sets`` of ``(features (N, 6), ground, weight)``
    (``keys``: the sets' keys in ``xyz_of``, for the walls' rise within another ``clear``):
    the tree and ``clear`` (:func:`fit_rule`), then the veto (:func:`fit_veto`), then
    ``above`` (:func:`fit_above`), one after the other. Returns ``(rule, tree, veto, above)``;
    ``rule`` None (and no veto or above) when the tree has not the coded shape."""
    rule, tree = fit_rule(sets, coded=coded, grid=grid)
    if rule is None:
        return None, tree, None, None
    veto = fit_veto(sets, rule)[0]
    risen = [(with_rise(xyz_of[k], f, rule["clear"], cache, k), g, w)
             for k, (f, g, w) in zip(keys, sets)]
    return rule, tree, veto, fit_above(risen, rule, veto)[0]


def fit_bagged(sets, keys, xyz_of, cache, leave=None, grid=None):
    """:func:`fit_sequence` (coded shape) on every subset of ``sets`` that leaves out
    ``leave`` (default :data:`BAG_LEAVE`) of the weight-1 sets (the ISPRS samples; the
    synthetic terrains, whose weights sum to 1, stay in every subset), and the median of each
    parameter over the subsets: a rule robust to which samples it saw.

    The median of each of ``near``, ``steep``, ``plain``, ``clear``, ``veto`` and ``above``
    (the lower median when the number of subsets is even, so that it is one of the fitted
    values; ``clear``, ``veto`` and ``above`` are ordered grids, inf last). Returns
    ``(rule, tree, veto, above)`` as :func:`fit_sequence`, ``tree`` that of the median
    thresholds.
    """
    leave = BAG_LEAVE if leave is None else leave
    real = [i for i, (_, _, w) in enumerate(sets) if w == 1.0]
    fits = []
    for drop in combinations(real, leave):
        kept = [i for i in range(len(sets)) if i not in drop]
        rule, _, veto, above = fit_sequence([sets[i] for i in kept], [keys[i] for i in kept],
                                            xyz_of, cache, coded=True, grid=grid)
        fits.append(dict(rule, veto=veto, above=above))
    med = {k: float(sorted(f[k] for f in fits)[(len(fits) - 1) // 2]) for k in fits[0]}
    rule = {k: med[k] for k in ("near", "steep", "plain", "clear")}
    tree = (0, rule["near"], (1, rule["steep"], True, False), (2, rule["plain"], True, False))
    return rule, tree, med["veto"], med["above"]


def fit_unit(sets, keys, xyz_of, cache):
    """No threshold fitted: ``near``, ``steep`` and ``plain`` at SMRF's own test (ratio 1);
    then ``clear``, the veto and ``above`` as :func:`fit_sequence` (what fitting the three
    thresholds buys)."""
    rule, tree = fit_unit_rule(sets)
    veto = fit_veto(sets, rule)[0]
    risen = [(with_rise(xyz_of[k], f, rule["clear"], cache, k), g, w)
             for k, (f, g, w) in zip(keys, sets)]
    return rule, tree, veto, fit_above(risen, rule, veto)[0]


def fit_unit_rule(sets):
    """The ``unit`` rule (thresholds 1) and its ``clear`` fitted on ``sets`` as by
    :func:`fit_rule`; returns ``(rule, tree)``."""
    rule = dict.fromkeys(NAMES, 1.0)
    total = sum(w for _, _, w in sets)

    def objective(clear):
        return sum(w * np.mean(vote_rule(f, **rule, clear=clear) != g) for f, g, w in sets) / total

    rule["clear"] = float(min(CLEAR, key=objective))
    return rule, (0, 1.0, (1, 1.0, True, False), (2, 1.0, True, False))


def fit_selected(sets, keys, xyz_of, cache, among=None, log=None):
    """The procedure of ``among`` (default: every other one of :data:`FITS`) with the lowest
    leave-one-out mean total error over the weight-1 sets of ``sets`` (each left out in turn,
    the synthetic terrains always fitted on), then fitted on all of ``sets``: choosing the
    procedure by its leave-one-out, nested, so that an outer leave-one-out scores the choice
    too. ``log``: a list the inner figures are appended to."""
    among = tuple(f for f in FITS if f != "selected") if among is None else among
    real = [i for i, (_, _, w) in enumerate(sets) if w == 1.0]
    inner = {}
    for how in among:
        errs = []
        for i in real:
            kept = [j for j in range(len(sets)) if j != i]
            rule, tree, veto, above = fit_procedure(how, [sets[j] for j in kept],
                                                    [keys[j] for j in kept], xyz_of, cache)
            f, g, _ = sets[i]
            if rule is None:
                errs.append(np.mean(predict(tree, f[:, :3]) != g))
                continue
            f = with_rise(xyz_of[keys[i]], f, rule["clear"], cache, keys[i])
            errs.append(np.mean(vote_rule(f, **rule, veto=veto, above=above) != g))
        inner[how] = float(np.mean(errs))
    best = min(among, key=inner.get)
    if log is not None:
        log.append((best, inner))
    return fit_procedure(best, sets, keys, xyz_of, cache)


def fit_procedure(how, sets, keys, xyz_of, cache):
    """The rule, veto and above fitted on ``sets`` by the procedure ``how`` of :data:`FITS`."""
    if how == "selected":
        log = []
        fitted = fit_selected(sets, keys, xyz_of, cache, log=log)
        best, inner = log[0]
        print(f"  [selected {best}; inner leave-one-out: "
              f"{', '.join(f'{k} {100 * v:.2f} %' for k, v in inner.items())}]")
        return fitted
    grid = RATIO_GRID if how.startswith("grid") else None
    if how == "unit":
        return fit_unit(sets, keys, xyz_of, cache)
    if how.endswith("bagged"):
        return fit_bagged(sets, keys, xyz_of, cache, grid=grid)
    return fit_sequence(sets, keys, xyz_of, cache, coded=how != "greedy", grid=grid)


def fitted_rule_check(samples, scenes, feats, syn, xyz_of, cache, rule, veto, above):
    """Print a rule fitted on all seven that is not the coded default: its errors on the
    seven, the synthetic terrains of TERRAIN_KINDS and the held-out kinds, with the ``above``
    fitted and with the default :data:`~lidar2city.ground.VOTE_ABOVE`."""
    print("that rule and veto (type I / type II / total %), with the fitted above, then with "
          f"the default above {VOTE_ABOVE:g}:")
    kinds = {f"{kind}@{spacing:g}m": make_terrain(kind, spacing=spacing, seed=1)
             for kind in HELD_OUT_KINDS for spacing in (1.0, 2.5)}
    rows = [(n, xyz_of[n], feats[n], ref) for n, (_, ref) in samples.items()]
    rows += [(k, xyz_of[i], f, g) for i, (k, (f, g)) in enumerate(zip(scenes, syn))]
    rows += [(k, s.xyz, vote_features(s.xyz, fourth=VETO_SLOPE, rise=VOTE_RULE["clear"],
                                      anchor=VOTE_ANCHOR)[0], s.ground) for k, s in kinds.items()]
    totals = {}
    for k, xyz, f, ref in rows:
        f = with_rise(xyz, f, rule["clear"], cache, ("check", k))
        es = [ground_errors(vote_rule(f, **rule, veto=veto, above=a), ref) for a in
              (above, VOTE_ABOVE)]
        totals[k] = [e["total"] for e in es]
        if k in samples or k in kinds:
            print(f"  {k:<20} " + "   ".join(" ".join(f"{100 * e[c]:6.2f}" for c in
                                                   ("type_i", "type_ii", "total")) for e in es))
    for what, ks in (("the seven", list(samples)),
                     (f"the {sum(k.split('@')[0] in TERRAIN_KINDS for k in scenes)} synthetic "
                      "terrains", [k for k in scenes if k.split("@")[0] in TERRAIN_KINDS])):
        v = np.array([totals[k] for k in ks])
        print(f"  mean total on {what}: {100 * v[:, 0].mean():.2f} % (fitted above), "
              f"{100 * v[:, 1].mean():.2f} % (above {VOTE_ABOVE:g}); max "
              f"{100 * v[:, 0].max():.2f} / {100 * v[:, 1].max():.2f} %")


def score(rule, tree, features):
    """Ground mask of a fitted rule (or of its tree when it has not the coded shape)."""
    return predict(tree, features[:, :3]) if rule is None else vote_rule(features, **rule)


def nested_pairs(samples, scenes, how="greedy"):
    """Print the leave-one-out with the slope pair chosen per fold (see ``--pairs``), without
    and with ``smrf_vote``'s ``veto`` (chosen per fold too, as by :func:`fit_veto`); the rule
    fitted as by :func:`fit_rule` (``how`` "greedy") or :func:`fit_unit_rule` ("unit")."""
    if how not in ("greedy", "unit"):
        raise SystemExit("--pairs takes --fit greedy or unit")
    fit = fit_unit_rule if how == "unit" else fit_rule
    feats = {}
    for pair in PAIRS:
        feats[pair] = ({n: vote_features(xyz, slopes=pair, fourth=VETO_SLOPE)[0]
                        for n, (xyz, _) in samples.items()},
                       [(vote_features(s.xyz, slopes=pair, fourth=VETO_SLOPE)[0], s.ground,
                         1.0 / len(scenes)) for s in scenes.values()])
    print("\nleave-one-out with the slope pair chosen per fold among "
          f"{', '.join(str(p) for p in PAIRS)}, without and with the veto (chosen per fold; "
          f"fit {how!r}, walls not anchored, no above)")
    held = {"no veto": [], "veto": []}
    for name, (_, ref) in samples.items():
        best = dict.fromkeys(held)
        for pair, (real, syn) in feats.items():
            sets = [(real[n], samples[n][1], 1.0) for n in samples if n != name] + syn
            rule, tree = fit(sets)
            objective = sum(w * np.mean(score(rule, tree, f) != g) for f, g, w in sets)
            if best["no veto"] is None or objective < best["no veto"][0]:
                best["no veto"] = (objective, pair, score(rule, tree, real[name]), "")
            if rule is None:
                continue
            veto, objective = fit_veto(sets, rule)
            if best["veto"] is None or objective < best["veto"][0]:
                best["veto"] = (objective, pair, vote_rule(real[name], **rule, veto=veto),
                                f" veto {veto:g}")
        line = f"{name:<8}"
        for k, (_, pair, pred, extra) in best.items():
            held[k].append(ground_errors(pred, ref)["total"])
            line += f"  {k}: held-out total {100 * held[k][-1]:5.2f} %  slopes {pair}{extra}"
        print(line)
    for k, v in held.items():
        print(f"smrf_vote leave-one-out with the slopes chosen per fold ({k}): mean total "
              f"{100 * np.mean(v):.2f} %, max {100 * np.max(v):.2f} %")


def fit_veto(sets, rule):
    """The veto of :data:`VETO` (and its objective) that minimises the weighted point error of
    ``rule`` over ``sets`` of ``(features (N, 5), ground, weight)``: ``rule`` with a point near
    the strict surface object when its ratio to the fourth surface (column 4) exceeds it."""
    total = sum(w for _, _, w in sets)
    objective = {v: sum(w * np.mean(vote_rule(f, **rule, veto=v) != g) for f, g, w in sets)
                 / total for v in VETO}
    veto = min(VETO, key=objective.get)
    return veto, objective[veto]


def fit_above(sets, rule, veto):
    """The ``above`` of :data:`ABOVE` (and its objective) that minimises the weighted point
    error of ``rule`` with ``veto`` over ``sets`` of ``(features (N, 6), ground, weight)``
    whose last column is the walls' rise within the rule's ``clear``."""
    total = sum(w for _, _, w in sets)
    objective = {a: sum(w * np.mean(vote_rule(f, **rule, veto=veto, above=a) != g)
                        for f, g, w in sets) / total for a in ABOVE}
    above = min(ABOVE, key=objective.get)
    return above, objective[above]


def with_rise(xyz, features, clear, cache, key):
    """``features`` (N, 6) with the last column the walls' rise within ``clear`` m (the one
    ``fit_above`` needs when a fold's ``clear`` is not the default's); cached by ``key``."""
    if clear == VOTE_RULE["clear"]:
        return features
    if (key, clear) not in cache:
        rise = vote_features(xyz, fourth=VETO_SLOPE, rise=clear, anchor=VOTE_ANCHOR)[0][:, -1]
        cache[key, clear] = np.column_stack([features[:, :-1], rise])
    return cache[key, clear]


def held_out_kinds(rule_above, fitted=False):
    """Print ``smrf_vote``'s errors on the scenes of
    :data:`~lidar2city.synthetic_terrain.HELD_OUT_KINDS` (left out of every fit unless
    ``fitted``) with its defaults and with ``above``."""
    print(f"\nscenes of kinds {'fitted on too' if fitted else 'held out of every fit'} (smrf_vote "
          f"type I / type II / total %: defaults; above={rule_above:g}; then ptd with its "
          f"defaults, likewise)")
    ptd_params = GroundConfig(method="ptd").method_params()
    for kind in HELD_OUT_KINDS:
        for spacing in HELD_OUT_SPACINGS:
            scene = make_terrain(kind, spacing=spacing, seed=1)
            line = f"{kind + '@' + format(spacing, 'g') + 'm':<20}"
            for pred in (smrf_vote(scene.xyz), smrf_vote(scene.xyz, above=rule_above),
                         ptd(scene.xyz, **ptd_params)):
                e = ground_errors(pred, scene.ground)
                line += (f"  {100 * e['type_i']:6.2f} {100 * e['type_ii']:6.2f} "
                         f"{100 * e['total']:6.2f}")
            print(line)


def candidates(xyz, features):
    """Ground masks of the candidates of the per-point bound: ``smrf_segments`` at each slope
    of :data:`ORACLE_SLOPES` and plain SMRF at 0.1 (from ``features``, the point's ratio)."""
    params = GroundConfig(method="smrf_segments").method_params()
    masks = {f"segments {slope:g}": smrf_segments(xyz, **dict(params, slope=slope))
             for slope in ORACLE_SLOPES}
    masks["plain 0.1"] = features[:, 2] <= 1.0
    return masks


def oracle(samples, feats):
    """Print the share of points every candidate surface gets wrong (see step 5)."""
    print(f"\nper-point bound: points wrong on all of smrf_segments at slopes "
          f"{', '.join(f'{v:g}' for v in ORACLE_SLOPES)} and plain SMRF at 0.1 (total error %)")
    wrong = []
    for name, (xyz, ref) in samples.items():
        right = np.zeros(len(ref), dtype=bool)
        for pred in candidates(xyz, feats[name]).values():
            right |= pred == ref
        wrong.append(np.mean(~right))
        print(f"{name:<8} {100 * wrong[-1]:5.2f}")
    print(f"{'mean':<8} {100 * np.mean(wrong):5.2f}")


def anatomy(samples, feats, out_dir=None, worst=ANATOMY_WORST):
    """Print where ``smrf_vote``'s errors are on its ``worst`` samples (see ``--anatomy``)."""
    errors = {n: ground_errors(smrf_vote(xyz), ref) for n, (xyz, ref) in samples.items()}
    names = sorted(errors, key=lambda n: -errors[n]["total"])[:worst]
    print(f"\nerror anatomy of smrf_vote on its {worst} worst samples: its wrong points, the "
          f"share of them each candidate has right, within {ANATOMY_WALL:g} m of a wall, and "
          f"the median ratio to the strict segment surface")
    for name in names:
        xyz, ref = samples[name]
        f = feats[name]
        pred = smrf_vote(xyz)
        masks = candidates(xyz, f)
        for label, wrong in (("type I", ref & ~pred), ("type II", ~ref & pred)):
            n = int(wrong.sum())
            right = " ".join(f"{k} {100 * np.mean(m[wrong] == ref[wrong]):3.0f}"
                             for k, m in masks.items())
            print(f"{name:<8} {label:<8} {n:>5} pts ({100 * n / len(ref):4.2f} % of all); right "
                  f"on (%): {right}; wall {100 * np.mean(f[wrong, 3] <= ANATOMY_WALL):3.0f} %; "
                  f"strict ratio {np.median(f[wrong, 0]):.2f}")
        if out_dir is not None:
            error_map(xyz, ref, pred, out_dir / f"{name}_errors.png", name)


def error_map(xyz, ref, pred, path, title):
    """A PNG of the points from above: heights, and the type I / type II errors of ``pred``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(1, 2, figsize=(14, 7), sharex=True, sharey=True)
    ax[0].scatter(xyz[:, 0], xyz[:, 1], c=xyz[:, 2], s=1, cmap="terrain")
    ax[0].set_title(f"{title}: height")
    ax[1].scatter(xyz[:, 0], xyz[:, 1], c="lightgrey", s=1)
    for mask, colour, label in ((ref & ~pred, "red", "type I (ground called object)"),
                                (~ref & pred, "blue", "type II (object called ground)")):
        ax[1].scatter(xyz[mask, 0], xyz[mask, 1], c=colour, s=2, label=label)
    ax[1].legend(loc="lower right")
    ax[1].set_title(f"{title}: smrf_vote errors")
    for a in ax:
        a.set_aspect("equal")
    fig.savefig(path, dpi=80)
    plt.close(fig)
    print(f"wrote {path}")


def height_above_lowest(xyz, cell=1.0):
    """Each point's height (m) above the lowest point of its cell and the 8 around it."""
    ij = np.floor((xyz[:, :2] - xyz[:, :2].min(axis=0)) / cell).astype(np.int64) + 1
    low = np.full(tuple(ij.max(axis=0) + 2), np.inf)
    np.minimum.at(low, (ij[:, 0], ij[:, 1]), xyz[:, 2])
    h, w = low.shape
    pad = np.pad(low, 1, constant_values=np.inf)
    around = np.minimum.reduce([pad[i:i + h, j:j + w] for i in range(3) for j in range(3)])
    return xyz[:, 2] - around[ij[:, 0], ij[:, 1]]


def knn_roughness(xyz, k=ROUGH_K):
    """Each point's local roughness, in point spacings: the root of the smallest eigenvalue
    of the covariance of its ``k`` nearest points in 3-D (itself left out), over the spacing
    of :func:`~lidar2city.ground.connect_filter._spacing` (a plane's residual spread: ~0 on
    smooth terrain, however steep; large in a bush or a tree crown, or across an edge)."""
    from scipy.spatial import cKDTree

    _, idx = cKDTree(xyz).query(xyz, k=k + 1)
    nbr = xyz[idx[:, 1:]]
    centred = nbr - nbr.mean(axis=1, keepdims=True)
    smallest = np.linalg.eigvalsh(np.einsum("nki,nkj->nij", centred, centred) / k)[:, 0]
    return np.sqrt(np.maximum(smallest, 0.0)) / _spacing(xyz)


def column_spread(xyz, reach=COLUMN_REACH):
    """The vertical spread (highest minus lowest z) of the points within ``reach`` point
    spacings of each point in plan, in spacings (a 1-3 m column at these surveys' spacing:
    the returns of a bush or a tree over the ground under it)."""
    from scipy.spatial import cKDTree

    sp = _spacing(xyz)
    near = cKDTree(xyz[:, :2]).query_ball_point(xyz[:, :2], reach * sp)
    return np.array([np.ptp(xyz[i, 2]) for i in near]) / sp


def auc(high, low):
    """The probability that a value of ``high`` exceeds one of ``low`` (ties half): 1 when a
    cue separates them perfectly, 0.5 when it does not at all; nan when either is empty."""
    if len(high) == 0 or len(low) == 0:
        return np.nan
    from scipy.stats import rankdata

    ranks = rankdata(np.concatenate([high, low]))
    return (ranks[:len(high)].sum() - len(high) * (len(high) + 1) / 2) / (len(high) * len(low))


def raised_all_sides(xyz, cell=1.0, reach=RAISED_REACH):
    """How far (m) each point stands above the ground on both sides of it, in its second most
    raised of four directions (rows, columns, both diagonals): for each direction, the least
    over distances up to ``reach`` of the mean of the lowest points of the two cells at that
    distance either side, minus the point's height (negative: raised). A roof is raised in
    every direction, a terrace top or a slope in at most the one across its edge; 0 where a
    side has no points."""
    ij = np.floor((xyz[:, :2] - xyz[:, :2].min(axis=0)) / cell).astype(np.int64)
    k_max = int(reach / cell)
    low = np.full(tuple(ij.max(axis=0) + 1), np.inf)
    np.minimum.at(low, (ij[:, 0], ij[:, 1]), xyz[:, 2])
    low = np.pad(np.where(np.isinf(low), np.nan, low), k_max, constant_values=np.nan)
    i, j = ij[:, 0] + k_max, ij[:, 1] + k_max
    sides = np.full((len(xyz), 4), np.nan)
    for p, (di, dj) in enumerate(((1, 0), (0, 1), (1, 1), (1, -1))):
        for k in range(1, k_max + 1):
            mid = (low[i + di * k, j + dj * k] + low[i - di * k, j - dj * k]) / 2 - xyz[:, 2]
            sides[:, p] = np.fmin(sides[:, p], mid)
    return np.sort(np.nan_to_num(sides, nan=0.0), axis=1)[:, 1]


#: join step (m) of the patches of the ``uphill step`` cues, the rise (m per metre) of the
#: agreed-ground surface that makes a neighbour cell uphill, and the share of a patch's
#: uphill edges the ``lowest uphill step`` takes (a low quantile, not the minimum: one edge
#: can be a stray point).
UPHILL_JUMP = 0.6
UPHILL_RISE = 0.05
UPHILL_LOW = 0.1


def uphill_steps(xyz, features, cell=None, jump=UPHILL_JUMP, rise=UPHILL_RISE, low=UPHILL_LOW,
                 on_ground=False):
    """Per patch, how high its edge stands over the ground surface on its uphill side.

    Patches are :func:`~lidar2city.ground.connect_filter.surface_patches` (lowest
    point per ``cell``, None: the point spacing, joined across steps of at most
    ``jump`` m): a roof, a terrace bench, ground running between buildings. The
    ground surface ``S`` is inpainted from the cells whose lowest point all four
    surfaces of ``features`` (N, 5) call ground (a parameter-free agreement, no
    fitted rule). Across each edge from a patch cell ``a`` to a cell ``b`` of
    another patch, the patch's edge height is ``z_a - S(b)``; the edge is uphill
    when ``S(b) - S(a)`` exceeds ``rise`` per metre. A roof stands above the
    ground on every side, the uphill one too; a terrace bench or the ground
    between buildings on a slope lies at or below the ground uphill of it (the
    riser, or a building's foot, rises over it), while it stands above the
    ground downhill, which is what SMRF's opening sees.

    Returns two per-point cues (N,) from each point's cell's patch: the median of
    its uphill edge heights and their ``low`` quantile (over all its edges when
    it has no uphill edge, e.g. on flat ground; 0 when it has no edge at all;
    with ``on_ground`` only the edges to agreed-ground cells count),
    each plus the point's height over its cell's lowest point (a crown over the
    ground stands that high over the ground uphill).
    """
    out = ~np.isfinite(features[:, 0])
    p = surface_patches(xyz, exclude=out, cell=cell, jump=jump)
    h, w = p["shape"]
    cell = p["cell"]
    zmin, label = p["zmin"], p["label"]
    agreed = (features[p["lowest"], :3] <= 1).all(axis=1) & (features[p["lowest"], 4] <= 1)
    known = np.full(h * w, np.nan)
    known[p["cells"][agreed]] = zmin[p["cells"][agreed]]
    if not agreed.any():
        return np.zeros(len(xyz)), np.zeros(len(xyz))
    s = inpaint(known.reshape(h, w)).ravel()
    a, b = np.concatenate([p["a"], p["b"]]), np.concatenate([p["b"], p["a"]])
    if on_ground:  # only edges to agreed ground, measured against its own lowest point
        is_agreed = np.zeros(h * w, dtype=bool)
        is_agreed[p["cells"][agreed]] = True
        a, b = a[is_agreed[b]], b[is_agreed[b]]
    dist = cell * np.hypot(a // w - b // w, a % w - b % w)
    value = zmin[a] - s[b]
    up = s[b] - s[a] > rise * dist
    lab = label[a]
    n_lab = int(label.max()) + 1
    has_up = np.bincount(lab[up], minlength=n_lab) > 0
    use = up | ~has_up[lab]
    lab, value = lab[use], value[use]
    order = np.lexsort((value, lab))
    lab, value = lab[order], value[order]
    start = np.searchsorted(lab, np.arange(n_lab))
    count = np.bincount(lab, minlength=n_lab)
    med = np.zeros(n_lab)
    lowq = np.zeros(n_lab)
    some = count > 0
    med[some] = value[start[some] + (count[some] - 1) // 2]
    lowq[some] = value[start[some] + np.floor(low * (count[some] - 1)).astype(np.int64)]
    point_label = label[p["flat"]]
    over = np.where(out, np.inf, xyz[:, 2] - zmin[p["flat"]])
    return med[point_label] + over, lowq[point_label] + over


def ring_cue(xyz, features, neighbourhood="box"):
    """Each point's ratio to the plane of the ground around its object patch
    (:func:`~lidar2city.ground.ring_plane.ring_ratios`, its ``neighbourhood``), the ground
    being the points within tolerance of all four surfaces of ``features`` (N, 5)."""
    out = ~np.isfinite(features[:, 0])
    agreed = (features[:, :3] <= 1).all(axis=1) & (features[:, 4] <= 1)
    return ring_ratios(xyz, agreed, exclude=out, neighbourhood=neighbourhood)


def ring_cue_exact(xyz, features, cell=None, jump=UPHILL_JUMP, reaches=(3.0, 6.0, 12.0, 24.0),
                   rms=0.3, threshold=0.5, scalar=1.25):
    """:func:`ring_cue` with each neighbourhood the ring of agreed-ground cells within a
    Chebyshev distance of the patch's own cells (not its grown bounding box), found patch by
    patch (a Python loop: ~1.4 CPU s on samp11's 38k points), and the plane fitted to the
    cell centres: the reference the library's ``ring_ratios(..., neighbourhood="dilation")``
    (no loop over patches) reproduces."""
    out = ~np.isfinite(features[:, 0])
    ratio = np.full(len(xyz), np.inf)
    p = surface_patches(xyz, exclude=out, cell=cell, jump=jump)
    h, w = p["shape"]
    cell = p["cell"]
    spec = grid_spec(xyz[:, :2], cell=cell)
    zmin, label = p["zmin"], p["label"]
    agreed = (features[p["lowest"], :3] <= 1).all(axis=1) & (features[p["lowest"], 4] <= 1)
    is_agreed = np.zeros(h * w, dtype=bool)
    is_agreed[p["cells"][agreed]] = True
    cell_lab = label[p["cells"]]
    n_lab = int(label.max()) + 1
    n_cells = np.bincount(cell_lab, minlength=n_lab)
    n_agreed = np.bincount(cell_lab[agreed], minlength=n_lab)
    objects = np.flatnonzero((n_cells >= 4) & (2 * n_agreed < n_cells))
    if len(objects) == 0 or not agreed.any():
        return ratio
    steps = [int(np.ceil(r / cell)) for r in reaches]
    big = steps[-1]
    order = np.argsort(cell_lab, kind="stable")
    starts = np.searchsorted(cell_lab[order], np.arange(n_lab + 1))
    point_lab = np.where(out, -1, label[p["flat"]])
    porder = np.argsort(point_lab, kind="stable")
    pstarts = np.searchsorted(point_lab[porder], np.arange(n_lab + 1))
    for lab in objects:
        cells = p["cells"][order[starts[lab]:starts[lab + 1]]]
        rr, cc = cells // w, cells % w
        r0, r1 = max(rr.min() - big, 0), min(rr.max() + big + 1, h)
        c0, c1 = max(cc.min() - big, 0), min(cc.max() + big + 1, w)
        box = np.zeros((r1 - r0, c1 - c0), dtype=np.uint8)
        box[rr - r0, cc - c0] = 1
        dist = np.where(box > 0, 0, big + 1)
        reached = box
        for i in range(1, big + 1):
            grown = dilate_square(reached, 3)
            dist[grown > reached] = i
            reached = grown
        ground = is_agreed.reshape(h, w)[r0:r1, c0:c1] & (dist > 0)
        chosen = None
        for k in steps:
            ring = ground & (dist <= k)
            if ring.sum() < 6:
                continue
            gi, gj = np.nonzero(ring)
            gx, gy = (gj + c0 + 0.5) * cell, -(gi + r0 + 0.5) * cell
            gz = zmin.reshape(h, w)[r0:r1, c0:c1][ring]
            a = np.column_stack([gx, gy, np.ones(len(gx))])
            coef, _, rank, _ = np.linalg.lstsq(a, gz, rcond=None)
            if rank < 3:
                continue
            fit_rms = float(np.sqrt(np.mean((a @ coef - gz) ** 2)))
            if chosen is None or fit_rms <= rms:
                chosen = coef
            if fit_rms > rms:
                break
        if chosen is None:
            continue
        pts = porder[pstarts[lab]:pstarts[lab + 1]]
        plane = chosen[0] * (xyz[pts, 0] - spec.x0) + chosen[1] * (xyz[pts, 1] - spec.y_top)
        tol = threshold + scalar * float(np.hypot(chosen[0], chosen[1]))
        ratio[pts] = np.abs(xyz[pts, 2] - plane - chosen[2]) / tol
    return ratio


#: heights (m) over the ground uphill at or below which :func:`uphill_loo` gives a point
#: near the lenient surface back (-inf: off; inf: every such point).
UPHILL_GIVE = (-np.inf, -3.0, -2.0, -1.0, -0.5, 0.0, 0.5, 1.0, np.inf)


def uphill_loo(samples, scenes, feats, syn):
    """Print the leave-one-out of ``smrf_vote``'s rule (fitted per fold, veto too) with a
    give-back: a point within SMRF's tolerance of the lenient surface is ground when its
    patch's low uphill step (:func:`uphill_steps`, against the inpainted agreed ground, or
    against the agreed-ground cells only) is at most ``t``, ``t`` of :data:`UPHILL_GIVE`
    chosen per fold by the same objective."""
    giveback_loo(samples, scenes, feats, syn, UPHILL_GIVE, "m", {
        "vs surface": (lambda xyz, f: uphill_steps(xyz, f)[1], True),
        "vs ground cells": (lambda xyz, f: uphill_steps(xyz, f, on_ground=True)[1], True)},
        "points within tolerance of the lenient surface given back when their patch's low "
        "uphill step is <= t")


#: tolerance ratios to the plane of the ground around an object patch at or below which
#: :func:`ring_loo` gives a point back (-inf: off; inf: every point of such a patch).
RING_GIVE = (-np.inf, 0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 3.0, np.inf)


def ring_loo(samples, scenes, feats, syn):
    """Print the leave-one-out of ``smrf_vote``'s rule (fitted per fold, veto too) with a
    give-back: a point of an object patch is ground when its ratio to the plane of the ground
    around that patch (:func:`ring_cue`) is at most ``t`` (alone, or also within SMRF's
    tolerance of the lenient surface), ``t`` of :data:`RING_GIVE` chosen per fold."""
    giveback_loo(samples, scenes, feats, syn, RING_GIVE, "", {
        "ring plane": (ring_cue, False),
        "ring + lenient": (ring_cue, True),
        "exact + lenient": (ring_cue_exact, True),
        "dilation + lenient": (lambda xyz, f: ring_cue(xyz, f, "dilation"), True)},
        "object-patch points given back when their ratio to the plane of the ground around "
        "the patch is <= t")


def _agreed_grid(xyz, features, cell=1.0):
    """The lowest and highest agreed-ground point (all four surfaces of ``features`` (N, 5)
    within tolerance) per ``cell`` (inf / -inf where none), the grid and each point's cell."""
    agreed = (features[:, :3] <= 1).all(axis=1) & (features[:, 4] <= 1)
    spec = grid_spec(xyz[:, :2], cell=cell)
    r, c = cell_of(xyz[:, :2], spec)
    lo = np.full(spec.shape, np.inf)
    hi = np.full(spec.shape, -np.inf)
    np.minimum.at(lo, (r[agreed], c[agreed]), xyz[agreed, 2])
    np.maximum.at(hi, (r[agreed], c[agreed]), xyz[agreed, 2])
    return lo, hi, spec, r, c


def sandwich_cue(xyz, features, reach=3.0, cell=1.0):
    """Minus how far (m) a point lies both below the highest and above the lowest agreed
    ground within a ``reach`` square (``-min(up, down)``; a point between ground above and
    below it is on a slope or bench, a roof stands over the ground around it): a point is
    given back when at most ``t``, i.e. ground rises more than ``-t`` over it and falls more
    than ``-t`` below it."""
    lo, hi, spec, r, c = _agreed_grid(xyz, features, cell)
    k = 2 * int(round(reach / cell)) + 1
    lo = running_extreme(running_extreme(lo, k, 0), k, 1)
    hi = running_extreme(running_extreme(hi, k, 0, maximum=True), k, 1, maximum=True)
    up, down = hi[r, c] - xyz[:, 2], xyz[:, 2] - lo[r, c]
    return np.nan_to_num(-np.minimum(up, down), nan=np.inf, posinf=np.inf, neginf=np.inf)


def surface_cue(xyz, features, cell=1.0, base=0.2, scalar=1.25, per_metre=0.1):
    """A point's height off the surface inpainted from the agreed ground (lowest agreed point
    per ``cell``), over a tolerance ``base + scalar |grad| + per_metre * d`` (``d`` the
    distance, m, to the nearest cell with agreed ground: the surface is less sure away from
    it)."""
    lo, _, spec, r, c = _agreed_grid(xyz, features, cell)
    known = np.isfinite(lo)
    if not known.any():
        return np.full(len(xyz), np.inf)
    surface = inpaint(np.where(known, lo, np.nan))
    weights = bilinear_weights(spec, xyz[:, :2])
    ref = sample_bilinear(surface, spec, weights=weights)
    grad = sample_bilinear(gradient_magnitude(surface, cell), spec, weights=weights)
    dist = _distance_to(known, int(np.ceil(40.0 / cell)))[r, c] * cell
    return np.abs(xyz[:, 2] - ref) / (base + scalar * grad + per_metre * dist)


#: heights (m, negated) :func:`terrain_loo`'s sandwich cue gives a point back at or below
#: (-inf: off; inf: every point near the lenient surface).
SANDWICH_GIVE = (-np.inf, -3.0, -2.0, -1.0, -0.5, -0.3, 0.0, np.inf)


def terrain_loo(samples, scenes, feats, syn):
    """Print the leave-one-out of the two terrain-structure give-backs of session 14
    (``--terrain``): a point near the lenient surface lying between agreed ground above and
    below it within 3 or 5 m (:func:`sandwich_cue`), or within ``t`` slope- and
    distance-scaled tolerances of the surface inpainted from the agreed ground
    (:func:`surface_cue`), ``t`` chosen per fold."""
    giveback_loo(samples, scenes, feats, syn, SANDWICH_GIVE, "m", {
        "between 3 m": (sandwich_cue, True),
        "between 5 m": (lambda xyz, f: sandwich_cue(xyz, f, reach=5.0), True)},
        "points within tolerance of the lenient surface given back when agreed ground "
        "within the reach rises and falls more than -t m around them")
    giveback_loo(samples, scenes, feats, syn, RING_GIVE, "", {
        "agreed surface": (surface_cue, False),
        "agreed surface + lenient": (surface_cue, True)},
        "object points given back when within t tolerances (0.2 m + 1.25 x slope + 0.1 per "
        "metre from agreed ground) of the surface inpainted from the agreed ground")


def wall_slope_loo(samples, scenes, slopes):
    """Print the leave-one-out of ``smrf_vote``'s rule and veto with
    :data:`~lidar2city.ground.vote_filter.WALL_SLOPE` (the opening step that marks a wall,
    whose distance ``clear`` tests) chosen per fold too among ``slopes`` (the one whose
    fitted rule has the lowest objective on the six other samples + synthetic terrains),
    then each slope fitted on all seven: the seven, the synthetic terrains and the held-out
    kinds (``--wall-slopes``; session 14: a steep embankment is marked as a wall at 1.0)."""
    import lidar2city.ground.vote_filter as vote_module

    def features_at(wall):
        def features(xyz):
            saved = vote_module.WALL_SLOPE
            vote_module.WALL_SLOPE = wall
            try:
                return vote_features(xyz, fourth=VETO_SLOPE)[0]
            finally:
                vote_module.WALL_SLOPE = saved
        return features

    return setting_loo(samples, scenes, {f"wall slope {w:g}": features_at(w) for w in slopes},
                       "the wall slope")


def wall_anchor_loo(samples, scenes, anchors):
    """Print the leave-one-out of ``smrf_vote``'s rule and veto with its ``wall_anchor``
    (a wall region counts only when the opening cuts one of its cells at that slope too:
    :func:`~lidar2city.ground.vote_features`' ``anchor``) chosen per fold too among off and
    ``anchors``, then each fitted on all seven (``--wall-anchors``; session 15)."""
    fns = {"wall anchor off": lambda xyz: vote_features(xyz, fourth=VETO_SLOPE)[0]}
    for a in anchors:
        fns[f"wall anchor {a:g}"] = (
            lambda a: lambda xyz: vote_features(xyz, fourth=VETO_SLOPE, anchor=a)[0])(a)
    return setting_loo(samples, scenes, fns, "the wall anchor")


#: anchor slopes of :func:`wall_anatomy`, and the wall distances (m) it scores the rule at.
ANATOMY_ANCHORS = (2.0, 3.0)
ANATOMY_CLEARS = (15.0, 30.0)


def wall_grids(xyz, anchors=ANATOMY_ANCHORS):
    """The grid of ``vote_features(xyz)`` at its defaults (the same opening), its cells
    marked at :data:`~lidar2city.ground.vote_filter.WALL_SLOPE` and at each of ``anchors``,
    the cell of every point and the low outliers."""
    from lidar2city.ground.segment_filter import _segment_surfaces
    from lidar2city.ground.smrf_filter import _checked_outliers
    from lidar2city.ground.vote_filter import VOTE_SLOPES, WALL_SLOPE

    xyz, out = _checked_outliers(xyz, cell=1.0, slope=VOTE_SLOPES[0], window=24.0, scalar=1.25,
                                 threshold=0.5, outlier_radius=5.0, outlier_depth=1.5, jump=0.6,
                                 lenient=VOTE_SLOPES[1])
    _, spec, marked, _ = _segment_surfaces(
        xyz, out, cell=1.0, slope=VOTE_SLOPES[0], window=24.0, extend=10.0, jump=0.6,
        raised=0.6, min_cells=4, also=(VOTE_SLOPES[1],), marks=(WALL_SLOPE, *anchors))
    r, c = cell_of(xyz[:, :2], spec)
    return marked[0], dict(zip(anchors, marked[1:])), (r, c), out


def wall_anatomy(samples):
    """Print, per ISPRS sample and scene of HELD_OUT_KINDS, what the wall mark of
    ``smrf_vote`` holds and what the ``wall_anchor`` option takes out of it (``--walls``):
    the cells marked (with points), those whose points are mostly reference ground, the
    4-connected wall regions, those anchored at each of :data:`ANATOMY_ANCHORS` and the
    share of the cells of the regions left out that are mostly reference object; then the
    total error of the vote's rule and veto at their defaults (fitted on all seven) with
    the walls as marked, with every wall cell holding a reference-ground point taken out
    (an oracle that frees every embankment), and anchored, at the ``clear`` of
    :data:`ANATOMY_CLEARS`."""
    from lidar2city.ground.segment_filter import _grid_labels, anchored_objects

    scenes = dict(samples)
    for kind in HELD_OUT_KINDS:
        for spacing in (1.0, 2.5):
            sc = make_terrain(kind, spacing=spacing, seed=1)
            scenes[f"{kind}@{spacing:g}m"] = (sc.xyz, sc.ground)
    heads = ["marked", "oracle"] + [f"anchor {a:g}" for a in ANATOMY_ANCHORS]
    print(f"\nwall anatomy: cells marked at WALL_SLOPE (with points: mostly reference ground), "
          f"regions (anchored at {', '.join(f'{a:g}' for a in ANATOMY_ANCHORS)}; cells of the "
          f"regions left out mostly object); total error % of the default rule with the walls "
          f"{', '.join(heads)} at clear {' / '.join(f'{c:g}' for c in ANATOMY_CLEARS)} m")
    sums = {}
    for name, (xyz, ref) in scenes.items():
        features, _ = vote_features(xyz, fourth=VETO_SLOPE)
        walls, steps, (r, c), out = wall_grids(xyz)
        flat = r * walls.shape[1] + c
        count = np.bincount(flat, minlength=walls.size).reshape(walls.shape)
        grounds = np.bincount(flat, weights=ref, minlength=walls.size).reshape(walls.shape)
        holds = walls & (count > 0)
        mostly_ground = holds & (2 * grounds > count)
        label = _grid_labels(walls[:, :-1] & walls[:, 1:], walls[:-1, :] & walls[1:, :])
        regions = np.unique(label.ravel()[walls.ravel()])
        line = (f"{name:<20} cells {int(holds.sum()):6d} ({int(mostly_ground.sum()):5d} ground) "
                f"regions {len(regions):5d}")
        masks = {"marked": walls, "oracle": walls & ~(grounds > 0)}
        for a in ANATOMY_ANCHORS:
            kept = anchored_objects(walls, steps[a])
            left = holds & ~kept
            kept_regions = len(np.unique(label.ravel()[kept.ravel()]))
            share = (left & ~mostly_ground).sum() / max(int(left.sum()), 1)
            line += f"; at {a:g}: {kept_regions:5d}, left out {100 * share:5.1f} % object"
            masks[f"anchor {a:g}"] = kept
        dist = {k: _distance_to(m, int(np.ceil(40.0 / 1.0)))[r, c] for k, m in masks.items()}
        assert np.array_equal(np.minimum(dist["marked"], 41), np.minimum(features[:, 3], 41))
        errs = []
        for k in heads:
            f = features.copy()
            f[:, 3] = dist[k]
            for clear in ANATOMY_CLEARS:
                e = ground_errors(vote_rule(f, **dict(VOTE_RULE, clear=clear), veto=VOTE_VETO)
                                  & ~out, ref)["total"]
                errs.append(e)
                if name in samples:
                    sums.setdefault((k, clear), []).append(e)
        print(line)
        print(f"{'':<20} " + "; ".join(
            f"{k} {' / '.join(f'{100 * v:.2f}' for v in errs[2 * i:2 * i + 2])}"
            for i, k in enumerate(heads)))
    print(f"{'mean of the seven':<20} " + "; ".join(
        f"{k} {' / '.join(f'{100 * np.mean(sums[k, c]):.2f}' for c in ANATOMY_CLEARS)}"
        for k in heads))


def setting_loo(samples, scenes, settings, what):
    """The leave-one-out of ``smrf_vote``'s rule and veto with one more setting chosen per
    fold among ``settings`` (``label: features(xyz) -> (N, 5)``; the one whose fitted rule
    has the lowest objective on the six other samples + synthetic terrains), then each
    setting fitted on all seven: the seven, the synthetic terrains of TERRAIN_KINDS and the
    scenes of HELD_OUT_KINDS (total error %); also the leave-one-out of each setting
    fixed (only the rule and veto fitted per fold). Returns the held-out totals of the
    per-fold choice."""
    kinds = {f"{k}@{s:g}m": make_terrain(k, spacing=s, seed=1)
             for k in HELD_OUT_KINDS for s in (1.0, 2.5)}
    feats = {label: ({n: fn(xyz) for n, (xyz, _) in samples.items()},
                     [(fn(sc.xyz), sc.ground, 1.0 / len(scenes)) for sc in scenes.values()],
                     [fn(sc.xyz) for sc in kinds.values()])
             for label, fn in settings.items()}

    def fitted(label, names):
        real, syn, _ = feats[label]
        sets = [(real[n], samples[n][1], 1.0) for n in names] + syn
        rule, _ = fit_rule(sets)
        if rule is None:
            return np.inf, None, None
        veto, objective = fit_veto(sets, rule)
        return objective, rule, veto

    print(f"\nleave-one-out with {what} chosen per fold among "
          f"{', '.join(settings)} (rule and veto per fold too)")
    held, line = [], []
    for name, (_, ref) in samples.items():
        others = [n for n in samples if n != name]
        (_, rule, veto), label = min(((fitted(k, others), k) for k in settings),
                                     key=lambda t: t[0][0])
        held.append(ground_errors(vote_rule(feats[label][0][name], **rule, veto=veto),
                                  ref)["total"])
        line.append(f"{name} {100 * held[-1]:.2f} ({label})")
        # how near a tie the fold's wall distance was: each clear's objective on the others
        # and its held-out error, the rest of the fold's rule kept
        real, syn, _ = feats[label]
        sets = [(real[n], samples[n][1], 1.0) for n in others] + syn
        total = sum(w for _, _, w in sets)
        ties = []
        for clear in CLEAR:
            r = dict(rule, clear=clear)
            objective = sum(w * np.mean(vote_rule(f, **r, veto=veto) != g)
                            for f, g, w in sets) / total
            e = ground_errors(vote_rule(real[name], **r, veto=veto), ref)["total"]
            ties.append(f"{clear:g} {100 * objective:.3f}/{100 * e:.2f}")
        print(f"  {name} fold ({label}, clear {rule['clear']:g}): clear objective/held-out % "
              f"{', '.join(ties)}")
    print(f"leave-one-out {100 * np.mean(held):.2f} %, max {100 * np.max(held):.2f} %: "
          f"{'; '.join(line)}")
    for label in settings:
        fixed = []
        for name, (_, ref) in samples.items():
            _, rule, veto = fitted(label, [n for n in samples if n != name])
            fixed.append(np.inf if rule is None else ground_errors(
                vote_rule(feats[label][0][name], **rule, veto=veto), ref)["total"])
        print(f"{label} fixed: leave-one-out {100 * np.mean(fixed):.2f} %, max "
              f"{100 * np.max(fixed):.2f} % ({' '.join(f'{100 * v:.2f}' for v in fixed)})")
    for label in settings:
        objective, rule, veto = fitted(label, list(samples))
        if rule is None:
            print(f"{label}: the tree has not the rule's shape")
            continue
        real, syn, kind_feats = feats[label]
        seven = [ground_errors(vote_rule(real[n], **rule, veto=veto), ref)["total"]
                 for n, (_, ref) in samples.items()]
        synth = [np.mean(vote_rule(f, **rule, veto=veto) != g)
                 for (k, sc), (f, g, _) in zip(scenes.items(), syn)
                 if k.split("@")[0] in TERRAIN_KINDS]
        kind_line = " ".join(
            f"{k} {100 * ground_errors(vote_rule(f, **rule, veto=veto), sc.ground)['total']:.2f}"
            for (k, sc), f in zip(kinds.items(), kind_feats))
        print(f"{label} fitted on all seven ({show_rule(rule)}, veto {veto:g}): "
              f"seven {100 * np.mean(seven):.2f} % ({' '.join(f'{100 * v:.2f}' for v in seven)}),"
              f" synthetic terrains {100 * np.mean(synth):.2f} %; held-out kinds (total %) "
              f"{kind_line}")
    return held


def giveback_loo(samples, scenes, feats, syn, grid, unit, variants, what):
    """The leave-one-out of :func:`uphill_loo` and :func:`ring_loo`: for each variant
    ``name: (cue(xyz, features) -> (N,), near_lenient)``, the rule and veto fitted per fold,
    then ``pred | (cue <= t) [& lenient ratio <= 1]`` with ``t`` of ``grid`` chosen per fold;
    then fitted on all seven and scored on the held-out kinds."""
    print(f"\nleave-one-out, the rule and veto per fold, then {what} (t among "
          f"{', '.join(f'{v:g}' for v in grid)}{' ' + unit if unit else ''}, per fold)")
    syn_set = [(f, g, 1.0 / len(syn)) for f, g in syn]
    for key, (cue_of, near_lenient) in variants.items():
        cpu = {}
        real = {}
        for n, (xyz, _) in samples.items():
            start = time.process_time()
            real[n] = cue_of(xyz, feats[n])
            cpu[n] = time.process_time() - start
        fake = [cue_of(sc.xyz, f) for sc, (f, _) in zip(scenes.values(), syn)]

        def fitted(names):
            sets = [(feats[n], samples[n][1], 1.0) for n in names] + syn_set
            cue = [real[n] for n in names] + fake
            rule, _ = fit_rule(sets)
            veto = fit_veto(sets, rule)[0]
            total = sum(w for _, _, w in sets)

            def give(f, c, t):
                extra = c <= t
                if near_lenient:
                    extra &= f[:, 1] <= 1.0
                return vote_rule(f, **rule, veto=veto) | extra

            t = min(grid, key=lambda t: sum(
                w * np.mean(give(f, c, t) != g) for (f, g, w), c in zip(sets, cue)) / total)
            return give, t, rule, veto

        held, base, line = [], [], []
        for name, (_, ref) in samples.items():
            give, t, rule, veto = fitted([n for n in samples if n != name])
            held.append(ground_errors(give(feats[name], real[name], t), ref)["total"])
            base.append(ground_errors(vote_rule(feats[name], **rule, veto=veto), ref)["total"])
            line.append(f"{name} {100 * held[-1]:.2f} (t {t:g})")
        print(f"{key:<16} leave-one-out {100 * np.mean(held):.2f} %, max {100 * np.max(held):.2f} "
              f"% against {100 * np.mean(base):.2f} %: {'; '.join(line)}")
        print(f"{'':<16} the cue's CPU s (load {os.getloadavg()[0]:.1f}): "
              + ", ".join(f"{n} {v:.3f}" for n, v in cpu.items())
              + f"; all seven {sum(cpu.values()):.2f}")
        give, t, _, _ = fitted(list(samples))
        seven = [ground_errors(give(feats[n], real[n], t), ref)["total"]
                 for n, (_, ref) in samples.items()]
        synth = np.mean([np.mean(give(f, c, t) != g) for (f, g), c in zip(syn, fake)])
        kinds_line = []
        for kind in HELD_OUT_KINDS:
            for spacing in (1.0, 2.5):
                scene = make_terrain(kind, spacing=spacing, seed=1)
                f = vote_features(scene.xyz, fourth=VETO_SLOPE)[0]
                c = cue_of(scene.xyz, f)
                e = [ground_errors(give(f, c, tt), scene.ground)["total"]
                     for tt in (-np.inf, t, np.inf)]
                kinds_line.append(f"{kind}@{spacing:g}m " + " / ".join(f"{100 * v:.2f}"
                                                                       for v in e))
        print(f"{'':<16} fitted on all seven: t {t:g}, seven {100 * np.mean(seven):.2f} % "
              f"({' '.join(f'{100 * v:.2f}' for v in seven)}), synthetic terrains "
              f"{100 * synth:.2f} %; held-out kinds (total % off / t / inf): "
              f"{'; '.join(kinds_line)}")


def roughness_check(samples, scenes):
    """Print whether a point-level roughness cue tells the vegetation the ``wall_anchor``
    frees (samp51's bushes, which must stay object) from the ground it frees (samp61's
    embankments), and the leave-one-out of the anchor with a roughness veto
    (``--roughness``; session 16).

    First, per sample, the points the anchor (:data:`ROUGH_ANCHOR`) changes from object
    to ground, each fold's rule and veto fitted on the six others + synthetic terrains
    with and without it (reference object / ground), and how well each cue
    (:func:`knn_roughness` with 16 and 8 neighbours, :func:`column_spread`) separates
    them (:func:`auc`: freed objects rougher than freed ground; pooled over the seven);
    then the same on the points near the lenient surface (ratio <= 1) in the rule's far
    branch that the default calls object (what any freeing of walls could give back),
    and samp11's type I points against its right objects. Then ``setting_loo`` with the
    anchor, and with the anchor whose freed walls still count for a point rougher than
    each of :data:`ROUGH_VETOES`: its wall distance is then the unanchored one."""
    names = {"roughness 16-NN": lambda xyz: knn_roughness(xyz, 16),
             "roughness 8-NN": lambda xyz: knn_roughness(xyz, 8),
             "column spread": column_spread}
    cache = {}

    def feats_of(xyz, anchor):
        key = (id(xyz), anchor)
        if key not in cache:
            cache[key] = vote_features(xyz, fourth=VETO_SLOPE, anchor=anchor)[0]
        return cache[key]

    def rough_of(xyz):
        key = (id(xyz), "rough")
        if key not in cache:
            cache[key] = knn_roughness(xyz)
        return cache[key]

    syn = {a: [(feats_of(sc.xyz, a), sc.ground, 1.0 / len(scenes)) for sc in scenes.values()]
           for a in (None, ROUGH_ANCHOR)}
    pooled = {k: {"freed": ([], []), "near lenient": ([], []), "samp11": ([], [])}
              for k in names}
    print(f"\nroughness: points the wall anchor {ROUGH_ANCHOR:g} frees (object -> ground; each "
          f"fold's rule and veto), reference object / ground; cue AUC (freed objects rougher "
          f"than freed ground) per sample")
    for name, (xyz, ref) in samples.items():
        pred = {}
        for a in (None, ROUGH_ANCHOR):
            sets = [(feats_of(samples[n][0], a), samples[n][1], 1.0) for n in samples
                    if n != name] + syn[a]
            rule, _ = fit_rule(sets)
            veto = fit_veto(sets, rule)[0]
            pred[a] = vote_rule(feats_of(xyz, a), **rule, veto=veto)
        f = feats_of(xyz, None)
        freed = pred[ROUGH_ANCHOR] & ~pred[None]
        candidate = (f[:, 1] <= 1.0) & (f[:, 0] > VOTE_RULE["near"]) & ~pred[None] & \
            np.isfinite(f[:, 0])
        cue = {k: fn(xyz) for k, fn in names.items()}
        line = (f"{name:<8} freed {int((freed & ~ref).sum()):4d} / {int((freed & ref).sum()):4d}"
                f"; near lenient {int((candidate & ~ref).sum()):5d} / "
                f"{int((candidate & ref).sum()):5d}:")
        for k, v in cue.items():
            pooled[k]["freed"][0].append(v[freed & ~ref])
            pooled[k]["freed"][1].append(v[freed & ref])
            pooled[k]["near lenient"][0].append(v[candidate & ~ref])
            pooled[k]["near lenient"][1].append(v[candidate & ref])
            if name == "samp11":
                wrong = ~pred[None] & np.isfinite(f[:, 0])
                pooled[k]["samp11"][0].append(v[wrong & ~ref])
                pooled[k]["samp11"][1].append(v[wrong & ref])
            line += (f" {k} {auc(v[freed & ~ref], v[freed & ref]):.2f} / "
                     f"{auc(v[candidate & ~ref], v[candidate & ref]):.2f}")
        print(line)
    for k, sets in pooled.items():
        print(f"{k:<16} pooled AUC: " + "; ".join(
            f"{what} {auc(np.concatenate(o), np.concatenate(g)):.2f} (object {sum(map(len, o))},"
            f" ground {sum(map(len, g))})" for what, (o, g) in sets.items()))

    def vetoed(t):
        def features(xyz):
            f = feats_of(xyz, ROUGH_ANCHOR).copy()
            f[:, 3] = np.where(rough_of(xyz) > t, feats_of(xyz, None)[:, 3], f[:, 3])
            return f
        return features

    settings = {"wall anchor off": lambda xyz: feats_of(xyz, None),
                f"wall anchor {ROUGH_ANCHOR:g}": lambda xyz: feats_of(xyz, ROUGH_ANCHOR)}
    settings |= {f"anchor {ROUGH_ANCHOR:g}, roughness veto {t:g}": vetoed(t)
                 for t in ROUGH_VETOES}
    return setting_loo(samples, scenes, settings, "the anchor and its roughness veto")


def above_loo(samples, scenes, aboves, anchors=(None,)):
    """Print the leave-one-out of ``smrf_vote``'s rule and veto (fitted per fold on the six
    others + synthetic terrains) with its ``above`` fixed at each of ``aboves`` (m; inf:
    off) and its ``wall_anchor`` at each of ``anchors`` (None: off), the rise measured
    within each fold's ``clear``; then each pair fitted on all seven: the seven, the
    synthetic terrains of TERRAIN_KINDS and the scenes of HELD_OUT_KINDS (total error %)
    (``--above-fixed``, ``--above-anchors``; session 16: ``above`` frees the ground between
    the large buildings of ``steep_town``)."""
    kinds = {f"{k}@{s:g}m": make_terrain(k, spacing=s, seed=1)
             for k in HELD_OUT_KINDS for s in (1.0, 2.5)}
    cache = {}

    def feats_of(xyz, anchor, clear=VOTE_RULE["clear"]):
        key = (id(xyz), anchor, clear)
        if key not in cache:
            cache[key] = vote_features(xyz, fourth=VETO_SLOPE, anchor=anchor, rise=clear)[0]
        return cache[key]

    def fitted(anchor, names):
        sets = [(feats_of(samples[n][0], anchor), samples[n][1], 1.0) for n in names]
        sets += [(feats_of(sc.xyz, anchor), sc.ground, 1.0 / len(scenes))
                 for sc in scenes.values()]
        rule, _ = fit_rule(sets)
        return rule, fit_veto(sets, rule)[0]

    def scored(xyz, truth, anchor, rule, veto, above):
        f = feats_of(xyz, anchor, rule["clear"])
        return ground_errors(vote_rule(f, **rule, veto=veto, above=None if np.isinf(above)
                                       else above), truth)["total"]

    print(f"\nleave-one-out with `above` fixed (m) and the wall anchor, the rule and veto fitted "
          f"per fold; then fitted on all seven: the seven, synthetic terrains, held-out kinds "
          f"(total %)")
    def objective(anchor, names, rule, veto, above):
        """The fit's objective (mean point error, the synthetic terrains as one sample)."""
        own = [scored(samples[n][0], samples[n][1], anchor, rule, veto, above) for n in names]
        syn = np.mean([1.0 - np.mean(vote_rule(
            feats_of(sc.xyz, anchor, rule["clear"]), **rule, veto=veto,
            above=None if np.isinf(above) else above) == sc.ground) for sc in scenes.values()])
        return (sum(own) + syn) / (len(own) + 1)

    chosen, line = [], []
    for anchor in anchors:
        folds = {n: fitted(anchor, [m for m in samples if m != n]) for n in samples}
        rule, veto = fitted(anchor, list(samples))
        for above in aboves:
            held = [scored(xyz, ref, anchor, *folds[n], above)
                    for n, (xyz, ref) in samples.items()]
            for (n, (xyz, ref)), e in zip(samples.items(), held):
                o = objective(anchor, [m for m in samples if m != n], *folds[n], above)
                chosen.append((n, o, e, f"anchor {anchor if anchor is not None else 'off'}, "
                                        f"above {above:g}"))
            seven = [scored(xyz, ref, anchor, rule, veto, above) for xyz, ref in samples.values()]
            synth = [scored(sc.xyz, sc.ground, anchor, rule, veto, above)
                     for k, sc in scenes.items() if k.split("@")[0] in TERRAIN_KINDS]
            kind = " ".join(f"{k} {100 * scored(sc.xyz, sc.ground, anchor, rule, veto, above):.2f}"
                            for k, sc in kinds.items())
            print(f"anchor {anchor if anchor is not None else 'off'}, above {above:g}: "
                  f"leave-one-out {100 * np.mean(held):.2f} %, max {100 * np.max(held):.2f} % "
                  f"({' '.join(f'{100 * v:.2f}' for v in held)}); fitted on all seven "
                  f"({show_rule(rule)}, veto {veto:g}) {100 * np.mean(seven):.2f} % "
                  f"({' '.join(f'{100 * v:.2f}' for v in seven)}), synthetic terrains "
                  f"{100 * np.mean(synth):.2f} %; {kind}")
    held = []
    for n in samples:
        _, _, e, label = min((c for c in chosen if c[0] == n), key=lambda c: c[1])
        held.append(e)
        line.append(f"{n} {100 * e:.2f} ({label})")
    print(f"the pair chosen per fold (lowest objective on the six others + synthetic "
          f"terrains): leave-one-out {100 * np.mean(held):.2f} %, max {100 * np.max(held):.2f} "
          f"%: {'; '.join(line)}")


def cloth_ground(xyz):
    """1 for the points the cloth simulation filter (``bench_ground_bounds.csf``, rigidness 2)
    calls ground, else 0; NaN everywhere when the package is not installed."""
    try:
        from bench_ground_bounds import csf
        return csf(xyz, 2).astype(float)
    except ImportError:
        return np.full(len(xyz), np.nan)


def seeded_tin_ratio(xyz, features):
    """Each point's tolerance ratio (as in :func:`~lidar2city.ground.vote_features`) to a TIN
    densified (:func:`~lidar2city.ground.tin_filter.seeded_tin`, ptd's default angle and
    distance) from the points within tolerance of all four surfaces of ``features`` (N, 5):
    the TIN grows from that agreed ground along connected terrain (terrace benches, ground
    between buildings on a slope), not onto roofs raised on all sides. Inf for low outliers."""
    out = ~np.isfinite(features[:, 0])
    seeds = (features[:, :3] <= 1).all(axis=1) & (features[:, 4] <= 1)
    p = GroundConfig(method="ptd").method_params()
    surface, grad = seeded_tin(xyz, seeds, exclude=out, cell=p["cell"],
                               iteration_angle=p["iteration_angle"],
                               iteration_distance=p["iteration_distance"],
                               max_iterations=p["max_iterations"])
    ratio = np.abs(xyz[:, 2] - surface) / (p["threshold"] + p["scalar"] * grad)
    return np.where(out | np.isnan(ratio), np.inf, ratio)


def cues(samples, scenes, feats, syn, only=None):
    """Print the leave-one-out of a depth-:data:`CUE_DEPTH` tree over the three ratios plus
    each further cue of :data:`CUES` (see ``--cues``), and the worst sample's error with the
    tree fitted on that sample itself over the ratios and every cue (the rule family's
    ceiling there, with hindsight)."""
    makers = {"segments 0.4 ratio": lambda xyz, f: f[:, 4],
              "wall distance": lambda xyz, f: f[:, 3],
              "height above lowest 3x3": lambda xyz, f: height_above_lowest(xyz),
              "raised on all sides": lambda xyz, f: raised_all_sides(xyz),
              "cloth (CSF) ground": lambda xyz, f: cloth_ground(xyz),
              "seeded TIN ratio": lambda xyz, f: np.minimum(seeded_tin_ratio(xyz, f), 1e6),
              "uphill step": lambda xyz, f: np.minimum(uphill_steps(xyz, f)[0], 1e6),
              "lowest uphill step": lambda xyz, f: np.minimum(uphill_steps(xyz, f)[1], 1e6),
              "uphill step to ground": lambda xyz, f: np.minimum(
                  uphill_steps(xyz, f, on_ground=True)[0], 1e6),
              "lowest uphill step to ground": lambda xyz, f: np.minimum(
                  uphill_steps(xyz, f, on_ground=True)[1], 1e6),
              "roughness 16-NN": lambda xyz, f: knn_roughness(xyz, 16),
              "roughness 8-NN": lambda xyz, f: knn_roughness(xyz, 8),
              "column spread": lambda xyz, f: column_spread(xyz)}
    chosen = tuple(c for c in CUES if only is None or c in only)

    def cue_columns(xyz, f):
        return {c: makers[c](xyz, f) for c in chosen}

    real = {n: cue_columns(xyz, feats[n]) for n, (xyz, _) in samples.items()}
    fake = [cue_columns(s.xyz, f) for s, (f, _) in zip(scenes.values(), syn)]
    print(f"\nleave-one-out of a depth-{CUE_DEPTH} tree over the three ratios and one more cue "
          f"(held-out total % per sample; the tree fitted on all seven)")
    worst = None
    for cue in (None, *chosen):
        def x(f, more, cue=cue):
            return f[:, :3] if cue is None else np.column_stack([f[:, :3], more[cue]])

        if cue is not None and np.isnan(real[next(iter(real))][cue]).all():
            print(f"{cue:<24} skipped: pip install cloth-simulation-filter to include it")
            continue
        held = []
        for name, (_, ref) in samples.items():
            sets = [(x(feats[n], real[n]), samples[n][1], 1.0) for n in samples if n != name]
            sets += [(x(f, m), g, 1.0 / len(syn)) for (f, g), m in zip(syn, fake)]
            tree = fit_tree(sets, depth=CUE_DEPTH)
            pred = predict(tree, x(feats[name], real[name])) & np.isfinite(feats[name][:, 0])
            held.append(ground_errors(pred, ref)["total"])
        tree = fit_tree([(x(feats[n], real[n]), samples[n][1], 1.0) for n in samples]
                        + [(x(f, m), g, 1.0 / len(syn)) for (f, g), m in zip(syn, fake)],
                        depth=CUE_DEPTH)
        print(f"{cue or 'ratios only':<24} leave-one-out {100 * np.mean(held):.2f} %, max "
              f"{100 * np.max(held):.2f} % ({' '.join(f'{100 * v:.2f}' for v in held)}); "
              f"{show(tree, (*NAMES, cue))}")
        worst = worst or list(samples)[int(np.argmax(held))]
    known = [c for c in chosen if not np.isnan(real[worst][c]).all()]
    every = np.column_stack([feats[worst][:, :3]] + [real[worst][c] for c in known])
    for depth in (CUE_DEPTH, 2 * CUE_DEPTH):
        tree = fit_tree([(every, samples[worst][1], 1.0)], depth=depth)
        wrong = np.mean(predict(tree, every) != samples[worst][1])
        print(f"{worst}, a depth-{depth} tree over the ratios and the {len(known)} cues fitted on "
              f"{worst} itself: total {100 * wrong:.2f} %")


def use_fill(share, where="o", value="nearest", marks=False, gate=None):
    """Make every ``smrf_vote`` and ``vote_features`` of this script use ``fill=share`` (and
    the private variants of :func:`~lidar2city.ground.segment_filter._segment_surfaces`:
    where the fill applies, the heights it gives, whether the walls see it)."""
    import lidar2city.ground.vote_filter as vf
    from lidar2city.ground import segment_filter, smrf_filter

    if gate is not None:
        smrf_filter.FILL_GATE = gate

    global smrf_vote, vote_features, FILL_SHARE
    FILL_SHARE = share
    vf._segment_surfaces = functools.partial(segment_filter._segment_surfaces,
                                             fill_where=where, fill_value=value,
                                             fill_marks=marks)
    smrf_vote = functools.partial(_SMRF_VOTE, fill=share)
    vote_features = functools.partial(_VOTE_FEATURES, fill=share)


#: the library's functions, whatever :func:`use_fill` binds the names to; the share in use.
_SMRF_VOTE, _VOTE_FEATURES, FILL_SHARE = smrf_vote, vote_features, VOTE_FILL


def smrf_filter_gate():
    """The gate (m) of the "gated" fill in use."""
    from lidar2city.ground import smrf_filter

    return smrf_filter.FILL_GATE


def fill_speed(samples, repeat):
    """Print the CPU seconds of ``smrf_vote`` with and without its fill on each ISPRS sample
    whose point spacing makes the fill act (best of ``repeat``, interleaved)."""
    from lidar2city.ground.smrf_filter import _minimum_grid, _point_spacing

    print(f"\nCPU seconds of smrf_vote with fill={FILL_SHARE:g} and without (best of {repeat}, "
          f"interleaved), on the samples where the fill acts")
    for name, (xyz, _) in samples.items():
        spacing = _point_spacing(_minimum_grid(xyz, cell=1.0)[2], 1.0, len(xyz))
        if FILL_SHARE * spacing < 1.0:
            continue
        best = {"fill": np.inf, "off": np.inf}
        for _ in range(repeat):
            for key, fn in (("off", functools.partial(_SMRF_VOTE, fill=None)), ("fill", smrf_vote)):
                t0 = time.process_time()
                fn(xyz)
                best[key] = min(best[key], time.process_time() - t0)
        print(f"{name:<8} spacing {spacing:.2f} m: {best['fill']:.3f} s with the fill, "
              f"{best['off']:.3f} s without ({best['fill'] / best['off']:.2f}x)")


def show_rule(rule):
    return ", ".join(f"{k}={v:g}" for k, v in rule.items())


def fit_tree(sets, depth=DEPTH):
    """Depth-``depth`` tree over the ratios minimising the mean over ``sets`` of the point error.

    ``sets`` is a list of ``(ratios (N, 3), ground (N,), weight)``; each set's
    points share its ``weight`` equally. A node is a leaf (bool: ground) or
    ``(feature, threshold, left (<=), right (>))``.
    """
    x = np.vstack([np.minimum(r, 1e6) for r, _, _ in sets])
    y = np.concatenate([g for _, g, _ in sets]).astype(float)
    w = np.concatenate([np.full(len(g), wt / len(g)) for _, g, wt in sets])
    edges = [np.unique(np.quantile(x[:, j], QUANTILES)) for j in range(x.shape[1])]
    if FINE_EDGES:
        edges = [np.union1d(e, FINE_EDGES) for e in edges]
    if FORCED_SHAPE and depth == 2 and x.shape[1] == 3:
        return _coded_tree(x, y, w, edges)
    return _grow(x, y, w, depth, edges)


def fit_coded(sets, grid=None):
    """The coded rule's tree (``near <= a ? (steep <= b ? G : O) : (plain <= c ? G : O)``) on
    ``sets`` as :func:`fit_tree` (the same objective), its three thresholds chosen together to
    minimise the objective exactly, not one split at a time, among the quantile edges of
    :func:`fit_tree` or, with ``grid``, among its values (the same for every ratio and every
    training set)."""
    x = np.vstack([np.minimum(r, 1e6) for r, _, _ in sets])
    y = np.concatenate([g for _, g, _ in sets]).astype(float)
    w = np.concatenate([np.full(len(g), wt / len(g)) for _, g, wt in sets])
    edges = ([np.unique(np.quantile(x[:, j], QUANTILES)) for j in range(x.shape[1])]
             if grid is None else [np.asarray(grid, dtype=float)] * x.shape[1])
    return _coded_tree(x, y, w, edges)


def _coded_tree(x, y, w, edges):
    """The coded rule's tree with the least weighted error over points ``x`` (N, 3) of
    ground ``y`` and weight ``w``, its thresholds among ``edges`` (one array per ratio),
    found exactly by cumulative tables (:func:`fit_coded`; ``--forced-shape``)."""
    bins = [np.searchsorted(e, x[:, j]) for j, e in enumerate(edges)]
    rows = len(edges[0]) + 1

    def tables(j):
        """Weighted ground and object counts per (near bin, bin of ratio j)."""
        cols = len(edges[j]) + 1
        at = bins[0] * cols + bins[j]
        return [np.bincount(at, weights=v, minlength=rows * cols).reshape(rows, cols)
                for v in (w * y, w * (1 - y))]

    def error(pos, neg):
        """Per near threshold (rows) and threshold on ratio j (columns): ground called object
        above the column's threshold plus object called ground at or below it."""
        cp, cn = np.cumsum(pos, axis=1)[:, :-1], np.cumsum(neg, axis=1)[:, :-1]
        return cn + (pos.sum(axis=1)[:, None] - cp)

    pos, neg = tables(1)
    left = error(np.cumsum(pos, axis=0)[:-1], np.cumsum(neg, axis=0)[:-1])
    pos, neg = tables(2)
    right = error(pos.sum(axis=0) - np.cumsum(pos, axis=0)[:-1],
                  neg.sum(axis=0) - np.cumsum(neg, axis=0)[:-1])
    total = left.min(axis=1) + right.min(axis=1)
    k = int(np.flatnonzero(total <= total.min() + 1e-12)[0])
    return (0, float(edges[0][k]), (1, float(edges[1][int(np.argmin(left[k]))]), True, False),
            (2, float(edges[2][int(np.argmin(right[k]))]), True, False))
#: ``--forced-shape``: :func:`fit_tree` fits the thresholds of the coded rule's shape
#: (``near ? (steep ? G : O) : (plain ? G : O)``) instead of a free depth-2 tree.
FORCED_SHAPE = False

#: ``--fine-edges``: thresholds :func:`fit_tree` tries besides the quantiles of the pooled
#: ratios (these crowd near 0, where most ground points are: between 0.2 and 1.6 the
#: ``near`` split has three candidates, and a fold can jump between them).
FINE_EDGES = ()
FINE_GRID = tuple(np.round(np.arange(0.1, 2.0001, 0.05), 2))


def _grow(x, y, w, depth, edges):
    pos, neg = float(w @ y), float(w @ (1 - y))
    leaf = pos > neg
    best, split = min(pos, neg), None
    if depth == 0 or best == 0:
        return leaf
    for j, e in enumerate(edges):
        b = np.searchsorted(e, x[:, j])
        cp = np.cumsum(np.bincount(b, weights=w * y, minlength=len(e) + 1))[:-1]
        cn = np.cumsum(np.bincount(b, weights=w * (1 - y), minlength=len(e) + 1))[:-1]
        err = np.minimum(cp, cn) + np.minimum(pos - cp, neg - cn)
        k = int(np.argmin(err))
        if err[k] < best - 1e-12:
            best, split = err[k], (j, float(e[k]))
    if split is None:
        return leaf
    j, t = split
    m = x[:, j] <= t
    return (j, t, _grow(x[m], y[m], w[m], depth - 1, edges),
            _grow(x[~m], y[~m], w[~m], depth - 1, edges))


def predict(tree, ratios):
    """Ground mask of ``tree`` on ``ratios`` (N, 3)."""
    if not isinstance(tree, tuple):
        return np.full(len(ratios), tree)
    j, t, left, right = tree
    m = ratios[:, j] <= t
    out = np.empty(len(ratios), dtype=bool)
    out[m] = predict(left, ratios[m])
    out[~m] = predict(right, ratios[~m])
    return out


def show(tree, names=NAMES):
    """One-line form of a tree: ``near<=1.14 ? (steep<=0.92 ? G : O) : (...)``."""
    if not isinstance(tree, tuple):
        return "G" if tree else "O"
    j, t, left, right = tree
    return f"{names[j]}<={t:.3f} ? {show(left, names)} : {show(right, names)}"


def rule_of(tree):
    """The thresholds of :data:`VOTE_RULE` when ``tree`` has the shape of the coded rule."""
    if (isinstance(tree, tuple) and tree[0] == 0 and isinstance(tree[2], tuple)
            and isinstance(tree[3], tuple) and tree[2][0] == 1 and tree[3][0] == 2
            and tree[2][2:] == (True, False) and tree[3][2:] == (True, False)):
        return {"near": round(tree[1], 2), "steep": round(tree[2][1], 2),
                "plain": round(tree[3][1], 2)}
    return None


def main():
    ap = arg_parser(__doc__)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-speed", action="store_true")
    ap.add_argument("--fit", choices=FITS, default="unit",
                    help="the fitting procedure of the leave-one-out and of the rule on all "
                         "seven (see FITS)")
    ap.add_argument("--pairs", action="store_true")
    ap.add_argument("--fit-held-out-kinds", action="store_true",
                    help="fit on the scenes of HELD_OUT_KINDS too (no longer held out)")
    ap.add_argument("--cues", action="store_true",
                    help="leave-one-out of depth-3 trees with one more cue each")
    ap.add_argument("--uphill", action="store_true",
                    help="leave-one-out of the rule with the uphill-step give-back")
    ap.add_argument("--ring", action="store_true",
                    help="leave-one-out of the rule with the ground-ring-plane give-back")
    ap.add_argument("--wall-slopes", default=None, metavar="SLOPES",
                    help="leave-one-out with WALL_SLOPE chosen per fold among these "
                         "(comma-separated, e.g. 1,1.5,2,2.5,3,4,6)")
    ap.add_argument("--wall-anchors", default=None, metavar="SLOPES",
                    help="leave-one-out with smrf_vote's wall_anchor chosen per fold among off "
                         "and these (comma-separated, e.g. 1.5,2,2.5,3)")
    ap.add_argument("--walls", action="store_true",
                    help="what the wall mark holds and what wall_anchor takes out of it")
    ap.add_argument("--roughness", action="store_true",
                    help="a roughness cue on the points the wall anchor frees, and its veto")
    ap.add_argument("--above-fixed", default=None, metavar="METRES",
                    help="leave-one-out with smrf_vote's above fixed at each of these "
                         "(comma-separated, inf: off)")
    ap.add_argument("--above-anchors", default=None, metavar="SLOPES",
                    help="with --above-fixed: wall anchors to pair with (comma-separated, "
                         "off: none)")
    ap.add_argument("--terrain", action="store_true",
                    help="leave-one-out of the rule with the terrain-structure give-backs")
    ap.add_argument("--only-cues", default=None, metavar="NAMES",
                    help="with --cues: only these cues (comma-separated names of CUES)")
    ap.add_argument("--fill", type=float, default=None, metavar="SHARE",
                    help="everything with smrf_vote's fill (empty cells within SHARE point "
                         "spacings of a point take its cell's height before the inpainting)")
    ap.add_argument("--fill-where", default="o", choices=FILL_WHERE,
                    help="with --fill: the opening's input (o), the final surfaces (f) or both")
    ap.add_argument("--fill-value", default="nearest", choices=FILL_VALUES,
                    help="with --fill: the nearest point's height, or the higher / lower of it "
                         "and the harmonic inpainting's")
    ap.add_argument("--fill-gate", type=float, default=None, metavar="METRES",
                    help="with --fill-value gated: the least difference from the harmonic "
                         "inpainting that a filled cell takes (default FILL_GATE)")
    ap.add_argument("--fill-marks", action="store_true",
                    help="with --fill: the walls from the filled opening too (default: from "
                         "the opening without the fill)")
    ap.add_argument("--forced-shape", action="store_true",
                    help="fit the coded rule's shape (near ? steep : plain) instead of a free "
                         "depth-2 tree")
    ap.add_argument("--fine-edges", action="store_true",
                    help="fit thresholds among 0.1, 0.15, ... 2 too, not only among quantiles")
    ap.add_argument("--syn-spacings", default=None, metavar="METRES",
                    help="spacings of the synthetic terrains fitted on (comma-separated; "
                         "default 1,2.5)")
    ap.add_argument("--syn-seeds", type=int, default=1, metavar="N",
                    help="seeds 1..N of each synthetic terrain fitted on (default 1)")
    ap.add_argument("--anatomy", nargs="?", const=True, default=None, metavar="PNG_DIR",
                    help="where smrf_vote's errors are on its worst samples (maps to PNG_DIR)")
    args = ap.parse_args()
    global FORCED_SHAPE, FINE_EDGES
    FORCED_SHAPE = args.forced_shape
    FINE_EDGES = FINE_GRID if args.fine_edges else ()
    if args.fill is not None:
        use_fill(args.fill, args.fill_where, args.fill_value, args.fill_marks, args.fill_gate)
    samples = {p.name.split("-")[0]: load(p) for p in reference_paths(args.data)}
    if args.syn_spacings is None and args.syn_seeds == 1:
        scenes = synthetic_scenes()
    else:
        spacings = [1.0, 2.5] if args.syn_spacings is None else [
            float(v) for v in args.syn_spacings.split(",")]
        scenes = {f"{kind}@{spacing:g}m#{seed}": make_terrain(kind, spacing=spacing, seed=seed)
                  for kind in TERRAIN_KINDS for spacing in spacings
                  for seed in range(1, args.syn_seeds + 1)}
    print(f"rule fitted as {'the coded shape' if FORCED_SHAPE else 'a free depth-2 tree'}"
          f"{' (thresholds among quantiles and 0.1-2 by 0.05)' if FINE_EDGES else ''}; "
          f"{len(scenes)} synthetic terrains; smrf_vote's fill {FILL_SHARE:g} spacings "
          + ("(its default)" if args.fill is None else
             f"({args.fill_where}, {args.fill_value}"
             f"{'' if args.fill_value != 'gated' else ' ' + format(smrf_filter_gate(), 'g') + ' m'}"
             f", walls "
             f"{'filled' if args.fill_marks else 'unfilled'})"))
    if args.fit_held_out_kinds:
        scenes |= {f"{kind}@{spacing:g}m": make_terrain(kind, spacing=spacing, seed=1)
                   for kind in HELD_OUT_KINDS for spacing in (1.0, 2.5)}
    # the three ratios, the wall distance (walls anchored as smrf_vote's default), the ratio
    # to the veto's fourth surface and the walls' rise within the default clear
    clear = VOTE_RULE["clear"]
    feats = {n: vote_features(xyz, fourth=VETO_SLOPE, rise=clear, anchor=VOTE_ANCHOR)[0]
             for n, (xyz, _) in samples.items()}
    syn = [(vote_features(s.xyz, fourth=VETO_SLOPE, rise=clear, anchor=VOTE_ANCHOR)[0], s.ground)
           for s in scenes.values()]
    syn_set = [(r, g, 1.0 / len(syn)) for r, g in syn]
    xyz_of = {n: xyz for n, (xyz, _) in samples.items()} | {
        k: s.xyz for k, s in enumerate(scenes.values())}
    rise_cache = {}

    how = {"unit": "the three thresholds at 1 (SMRF's test)",
           "greedy": f"a greedy depth-{DEPTH} tree over the ratios",
           "coded": "the coded tree's thresholds fitted together",
           "bagged": f"the coded tree bagged over the leave-{BAG_LEAVE}-out subsets",
           "grid": "the coded tree on RATIO_GRID",
           "grid-bagged": f"the coded tree on RATIO_GRID bagged over the leave-{BAG_LEAVE}-out "
                          "subsets",
           "selected": "the procedure chosen by its inner leave-one-out"}[args.fit]
    print(f"leave-one-out, fit {args.fit!r}: {how}, then the wall distance, then the "
          f"veto among {', '.join(f'{v:g}' for v in VETO)} (fitted on the six other samples + "
          f"synthetic terrains; walls anchored at {VOTE_ANCHOR:g}, smrf_vote's default); the "
          f"held-out errors with the veto, the total without it, with the veto and `above` "
          f"(among {', '.join(f'{v:g}' for v in ABOVE)} m), and with the veto and the default "
          f"`above` {VOTE_ABOVE:g} m (smrf_vote's defaults)")
    print(f"{'sample':<8} {'type I %':>9} {'type II %':>10} {'total %':>8} {'no veto %':>10} "
          f"{'above %':>8} {'default above %':>16}  rule")
    held = {"veto": [], "no veto": [], "veto + above": [], "defaults": []}
    for name, (_, ref) in samples.items():
        sets = [(feats[n], samples[n][1], 1.0) for n in samples if n != name] + syn_set
        keys = [n for n in samples if n != name] + list(range(len(syn)))
        rule, tree, veto, above = fit_procedure(args.fit, sets, keys, xyz_of, rise_cache)
        plain = ground_errors(score(rule, tree, feats[name]), ref)
        e = plain if rule is None else ground_errors(vote_rule(feats[name], **rule, veto=veto),
                                                     ref)
        held["veto"].append(e["total"])
        held["no veto"].append(plain["total"])
        up = e
        if rule is not None:
            f_held = with_rise(xyz_of[name], feats[name], rule["clear"], rise_cache, name)
            up = ground_errors(vote_rule(f_held, **rule, veto=veto, above=above), ref)
            held["defaults"].append(ground_errors(
                vote_rule(f_held, **rule, veto=veto, above=VOTE_ABOVE), ref)["total"])
        else:  # a tree without the rule's shape has no veto or above: its own score
            held["defaults"].append(plain["total"])
        held["veto + above"].append(up["total"])
        print(f"{name:<8} {100 * e['type_i']:>9.2f} {100 * e['type_ii']:>10.2f} "
              f"{100 * e['total']:>8.2f} {100 * plain['total']:>10.2f} {100 * up['total']:>8.2f} "
              f"{100 * held['defaults'][-1]:>16.2f}  "
              f"{show(tree) if rule is None else show_rule(dict(rule, veto=veto, above=above))}")
    for k, v in held.items():
        print(f"smrf_vote leave-one-out ({k}) mean total {100 * np.mean(v):.2f} %, "
              f"max {100 * np.max(v):.2f} %")
    sets = [(feats[n], samples[n][1], 1.0) for n in samples] + syn_set
    keys = list(samples) + list(range(len(syn)))
    rule, tree, veto, above = fit_procedure(args.fit, sets, keys, xyz_of, rise_cache)
    print(f"fitted on all seven ({args.fit}): "
          f"{show(tree) if rule is None else show_rule(rule)}, veto {veto}, above {above}; "
          f"{'VOTE_RULE matches' if rule == VOTE_RULE else f'VOTE_RULE {VOTE_RULE} differs'}; "
          f"{'VOTE_VETO matches' if veto == VOTE_VETO else f'VOTE_VETO {VOTE_VETO} differs'}; "
          f"{'VOTE_ABOVE matches' if above == VOTE_ABOVE else f'VOTE_ABOVE {VOTE_ABOVE} differs'}")
    if rule is not None and (rule != VOTE_RULE or veto != VOTE_VETO):
        fitted_rule_check(samples, scenes, feats, syn, xyz_of, rise_cache, rule, veto, above)

    methods = {"smrf_segments": lambda xyz: smrf_segments(
        xyz, **GroundConfig(method="smrf_segments").method_params()), "smrf_vote": smrf_vote,
        "smrf_vote no veto": lambda xyz: smrf_vote(xyz, veto=None),
        "smrf_vote no anchor, no above": lambda xyz: smrf_vote(xyz, wall_anchor=None, above=None),
        f"smrf_vote above {ABOVE_SHOWN:g}": lambda xyz: smrf_vote(xyz, above=ABOVE_SHOWN)}
    print(f"\n{'sample':<8} " + " ".join(f"{m + ' ' + c:>20}" for m in methods
                                         for c in ("I", "II", "total")))
    rows = []
    for name, (xyz, ref) in samples.items():
        row = []
        for fn in methods.values():
            e = ground_errors(fn(xyz), ref)
            row += [e["type_i"], e["type_ii"], e["total"]]
        rows.append(row)
        print(f"{name:<8} " + " ".join(f"{100 * v:>20.2f}" for v in row))
    print(f"{'mean':<8} " + " ".join(f"{100 * v:>20.2f}" for v in np.mean(rows, axis=0)))
    for m, fn in methods.items():
        s = np.mean([ground_errors(fn(sc.xyz), sc.ground)["total"] for sc in scenes.values()])
        xyz, truth = small_tile()
        print(f"{m}: synthetic terrains mean total {100 * s:.2f} % ({len(scenes)} scenes); "
              f"small tile with a building {100 * (fn(xyz) == truth).mean():.1f} % right")
    held_out_kinds(ABOVE_SHOWN, fitted=args.fit_held_out_kinds)
    oracle(samples, feats)
    if args.anatomy is not None:
        anatomy(samples, feats, None if args.anatomy is True else Path(args.anatomy))
    if args.cues:
        cues(samples, scenes, feats, syn,
             None if args.only_cues is None else args.only_cues.split(","))
    if args.uphill:
        uphill_loo(samples, scenes, feats, syn)
    if args.ring:
        ring_loo(samples, scenes, feats, syn)
    if args.terrain:
        terrain_loo(samples, scenes, feats, syn)
    if args.wall_slopes:
        wall_slope_loo(samples, scenes, [float(v) for v in args.wall_slopes.split(",")])
    if args.walls:
        wall_anatomy(samples)
    if args.roughness:
        roughness_check(samples, scenes)
    if args.above_fixed:
        above_loo(samples, scenes, [float(v) for v in args.above_fixed.split(",")],
                  [None if v == "off" else float(v)
                   for v in (args.above_anchors or "off").split(",")])
    if args.wall_anchors:
        wall_anchor_loo(samples, scenes, [float(v) for v in args.wall_anchors.split(",")])
    if args.pairs:
        nested_pairs(samples, scenes, "unit" if args.fit == "unit" else "greedy")
    if FILL_SHARE > 0:
        fill_speed(samples, args.repeat)
    if not args.no_speed:
        speed(args.data / "isprs" / "sites" / "CSite4_orig-utm.laz", args.repeat,
              methods=("smrf_segments", "smrf_vote"))


if __name__ == "__main__":
    main()
