"""The min-weight choice kept up to date incrementally picks what a full rescan picks."""

import numpy as np

from lidar2city.snake.solver import _Structure


def _rescan_min_weight(st):
    def key(v):
        nb = list(st.adj[v])
        fill = sum(1 for i, a in enumerate(nb) for b in nb[i + 1:] if b not in st.adj[a])
        return (st.weight(v), fill, v)

    return min(st.active, key=key)


def _structure(dims, edges):
    st = _Structure(np.asarray(dims), len(dims))
    for v in range(len(dims)):
        st.add(frozenset((v,)))
    for u, v in edges:
        if u != v:
            st.add(frozenset((int(u), int(v))))
    st.push(range(len(dims)))
    return st


def test_every_choice_is_the_rescans_choice_through_eliminations_and_type_iv():
    rng = np.random.default_rng(7)
    for _ in range(60):
        n = int(rng.integers(4, 40))
        edges = rng.integers(0, n, size=(int(rng.integers(n, 4 * n)), 2))
        st = _structure(rng.integers(1, 5, size=n), edges)
        step = 0
        while st.active:
            want = _rescan_min_weight(st)
            assert st.min_weight() == want
            if step % 5 == 4 and len(st.active) > 2:
                st.condition(want)  # a type IV removal changes the graph another way
            else:
                st.eliminate(want)
            # a copy restricted to part of the graph (the solver's planning) agrees too
            if st.active and step % 3 == 0:
                sim = st.copy()
                sim.active = set(sorted(st.active)[: max(1, len(st.active) // 2)])
                assert sim.min_weight() == _rescan_min_weight(sim)
            step += 1

