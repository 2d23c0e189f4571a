"""Parameter tuning: a genetic algorithm for the active-contour weights (DEAP, optional extra ``tune``)."""

from .ga import GAResult, converged_share, genetic_minimize, tune_weights, weights_cost

__all__ = ["GAResult", "converged_share", "genetic_minimize", "tune_weights", "weights_cost"]
