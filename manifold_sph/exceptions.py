"""The package's own warning class, so users can filter what manifold-sph tells them.

Every warning the library issues (widened supports, flipped normals, merged
near-duplicates, fallbacks to a lower-order scheme or to the stable Laplacian,
unconverged projections) is a :class:`ManifoldSPHWarning`. It subclasses
:class:`RuntimeWarning`, so filters on ``RuntimeWarning`` keep working.

Examples
--------
>>> import warnings
>>> from manifold_sph import ManifoldSPHWarning
>>> with warnings.catch_warnings():
...     warnings.simplefilter("ignore", ManifoldSPHWarning)   # silence the library only
...     warnings.warn("widened 3 supports", ManifoldSPHWarning)
>>> issubclass(ManifoldSPHWarning, RuntimeWarning)
True
"""

from __future__ import annotations

__all__ = ["ManifoldSPHWarning"]


class ManifoldSPHWarning(RuntimeWarning):
    """A warning issued by manifold-sph (filter with ``warnings.simplefilter("ignore", ManifoldSPHWarning)``)."""
