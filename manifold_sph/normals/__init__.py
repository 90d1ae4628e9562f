"""Normals for clouds that have none: fitted, oriented consistently and outward.

:func:`estimate_normals` is the entry point (``Surface`` calls it for a cloud without
normals). The steps live in modules named after their concept:

- :mod:`.fitting`: PCA and jet (local polynomial) fits, the feature-aware refit;
- :mod:`.rows`: fits that took a row of a line-sampled cloud for the surface;
- :mod:`.scale`, :mod:`.consensus`: agreement across neighbourhood sizes, and the choice of
  undetermined directions among candidate fits;
- :mod:`.graph`, :mod:`.orientation`: consistent orientation over the spanning forest, then
  the outward check with the generalised winding number (:mod:`.winding`);
- :mod:`.patches`: the global orientation of noisy clouds (patch signs chosen for the whole cloud);
- :mod:`.shells`: closed surfaces that pass through each other, and closed parts turned outward
  by their own field (the sheets of parts that touch or cross);
- :mod:`.visibility`, :mod:`.poles`: optional sign checks (``orient="visible"``, ``poles=True``);
- :mod:`.confidence`: the per-particle confidence;
- :mod:`.arrays`: distinct integer keys by one sort;
- :mod:`.tuning`: every tuning constant, in one place.

The method and its measurements are in ``docs/normals.md``.
"""

from __future__ import annotations

from .estimate import estimate_normals
from .fitting import jet_normals, pca_normals
from .orientation import orient_normals
from .poles import voronoi_poles
from .tuning import DEFAULT_JET_K, DEFAULT_K, METHODS, ORIENTATIONS

__all__ = [
    "DEFAULT_JET_K",
    "DEFAULT_K",
    "METHODS",
    "ORIENTATIONS",
    "estimate_normals",
    "jet_normals",
    "orient_normals",
    "pca_normals",
    "voronoi_poles",
]
