"""Exact minimisation of a pairwise energy on a graph by graph reduction.

The energy of a labelling ``s`` (one state per vertex) is

.. math:: E_G(s) = \\sum_v E_V(v, s_v) + \\sum_{e=(u,v)} E_E(e, s_u, s_v)

(Yan et al. 2015, eq. 1). Dynamic programming along a contour (the classic
snake) is generalised to any graph by four reduction operations that each
remove vertices or edges while keeping the minimum of ``E_G``:

* **type I** — a vertex of degree 2 is eliminated into a new edge between its
  two neighbours; the new edge table is
  ``min_j E(u, v)[i, j] + E_V(v, j) + E(v, w)[j, k]`` and a look-up table
  keeps the best ``j`` per ``(i, k)`` (eq. 2);
* **type II** — parallel edges are merged by summing their tables;
* **type III** — a vertex of degree 1 is eliminated into its neighbour's vertex
  energy, ``E_V(u, i) += min_j E(u, v)[i, j] + E_V(v, j)`` (eq. 3), with a
  look-up table;
* **type IV** — when no vertex has degree <= 2, a pair of vertices ``a, c`` is
  removed: for every pair of their states ``(i, k)`` the energies of their
  edges are pushed into their neighbours' vertex energies (eqs. 7–10) and the
  reduced graph is solved; the best pair wins.

Type IV is not enumerated with a Python loop. Every energy table is kept
with one axis per vertex it depends on (its *scope*); removing ``a`` and ``c``
by type IV takes them out of the graph whose degrees drive the reductions, but
the tables that touched them keep their axes. Those axes are the batch of the
``d_a x d_c`` conditioned sub-problems: numpy broadcasting carries all of them
through the remaining reductions at once, and only the tables that actually
see ``a`` or ``c`` grow. When the graph is reduced, a last minimisation over
the joint tables of the removed vertices picks the best pair, and the look-up
tables are back-tracked in reverse order (each is indexed by the states of its
scope, known by then).

Beyond the paper, and still exact: when all vertices have degree >= 3 the
solver may instead eliminate one vertex into a table over its neighbours
(min-sum variable elimination, counted as ``"VE"``). Which move is taken is
decided by simulating, on the graph structure alone, the whole remaining
reduction after each candidate (type IV on each candidate pair, or the
min-weight elimination) and keeping the cheapest; type IV wins ties. With
``strategy="paper"`` only type IV is used.
"""

from __future__ import annotations

import heapq
import itertools
import logging
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..errors import FitError, InputError

__all__ = ["SnakeSolution", "minimize_energy", "graph_energy", "reduction_work"]

logger = logging.getLogger(__name__)

#: Size (elements) above which a min-plus product is computed state by state
#: of the eliminated vertex instead of in one broadcast (bounds memory).
_BROADCAST_LIMIT = 2_000_000
#: Largest table (elements) the solver will build; denser graphs raise FitError.
_MAX_TABLE = 50_000_000
#: Irreducible parts up to this many vertices are planned whole; larger ones
#: within a radius (edges) of the vertex to remove.
_PLAN_GLOBAL = 40
_PLAN_RADIUS = 3
#: Type IV candidate pairs examined when the irreducible part is large.
_MAX_PAIRS = 16


@dataclass(frozen=True)
class SnakeSolution:
    """Result of :func:`minimize_energy`.

    Attributes
    ----------
    states : ndarray of int, shape (n,)
        The minimising state of every vertex.
    energy : float
        ``E_G(states)``, recomputed from the input energies.
    reductions : dict
        How many operations of each type were applied: keys ``"I"``, ``"II"``,
        ``"III"``, ``"IV"`` (always present).
    """

    states: np.ndarray
    energy: float
    reductions: dict = field(default_factory=dict)


