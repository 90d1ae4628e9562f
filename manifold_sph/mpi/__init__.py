"""The MPI engine of :class:`~manifold_sph.distributed.TiledSurface`'s global solves (docs/distributed.md).

``mpirun -n RANKS python -m manifold_sph.mpi JOB.json`` runs a job written by
:mod:`manifold_sph.distributed.solve`; needs the ``mpi`` extra (petsc4py, slepc4py, mpi4py).
"""

from .engine import RTOL, main, rank_tiles

__all__ = ["RTOL", "main", "rank_tiles"]
