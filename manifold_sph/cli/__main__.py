"""``python -m manifold_sph.cli``: the ``manifold-sph`` command."""

import sys

from .app import main

sys.exit(main())