def _as_float_array(value, name: str, ndim: int) -> np.ndarray:
    try:
        # no copy of a float64 array: the solver never writes into its inputs
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a numeric {ndim}-D array") from None
    if arr.ndim != ndim:
        raise InputError(f"{name} must be {ndim}-D, got shape {arr.shape}")
    if arr.size == 0:
        raise InputError(f"{name} must not be empty, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name} must hold finite values only")
    return arr


def _validate(vertex_energies, edges, edge_energies):
    if isinstance(vertex_energies, np.ndarray) and vertex_energies.ndim == 2:
        vertex_energies = list(vertex_energies)
    try:
        n = len(vertex_energies)
    except TypeError:
        raise InputError("vertex_energies must be a sequence of 1-D arrays") from None
    unary = [_as_float_array(e, f"vertex_energies[{v}]", 1) for v, e in enumerate(vertex_energies)]
    dims = np.array([len(u) for u in unary], dtype=np.int64)
    try:
        edge_arr = np.asarray(edges)
    except (TypeError, ValueError):
        raise InputError("edges must be a sequence of (u, v) index pairs") from None
    if edge_arr.size == 0:
        edge_arr = np.zeros((0, 2), dtype=np.int64)
    if edge_arr.ndim != 2 or edge_arr.shape[1] != 2:
        raise InputError(f"edges must have shape (m, 2), got {edge_arr.shape}")
    if edge_arr.dtype == bool or not np.issubdtype(edge_arr.dtype, np.integer):
        raise InputError(f"edges must hold integer vertex indices, got dtype {edge_arr.dtype}")
    edge_arr = edge_arr.astype(np.int64)
    if len(edge_arr) and (edge_arr.min() < 0 or edge_arr.max() >= n):
        raise InputError(f"edges: vertex indices must be in [0, {n}), got {edge_arr.min()}..{edge_arr.max()}")
    loops = np.flatnonzero(edge_arr[:, 0] == edge_arr[:, 1])
    if len(loops):
        raise InputError(f"edges[{loops[0]}] is a self-loop ({edge_arr[loops[0], 0]}); u != v is required")
    try:
        m = len(edge_energies)
    except TypeError:
        raise InputError("edge_energies must be a sequence of 2-D arrays") from None
    if m != len(edge_arr):
        raise InputError(f"edge_energies has {m} tables for {len(edge_arr)} edges")
    tables = []
    for k, ((u, v), t) in enumerate(zip(edge_arr, edge_energies, strict=True)):
        arr = _as_float_array(t, f"edge_energies[{k}]", 2)
        if arr.shape != (dims[u], dims[v]):
            raise InputError(
                f"edge_energies[{k}] must have shape (d_u, d_v) = ({dims[u]}, {dims[v]}) "
                f"for edge ({u}, {v}), got {arr.shape}"
            )
        tables.append(arr)
    return unary, dims, edge_arr, tables


def graph_energy(states, vertex_energies, edges, edge_energies) -> float:
    """Total energy ``E_G`` of a labelling (Yan et al. 2015, eq. 1).

    Parameters
    ----------
    states : array of int, shape (n,)
    vertex_energies, edges, edge_energies
        As for :func:`minimize_energy`.
    """
    states = np.asarray(states, dtype=np.int64)
    total = 0.0
    for v, e in enumerate(vertex_energies):
        total += float(np.asarray(e, dtype=np.float64)[states[v]])
    for (u, v), t in zip(edges, edge_energies, strict=True):
        total += float(np.asarray(t, dtype=np.float64)[states[u], states[v]])
    return total


def _prod(dims, scope) -> int:
    out = 1
    for x in scope:
        out *= int(dims[x])
    return out


