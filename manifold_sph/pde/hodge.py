"""Helmholtz-Hodge decomposition of a tangent vector field on a closed point-cloud surface."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from .._validation import as_field
from ..results import Result
from .elliptic import poisson_solve
from .laplacians import operator_for

if TYPE_CHECKING:
    from ..surface import Surface

__all__ = ["HodgeDecomposition", "helmholtz_hodge"]


@dataclass(frozen=True, eq=False, repr=False)
class HodgeDecomposition(Result):
    """``F = gradient + cogradient + harmonic`` with ``gradient = grad phi`` and
    ``cogradient = n x grad psi`` (all (N, 3)); ``phi``, ``psi`` zero-mean (N,)."""

    gradient: np.ndarray
    cogradient: np.ndarray
    harmonic: np.ndarray
    phi: np.ndarray
    psi: np.ndarray


def helmholtz_hodge(surface: Surface, F: ArrayLike) -> HodgeDecomposition:
    """Helmholtz-Hodge decomposition of a tangent field on a closed surface.

    ``Lap phi = div F`` and ``Lap psi = -div(n x F)`` are solved together (one set-up of
    the solver, :func:`~manifold_sph.pde.poisson`); the harmonic part is what remains
    (zero on a sphere; on a torus it holds the two harmonic fields).

    Parameters
    ----------
    surface : Surface
    F : array_like, shape (N, 3)
        Its normal part is discarded.

    Returns
    -------
    HodgeDecomposition

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> s = Surface(shapes.sphere(2000))
    >>> F = s.gradient(s.points[:, 2]) + np.cross(s.normals, s.gradient(s.points[:, 0]))
    >>> h = helmholtz_hodge(s, F)
    >>> bool(np.abs(h.harmonic).max() < 0.05 * np.abs(F).max())
    True
    """
    from ..surface import Surface

    if not isinstance(surface, Surface):
        raise TypeError(f"surface must be a Surface (a closed point-cloud surface), got {type(surface).__name__}")
    n = surface.normals
    Fv = as_field("F", F, surface.n_points, 3)
    Ft = Fv - np.einsum("ij,ij->i", Fv, n)[:, None] * n  # the tangent part
    op = operator_for(surface, "auto")
    rhs = np.stack([surface.divergence(Ft), -surface.divergence(np.cross(n, Ft))], axis=1)
    rhs -= (op.m @ rhs) / op.m.sum()  # zero mean: the compatibility condition on a closed surface
    phi, psi = poisson_solve(surface, op, rhs).T
    grad = surface.gradient(phi)
    cograd = np.cross(n, surface.gradient(psi))
    return HodgeDecomposition(gradient=grad, cogradient=cograd, harmonic=Ft - grad - cograd, phi=phi, psi=psi)
