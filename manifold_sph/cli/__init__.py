"""The ``manifold-sph`` command line.

Subcommands: ``demo`` (the main job: four schemes against the exact operators
on a sphere, a short heat and wave run, pictures and a summary table),
``operators``, ``convergence``, ``heat``, ``wave``, ``poisson``, ``render``, the
geometry of a point-cloud file (``curvature``, ``geodesic``) and ``spem``.

One module per group of subcommands (:mod:`.demo`, :mod:`.studies`, :mod:`.evolve`,
:mod:`.render`, :mod:`.geometry`, :mod:`.spem`), each registering its parsers with
``add_parsers``; :mod:`.common` holds the shared options, argument types and checks;
:mod:`.app` builds the parser and runs :func:`main`.

Exit codes: 0 success, 1 failure while computing, 2 a user mistake (reported
in one line, without a traceback). With ``--json`` a failure also prints one
JSON object on stdout, ``{"error": ..., "type": ..., "command": ..., "exit_code": ...}``,
for every subcommand (argument errors included).
"""

from .app import main
from .common import FOUR_SCHEMES
from .demo import run_demo

__all__ = ["main", "run_demo", "FOUR_SCHEMES"]
