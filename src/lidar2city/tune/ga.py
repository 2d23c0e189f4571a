"""A continuous genetic algorithm (DEAP) for the active-contour weights.

Selection by roulette on ``1 / cost`` (probability inversely proportional to
the cost), blend crossover, bounded Gaussian mutation, elitism; stops when 95 %
of the chromosomes are the same (within a tolerance) or after ``generations``.
DEAP provides the individuals, fitness, toolbox and logbook; the operators are
our own so that every random draw comes from one private ``random.Random(seed)``
(DEAP's operators use the global ``random`` module, which we never touch).
Fitness evaluations run in parallel processes and do not depend on the
number of processes.
"""

from __future__ import annotations

import logging
import random
from dataclasses import dataclass, field

import numpy as np

from ..errors import DependencyError, InputError

logger = logging.getLogger(__name__)

__all__ = ["GAResult", "OBJECTIVES", "SCALES", "genetic_minimize", "converged_share",
           "genes_to_weights", "tune_weights", "weights_cost"]


def _deap():
    try:
        from deap import base, tools
    except ImportError:  # pragma: no cover - depends on the environment
        raise DependencyError(
            "the genetic algorithm needs DEAP: pip install lidar2city[tune]") from None
    return base, tools


@dataclass
class GAResult:
    """Outcome of :func:`genetic_minimize`.

    Attributes
    ----------
    best : ndarray, shape (D,)
        Best chromosome found.
    best_cost : float
    history : list of dict
        Per generation: ``generation``, ``best_cost`` (best so far), ``min``,
        ``mean``, ``max`` cost of the population, ``same`` (share of chromosomes
        equal to the most common one), ``evaluations`` (cumulative).
    stopped : str
        ``"converged"`` (95 % rule) or ``"generations"``.
    """

    best: np.ndarray
    best_cost: float
    history: list = field(default_factory=list)
    stopped: str = "generations"


def converged_share(population, *, tol) -> float:
    """Largest share of chromosomes within ``tol`` (every gene) of one chromosome.

    Two chromosomes are "the same" when no gene differs by more than ``tol``.
    """
    pop = np.asarray(population, dtype=np.float64)
    if len(pop) == 0:
        return 0.0
    close = (np.abs(pop[:, None, :] - pop[None, :, :]) <= tol).all(axis=2)
    return float(close.sum(axis=1).max()) / len(pop)


def _roulette(rnd, population, k, costs):
    """Select ``k`` individuals with probability proportional to ``1 / cost``."""
    c = np.asarray(costs, dtype=np.float64)
    floor = max(float(c[c > 0].min()) * 1e-3, 1e-12) if (c > 0).any() else 1e-12
    w = 1.0 / np.maximum(c, floor)
    cum = np.cumsum(w)
    total = cum[-1]
    picks = [int(np.searchsorted(cum, rnd.random() * total, side="right")) for _ in range(k)]
    return [population[min(i, len(population) - 1)] for i in picks]


def _blend(rnd, a, b, alpha, lo, hi):
    """BLX-alpha crossover in place, clipped to the bounds."""
    for i in range(len(a)):
        g = (1.0 + 2.0 * alpha) * rnd.random() - alpha
        x, y = a[i], b[i]
        a[i] = min(max((1.0 - g) * x + g * y, lo), hi)
        b[i] = min(max(g * x + (1.0 - g) * y, lo), hi)


def _mutate(rnd, ind, indpb, sigma, lo, hi):
    """Gaussian mutation of each gene with probability ``indpb``, clipped to the bounds."""
    for i in range(len(ind)):
        if rnd.random() < indpb:
            ind[i] = min(max(ind[i] + rnd.gauss(0.0, sigma), lo), hi)


def _evaluate(fitness, chromosomes, executor):
    if executor is None:
        return [float(fitness(list(c))) for c in chromosomes]
    return [float(v) for v in executor.map(fitness, [list(c) for c in chromosomes])]


