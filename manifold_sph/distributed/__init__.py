"""Tiled, out-of-core builds on Dask and global solves on MPI (docs/distributed.md).

- :mod:`~manifold_sph.distributed.tiling`: cutting the cloud into tiles;
- :mod:`~manifold_sph.distributed.tiles`: one tile's build and its files (on a worker);
- :mod:`~manifold_sph.distributed.surface`: :class:`TiledSurface`, the driver;
- :mod:`~manifold_sph.distributed.solve`: global solves (PETSc/SLEPc on MPI ranks, or one process).
"""

from .surface import LOCAL_AREAS, SCHEDULERS, SURFACE_OPTIONS, TileBuildError, TiledSurface
from .tiles import KEEP, TileDamagedError

__all__ = ["KEEP", "LOCAL_AREAS", "SCHEDULERS", "SURFACE_OPTIONS", "TileBuildError", "TileDamagedError", "TiledSurface"]
