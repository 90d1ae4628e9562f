"""manifold-sph: consistent SPH differential operators on point-cloud surfaces.

The pipeline: point cloud -> neighbourhood -> tangent frames -> local 2D
coordinates -> scheme -> sparse operator matrices -> PDEs -> renderer.

The main classes and readers are imported here; every submodule is reachable
as an attribute on first use (PEP 562), as in scipy:

>>> import manifold_sph as ms
>>> ms.pde.heat.__module__
'manifold_sph.pde.time_stepping'
>>> ms.reference.shapes.sphere(100).geometry.name
'sphere'
>>> "viz" in dir(ms)
True
"""

from __future__ import annotations

import importlib as _importlib

from .domain import Domain2D
from .exceptions import ManifoldSPHWarning
from .normals import estimate_normals
from .pointcloud import PointCloud, as_cloud
from .scans.io import read, write
from .surface import Surface
from .threads import get_num_threads, set_num_threads

__version__ = "0.2.0"

# Public submodules loaded on attribute access (heavy ones such as viz and spem are not
# imported until asked for). The flat core follows the pipeline; scans, reference and viz
# group the periphery.
_SUBMODULES = (
    "area", "assembly", "cli", "distributed", "domain", "exceptions", "frames", "geometry", "kernels",
    "neighbors", "normals", "operators", "pde", "pointcloud", "results", "schemes", "spem", "surface", "threads", "voronoi",
    "scans", "reference", "viz",
)


__all__ = ["PointCloud", "as_cloud", "Surface", "Domain2D", "read", "write", "estimate_normals", "get_num_threads",
           "set_num_threads", "ManifoldSPHWarning", "__version__"]


def __getattr__(name: str):
    if name in _SUBMODULES:
        return _importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_SUBMODULES))