class _Structure:
    """The graph structure of a reduction in progress (no energies).

    ``scopes[v]`` holds the scopes (frozensets of vertices) of the energy
    tables that involve ``v``; ``adj`` is the graph among the *active*
    vertices (neither eliminated nor removed by type IV). The next vertex to
    reduce by I–III is the one of degree <= 2 whose elimination builds the
    smallest table (a lazy heap keyed by table size, then vertex index), so a
    copy simulates exactly what the solver will do. Used by the solver itself
    and, copied, to plan type IV / elimination choices.
    """

    def __init__(self, dims, n: int):
        self.dims = dims
        self.scopes: dict[int, set] = {v: set() for v in range(n)}
        self.adj: dict[int, set] = {v: set() for v in range(n)}
        self.active: set[int] = set(range(n))
        self.heap: list[tuple[int, int]] = []
        self.conditioned: set[int] = set()
        # min_weight's keys, kept up to date instead of recomputed for every active
        # vertex at each call: a lazy heap of (key, v), ``keys`` the current key of
        # each vertex, and the vertices whose key may have changed since
        self.keys: dict[int, tuple] = {}
        self.key_heap: list[tuple[tuple, int]] = []
        self.dirty: set[int] = set(range(n))

    def copy(self) -> _Structure:
        new = _Structure.__new__(_Structure)
        new.dims = self.dims
        new.scopes = {v: set(s) for v, s in self.scopes.items()}
        new.adj = {v: set(s) for v, s in self.adj.items()}
        new.active = set(self.active)
        new.heap = list(self.heap)
        new.conditioned = set(self.conditioned)
        new.keys = dict(self.keys)
        new.key_heap = list(self.key_heap)
        new.dirty = set(self.dirty)
        return new

    def _touch(self, vertices) -> None:
        """``vertices`` changed their tables or neighbours: their min-weight keys and
        their neighbours' (whose fill counts their adjacency) are out of date."""
        for x in vertices:
            self.dirty.add(x)
            a = self.adj.get(x)
            if a:
                self.dirty.update(a)

    def add(self, scope: frozenset) -> None:
        """Register a table over ``scope``."""
        act = [x for x in scope if x in self.active]
        for x in scope:
            self.scopes[x].add(scope)
        for i, a in enumerate(act):
            for b in act[i + 1:]:
                self.adj[a].add(b)
                self.adj[b].add(a)
        self._touch(scope)

    def union(self, v: int) -> frozenset:
        return frozenset().union(*self.scopes[v]) if self.scopes[v] else frozenset((v,))

    def weight(self, v: int) -> int:
        return _prod(self.dims, self.union(v))

    def push(self, vertices) -> None:
        for v in vertices:
            if v in self.active and len(self.adj[v]) <= 2:
                heapq.heappush(self.heap, (self.weight(v), v))

    def pop_reducible(self) -> int | None:
        """Next vertex to reduce by I–III (degree <= 2, smallest table), or None.

        A vertex removed by type IV whose tables now span at most two other
        vertices (its part of the graph is reduced) is minimised out first:
        carrying its axis further would only multiply later tables.
        """
        for a in sorted(self.conditioned):
            if len(self.union(a)) <= 3:
                self.conditioned.discard(a)
                return a
        while self.heap:
            w, v = heapq.heappop(self.heap)
            if v not in self.active or len(self.adj[v]) > 2:
                continue
            now = self.weight(v)
            if now != w:
                heapq.heappush(self.heap, (now, v))
                continue
            return v
        return None

    def eliminate(self, v: int) -> tuple[frozenset, int]:
        """Remove ``v``; return the scope of the new table and the work (elements)."""
        old = self.scopes.pop(v)
        union = frozenset().union(*old) if old else frozenset((v,))
        work = _prod(self.dims, union)
        for s in old:
            for x in s:
                if x != v:
                    self.scopes[x].discard(s)
        self._touch(union - {v})
        nb = self._deactivate(v)
        new = union - {v}
        if new:
            self.add(new)
        self.push(sorted(nb | (new & self.active)))
        return new, work

    def condition(self, a: int) -> None:
        """Type IV: ``a`` leaves the active graph; its tables keep its axis."""
        self.conditioned.add(a)
        self.push(sorted(self._deactivate(a)))

    def _deactivate(self, v: int) -> set:
        self.active.discard(v)
        nb = self.adj.pop(v, set())
        for x in nb:
            self.adj[x].discard(v)
        self._touch(nb)
        return nb

    def min_weight(self) -> int:
        """Active vertex whose elimination makes the smallest table (then least fill).

        The least key ``(table size, fill, v)`` over the active vertices: keys are
        recomputed only for the vertices whose tables or neighbourhood changed
        since the last call, so a large graph is not rescanned at each step.
        """
        adj, keys, heap = self.adj, self.keys, self.key_heap
        for v in self.dirty:
            if v in self.active:
                nb = list(adj[v])
                fill = sum(1 for i, a in enumerate(nb) for b in nb[i + 1:] if b not in adj[a])
                k = (self.weight(v), fill, v)
                if keys.get(v) != k:
                    keys[v] = k
                    heapq.heappush(heap, (k, v))
        self.dirty.clear()
        while heap:
            k, v = heap[0]
            if v in self.active and keys.get(v) == k:
                return v
            heapq.heappop(heap)
        raise ValueError("no active vertex")  # pragma: no cover - callers check

    def ball(self, v: int, radius: int | None = None) -> set[int]:
        """Active vertices within ``radius`` edges of ``v`` (its component if None)."""
        seen, front = {v}, [v]
        for _ in itertools.count() if radius is None else range(radius):
            nxt = []
            for x in front:
                for y in self.adj[x]:
                    if y not in seen:
                        seen.add(y)
                        nxt.append(y)
            front = nxt
            if not front:
                break
        return seen

    def rollout(self, bound: float = np.inf) -> float:
        """Work (table elements) to finish the active graph (I–III, else min-weight
        elimination), then the type IV vertices; ``inf`` once above ``bound``."""
        work = 0
        while self.active:
            v = self.pop_reducible()
            if v is None:
                v = self.min_weight()
            work += self.eliminate(v)[1]
            if work > bound:
                return np.inf
        for v in sorted(self.conditioned):
            work += self.eliminate(v)[1]
        return work


