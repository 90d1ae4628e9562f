"""manifold-sph: consistent SPH differential operators on point-cloud surfaces.

The pipeline: point cloud -> neighbourhood -> tangent frames -> local 2D
coordinates -> scheme -> sparse operator matrices -> PDEs -> renderer.

The main classes and readers are imported here; every submodule is reachable
as an attribute on first use (PEP 562), as in scipy:

>>> import manifold_sph as ms
>>> ms.pde.heat.__module__
'manifold_sph.pde'
>>> "render" in dir(ms)
True
"""

from __future__ import annotations

import importlib as _importlib

from .pointcloud import PointCloud
from .surface import Surface
from .domain import Domain2D
from .io import read, write
from .normals import estimate_normals
from .threads import get_num_threads, set_num_threads
from .exceptions import ManifoldSPHWarning

__version__ = "0.1.0"

# Public submodules loaded on attribute access (heavy ones such as render and spem
# are not imported until asked for).
_SUBMODULES = (
    "accuracy", "area", "assembly", "boundary", "cleaning", "cli", "distributed", "domain", "errors",
    "exceptions", "frames", "functions", "geometry", "io", "kernels", "neighbors", "normals",
    "operators", "pde", "plots", "pointcloud", "render", "sampling", "schemes", "shapes", "spem",
    "surface", "threads", "voronoi",
)

__all__ = ["PointCloud", "Surface", "Domain2D", "read", "write", "estimate_normals", "get_num_threads",
           "set_num_threads", "ManifoldSPHWarning", "__version__"]


def __getattr__(name: str):
    if name in _SUBMODULES:
        return _importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_SUBMODULES))
