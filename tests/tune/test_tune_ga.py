import random

import numpy as np
import pytest

from lidar2city.errors import InputError
from lidar2city.tune.ga import converged_share, genetic_minimize

OPTIMUM = np.array([0.4, 2.2, 1.5, 0.1, 2.8])


def toy_cost(w):
    """A smooth bowl with its minimum (cost 0.01) at OPTIMUM."""
    return 0.01 + float(np.sum((np.asarray(w) - OPTIMUM) ** 2))


def test_known_optimum_found():
    res = genetic_minimize(toy_cost, 5, population=40, generations=60, seed=3)
    assert np.abs(res.best - OPTIMUM).max() < 0.15
    assert res.best_cost < 0.01 + 0.03
    best = [r["best_cost"] for r in res.history]
    assert best == sorted(best, reverse=True)  # elitism: never worse
    assert res.history[0]["generation"] == 0


def test_fixed_seed_reproduces_and_leaves_global_random_alone():
    random.seed(123)
    state = random.getstate()
    a = genetic_minimize(toy_cost, 5, population=12, generations=5, seed=7)
    assert random.getstate() == state
    b = genetic_minimize(toy_cost, 5, population=12, generations=5, seed=7)
    c = genetic_minimize(toy_cost, 5, population=12, generations=5, seed=8)
    assert np.array_equal(a.best, b.best) and a.history == b.history
    assert not np.array_equal(a.best, c.best)


def test_jobs_do_not_change_the_result():
    a = genetic_minimize(toy_cost, 5, population=8, generations=2, seed=11, n_jobs=1)
    b = genetic_minimize(toy_cost, 5, population=8, generations=2, seed=11, n_jobs=2)
    assert np.array_equal(a.best, b.best)
    assert a.history == b.history


def test_stops_when_population_converged():
    res = genetic_minimize(lambda w: 1.0, 2, bounds=(0.0, 1e-4), population=10, generations=50, same_tol=1e-3,
                           seed=0)
    assert res.stopped == "converged"
    assert len(res.history) == 1


def test_converged_share():
    pop = np.zeros((20, 5))
    pop[19] += 1.0
    assert converged_share(pop, tol=0.01) == pytest.approx(0.95)
    assert converged_share(pop, tol=2.0) == 1.0


@pytest.mark.parametrize("kwargs", [{"cxpb": 0.5}, {"mutpb": 0.2}, {"population": 2},
                                    {"bounds": (1, 1)}, {"n_jobs": 0}])
def test_bad_parameters(kwargs):
    with pytest.raises(InputError):
        genetic_minimize(toy_cost, 5, **kwargs)


def test_callback_gets_every_generation():
    seen = []
    genetic_minimize(toy_cost, 5, population=6, generations=3, seed=1, callback=seen.append)
    assert [r["generation"] for r in seen] == [0, 1, 2, 3]


def test_seeded_chromosome_bounds_the_result():
    # the optimum itself in the first generation: elitism keeps it
    res = genetic_minimize(toy_cost, 5, population=6, generations=2, seed=5, initial=[OPTIMUM])
    assert res.best_cost == pytest.approx(0.01)
    with pytest.raises(InputError):
        genetic_minimize(toy_cost, 5, population=6, generations=1, seed=5, initial=[[1.0, 2.0]])


def test_tune_weights_on_a_synthetic_dsm_is_reproducible_across_jobs():
    from lidar2city.tune.ga import tune_weights

    rng = np.random.default_rng(0)
    dsm = rng.normal(0.0, 0.1, (50, 50))
    ref = np.zeros((50, 50), bool)
    for r0, r1, c0, c1 in [(5, 15, 5, 20), (25, 45, 20, 32)]:
        dsm[r0:r1, c0:c1] += 7.0
        ref[r0:r1, c0:c1] = True
    a = tune_weights(dsm, dsm, ref, cell=1.0, population=4, generations=1, seed=2, n_jobs=1)
    b = tune_weights(dsm, dsm, ref, cell=1.0, population=4, generations=1, seed=2, n_jobs=2)
    assert a == b
    weights, history = a
    assert set(weights) == {"alpha", "beta", "gamma", "mu", "epsilon", "anchor"}
    assert history[-1]["best_cost"] < 0.05
    with pytest.raises(InputError):
        tune_weights(dsm, dsm, ref[:10], cell=1.0)
    with pytest.raises(InputError):
        tune_weights(dsm, dsm, ref, cell=1.0, objective="iou")


def test_log_scale_genes_and_validation():
    from lidar2city.contour.outlines import LOG_WEIGHT_BOUNDS
    from lidar2city.tune.ga import genes_to_weights, tune_weights

    assert genes_to_weights([-2, 0, 1], "log") == [0.01, 1.0, 10.0]
    assert genes_to_weights([0.5, 2.0], "linear") == [0.5, 2.0]
    assert LOG_WEIGHT_BOUNDS == (-2.0, 1.0)
    dsm = np.zeros((30, 30))
    dsm[8:22, 8:22] = 6.0
    ref = dsm > 3
    with pytest.raises(InputError, match="scale"):
        tune_weights(dsm, dsm, ref, cell=1.0, scale="cubic")
    w, hist = tune_weights(dsm, dsm, ref, cell=1.0, population=4, generations=1, seed=1,
                           scale="log")
    assert all(0.01 - 1e-12 <= v <= 10 + 1e-9 for v in w.values())
    assert w == tune_weights(dsm, dsm, ref, cell=1.0, population=4, generations=1, seed=1,
                             scale="log")[0]


def test_first_generation_holds_the_configured_and_the_keep_the_start_weights(monkeypatch):
    import lidar2city.tune.ga as ga
    from lidar2city.contour.outlines import LOG_WEIGHT_BOUNDS, WEIGHT_NAMES, ActiveContourConfig

    seen = {}

    def fake(fitness, n_genes, *, initial, bounds, **kw):
        seen["initial"], seen["bounds"] = initial, bounds
        return ga.GAResult(np.asarray(initial[1], float), 0.0, [{"best_cost": 0.0}])

    monkeypatch.setattr(ga, "genetic_minimize", fake)
    dsm = np.zeros((30, 30))
    dsm[8:22, 8:22] = 6.0
    cfg = ActiveContourConfig().with_weights({"alpha": 0.1, "beta": 1.0, "gamma": 1.0,
                                              "mu": 10.0, "epsilon": 1.0, "anchor": 1.0})
    w, _ = ga.tune_weights(dsm, dsm, dsm > 3, cell=1.0, config=cfg, scale="log")
    lo, hi = LOG_WEIGHT_BOUNDS
    assert seen["initial"][0] == pytest.approx([-1.0, 0.0, 0.0, 1.0, 0.0, 0.0])
    hold = seen["initial"][1]
    assert hold == [hi if k == "anchor" else lo for k in WEIGHT_NAMES]
    assert w["anchor"] == pytest.approx(10.0) and w["mu"] == pytest.approx(0.01)
