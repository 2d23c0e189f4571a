"""The analytic roof Jacobians of the primitives against finite differences."""

import numpy as np
import pytest

from lidar2city.fit.primitives import PRIMITIVES


def _numeric(cls, q, u, v, length, width, z):
    def resid(qq):
        zr, s = cls._roof(qq, u, v, length, width)
        return (z - zr) / np.sqrt(1.0 + s * s)

    J = np.empty((len(u), len(q)))
    for j in range(len(q)):
        h = 1e-6 * max(1.0, abs(q[j]))
        qp, qm = q.copy(), q.copy()
        qp[j] += h
        qm[j] -= h
        J[:, j] = (resid(qp) - resid(qm)) / (2 * h)
    return J, resid(q)


@pytest.mark.parametrize("kind,q", [("box", [7.0]), ("gable", [5.0, 2.5, 0.7]), ("gable", [5.0, 2.5, -1.1]),
                                    ("hip", [4.0, 3.0, 2.2]), ("shed", [6.0, 1.8]), ("shed", [6.0, -2.4]),
                                    ("prism_gable", [5.0, 3.0, 0.4]), ("prism_shed", [3.0, 1.5])])
def test_roof_jacobian_matches_finite_differences(kind, q):
    cls = PRIMITIVES[kind]
    rng = np.random.default_rng(3)
    length, width = 14.0, 9.0
    u = rng.uniform(-length / 2, length / 2, 400)
    v = rng.uniform(-width / 2, width / 2, 400)
    z = rng.uniform(3.0, 10.0, 400)
    q = np.asarray(q, dtype=float)
    num, r = _numeric(cls, q, u, v, length, width, z)
    ana = cls._roof_jac(q, u, v, length, width, r)
    assert ana.shape == num.shape
    # points within 1e-5 of a kink (ridge, hip line) have one-sided derivatives
    ok = np.all(np.isfinite(num), axis=1)
    np.testing.assert_allclose(ana[ok], num[ok], atol=1e-5, rtol=1e-5)


def test_polygon_jacobian_matches_finite_differences():
    from lidar2city.fit.lsm import _poly_jacobian, _poly_residuals

    rng = np.random.default_rng(5)
    verts = np.array([[0.0, 0.0], [10.0, 0.5], [11.0, 8.0], [4.0, 9.0], [-1.0, 5.0]])
    flat = verts.ravel()
    i0 = rng.integers(0, 5, 60)
    i1 = (i0 + 1) % 5
    samples = rng.uniform(-2, 12, (60, 2))
    ana = _poly_jacobian(flat, samples, i0, i1, 0.01)
    num = np.empty_like(ana)
    for j in range(flat.size):
        fp, fm = flat.copy(), flat.copy()
        fp[j] += 1e-6
        fm[j] -= 1e-6
        num[:, j] = (_poly_residuals(fp, samples, i0, i1, flat, 0.01)
                     - _poly_residuals(fm, samples, i0, i1, flat, 0.01)) / 2e-6
    np.testing.assert_allclose(ana, num, atol=1e-6)


def test_fit_limits_blas_threads_only_while_fitting():
    threadpoolctl = pytest.importorskip("threadpoolctl")
    import shapely

    from lidar2city.fit.primitives import fit_best

    seen = []

    def spy(*args, **kwargs):
        seen.append(max(i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"))
        raise AssertionError("stop")

    import scipy.optimize  # noqa: F401 - scipy's BLAS loaded before counting

    import lidar2city.fit.primitives as prim

    before = [i["num_threads"] for i in threadpoolctl.threadpool_info()]
    original = prim._check_inputs
    prim._check_inputs = spy
    try:
        with pytest.raises(AssertionError):
            fit_best(shapely.box(0, 0, 10, 8), np.zeros((10, 3)))
    finally:
        prim._check_inputs = original
    assert seen == [1]
    assert [i["num_threads"] for i in threadpoolctl.threadpool_info()] == before