class _Buffer:
    """One float64 work buffer reused by the eliminations of a solve: a fresh
    megabyte for every sum costs the kernel more (pages mapped and zeroed) than the
    additions. Dropped with its solve."""

    def __init__(self):
        self.buf = np.empty(0)

    def __call__(self, shape: tuple[int, ...]) -> np.ndarray:
        size = _prod(shape, range(len(shape))) if shape else 1
        if self.buf.size < size:
            self.buf = np.empty(size)
        return self.buf[:size].reshape(shape)


def _min_over(arrays: list[np.ndarray], axis: int, shape: tuple[int, ...], buffer: _Buffer | None = None):
    """Minimum (and argmin) over ``axis`` of the broadcast sum of ``arrays``.

    ``buffer``: where the sum is formed (the results are new arrays); default a new one.
    """
    size = int(np.prod(shape, dtype=np.int64))
    if size <= _BROADCAST_LIMIT:
        # The eliminated axis last: every element is the same sum in the same order
        # (the first two tables, then each next one added), formed in one reused
        # buffer, and the argmin runs along contiguous memory.
        out_shape = shape[:axis] + shape[axis + 1:]
        last = tuple(i for i in range(len(shape)) if i != axis) + (axis,)  # np.moveaxis(a, axis, -1)
        parts = [a.transpose(last) for a in arrays]
        if len(parts) == 1:
            total = np.ascontiguousarray(parts[0])
        else:
            # The sums formed on the broadcast shape of the tables summed so far, the
            # whole table only from the first table that needs it: a vertex energy
            # added to an edge table costs d_u x d_v additions, not d_u x d_v x d_w
            # (each element is still the same sums in the same order)
            full = np.broadcast_shapes(*(a.shape for a in parts))
            total = parts[0]
            for k, a in enumerate(parts[1:]):
                shape_k = np.broadcast_shapes(total.shape, a.shape)
                if shape_k == full:
                    out = (buffer or _Buffer())(full)
                    np.add(total, a, out=out)
                    for b in parts[k + 2:]:
                        np.add(out, b, out=out)
                    total = out
                    break
                total = total + a
        flat = np.broadcast_to(total, out_shape + (shape[axis],)).reshape(-1, shape[axis])
        arg = flat.argmin(axis=1)
        best = flat[np.arange(len(flat)), arg]
        return best.reshape(out_shape), arg.reshape(out_shape)
    # Large table: run over the eliminated vertex's states, keeping a running minimum
    # in preallocated buffers (the sums are taken in the same order as above).
    out_shape = shape[:axis] + shape[axis + 1:]
    best = np.full(out_shape, np.inf)
    arg = np.zeros(out_shape, dtype=np.int64)
    cand = np.empty(out_shape)
    better = np.empty(out_shape, dtype=bool)
    lead = (slice(None),) * axis
    for j in range(shape[axis]):
        for k, a in enumerate(arrays):
            part = a[lead + (j if a.shape[axis] > 1 else 0,)]  # a view: np.take(a, j, axis) without its copy
            if k == 0:
                np.copyto(cand, part)
            else:
                np.add(cand, part, out=cand)
        np.less(cand, best, out=better)
        np.copyto(best, cand, where=better)
        np.copyto(arg, j, where=better)
    return best, arg