def genetic_minimize(fitness, n_genes, *, bounds=(0.0, 3.0), population=30, generations=20,
                     cxpb=0.8, mutpb=0.04, blend_alpha=0.3, sigma=None, elite=1,
                     same_share=0.95, same_tol=None, seed=None, n_jobs=1, initial=None,
                     initializer=None, initargs=(), callback=None) -> GAResult:
    """Minimise ``fitness`` over a box with a continuous genetic algorithm.

    Parameters
    ----------
    fitness : callable
        ``fitness(list of float) -> cost >= 0``; picklable (a module-level
        function) when ``n_jobs > 1``.
    n_genes : int
    bounds : (float, float)
        Every gene's range.
    population : int
        Chromosomes per generation (>= 4).
    generations : int
        Maximum number of generations after the initial one.
    cxpb : float in [0.6, 1]
        Probability that a pair of parents is crossed (blend crossover).
    mutpb : float in [0.01, 0.06]
        Per-gene mutation probability (Gaussian, ``sigma`` default 10 % of the range).
    blend_alpha : float
        BLX-alpha extension of the blend crossover.
    elite : int
        Best chromosomes copied unchanged into the next generation.
    same_share, same_tol : float
        Stop when ``same_share`` of the chromosomes are within ``same_tol``
        (default 1 % of the range) of one chromosome (:func:`converged_share`).
    seed : int, optional
        Seeds a private ``random.Random``; the global ``random`` state is
        neither used nor changed. ``None`` draws a seed from the OS.
    n_jobs : int
        Processes evaluating fitness (1: in this process). Results do not
        depend on it.
    initial : sequence of sequences, optional
        Chromosomes placed in the first generation (e.g. the current
        defaults, so that with elitism the result is never worse than them);
        the rest is drawn uniformly.
    initializer, initargs
        Run once in every worker process (e.g. to load a shared scene).
    callback : callable, optional
        ``callback(record)`` after every generation with its history record.

    Returns
    -------
    GAResult

    References
    ----------
    Eshelman, L. J., Schaffer, J. D. (1993). Real-coded genetic algorithms and
    interval-schemata (BLX-alpha). Foundations of Genetic Algorithms 2.
    Fortin, F.-A. et al. (2012). DEAP: evolutionary algorithms made easy. JMLR 13.
    """
    base, tools = _deap()
    lo, hi = (float(b) for b in bounds)
    if not hi > lo:
        raise InputError(f"bounds must be (low, high) with high > low, got {bounds}")
    if population < 4:
        raise InputError(f"population must be >= 4, got {population}")
    if generations < 0:
        raise InputError(f"generations must be >= 0, got {generations}")
    if not 0.6 <= cxpb <= 1.0:
        raise InputError(f"cxpb (crossover probability) must be in [0.6, 1], got {cxpb}")
    if not 0.01 <= mutpb <= 0.06:
        raise InputError(f"mutpb (mutation probability) must be in [0.01, 0.06], got {mutpb}")
    if not 0 <= elite < population:
        raise InputError(f"elite must be in [0, population), got {elite}")
    if n_jobs < 1:
        raise InputError(f"n_jobs must be >= 1, got {n_jobs}")
    sigma = 0.1 * (hi - lo) if sigma is None else float(sigma)
    same_tol = 0.01 * (hi - lo) if same_tol is None else float(same_tol)
    rnd = random.Random(seed if seed is not None else random.SystemRandom().randrange(2 ** 32))

    class _Fitness(base.Fitness):
        weights = (-1.0,)

    class _Individual(list):
        def __init__(self, *args):
            super().__init__(*args)
            self.fitness = _Fitness()

    toolbox = base.Toolbox()
    toolbox.register("individual", lambda: _Individual(rnd.uniform(lo, hi) for _ in range(n_genes)))
    toolbox.register("select", _roulette, rnd)
    toolbox.register("mate", _blend, rnd, alpha=blend_alpha, lo=lo, hi=hi)
    toolbox.register("mutate", _mutate, rnd, indpb=mutpb, sigma=sigma, lo=lo, hi=hi)
    hof = tools.HallOfFame(1)
    logbook = tools.Logbook()
    evaluations = 0

    executor = None
    if n_jobs > 1:
        from concurrent.futures import ProcessPoolExecutor

        executor = ProcessPoolExecutor(max_workers=n_jobs, initializer=initializer,
                                       initargs=tuple(initargs))
    elif initializer is not None:
        initializer(*initargs)

    def evaluate(inds):
        nonlocal evaluations
        todo = [ind for ind in inds if not ind.fitness.valid]
        for ind, cost in zip(todo, _evaluate(fitness, todo, executor), strict=True):
            ind.fitness.values = (cost,)
        evaluations += len(todo)

    def record(gen, pop):
        costs = np.array([ind.fitness.values[0] for ind in pop])
        hof.update(pop)
        rec = {"generation": gen, "best_cost": float(hof[0].fitness.values[0]),
               "min": float(costs.min()), "mean": float(costs.mean()), "max": float(costs.max()),
               "same": converged_share(pop, tol=same_tol), "evaluations": evaluations}
        logbook.record(**rec)
        logger.info("generation %d: best cost %.5f (population min %.5f, mean %.5f), %.0f %% same",
                    gen, rec["best_cost"], rec["min"], rec["mean"], 100 * rec["same"])
        if callback is not None:
            callback(rec)
        return rec

    try:
        pop = [toolbox.individual() for _ in range(population)]
        for i, chrom in enumerate(list(initial or [])[:population]):
            if len(chrom) != n_genes:
                raise InputError(f"initial chromosome {i} has {len(chrom)} genes, expected {n_genes}")
            pop[i][:] = [min(max(float(g), lo), hi) for g in chrom]
        evaluate(pop)
        rec = record(0, pop)
        stopped = "generations"
        for gen in range(1, generations + 1):
            if rec["same"] >= same_share:
                stopped = "converged"
                break
            elites = [toolbox.clone(ind) for ind in tools.selBest(pop, elite)] if elite else []
            costs = [ind.fitness.values[0] for ind in pop]
            offspring = [toolbox.clone(ind) for ind in toolbox.select(pop, population - elite, costs)]
            for a, b in zip(offspring[::2], offspring[1::2], strict=False):
                if rnd.random() < cxpb:
                    toolbox.mate(a, b)
                    del a.fitness.values, b.fitness.values
            for ind in offspring:
                before = list(ind)
                toolbox.mutate(ind)
                if list(ind) != before and ind.fitness.valid:
                    del ind.fitness.values
            pop = elites + offspring
            evaluate(pop)
            rec = record(gen, pop)
        else:
            if rec["same"] >= same_share:
                stopped = "converged"
    finally:
        if executor is not None:
            executor.shutdown()
    best = hof[0]
    return GAResult(np.array(best, dtype=np.float64), float(best.fitness.values[0]),
                    list(logbook), stopped)


