"""The 2-D snake: exact energy minimisation on (planar) graphs by graph reduction.

:func:`minimize_energy` solves ``min_s sum_v E_V(v, s_v) + sum_e E_E(e, s_u, s_v)``
exactly with the reductions of Yan et al. (2015); :mod:`.energies` builds the
candidate positions and the direction / deviation energies (eqs. 4–6) of a
building topology snake.
"""

from .solver import SnakeSolution, graph_energy, minimize_energy

__all__ = ["SnakeSolution", "graph_energy", "minimize_energy"]
