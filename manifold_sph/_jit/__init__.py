"""Compiled per-row kernels (numba) for the hot steps of the pipeline, one module per client.

numpy does these steps in several passes over the per-pair arrays (gathers,
padding, one temporary per factor), and at a few dozen pairs per particle they are
bound by memory traffic. Each function here does one step for the rows
``lo:hi`` in a single pass, keeping a particle's pairs in registers and cache:

- :func:`filter_count`, :func:`filter_fill`: the radius mask and normal filter of
  :func:`manifold_sph.neighbors.find_neighbors`;
- :func:`frames_rows`: :func:`manifold_sph.frames.tangent_frames`;
- :func:`project_rows`: :func:`manifold_sph.frames.project_neighborhood`;
- :func:`quintic_values`: :func:`manifold_sph.area.kernel_values` (quintic spline);
- :func:`cspm_rows`, :func:`msph_rows`, :func:`ncsph_rows`, :func:`moment_rows`: the
  weights of the schemes of :mod:`manifold_sph.schemes` (quintic spline), with the same
  condition-number test; a particle that fails is only flagged, and the assembly
  recomputes it (with the fallback chain) through the numpy schemes;
- :func:`voronoi_rows`: the tangent-plane Voronoi cells of :mod:`manifold_sph.voronoi`;
- :func:`csr_matvec_dot`, :func:`csr_matvec_dots2`, :func:`bicgstab_direction`,
  :func:`bicgstab_half`, :func:`bicgstab_step`: the passes of
  :func:`manifold_sph._sparse.bicgstab_csr` (the area elements' solve and the implicit
  steps), each a CSR product or vector update fused with the inner products after it.
- :func:`ssor_count`, :func:`ssor_fill`, :func:`ssor_forward`, :func:`ssor_backward`,
  :func:`ssor_upper_times`, :func:`ssor_residual`: the block-SSOR preconditioned area solve
  (:func:`manifold_sph.area.bicgstab_ssor`);

Every function releases the GIL and writes only its rows' slices, so
:func:`manifold_sph.threads.run_chunks` runs chunks on threads. Each has a numpy
twin that defines it; ``tests/test_jit.py`` compares them (to round-off).

``MANIFOLD_SPH_JIT=0`` in the environment, or ``ENABLED = False`` in this package, selects
the numpy twins everywhere (for debugging: the whole cspm build is then 1.6-2.2x
slower, ``benchmarks/perf.py``). Compiled code is cached on disk (numba
``cache=True``): the first call of each kernel on a machine compiles it (about 7 s
for all of them), later processes load it (about 0.3 s).
"""

from . import frames, kernel, krylov, neighbors, rows, ssor, voronoi
from .compile import ENABLED, from_env
from .frames import *  # noqa: F403 - the kernels under one name, as their clients call them
from .kernel import *  # noqa: F403
from .krylov import *  # noqa: F403
from .neighbors import *  # noqa: F403
from .rows import *  # noqa: F403
from .ssor import *  # noqa: F403
from .voronoi import *  # noqa: F403

__all__ = ["ENABLED", "from_env", *frames.__all__, *kernel.__all__, *krylov.__all__, *neighbors.__all__,
           *rows.__all__, *ssor.__all__, *voronoi.__all__]
