"""Mirror (perfect magnetic conductor) walls on planes ``x = const`` for the TMz derivative matrices.

A TMz field meets ``Hy = 0`` and ``dEz/dx = 0`` on a perfect magnetic
conductor ``x = m``: continued across the plane, Ez and Hx are even in
``x - m`` and Hy is odd. A derivative matrix then needs no particle beyond
the plane: its kernel sum runs over the real columns and their mirror images
``(2 m - x, y)`` within reach of the plane, each image's weight folded back
onto its real column with the parity's sign (``D[:, real] + D[:, images] P``,
``P`` with entries +-1). An odd field is zero on the plane, so a row of
zero-valued points on the plane (at the lattice's y spacing) joins the
columns of an odd field and is dropped after the derivative system is built:
it completes the supports next to the plane without adding unknowns.

For a y-travelling TMz plane wave the mirror conditions hold exactly on every
plane ``x = const``, so two mirror walls bound the plane wave's domain at the
sides without an absorbing layer.

Examples
--------
>>> from manifold_sph.spem.layouts import yee_layout
>>> lay = yee_layout((0.0, 1.0, 0.0, 1.0), 0.1)
>>> planes = (-0.05, 1.05)
>>> D = folded_gradient(lay.e, lay.hy, 0.07, 0, planes=planes, odd=True, spacing=0.1, y_range=(0.0, 1.0))
>>> f = lay.hy[:, 0] + 0.05  # odd about x = -0.05
>>> near = lay.e[:, 0] < 0.3
>>> bool(np.allclose((D @ f)[near], 1.0))
True
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from .operators import cross_gradient

if TYPE_CHECKING:
    from ..kernels import Kernel

__all__ = ["MIRROR_GAP", "check_mirror_planes", "mirror_reach", "folded_gradient"]

#: Smallest distance (in spacings) from a particle to a mirror plane: a closer particle's image would be
#: closer to it than half a spacing (a near-duplicate column that makes its derivative system singular).
MIRROR_GAP = 0.25


def check_mirror_planes(planes: Sequence[float] | None, sets: Sequence[tuple[str, np.ndarray]],
                        dr: float) -> tuple[float, ...]:
    """Validated mirror planes (sorted x values); ValueError if a particle lies within MIRROR_GAP dr of one.

    ``sets`` are ``(name, (n, 2) points)`` pairs; every particle must lie on the same side of each plane as
    the domain (between the first and the last plane when there are two).
    """
    if planes is None:
        return ()
    arr = np.atleast_1d(np.asarray(planes, dtype=np.float64))
    if arr.ndim != 1 or arr.size == 0 or arr.size > 2 or not np.all(np.isfinite(arr)):
        raise ValueError(f"mirror must be one or two finite x values (the mirror planes), got {planes!r}")
    arr = np.sort(arr)
    for name, p in sets:
        x = np.asarray(p)[:, 0]
        gap = np.min(np.abs(x[:, None] - arr[None, :]))
        if gap < MIRROR_GAP * dr:
            raise ValueError(
                f"mirror: {name} lie {gap / dr:.3g} spacings from a mirror plane (at least {MIRROR_GAP} expected: "
                f"a particle on or next to a plane has its own image as a near-duplicate neighbour); put the planes "
                f"between particle columns (a lattice's half-spacing lines) or use side layers")
        if arr.size == 2 and (x.min() < arr[0] or x.max() > arr[1]):
            raise ValueError(f"mirror: {name} lie outside the planes x = {arr[0]:.6g} and x = {arr[1]:.6g}")
    return tuple(float(a) for a in arr)


def mirror_reach(h: float | np.ndarray, support: float = 3.0) -> float:
    """Distance from a plane within which a column's image can enter a support (``support`` times the
    largest h; 3 covers every kernel of :mod:`manifold_sph.kernels` with margin)."""
    return support * float(np.max(h))


def folded_gradient(rows: np.ndarray, cols: np.ndarray, h: float | np.ndarray, axis: int, *,
                    planes: Sequence[float], odd: bool, spacing: float, y_range: tuple[float, float],
                    kernel: str | Kernel | type[Kernel] = "cubic", form: str = "fpm", row_name: str = "rows",
                    col_name: str = "columns") -> sp.csr_matrix:
    """``d/dx_axis`` from ``cols`` to ``rows`` with mirror images of the columns across ``planes`` folded back.

    Parameters
    ----------
    rows, cols : (n_r, 2), (n_c, 2) arrays
    h : float or (n_r,) array
        Smoothing length(s), as in :func:`.operators.cross_gradient`.
    axis : int
        0 for d/dx, 1 for d/dy.
    planes : sequence of float
        The mirror planes' x values.
    odd : bool
        The column field is odd about the planes (Hy of TMz); else even (Ez, Hx).
    spacing : float
        y spacing of the zero-valued points on the planes (odd fields only).
    y_range : (float, float)
        y extent of those points.

    Returns
    -------
    csr (n_r, n_c)
    """
    reach = mirror_reach(h)
    x = cols[:, 0]
    src, images = [], []
    for m in planes:
        near = np.flatnonzero(np.abs(x - m) < reach)
        src.append(near)
        images.append(np.column_stack([2 * m - x[near], cols[near, 1]]))
    src = np.concatenate(src) if src else np.zeros(0, dtype=np.int64)
    extra = [np.vstack(images)] if images else []
    if odd and len(planes):
        ny = int(round((y_range[1] - y_range[0]) / spacing))
        yk = y_range[0] + spacing * np.arange(ny + 1)
        extra += [np.column_stack([np.full_like(yk, m), yk]) for m in planes]
    allcols = np.vstack([cols, *extra])
    D = cross_gradient(rows, allcols, h, kernel=kernel, form=form, row_name=row_name, col_name=col_name)[axis]
    D = sp.csr_matrix(D)
    nc, ns = len(cols), len(src)
    P = sp.csr_matrix(((-1.0 if odd else 1.0) * np.ones(ns), (np.arange(ns), src)), shape=(ns, nc))
    return (D[:, :nc] + D[:, nc:nc + ns] @ P).tocsr()
