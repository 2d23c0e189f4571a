"""The learnt vote of three SMRF surfaces (``smrf_vote``): its rule refitted, leave-one-out, speed.

Usage::

    python benchmarks/bench_ground_vote.py [--data DIR] [--repeat 3] [--no-speed] [--pairs]

``smrf_vote`` (:mod:`lidar2city.ground.vote_filter`) judges each point from
its tolerance ratios to three provisional surfaces of one SMRF opening
(:func:`~lidar2city.ground.vote_features`: ``smrf_segments``' surface at
slope 0.1, the same at 0.3, plain SMRF's at 0.1) and its distance to the
nearest wall. This script:

1. computes the features of every point of the ISPRS reference samples in
   ``DIR/isprs/reference`` and of the synthetic terrains of
   :mod:`lidar2city.synthetic_terrain` (1 m and 2.5 m spacing);
2. fits the rule (:func:`fit_rule`): a depth-2 decision tree on the three
   ratios (:func:`fit_tree`: each split the threshold, among 48 quantiles of
   the pooled ratios, that minimises the weighted point error, every sample
   weighted equally and the synthetic terrains together as one more sample),
   then the wall distance ``clear`` of :data:`CLEAR` that minimises the same
   objective, leaving each ISPRS sample out in turn; it prints the held-out
   sample's type I / type II / total error, the rule of each fold, their
   mean and maximum (the leave-one-out figure);
3. fits it on all seven and prints the rule: its thresholds, rounded to two
   decimals, are :data:`lidar2city.ground.VOTE_RULE` (the script says
   whether they still are);
4. scores ``smrf_vote`` with its defaults against ``smrf_segments`` (the
   ``ground`` default) on the seven samples, the synthetic terrains and the
   small tile with a building of ``bench_ground_segments.py``;
5. the bound of any per-point rule over such surfaces: the share of points
   that every one of ``smrf_segments`` at the slopes of :data:`ORACLE_SLOPES`
   and plain SMRF at 0.1 classifies wrongly, per sample;
6. with ``--pairs``, the same leave-one-out with the two SMRF slopes chosen
   too, per fold, among :data:`PAIRS` (the pair whose fitted rule has the
   lowest objective on the six other samples + synthetic terrains): the
   default pair (0.1, 0.3) was chosen among these by looking at all seven
   samples' leave-one-out, so this nested figure is the honest one for the
   whole procedure (a few minutes more);
7. unless ``--no-speed``, times ``lidar2city ground`` with both methods on
   ``DIR/isprs/sites/CSite4_orig-utm.laz`` against reading and writing it
   with laspy (best of ``--repeat``, interleaved).

About a minute plus the speed runs.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_ground import arg_parser, load, reference_paths, speed, synthetic_scenes  # noqa: E402
from bench_ground_segments import small_tile  # noqa: E402
from lidar2city.ground import (  # noqa: E402
    VOTE_RULE,
    GroundConfig,
    smrf_segments,
    smrf_vote,
    vote_features,
)
from lidar2city.ground.vote_filter import vote_rule  # noqa: E402
from lidar2city.metrics.ground import ground_errors  # noqa: E402

NAMES = ("near", "steep", "plain")  # the three ratios, in the order of vote_features
DEPTH = 2
QUANTILES = np.linspace(0.01, 0.99, 48)
#: (strict, lenient) SMRF slope pairs of the ``--pairs`` check.
PAIRS = ((0.1, 0.2), (0.1, 0.25), (0.1, 0.3), (0.1, 0.4), (0.15, 0.3), (0.15, 0.4))
#: slopes of the smrf_segments surfaces of the per-point bound.
ORACLE_SLOPES = (0.1, 0.15, 0.2, 0.3, 0.4)
#: wall distances (m) tried for ``clear``; inf: the lenient surface never decides alone.
CLEAR = (5.0, 8.0, 10.0, 15.0, 20.0, 30.0, np.inf)


def fit_rule(sets):
    """:data:`VOTE_RULE` fitted on ``sets`` (as :func:`fit_tree`): the tree, then ``clear``.

    Returns the rule (dict, thresholds rounded to two decimals), or None when
    the tree has not the shape of the coded rule (its one-line form is then
    printed by the caller).
    """
    tree = fit_tree([(f[:, :3], g, w) for f, g, w in sets])
    rule = rule_of(tree)
    if rule is None:
        return None, tree
    total = sum(w for _, _, w in sets)

    def objective(clear):
        return sum(w * np.mean(vote_rule(f, **rule, clear=clear) != g) for f, g, w in sets) / total

    return dict(rule, clear=float(min(CLEAR, key=objective))), tree


def score(rule, tree, features):
    """Ground mask of a fitted rule (or of its tree when it has not the coded shape)."""
    return predict(tree, features[:, :3]) if rule is None else vote_rule(features, **rule)


def nested_pairs(samples, scenes):
    """Print the leave-one-out with the slope pair chosen per fold (see ``--pairs``)."""
    feats = {}
    for pair in PAIRS:
        feats[pair] = ({n: vote_features(xyz, slopes=pair)[0] for n, (xyz, _) in samples.items()},
                       [(vote_features(s.xyz, slopes=pair)[0], s.ground, 1.0 / len(scenes))
                        for s in scenes.values()])
    print("\nleave-one-out with the slope pair chosen per fold among "
          f"{', '.join(str(p) for p in PAIRS)}")
    held = []
    for name, (_, ref) in samples.items():
        best = None
        for pair, (real, syn) in feats.items():
            sets = [(real[n], samples[n][1], 1.0) for n in samples if n != name] + syn
            rule, tree = fit_rule(sets)
            objective = sum(w * np.mean(score(rule, tree, f) != g) for f, g, w in sets)
            if best is None or objective < best[0]:
                best = (objective, pair, score(rule, tree, real[name]))
        held.append(ground_errors(best[2], ref)["total"])
        print(f"{name:<8} held-out total {100 * held[-1]:5.2f} %  slopes {best[1]}")
    print(f"smrf_vote leave-one-out with the slopes chosen per fold: mean total "
          f"{100 * np.mean(held):.2f} %, max {100 * np.max(held):.2f} %")


def oracle(samples, feats):
    """Print the share of points every candidate surface gets wrong (see step 5)."""
    print(f"\nper-point bound: points wrong on all of smrf_segments at slopes "
          f"{', '.join(f'{v:g}' for v in ORACLE_SLOPES)} and plain SMRF at 0.1 (total error %)")
    wrong = []
    for name, (xyz, ref) in samples.items():
        right = feats[name][:, 2] <= 1.0
        right = np.where(ref, right, ~right)
        for slope in ORACLE_SLOPES:
            pred = smrf_segments(xyz, **dict(GroundConfig(method="smrf_segments").method_params(),
                                              slope=slope))
            right |= pred == ref
        wrong.append(np.mean(~right))
        print(f"{name:<8} {100 * wrong[-1]:5.2f}")
    print(f"{'mean':<8} {100 * np.mean(wrong):5.2f}")


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
    return _grow(x, y, w, depth, edges)


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


def show(tree):
    """One-line form of a tree: ``near<=1.14 ? (steep<=0.92 ? G : O) : (...)``."""
    if not isinstance(tree, tuple):
        return "G" if tree else "O"
    j, t, left, right = tree
    return f"{NAMES[j]}<={t:.3f} ? {show(left)} : {show(right)}"


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
    ap.add_argument("--pairs", action="store_true")
    args = ap.parse_args()
    samples = {p.name.split("-")[0]: load(p) for p in reference_paths(args.data)}
    scenes = synthetic_scenes()
    feats = {n: vote_features(xyz)[0] for n, (xyz, _) in samples.items()}
    syn = [(vote_features(s.xyz)[0], s.ground) for s in scenes.values()]
    syn_set = [(r, g, 1.0 / len(syn)) for r, g in syn]

    print(f"leave-one-out, depth-{DEPTH} tree over the ratios, then the wall distance "
          f"(fitted on the six other samples + synthetic terrains)")
    print(f"{'sample':<8} {'type I %':>9} {'type II %':>10} {'total %':>8}  rule")
    held = []
    for name, (_, ref) in samples.items():
        rule, tree = fit_rule([(feats[n], samples[n][1], 1.0) for n in samples if n != name]
                              + syn_set)
        e = ground_errors(score(rule, tree, feats[name]), ref)
        held.append(e["total"])
        print(f"{name:<8} {100 * e['type_i']:>9.2f} {100 * e['type_ii']:>10.2f} "
              f"{100 * e['total']:>8.2f}  {show(tree) if rule is None else show_rule(rule)}")
    print(f"smrf_vote leave-one-out mean total {100 * np.mean(held):.2f} %, "
          f"max {100 * np.max(held):.2f} %")
    rule, tree = fit_rule([(feats[n], samples[n][1], 1.0) for n in samples] + syn_set)
    print(f"fitted on all seven: {show(tree) if rule is None else show_rule(rule)}; "
          f"{'VOTE_RULE matches' if rule == VOTE_RULE else f'VOTE_RULE {VOTE_RULE} differs'}")

    methods = {"smrf_segments": lambda xyz: smrf_segments(
        xyz, **GroundConfig(method="smrf_segments").method_params()), "smrf_vote": smrf_vote}
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
    oracle(samples, feats)
    if args.pairs:
        nested_pairs(samples, scenes)
    if not args.no_speed:
        speed(args.data / "isprs" / "sites" / "CSite4_orig-utm.laz", args.repeat,
              methods=("smrf_segments", "smrf_vote"))


if __name__ == "__main__":
    main()
