"""What the replay benchmarks share (``bench_roof_frontend.py``, ``bench_solid_replay.py``,
``bench_lod13_kernels.py``): recording a stage's calls in one run, replaying them in a
fresh process of each tree, the least CPU of a pass with its parts timed by wrappers on
their module attributes, and a digest of the answers (the same digest: the same answers
to the bit).

Only CPU seconds (``time.process_time``) are used: on a shared machine wall time does not
compare. A wrapper costs ~1 us per wrapped call, alike in every tree.
"""

from __future__ import annotations

import argparse
import os
import pickle
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def replay_parser(doc, *, traced=True) -> argparse.ArgumentParser:
    """The options every replay benchmark takes: other trees' ``src`` folders, ``--data``,
    (``--traced``,) ``--repeat``, ``--rounds``, ``--cache`` and the hidden ``--child``."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("others", nargs="*", help="src folders of other trees to compare with")
    ap.add_argument("--data")
    if traced:
        ap.add_argument("--traced", action="store_true", help="the run without footprints")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--cache")
    ap.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    return ap


def data_dir(arg=None) -> Path:
    """The shared data folder: ``arg``, else ``$LIDAR2CITY_DATA``, else ../shared/data."""
    return Path(arg or os.environ.get("LIDAR2CITY_DATA") or ROOT.parent / "shared" / "data")


def recording(module, names) -> dict:
    """Replace each function ``names`` of ``module`` by one that pickles its arguments
    before the call (it may change them); returns ``{name: [pickled (args, kwargs)]}``."""
    calls = {name: [] for name in names}

    def recorder(name, f):
        def g(*a, **k):
            calls[name].append(pickle.dumps((a, k)))
            return f(*a, **k)
        return g

    for name in names:
        setattr(module, name, recorder(name, getattr(module, name)))
    return calls


def capture_delft(module, names, data: Path, out: Path, traced: bool) -> None:
    """Record the calls of the functions ``names`` of ``module`` in one ``reconstruct`` of
    the Delft tile (LoD 1.2 + 1.3 + 2.2 in one process, with its BGT footprints or, when
    ``traced``, without them) and pickle them to ``out`` (run it in a child process)."""
    from lidar2city.cli.main import cli

    calls = recording(module, names)
    d = Path(data) / "delft"
    given = [] if traced else ["--footprints", str(d / "footprints_bgt.gpkg")]
    with tempfile.TemporaryDirectory() as tmp:
        cli.main(["reconstruct", str(d / "ahn3_cropped_1.laz"), *given, "--lod", "1.2", "--lod",
                  "1.3", "--lod", "2.2", "--workers", "1", "-o", str(Path(tmp) / "out.city.json")],
                 standalone_mode=False)
    with open(out, "wb") as f:
        pickle.dump(calls, f)


def digest(out, h) -> None:
    """Feed ``out`` (arrays, geometries, solids, nested lists / tuples / dicts) to hash ``h``."""
    import numpy as np
    import shapely

    if isinstance(out, np.ndarray):
        h.update(str(out.dtype).encode())
        h.update(np.ascontiguousarray(out).tobytes())
    elif isinstance(out, shapely.Geometry):
        h.update(shapely.to_wkb(out))
    elif hasattr(out, "vertices") and hasattr(out, "surfaces"):  # a Solid
        digest(np.asarray(out.vertices), h)
        for s in out.surfaces:
            digest([np.asarray(r) for r in getattr(s, "rings", s)], h)
            h.update(repr(getattr(s, "semantic", None)).encode())
    elif isinstance(out, (list, tuple)):
        h.update(b"(%d" % len(out))
        for o in out:
            digest(o, h)
    elif isinstance(out, dict):
        for k, v in out.items():
            h.update(repr(k).encode())
            digest(v, h)
    else:
        h.update(repr(out).encode())


def time_parts(parts, callers, acc) -> None:
    """Put CPU timers on the functions ``parts`` (``"module:function"``, module under
    lidar2city): each call adds its inclusive CPU to ``acc[function]``. The wrapper
    replaces the function in every module of ``callers`` (names under lidar2city) that
    holds it by that name; a part missing from this tree is left out."""
    import importlib
    import time

    mods = [importlib.import_module(f"lidar2city.{m}") for m in callers]
    for item in parts:
        mname, fname = item.split(":")
        try:
            mod = importlib.import_module(f"lidar2city.{mname}")
        except ImportError:
            continue
        f = getattr(mod, fname, None)
        if f is None:
            continue

        def wrap(f=f, key=fname):
            def g(*a, **k):
                t = time.process_time()
                try:
                    return f(*a, **k)
                finally:
                    acc[key] += time.process_time() - t
            return g

        g = wrap()
        for m in mods:  # every module that calls it by this name
            if getattr(m, fname, None) is f:
                setattr(m, fname, g)


def least_pass(f, raw, repeat, acc, answer_digest=None):
    """Replay ``f`` on the pickled calls ``raw`` ``repeat`` times, each pass on calls
    unpickled anew. Returns the least CPU of a pass, the parts' CPU of that pass (``acc``,
    filled by :func:`time_parts`' wrappers) and the MD5 of the first pass's answers
    (``answer_digest(answers, h)``, default :func:`digest`)."""
    import hashlib
    import time

    best, parts, md5 = float("inf"), {}, None
    for _ in range(repeat):
        calls = [pickle.loads(c) for c in raw]
        acc.clear()
        t = time.process_time()
        res = [f(*a, **k) for a, k in calls]
        cpu = time.process_time() - t
        if cpu < best:
            best, parts = cpu, dict(acc)
        if md5 is None:
            h = hashlib.md5()
            (answer_digest or digest)(res, h)
            md5 = h.hexdigest()
    return best, parts, md5


def compare_stages(script, trees, stages, *, cache, capture_args, repeat, rounds,
                   flags=(), first_flags=()):
    """Run ``script``'s capture child once in ``trees[0]`` (when ``cache`` is missing), then
    its timed child in each tree in turn, ``rounds`` times; returns the least pass per
    ``(tree index, stage)``: ``(cpu, parts, digest, calls)``, and the loads seen.

    A child is ``script [flags] [first_flags for trees[0]] --repeat N --child MODE A B``
    with ``PYTHONPATH`` the tree; the timed child writes ``{stage: (cpu, parts, digest,
    calls)}`` to B."""
    def child(src, *argv, first=False):
        env = dict(os.environ, PYTHONPATH=str(src))
        subprocess.run([sys.executable, str(script), *flags, *(first_flags if first else ()),
                        "--repeat", str(repeat), "--child", *map(str, argv)], env=env,
                       check=True, stdout=subprocess.DEVNULL)

    if not Path(cache).exists():
        child(trees[0], "capture", *capture_args, cache)
    best: dict = {}
    loads = [os.getloadavg()[0]]
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(rounds):
            for i, src in enumerate(trees):
                res = Path(tmp) / f"{i}_{r}.pkl"
                child(src, "timed", cache, res, first=i == 0)
                loads.append(os.getloadavg()[0])
                with open(res, "rb") as fh:
                    got = pickle.load(fh)
                for name, entry in got.items():
                    old = best.get((i, name))
                    if old is None or entry[0] < old[0]:
                        best[(i, name)] = entry
    return best, loads


def print_stages(best, trees, stages) -> None:
    """Per tree and stage the least CPU, the parts' CPU of that pass, the ratio of tree [0]
    to each other tree and the answers' digest; then whether every tree answered alike."""
    for i, src in enumerate(trees):
        total = sum(best[(i, s)][0] for s in stages)
        print(f"[{i}] {src}: stages {total:.3f} CPU s"
              + ("" if i == 0 else
                 f"; [0] / [{i}] = {sum(best[(0, s)][0] for s in stages) / total:.3f}"))
        for s in stages:
            cpu, parts, md5, n = best[(i, s)]
            ratio = "" if i == 0 else f" ([0] / [{i}] = {best[(0, s)][0] / cpu:.3f})"
            print(f"  {s}: {n} calls {cpu:.3f}{ratio}  digest {md5[:12]}")
            for p, t in sorted(parts.items(), key=lambda kv: -kv[1]):
                print(f"      {p:24s} {t:.3f}")
    same = all(best[(i, s)][2] == best[(0, s)][2] for i in range(len(trees)) for s in stages)
    print("same outputs in every tree:", same)
    if len(trees) > 1:
        print("stage CPU of [0] over the others' (median over trees):",
              {s: round(statistics.median(best[(0, s)][0] / best[(i, s)][0]
                                          for i in range(1, len(trees))), 3) for s in stages})