class _Reducer:
    """Energy tables keyed by their (sorted) vertex scope, plus the operation log.

    A table over scope ``(x0, x1, ...)`` has one axis per vertex, in that order.
    Pairwise tables are the edges of the snake, 1-vertex tables the vertex
    energies. After a type IV operation the tables that touched a removed
    vertex keep its axis: they are the batch of conditioned sub-problems.
    """

    def __init__(self, unary, dims, edges, tables, strategy="auto"):
        self.n = len(unary)
        self.dims = dims
        self.strategy = strategy
        self.struct = _Structure(dims, self.n)
        self.tables: dict[tuple, np.ndarray] = {}
        self.ops: list = []
        self.conditioned: list[int] = []
        self.counts = {"I": 0, "II": 0, "III": 0, "IV": 0, "VE": 0}
        self.buffer = _Buffer()
        for v, u in enumerate(unary):
            self._add((v,), u)
        for (u, v), t in zip(edges, tables, strict=True):
            u, v = int(u), int(v)
            if u > v:
                u, v, t = v, u, t.T
            self._add((u, v), t)

    def _add(self, scope: tuple, table: np.ndarray) -> None:
        if scope in self.tables:
            if len(scope) >= 2:  # type II: merge parallel edges (sum their tables)
                self.counts["II"] += 1
            self.tables[scope] = self.tables[scope] + table
            return
        self.struct.add(frozenset(scope))
        self.tables[scope] = table

    def _eliminate(self, v: int, kind: str | None) -> list[int]:
        """Min out ``v`` (types I, III, isolated, or general elimination)."""
        nb = sorted(self.struct.adj.get(v, ()))
        old = [tuple(sorted(s)) for s in self.struct.scopes[v]]
        new, _ = self.struct.eliminate(v)
        union = tuple(sorted(new | {v}))
        shape = tuple(int(self.dims[x]) for x in union)
        if _prod(self.dims, new) > _MAX_TABLE:
            raise FitError(
                f"graph too dense for exact minimisation: a table over {len(new)} vertices "
                f"({_prod(self.dims, new)} entries) would be needed"
            )
        arrays = []
        for s in old:
            arr = self.tables.pop(s)
            arrays.append(arr.reshape(tuple(int(self.dims[x]) if x in s else 1 for x in union)))
        axis = union.index(v)
        best, arg = _min_over(arrays, axis, shape, self.buffer)
        scope = tuple(x for x in union if x != v)
        self.ops.append((v, scope, arg))
        if scope:
            if scope in self.tables:
                if len(scope) >= 2:  # type II: the new edge is parallel to an old one
                    self.counts["II"] += 1
                self.tables[scope] = self.tables[scope] + best
            else:
                self.tables[scope] = best
        if kind is not None:
            self.counts[kind] += 1
        return nb

    def _choose(self):
        """Pick the next move when every active vertex has degree >= 3.

        Within the connected part of the graph holding the min-weight vertex
        (or, when that part is large, within ``_PLAN_RADIUS`` edges of it,
        the rest frozen during the simulation, so planning stays cheap), the
        candidates are type IV on a pair of vertices and (unless the
        strategy is ``"paper"``) the general elimination of that vertex. Each
        is simulated on the structure and the reduction of that part finished
        with a fixed policy (I–III, else min-weight elimination); the move with
        the least total work wins, ties going to type IV.
        """
        st = self.struct
        v = st.min_weight()
        comp = st.ball(v)
        if len(comp) > _PLAN_GLOBAL:
            comp = st.ball(v, _PLAN_RADIUS)

        def restricted():
            sim = st.copy()
            sim.active = set(comp)
            return sim

        best = None
        if self.strategy != "paper":
            sim = restricted()
            w0 = sim.eliminate(v)[1]
            best = (w0 + sim.rollout(), 1, ("VE", v))
        alive = sorted(comp)
        if len(alive) <= 8:
            pairs = list(itertools.combinations(alive, 2))
        else:
            deg = {x: len(st.adj[x]) for x in alive}
            pairs = sorted(
                ((x, y) for x in alive for y in st.adj[x] if x < y and y in comp),
                key=lambda p: (-(deg[p[0]] + deg[p[1]]), p),
            )[:_MAX_PAIRS]
        for a, c in pairs:
            sim = restricted()
            sim.condition(a)
            sim.condition(c)
            score = (sim.rollout(np.inf if best is None else best[0]), 0, ("IV", a, c))
            if best is None or score[:2] < best[:2]:
                best = score
        return best[2]

    def reduce(self) -> None:
        st = self.struct
        st.push(range(self.n))
        kinds = {0: None, 1: "III", 2: "I"}
        while st.active:
            v = st.pop_reducible()
            if v is not None:
                kind = kinds[len(st.adj[v])] if v in st.active else None
                self._eliminate(v, kind)
                continue
            move = self._choose()
            if move[0] == "IV":
                _, a, c = move
                logger.debug("type IV on %d, %d (%d active)", a, c, len(st.active))
                st.condition(a)
                st.condition(c)
                self.conditioned += [a, c]
                self.counts["IV"] += 1
            else:
                _, v = move
                logger.debug("general elimination of %d (degree %d)", v, len(st.adj[v]))
                self._eliminate(v, "VE")
        # Enumerate the states of the type IV vertices: min over their joint tables.
        for a in sorted(st.scopes):
            self._eliminate(a, None)

    def backtrack(self) -> np.ndarray:
        states = np.zeros(self.n, dtype=np.int64)
        for v, scope, arg in reversed(self.ops):
            states[v] = arg[tuple(states[x] for x in scope)]
        return states


