"""SPH schemes behind one interface: local 2D pair data in, per-pair weights out.

A new scheme is one new module with a :class:`~manifold_sph.schemes.base.Scheme`
subclass, registered in :data:`SCHEMES`.
"""

from __future__ import annotations

from .base import LocalPairs, Scheme, SchemeWeights
from .cspm import CSPM
from .msph import MSPH
from .msph4 import MSPH3, MSPH4, MSPH5
from .ncsph import NCSPH
from .standard import Standard

#: Registry: name -> scheme class.
SCHEMES: dict[str, type[Scheme]] = {cls.name: cls for cls in (Standard, CSPM, MSPH, NCSPH, MSPH3, MSPH4, MSPH5)}


def get_scheme(scheme: str | Scheme) -> Scheme:
    """Return a scheme instance from a name or an instance.

    Examples
    --------
    >>> get_scheme("cspm")
    <scheme 'cspm'>
    """
    if isinstance(scheme, Scheme):
        return scheme
    if not isinstance(scheme, str) or scheme not in SCHEMES:
        raise ValueError(f"scheme must be one of {sorted(SCHEMES)}, got {scheme!r}")
    return SCHEMES[scheme]()


__all__ = ["SCHEMES", "get_scheme", "Scheme", "LocalPairs", "SchemeWeights", "Standard", "CSPM", "MSPH", "NCSPH", "MSPH3", "MSPH4", "MSPH5"]