def stage_replay(args, script, stages, *, title, cache_stem, capture, timed, first_flags=(),
                 note=""):
    """The main of a stage replay benchmark (options of :func:`replay_parser`): as a child,
    ``capture(data, cache, traced)`` or ``timed(cache, repeat, result)``; else every tree's
    passes (:func:`compare_stages`, the capture cached in ``cache_stem_{kind}.pkl``) and
    their table (:func:`print_stages`) under a line naming ``title`` and the loads."""
    if args.child:
        mode, a, b = args.child
        if mode == "capture":
            capture(Path(a), Path(b), args.traced)
        else:
            timed(Path(a), args.repeat, Path(b))
        return
    kind = "traced" if args.traced else "footprints"
    cache = Path(args.cache or Path(tempfile.gettempdir()) / f"{cache_stem}_{kind}.pkl")
    trees = [str(ROOT / "src"), *[str(Path(o).resolve()) for o in args.others]]
    best, loads = compare_stages(Path(script).resolve(), trees, stages, cache=cache,
                                 capture_args=(data_dir(args.data),), repeat=args.repeat,
                                 rounds=args.rounds, flags=["--traced"] if args.traced else [],
                                 first_flags=first_flags)
    print(f"Delft, {kind}: {title}, least CPU s of {args.repeat} passes x {args.rounds} rounds "
          f"per tree; load {min(loads):.1f}-{max(loads):.1f}{note}")
    print_stages(best, trees, stages)
