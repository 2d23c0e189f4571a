import numpy as np
import pytest
from shapely.geometry import box

from lidar2city.lod.mesh import solid_triangles
from lidar2city.lod.prism import prism_solid
from lidar2city.metrics.model import (
    footprint_coverage,
    model_rmse,
    point_mesh_distance,
    point_triangle_distance2,
)

TRI = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], dtype=float)


@pytest.mark.parametrize("p, d", [
    ([0.2, 0.2, 2.0], 2.0),        # above the inside: plane distance
    ([2.0, 0.0, 0.0], 1.0),        # beyond a vertex
    ([0.5, -1.0, 0.0], 1.0),       # beside an edge
    ([1.0, 1.0, 0.0], np.sqrt(0.5)),  # beyond the hypotenuse
    ([0.0, 0.0, -3.0], 3.0),
])
def test_point_triangle_exact(p, d):
    assert point_mesh_distance(np.array([p]), TRI)[0] == pytest.approx(d)


def test_box_rmse_of_roof_points_is_zero_and_of_lifted_points_is_the_lift():
    s = prism_solid(box(0, 0, 10, 5), 0.0, 4.0)
    rng = np.random.default_rng(0)
    roof = np.column_stack([rng.uniform(1, 9, 500), rng.uniform(1, 4, 500), np.full(500, 4.0)])
    assert model_rmse(roof, [s]) == pytest.approx(0.0, abs=1e-12)
    assert model_rmse(roof + [0, 0, 0.3], [s]) == pytest.approx(0.3)
    # inside the block, 0.5 m below the roof and 2 m from the walls: nearest face is the roof
    assert model_rmse(roof[(roof[:, 1] > 2) & (roof[:, 1] < 3) & (roof[:, 0] > 3) & (roof[:, 0] < 7)]
                      - [0, 0, 0.5], [s]) == pytest.approx(0.5)


def test_grid_prefilter_equals_brute_force():
    rng = np.random.default_rng(3)
    n = 30
    x, y = np.meshgrid(np.arange(n + 1.0), np.arange(n + 1.0))
    v = np.stack([x, y, np.sin(x / 4) * 2], -1)
    a, b, c, d = v[:-1, :-1].reshape(-1, 3), v[:-1, 1:].reshape(-1, 3), v[1:, 1:].reshape(-1, 3), v[1:, :-1].reshape(-1, 3)
    tris = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    pts = np.column_stack([rng.uniform(-5, 35, 800), rng.uniform(-5, 35, 800), rng.normal(0, 3, 800)])
    pts[:50, 2] += 40  # far points take the fallback
    fast = point_mesh_distance(pts, tris, brute_force_pairs=0)
    slow = point_mesh_distance(pts, tris, brute_force_pairs=10**12)
    assert np.allclose(fast, slow, atol=1e-12)


def test_rowwise_and_broadcast_agree():
    rng = np.random.default_rng(1)
    p, a, b, c = (rng.normal(size=(50, 3)) for _ in range(4))
    rows = point_triangle_distance2(p, a, b, c)
    full = point_triangle_distance2(p[:, None], a[None], b[None], c[None])
    assert np.allclose(rows, np.diag(full))


def test_coverage():
    fp = box(0, 0, 10, 10)
    xy = np.column_stack([np.repeat(np.arange(5) + 0.5, 10), np.tile(np.arange(10) + 0.5, 5)])
    assert footprint_coverage(fp, xy, cell=1.0) == pytest.approx(0.5)
    assert footprint_coverage(fp, np.zeros((0, 2))) == 0.0


def test_solid_triangles_cover_the_surface():
    s = prism_solid(box(0, 0, 2, 3), 0.0, 1.0)
    t = solid_triangles(s)
    area = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum()
    assert area == pytest.approx(2 * 6 + 10 * 1)
