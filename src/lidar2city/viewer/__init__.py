"""A local web viewer of lidar2city models with semi-automatic editing (``lidar2city view``).

Built on viser (its three.js client ships inside the wheel: no internet needed);
install it with ``pip install lidar2city[view]``. :class:`~lidar2city.viewer.app.Viewer`
is the application; :mod:`lidar2city.viewer.scene` the pure drawing helpers;
:mod:`lidar2city.viewer.browser` a headless-chromium screenshot used by the tests
and the benchmark.
"""

__all__ = ["Viewer"]


def __getattr__(name):
    if name == "Viewer":
        from .app import Viewer

        return Viewer
    raise AttributeError(name)
