"""``python -m manifold_sph.mpi JOB.json`` under mpirun or srun."""

import sys

from .engine import main

sys.exit(main())
