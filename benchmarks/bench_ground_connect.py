"""Segment connectivity on ``smrf_vote``'s mask (``connect_ground``): leave-one-out, bounds, cost.

Usage::

    python benchmarks/bench_ground_connect.py [--data DIR] [--repeat 3] [--no-speed]

:func:`lidar2city.ground.connect_ground` revises a ground mask per smooth
surface patch of a 2.5-D grid of lowest points (:func:`~lidar2city.ground.
surface_patches`, cells of about the point spacing): a patch that runs on from
the mask's ground without a step gives its points to the ground (``share``),
an object patch lying lower than the patches around it along most of its
boundary and touching ground does too (``lower``: a bench below a riser,
ground between buildings on a slope), a ground patch raised above its
surroundings along most of its boundary is object (``raised``: a roof), and
so is a small ground patch lower than everything around it (``pit``),
iterated from the revised mask. This script:

1. computes ``smrf_vote``'s features of the ISPRS reference samples in
   ``DIR/isprs/reference`` and of the synthetic terrains, and the patches of
   each under every patch setting of :data:`PATCHES`;
2. leave-one-sample-out: in each fold the vote's rule and veto are refitted
   on the six other samples + the synthetic terrains (as
   ``bench_ground_vote.py`` does), then the connectivity setting of
   :data:`GRID` x :data:`PATCHES` (off among them) with the lowest mean
   point error over the same sets; prints the held-out totals of the vote
   and of the vote + connectivity, the chosen setting, their mean and
   maximum;
3. the setting fitted on all seven, and with it the seven samples, the
   synthetic terrains, the small tile with a building and the held-out kinds
   (:data:`~lidar2city.synthetic_terrain.HELD_OUT_KINDS`, never fitted on);
4. the best setting on samp11 itself (hindsight: the ceiling of this rule
   family there) and on each held-out kind, and where samp11's type I cells
   (lowest point of a cell reference ground, called object by the vote) lie
   among the patches, against its right object cells;
5. unless ``--no-speed``, the CPU seconds of :func:`~lidar2city.ground.smrf_vote`
   without and with ``connect`` (3 rounds, its defaults) on
   ``DIR/isprs/sites/CSite4_orig-utm.laz`` (best of ``--repeat``,
   interleaved, in this process).

About a minute.
"""

from __future__ import annotations

import itertools
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_ground import arg_parser, load, reference_paths, synthetic_scenes  # noqa: E402
from bench_ground_segments import small_tile  # noqa: E402
from bench_ground_vote import fit_rule, fit_veto  # noqa: E402
from lidar2city.ground import (  # noqa: E402
    VETO_SLOPE,
    VOTE_RULE,
    VOTE_VETO,
    connect_ground,
    smrf_vote,
    surface_patches,
    vote_features,
)
from lidar2city.ground.connect_filter import CONNECT_LOWER  # noqa: E402
from lidar2city.ground.vote_filter import vote_rule  # noqa: E402
from lidar2city.metrics.ground import ground_errors  # noqa: E402
from lidar2city.synthetic_terrain import HELD_OUT_KINDS, make_terrain  # noqa: E402

#: patch settings (jump in m per metre of cell, step_slope) tried.
PATCHES = ((0.3, 0.0), (0.6, 0.0), (0.3, 0.5))
#: rule settings (share, lower, raised, pit) tried; None or a pit of 0 is off.
OFF = None
GRID = tuple(itertools.product((0.9, OFF), (0.6, 0.8, 0.95, OFF), (0.9, OFF), (0, 4)))
ROUNDS = 3
#: single rules scored on the seven samples beside the fitted setting: spreading along
#: patches, roofs taken back, a lenient ``lower``.
SHOWN = ((0.9, OFF, OFF, 0), (OFF, OFF, 0.9, 0), (OFF, 0.8, OFF, 0))


def settings():
    """Every (patch setting, rule setting); the first is everything off."""
    return [(PATCHES[0], (OFF, OFF, OFF, 0))] + [
        (pt, rule) for pt in PATCHES for rule in GRID if rule != (OFF, OFF, OFF, 0)]


def revise(xyz, mask, out, patches, setting):
    """``mask`` revised by :func:`connect_ground` under ``setting`` (patches precomputed)."""
    pt, (share, lower, raised, pit) = setting
    if (share, lower, raised, pit) == (OFF, OFF, OFF, 0):
        return mask
    return connect_ground(xyz, mask, exclude=out, share=share, lower=lower, raised=raised,
                          pit=pit, rounds=ROUNDS, patches=patches[pt])


def prepare(xyz):
    """Features (N, 5), low outliers and the patches of every :data:`PATCHES` setting."""
    features, out = vote_features(xyz, fourth=VETO_SLOPE)
    patches = {pt: surface_patches(xyz, exclude=out, jump=pt[0], step_slope=pt[1])
               for pt in PATCHES}
    return xyz, features, out, patches