# ----------------------------------------------------------------------------
# Active-contour weights

_SCENE = {}


#: Fitness choices: eq. 4's share of wrong pixels, or one minus Cohen's kappa.
OBJECTIVES = ("cost", "kappa")
#: Gene scales: ``"log"`` searches log10 of the weights (:data:`LOG_WEIGHT_BOUNDS`),
#: ``"linear"`` the weights themselves (:data:`~lidar2city.contour.outlines.WEIGHT_BOUNDS`).
SCALES = ("log", "linear")


def genes_to_weights(genes, scale="log") -> list:
    """The five weights of a chromosome: ``10 ** g`` on the log scale, ``g`` otherwise."""
    g = [float(v) for v in genes]
    return [10.0 ** v for v in g] if scale == "log" else g


def _init_worker(scene, frame, reference, domain, config, objective="cost", scale="linear"):
    _SCENE.update(scene=scene, frame=frame, reference=reference, domain=domain, config=config,
                  objective=objective, scale=scale)


def weights_cost(weights) -> float:
    """Fitness of one chromosome on the scene loaded by ``_init_worker``.

    The genes are the weights, or their log10 when the worker was loaded with
    ``scale="log"``. ``(FP + FN) / N`` over the domain (objective ``"cost"``),
    or ``1 - kappa``.
    """
    from ..contour.outlines import contours_to_polygons, run_scene
    from ..contour.raster import rasterize_polygons

    s = _SCENE
    cfg = s["config"]
    contours = run_scene(s["scene"], genes_to_weights(weights, s.get("scale", "linear")), config=cfg)
    polys = contours_to_polygons(contours, s["frame"], simplify=cfg.simplify)
    pred = rasterize_polygons(polys, s["reference"].shape, s["frame"])
    dom = s["domain"]
    ref = s["reference"]
    if s.get("objective", "cost") == "kappa":
        from ..metrics.footprints import pixel_metrics

        return 1.0 - float(pixel_metrics(pred[dom], ref[dom])["kappa"])
    return float(np.count_nonzero(pred[dom] != ref[dom])) / max(int(dom.sum()), 1)


#: Farther than this (m) from the scored pixels, a contour cannot change the cost.
_SNAKE_REACH = 10.0


def _near_domain(scene, domain, *, margin):
    """The scene with only the contours whose bounding box, grown by ``margin``
    pixels, holds a pixel of ``domain``: the others cannot change the cost,
    and the fitness runs once per chromosome."""
    import dataclasses

    integral = np.pad(np.cumsum(np.cumsum(domain, axis=0), axis=1), ((1, 0), (1, 0)))
    h, w = domain.shape
    keep = []
    for c in scene.contours:
        r0, c0 = np.clip(np.floor(c.min(axis=0)).astype(int) - margin, 0, [h, w])
        r1, c1 = np.clip(np.ceil(c.max(axis=0)).astype(int) + margin + 1, 0, [h, w])
        if integral[r1, c1] - integral[r0, c1] - integral[r1, c0] + integral[r0, c0] > 0:
            keep.append(c)
    return dataclasses.replace(scene, contours=keep)


