"""Benchmark of the graph-reduction snake solver against a generic exact ILP.

Prints, for random building-like graphs (a spanning tree of a random planar
Delaunay graph plus a few planar chords: "a tree plus a few cycles"), the
solver time against the number of vertices, of states per vertex and of type
IV operations, and the time of scipy's HiGHS MILP on the same problem with
the standard local-polytope formulation (one indicator per vertex state,
integral, and one per edge state pair, tied by marginalisation constraints).
Both energies are compared (they must agree: both are exact).

Run: ``PYTHONPATH=src python benchmarks/bench_snake.py [--quick]``
"""

from __future__ import annotations

import sys
import time

import numpy as np
from scipy import sparse
from scipy.optimize import Bounds, LinearConstraint, milp

from lidar2city.snake import graph_energy, minimize_energy
from lidar2city.synthetic import building_like_graph


def wheels_graph(k, spokes=5):
    """``k`` wheels (a hub joined to a rim cycle) chained by an edge: needs k type IV."""
    edges, base = [], 0
    for w in range(k):
        hub = base
        rim = [base + 1 + i for i in range(spokes)]
        edges += [(hub, r) for r in rim] + [(rim[i], rim[(i + 1) % spokes]) for i in range(spokes)]
        if w:
            edges.append((base - 1, base + 1))
        base += spokes + 1
    return base, edges


def problem(n, edges, d, rng):
    unary = [rng.random(d) for _ in range(n)]
    tables = [rng.random((d, d)) * 2 for _ in edges]
    return unary, tables


def solve_ilp(unary, edges, tables, time_limit=120.0):
    dims = [len(u) for u in unary]
    xoff = np.cumsum([0] + dims[:-1])
    nx = int(sum(dims))
    yoff = nx + np.cumsum([0] + [dims[u] * dims[v] for u, v in edges][:-1]) if edges else []
    ny = int(sum(dims[u] * dims[v] for u, v in edges))
    c = np.concatenate([np.concatenate(unary)] + [t.ravel() for t in tables])
    rows, cols, vals, rhs = [], [], [], []
    r = 0
    for v, d in enumerate(dims):  # one state per vertex
        rows += [r] * d
        cols += list(range(xoff[v], xoff[v] + d))
        vals += [1.0] * d
        rhs.append(1.0)
        r += 1
    for e, (u, v) in enumerate(edges):  # marginalisation
        du, dv = dims[u], dims[v]
        idx = yoff[e] + np.arange(du * dv).reshape(du, dv)
        for i in range(du):
            rows += [r] * (dv + 1)
            cols += idx[i].tolist() + [xoff[u] + i]
            vals += [1.0] * dv + [-1.0]
            rhs.append(0.0)
            r += 1
        for j in range(dv):
            rows += [r] * (du + 1)
            cols += idx[:, j].tolist() + [xoff[v] + j]
            vals += [1.0] * du + [-1.0]
            rhs.append(0.0)
            r += 1
    a = sparse.csr_matrix((vals, (rows, cols)), shape=(r, nx + ny))
    integrality = np.concatenate([np.ones(nx), np.zeros(ny)])
    t0 = time.perf_counter()
    res = milp(c, constraints=LinearConstraint(a, rhs, rhs), integrality=integrality,
               bounds=Bounds(0, 1), options={"time_limit": time_limit})
    dt = time.perf_counter() - t0
    if res.x is None:
        return None, dt, "no solution"
    return float(res.fun), dt, "optimal" if res.status == 0 else "time limit"


def timed(unary, edges, tables, strategy="auto", repeat=3):
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        sol = minimize_energy(unary, edges, tables, strategy=strategy)
        best = min(best, time.perf_counter() - t0)
    return sol, best


def row(label, sol, dt, ilp=None):
    red = sol.reductions
    txt = (f"{label:<34} {dt * 1e3:9.2f} {red['I']:4d} {red['II']:4d} {red['III']:4d} {red['IV']:4d}"
           f" {red.get('VE', 0):4d} {sol.energy:12.5f}")
    if ilp is not None:
        e, t, status = ilp
        if e is None:
            same = status
        elif abs(e - sol.energy) < 1e-6 * max(1, abs(e)):
            same = "yes"
        elif status != "optimal":
            same = f"{status}: milp {e:.5f}"
        else:
            same = f"NO (milp {e:.5f})"
        txt += f" {t * 1e3:10.1f} {same:>6}"
    print(txt)


def main(quick=False):
    rng = np.random.default_rng(20261121)
    head = f"{'case':<34} {'ms':>9} {'I':>4} {'II':>4} {'III':>4} {'IV':>4} {'VE':>4} {'energy':>12}"
    print("== time vs vertices (25 states, tree + n/15 planar chords), vs HiGHS MILP ==")
    print(head + f" {'milp ms':>10} {'same':>6}")
    for n in (20, 60, 120, 240):
        extra = max(2, n // 15)
        edges = building_like_graph(n, extra, rng)
        unary, tables = problem(n, edges, 25, rng)
        sol, dt = timed(unary, edges, tables)
        assert abs(sol.energy - graph_energy(sol.states, unary, edges, tables)) < 1e-9
        ilp = solve_ilp(unary, edges, tables) if (n <= 120 or not quick) else None
        row(f"n={n} m={len(edges)}", sol, dt, ilp)
    print()
    print("== 60-vertex building topology, 25 states, more cycles ==")
    print(head + f" {'milp ms':>10} {'same':>6}")
    for extra in (3, 6, 10):
        times = []
        for rep in range(5):
            edges = building_like_graph(60, extra, rng)
            unary, tables = problem(60, edges, 25, rng)
            sol, dt = timed(unary, edges, tables)
            times.append(dt)
            ilp = solve_ilp(unary, edges, tables) if rep == 0 else None
            row(f"chords={extra} rep={rep}", sol, dt, ilp)
        print(f"   median {np.median(times) * 1e3:.2f} ms, max {np.max(times) * 1e3:.2f} ms")
    print()
    print("== time vs states (60 vertices, 4 chords) ==")
    print(head + f" {'milp ms':>10} {'same':>6}")
    edges = building_like_graph(60, 4, rng)
    for d in (9, 25, 49, 81):
        unary, tables = problem(60, edges, d, rng)
        sol, dt = timed(unary, edges, tables)
        ilp = solve_ilp(unary, edges, tables) if d <= 49 else None
        row(f"d={d}", sol, dt, ilp)
    print()
    print("== time vs type IV operations (chained wheels, 9 states), paper vs auto ==")
    print(head + f" {'milp ms':>10} {'same':>6}")
    for k in (1, 2, 4, 8):
        n, edges = wheels_graph(k)
        unary, tables = problem(n, edges, 9, rng)
        ilp = solve_ilp(unary, edges, tables)
        sol, dt = timed(unary, edges, tables, strategy="paper")
        row(f"wheels={k} n={n} paper", sol, dt, ilp)
        sol, dt = timed(unary, edges, tables, strategy="auto")
        row(f"wheels={k} n={n} auto", sol, dt, None)


if __name__ == "__main__":
    main(quick="--quick" in sys.argv)