def best_setting(cases, masks):
    """The setting of :func:`settings` with the lowest weighted point error over ``cases``
    (``(prepared, reference, weight)``) whose vote masks are ``masks``."""
    def objective(setting):
        return sum(w * np.mean(revise(c[0], m, c[2], c[3], setting) != ref)
                   for (c, ref, w), m in zip(cases, masks))
    return min(settings(), key=objective)


def show(setting):
    (jump, step), (share, lower, raised, pit) = setting
    if (share, lower, raised, pit) == (OFF, OFF, OFF, 0):
        return "off"
    rule = ", ".join(f"{k} {v:g}" for k, v in (("share", share), ("lower", lower),
                                               ("raised", raised)) if v is not None)
    return f"jump {jump:g}, step_slope {step:g}: {rule}{', pit ' + str(pit) if pit else ''}"


def patch_anatomy(c, ref, mask, pt):
    """Print where the vote's type I cells (a cell whose lowest point is reference ground and
    called object) lie among the patches of setting ``pt``, against its right object cells."""
    p = c[3][pt]
    label, n = p["label"], p["label"].size
    low_ground, low_ref = np.zeros(n, bool), np.zeros(n, bool)
    low_ground[p["cells"]], low_ref[p["cells"]] = mask[p["lowest"]], ref[p["lowest"]]
    filled = np.zeros(n, bool)
    filled[p["cells"]] = True
    size = np.bincount(label[filled], minlength=n)
    is_ground = np.bincount(label[filled], weights=low_ground[filled], minlength=n) >= 0.5 * size
    side, other = np.concatenate([label[p["a"]], label[p["b"]]]), np.concatenate([p["b"], p["a"]])
    lower = np.concatenate([p["dz"] < 0, p["dz"] > 0])
    to_g, to_o = low_ground[other], ~low_ground[other]
    share = {}
    for key, m in (("ground", to_g), ("objects", to_o)):
        e = np.bincount(side[m], minlength=n)
        share[key] = (np.bincount(side[m], weights=lower[m], minlength=n) / np.maximum(e, 1), e > 0)
    line = f"  patches jump {pt[0]:g}, step_slope {pt[1]:g} (cell {p['cell']:g} m):"
    for what, m in (("type I", filled & low_ref & ~low_ground),
                    ("right object", filled & ~low_ref & ~low_ground)):
        lab = label[m]
        touch = share["ground"][1][lab]
        lo_g = share["ground"][0][lab][touch & ~is_ground[lab]]
        lo_o = share["objects"][0][lab][touch & ~is_ground[lab] & share["objects"][1][lab]]
        line += (f"\n    {what} cells {m.sum()}: in ground patches {100 * np.mean(is_ground[lab]):.0f} "
                 f"%, object patches touching ground {100 * np.mean(~is_ground[lab] & touch):.0f} %, "
                 f"not touching {100 * np.mean(~is_ground[lab] & ~touch):.0f} %; in patches of <= 4 "
                 f"cells {100 * np.mean(size[lab] <= 4):.0f} %; touching: boundary to ground lying "
                 f"lower, median {np.median(lo_g):.2f}, to objects {np.median(lo_o):.2f}")
    print(line)


def speed(path, repeat):
    """CPU seconds of smrf_vote without and with connect (best of ``repeat``)."""
    xyz, _ = load(path)
    best = {"smrf_vote": np.inf, "smrf_vote connect=3": np.inf}
    for _ in range(repeat):
        for name, kw in (("smrf_vote", {}), ("smrf_vote connect=3", {"connect": ROUNDS})):
            t = time.process_time()
            smrf_vote(xyz, **kw)
            best[name] = min(best[name], time.process_time() - t)
    print(f"\n{path.name}, {len(xyz)} points, CPU s (best of {repeat}): "
          + ", ".join(f"{k} {v:.3f}" for k, v in best.items())
          + f"; connect adds {100 * (best['smrf_vote connect=3'] / best['smrf_vote'] - 1):.1f} %")


