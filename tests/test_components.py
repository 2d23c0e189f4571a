"""component_labels: the labels scipy's connected_components gives, on random graphs."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from lidar2city._components import component_labels


@settings(max_examples=200, deadline=None)
@given(n=st.integers(1, 60), seed=st.integers(0, 2**32 - 1), chain=st.booleans())
def test_same_labels_as_scipy(n, seed, chain):
    rng = np.random.default_rng(seed)
    m = int(rng.integers(0, 2 * n + 1))
    a = rng.integers(0, n, m)
    b = np.minimum(a + rng.integers(0, 3, m), n - 1) if chain else rng.integers(0, n, m)
    g = coo_matrix((np.ones(m), (a, b)), shape=(n, n))
    _, expected = connected_components(g, directed=False)
    got = component_labels(n, a, b)
    assert got.dtype == expected.dtype
    np.testing.assert_array_equal(got, expected)


def test_long_chain_and_no_edges():
    n = 1000
    a = np.arange(n - 1)[::-1]  # one path, given from its far end
    np.testing.assert_array_equal(component_labels(n, a, a + 1), np.zeros(n))
    np.testing.assert_array_equal(component_labels(4, [], []), np.arange(4))