def tune_weights(dsm, ndsm, reference_mask, *, ortho=None, cell=1.0, domain=None, config=None,
                 population=30, generations=15, seed=None, n_jobs=1, cxpb=0.8, mutpb=0.04,
                 objective="cost", scale="log", callback=None):
    """Learn the active-contour weights from reference buildings.

    The cost of a weight vector is the share of wrongly classified pixels,
    ``(FP + FN) / N``, of the rasterised snake outlines against
    ``reference_mask`` over ``domain`` (eq. 4 of the method's paper).
    The first generation holds the configured weights and the weights that
    keep the initial contours (the anchor at its upper bound, the other
    energies at their lower one): where the snake cannot improve on a good
    start (roof regions on a 0.5 m DSM), the search starts from the start.

    Parameters
    ----------
    dsm, ndsm : ndarray, shape (H, W)
    reference_mask : ndarray of bool, shape (H, W)
        Reference building pixels.
    ortho : ndarray, optional
        Orthoimage on the DSM grid.
    cell : float
        Pixel size (m).
    domain : ndarray of bool, shape (H, W), optional
        Pixels scored (default: all); see
        :func:`lidar2city.contour.raster.evaluation_domain`.
    config : ActiveContourConfig, optional
        Everything but the weights.
    objective : {"cost", "kappa"}
        ``"cost"``: (FP + FN) / N (eq. 4). ``"kappa"``: 1 - Cohen's kappa, which
        does not reward erasing buildings where false positives abound.
    scale : {"log", "linear"}
        Genes are log10 of the weights in :data:`LOG_WEIGHT_BOUNDS` (0.01 to
        10: a weight matters by its order of magnitude relative to the
        others, and the blend crossover and mutation then move it by factors,
        not by steps that swamp small weights), or the weights themselves in
        :data:`WEIGHT_BOUNDS`.
    population, generations, seed, n_jobs, cxpb, mutpb, callback
        See :func:`genetic_minimize`.

    Returns
    -------
    weights : dict
        ``{alpha, beta, gamma, mu, epsilon, anchor}`` of the best chromosome.
    history : list of dict
        Per generation records (see :class:`GAResult`), ``best_cost`` included.
    """
    from ..contour.outlines import (
        LOG_WEIGHT_BOUNDS,
        WEIGHT_BOUNDS,
        WEIGHT_NAMES,
        ActiveContourConfig,
        prepare_scene,
    )
    from ..contour.raster import PixelFrame

    if objective not in OBJECTIVES:
        raise InputError(f"objective must be one of {', '.join(OBJECTIVES)}, got {objective!r}")
    if scale not in SCALES:
        raise InputError(f"scale must be one of {', '.join(SCALES)}, got {scale!r}")
    cfg = config or ActiveContourConfig()
    ref = np.asarray(reference_mask, dtype=bool)
    if ref.shape != np.shape(dsm):
        raise InputError(f"reference mask {ref.shape} and DSM {np.shape(dsm)} differ in shape")
    dom = np.ones_like(ref) if domain is None else np.asarray(domain, dtype=bool)
    if dom.shape != ref.shape:
        raise InputError("domain and reference differ in shape")
    if not (ref & dom).any():
        raise InputError("no reference building pixel inside the scoring domain")
    scene = _near_domain(prepare_scene(dsm, ndsm, ortho=ortho, cell=cell, config=cfg), dom,
                         margin=int(np.ceil(_SNAKE_REACH / cell)))
    frame = PixelFrame(cell=cell)
    bounds = LOG_WEIGHT_BOUNDS if scale == "log" else WEIGHT_BOUNDS
    start = np.array([getattr(cfg, k) for k in WEIGHT_NAMES], dtype=float)
    if scale == "log":
        start = np.log10(np.maximum(start, 10.0 ** bounds[0]))
    start = np.clip(start, *bounds).tolist()
    # the second chromosome keeps the initial contours: the anchor at its largest
    # weight, every other energy at its smallest
    hold = [bounds[1] if k == "anchor" else bounds[0] for k in WEIGHT_NAMES]
    result = genetic_minimize(
        weights_cost, len(WEIGHT_NAMES), bounds=bounds, population=population,
        generations=generations, cxpb=cxpb, mutpb=mutpb, seed=seed, n_jobs=n_jobs,
        initial=[start, hold], initializer=_init_worker,
        initargs=(scene, frame, ref, dom, cfg, objective, scale), callback=callback)
    weights = {k: float(v) for k, v in
               zip(WEIGHT_NAMES, genes_to_weights(result.best, scale), strict=True)}
    # (the configured weights and the hold-the-start ones are in the first generation: with
    # elitism the tuned weights are never worse than either on these pixels)
    logger.info("tuned weights %s: cost %.5f (%s)", weights, result.best_cost, result.stopped)
    return weights, result.history