def main():
    ap = arg_parser(__doc__)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-speed", action="store_true")
    args = ap.parse_args()
    samples = {p.name.split("-")[0]: load(p) for p in reference_paths(args.data)}
    scenes = synthetic_scenes()
    real = {n: prepare(xyz) for n, (xyz, _) in samples.items()}
    fake = [(prepare(s.xyz), s.ground, 1.0 / len(scenes)) for s in scenes.values()]

    print(f"leave-one-out: vote rule + veto refitted per fold, then the connectivity setting "
          f"({len(settings())} settings, off among them) on the six other samples + "
          f"synthetic terrains; held-out total %")
    held = {"vote": [], "vote + connect": []}
    for name, (_, ref) in samples.items():
        cases = [(real[n], samples[n][1], 1.0) for n in samples if n != name] + fake
        rule, _ = fit_rule([(c[1], g, w) for c, g, w in cases])
        veto = fit_veto([(c[1], g, w) for c, g, w in cases], rule)[0]
        masks = [vote_rule(c[1], **rule, veto=veto) & ~c[2] for c, _, _ in cases]
        setting = best_setting(cases, masks)
        c = real[name]
        mask = vote_rule(c[1], **rule, veto=veto) & ~c[2]
        e0 = ground_errors(mask, ref)["total"]
        e1 = ground_errors(revise(c[0], mask, c[2], c[3], setting), ref)["total"]
        held["vote"].append(e0)
        held["vote + connect"].append(e1)
        print(f"{name:<8} vote {100 * e0:5.2f}  vote + connect {100 * e1:5.2f}  ({show(setting)})")
    for k, v in held.items():
        print(f"{k} leave-one-out mean total {100 * np.mean(v):.2f} %, max {100 * np.max(v):.2f} %")

    cases = [(real[n], samples[n][1], 1.0) for n in samples] + fake
    default = [vote_rule(c[1], **VOTE_RULE, veto=VOTE_VETO) & ~c[2] for c, _, _ in cases]
    setting = best_setting(cases, default)
    print(f"\nfitted on all seven: {show(setting)}")
    rows = []
    for (c, ref, _), m in zip(cases[:len(samples)], default):
        rows.append((ground_errors(m, ref)["total"],
                     ground_errors(revise(c[0], m, c[2], c[3], setting), ref)["total"]))
    print("seven samples, vote / vote + connect (total %): "
          + ", ".join(f"{n} {100 * a:.2f} / {100 * b:.2f}" for n, (a, b) in zip(samples, rows))
          + f"; mean {100 * np.mean([a for a, _ in rows]):.2f} / "
            f"{100 * np.mean([b for _, b in rows]):.2f}")
    for rule in SHOWN:
        one = (PATCHES[0], rule)
        totals = [ground_errors(revise(c[0], m, c[2], c[3], one), ref)["total"]
                  for (c, ref, _), m in zip(cases[:len(samples)], default)]
        print(f"  {show(one)} alone: " + ", ".join(f"{n} {100 * v:.2f}" for n, v in
                                                   zip(samples, totals))
              + f"; mean {100 * np.mean(totals):.2f}")
    syn = [(ground_errors(m, ref)["total"],
            ground_errors(revise(c[0], m, c[2], c[3], setting), ref)["total"])
           for (c, ref, _), m in zip(cases[len(samples):], default[len(samples):])]
    print(f"synthetic terrains ({len(syn)} scenes) mean total {100 * np.mean([a for a, _ in syn]):.2f}"
          f" / {100 * np.mean([b for _, b in syn]):.2f} %")
    xyz, truth = small_tile()
    t = prepare(xyz)
    m = smrf_vote(xyz)
    print(f"small tile with a building: {100 * np.mean(m == truth):.1f} / "
          f"{100 * np.mean(revise(xyz, m, t[2], t[3], setting) == truth):.1f} % right")
    own = (PATCHES[0], (None, CONNECT_LOWER, None, 0))
    print(f"connect_ground's defaults ({show(own)}) "
          f"{'match' if own == setting else 'DIFFER from'} that setting")

    print("\nheld-out kinds (never fitted on): vote / vote + connect (the all-seven setting) / "
          "the best setting with hindsight (total %)")
    for kind in HELD_OUT_KINDS:
        for spacing in (1.0, 2.5):
            scene = make_terrain(kind, spacing=spacing, seed=1)
            c = prepare(scene.xyz)
            m = smrf_vote(scene.xyz)
            errs = {s: ground_errors(revise(c[0], m, c[2], c[3], s), scene.ground)["total"]
                    for s in settings()}
            hind = min(errs, key=errs.get)
            print(f"{kind + '@' + format(spacing, 'g') + 'm':<20} "
                  f"{100 * ground_errors(m, scene.ground)['total']:5.2f} / "
                  f"{100 * errs[setting]:5.2f} / {100 * errs[hind]:5.2f} ({show(hind)})")
    name = "samp11"
    if name in samples:
        c, ref = real[name], samples[name][1]
        m = vote_rule(c[1], **VOTE_RULE, veto=VOTE_VETO) & ~c[2]
        errs = {s: ground_errors(revise(c[0], m, c[2], c[3], s), ref)["total"]
                for s in settings()}
        hind = min(errs, key=errs.get)
        print(f"\n{name} with hindsight (the setting chosen on {name} itself): "
              f"{100 * ground_errors(m, ref)['total']:.2f} -> {100 * errs[hind]:.2f} % "
              f"({show(hind)})")
        print(f"{name}: the vote's type I cells among the patches (the share of a patch's "
              f"boundary edges where it lies lower than the cell across)")
        for pt in PATCHES[:2]:
            patch_anatomy(c, ref, m, pt)
    if not args.no_speed:
        speed(args.data / "isprs" / "sites" / "CSite4_orig-utm.laz", args.repeat)


if __name__ == "__main__":
    main()
