"""Connected components of small undirected graphs given as index pairs, in numpy.

The roof and LoD1.3 steps label a few hundred nodes at a time, hundreds of
times per tile; building a sparse matrix for
:func:`scipy.sparse.csgraph.connected_components` costs more than the labelling.
"""

from __future__ import annotations

import numpy as np

__all__ = ["component_labels"]


def component_labels(n: int, a, b) -> np.ndarray:
    """Component of every node of the undirected graph with edges ``(a[i], b[i])``.

    Components are numbered 0, 1, ... in the order of their smallest node, as
    ``scipy.sparse.csgraph.connected_components(..., directed=False)`` numbers
    them (it visits the nodes in order and starts a component at each one not
    yet reached), so the labels are the same.

    Parameters
    ----------
    n : int
        Number of nodes.
    a, b : array_like of int, shape (m,)
        Edge ends in ``[0, n)``; repeated edges and self-loops are allowed.

    Returns
    -------
    ndarray of int32, shape (n,)

    Examples
    --------
    >>> component_labels(5, [3, 1], [4, 0]).tolist()
    [0, 0, 1, 2, 2]
    """
    a = np.asarray(a, dtype=np.int64).reshape(-1)
    b = np.asarray(b, dtype=np.int64).reshape(-1)
    root = np.arange(n, dtype=np.int64)
    # every root takes the smallest root linked to its tree (hooking roots, not nodes),
    # then every node jumps to the end of its chain: trees merge whole, so the rounds
    # are few (every tree merges with another each round, so their number halves; node
    # by node, the rounds were the graph's diameter). A fixpoint holds one value per
    # component, its smallest node (that node never takes a smaller one)
    while len(a):
        ra, rb = root[a], root[b]
        m = np.minimum(ra, rb)
        new = root.copy()
        np.minimum.at(new, ra, m)
        np.minimum.at(new, rb, m)
        while True:
            jumped = new[new]
            if np.array_equal(jumped, new):
                break
            new = jumped
        if np.array_equal(new, root):
            break
        root = new
    first = np.zeros(n, dtype=bool)
    first[root] = True
    return (np.cumsum(first) - 1)[root].astype(np.int32)
