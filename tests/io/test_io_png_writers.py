"""The PNG writers of lidar2city.io share one matplotlib entry (figures.figure_class)."""

import numpy as np
import pytest
import shapely

pytest.importorskip("matplotlib")

PNG = b"\x89PNG\r\n\x1a\n"


def test_contour_and_ga_figures_are_pngs(tmp_path):
    from lidar2city.io.contour_plots import plot_contour_evolution, plot_ga_history

    sq = np.array([[2.0, 2.0], [2.0, 8.0], [8.0, 8.0], [8.0, 2.0]])
    plot_contour_evolution(tmp_path / "c.png", np.zeros((10, 10)), [(0, sq), (5, sq + 0.5)],
                           reference=[sq])
    plot_ga_history(tmp_path / "g.png", [{"generation": g, "best_cost": 1.0 / (g + 1),
                                          "min": 1.0 / (g + 1), "mean": 2.0 / (g + 1)}
                                         for g in range(3)])
    assert (tmp_path / "c.png").read_bytes()[:8] == PNG
    assert (tmp_path / "g.png").read_bytes()[:8] == PNG


def test_outline_figure_is_a_png_and_leaves_no_pyplot_figure(tmp_path):
    import matplotlib.pyplot as plt

    from lidar2city.io.plots import plot_outlines

    before = plt.get_fignums()
    plot_outlines(tmp_path / "o.png", np.ones((20, 20)), (0, 20, 0, 20),
                  [shapely.box(2, 2, 10, 8)], ["rectangle"])
    assert (tmp_path / "o.png").read_bytes()[:8] == PNG
    assert plt.get_fignums() == before