def reduction_work(dims, edges) -> float:
    """Table elements an exact solve of a graph would touch, estimated on its structure
    alone (no energy table is built): reductions I–III, else the min-weight
    elimination, as the solver's planner simulates them.

    It lets a caller skip a solve that would take too long before computing its
    energy tables; the solver's type IV choices only lower the work (each is
    taken when its simulated work is smaller). ``inf`` when a table would exceed
    the solver's limit (it would raise :class:`~lidar2city.errors.FitError`).

    Parameters
    ----------
    dims : sequence of int, shape (n,)
        States per vertex (1 for a fixed vertex).
    edges : array of int, shape (m, 2)

    Returns
    -------
    float
    """
    dims = np.asarray(dims, dtype=np.int64)
    st = _Structure(dims, len(dims))
    for v in range(len(dims)):
        st.add(frozenset((v,)))
    for u, v in np.asarray(edges, dtype=np.int64).reshape(-1, 2):
        if u != v:
            st.add(frozenset((int(u), int(v))))
    st.push(range(len(dims)))
    work = 0
    while st.active:
        v = st.pop_reducible()
        if v is None:
            v = st.min_weight()
        new, w = st.eliminate(v)
        if _prod(dims, new) > _MAX_TABLE:
            return np.inf
        work += w
    return float(work)


def minimize_energy(
    vertex_energies: Sequence,
    edges: Sequence,
    edge_energies: Sequence,
    *,
    strategy: str = "auto",
) -> SnakeSolution:
    """Global minimum of a pairwise graph energy by graph reduction.

    Parameters
    ----------
    vertex_energies : sequence of ndarray, each shape (d_v,)
        ``E_V(v, i)``: energy of vertex ``v`` in state ``i``.
    edges : sequence of (int, int), shape (m, 2)
        Vertex index pairs ``(u, v)``, ``u != v``; parallel edges are allowed.
    edge_energies : sequence of ndarray, each shape (d_u, d_v)
        ``E_E(e, i, j)`` for edge ``e = (u, v)``, indexed ``[state_u, state_v]``.
    strategy : {"auto", "paper"}
        What to do when no vertex has degree <= 2. ``"paper"``: always a
        type IV operation (the pair chosen by simulating the rest of the
        reduction). ``"auto"`` (default): type IV or, when cheaper, the general
        elimination of the vertex that makes the smallest table (min-weight
        variable elimination, beyond the paper, counted as ``"VE"``); the
        choice compares the total work of both plans simulated to the end.

    Returns
    -------
    SnakeSolution
        ``states`` (shape (n,)), ``energy`` (recomputed from the inputs) and
        ``reductions`` (counts of operations ``"I"``, ``"II"``, ``"III"``,
        ``"IV"`` and ``"VE"``).

    Raises
    ------
    InputError
        Shapes inconsistent, an index out of range, a self-loop, a
        non-finite energy, an unknown strategy.
    FitError
        The graph is so dense that an exact solution needs a table of more
        than 5e7 entries.

    Notes
    -----
    Exact on any graph (planar or not, disconnected, with parallel edges):
    every operation preserves the minimum, type IV by exhaustive (batched)
    enumeration of the removed pair's states. The cost is polynomial for
    graphs reducible by I–III (series–parallel components, i.e. trees, cycles
    and nested cycles) and grows with ``(d_a d_c)`` per nested type IV.

    References
    ----------
    Yan, J., Zhang, K., Zhang, C., Chen, S.-C., Narasimhan, G. (2015).
    Automatic construction of 3-D building model from airborne LIDAR data
    through 2-D snake algorithm. IEEE TGRS 53(1), 3–14. Eqs. 1–3 and 7–10.

    Examples
    --------
    >>> import numpy as np
    >>> sol = minimize_energy([np.array([0., 1.]), np.array([1., 0.])],
    ...                       [(0, 1)], [np.array([[0., 5.], [5., 0.]])])
    >>> sol.states.tolist(), sol.energy
    ([0, 0], 1.0)
    """
    if strategy not in ("auto", "paper"):
        raise InputError(f"strategy must be 'auto' or 'paper', got {strategy!r}")
    unary, dims, edge_arr, tables = _validate(vertex_energies, edges, edge_energies)
    reducer = _Reducer(unary, dims, edge_arr, tables, strategy=strategy)
    reducer.reduce()
    states = reducer.backtrack()
    energy = graph_energy(states, unary, edge_arr, tables)
    return SnakeSolution(states=states, energy=energy, reductions=dict(reducer.counts))
