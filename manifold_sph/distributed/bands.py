"""The geodesic heat step in bands, each solved in a window around its seed.

The heat method's first step ``(M + t K) u = e_s`` has a solution that decays like
``exp(-d / sqrt(t))`` away from the sources: below any residual tolerance of an iterative
solve a few dozen spacings out, while the method needs the directions of ``grad u``
everywhere. :func:`band_directions` keeps the directions where ``u`` exceeds
:data:`BAND_FLOOR` of its largest value, seeds the next solve from that region's outer shell
(values up to :data:`BAND_SHELL` times the floor) scaled to 1, and so on outwards; each band's
field continues ``exp(-(d_shell + |x - x_shell|) / sqrt(t))``, whose directions are the
geodesic's.

A band's field is negligible more than :data:`BAND_WINDOW` ``sqrt(t)`` from its seed
(``exp(-32)`` ~ 1e-14 of its values at the seed; the directions it keeps lie within about 18
``sqrt(t)``, and a zero held at the window's edge changes them by about ``exp(-2 (32 - 18))``
~ 1e-12 relatively). :class:`WindowedHeat` therefore solves each band only on the particles
of the voxels (side ``BAND_WINDOW sqrt(t)``) around those of its seed, with Jacobi-preconditioned
CG: ``M + t K`` with ``t`` a few mean cells has a condition number of a few dozen whatever the
cloud's size, so CG needs 60-130 iterations and no multigrid set-up, and the work of a band is
that of its window, not of the cloud.
"""

from __future__ import annotations

from itertools import product
from typing import Any

import numpy as np
import scipy.sparse as sp

__all__ = ["BAND_FLOOR", "BAND_RTOL", "BAND_SHELL", "BAND_WINDOW", "DIRECT_FLOOR", "VoxelWindows", "WindowedHeat",
           "band_directions", "jacobi_cg"]

#: A band keeps the directions where the heat field exceeds this fraction of its largest value ...
BAND_FLOOR = 1e-8
#: ... and seeds the next band from the values between the floor and this many times it.
BAND_SHELL = 1e3
#: Relative residual of each band's CG solve.
BAND_RTOL = 1e-12
#: The floor of a direct (Cholesky) heat step's bands: its entries keep their digits down to float64's range, so one
#: band covers what does not underflow (more bands only on very elongated clouds).
DIRECT_FLOOR = 1e-280
#: Half-width of a band's window in units of ``sqrt(t)`` (the voxel side).
BAND_WINDOW = 32.0


class VoxelWindows:
    """The particles of the voxels around given seeds: voxels of side ``cell``, the 27 around each seed's.

    Every particle within ``cell`` (Euclidean, so also geodesic) of a seed is in its window.

    Parameters
    ----------
    points : (N, 3) float64
    cell : float
        Voxel side.
    origin : (3,) float64, optional
        The voxel grid's corner (default: the points' minimum); clouds split over processes pass
        the whole cloud's so every process hashes alike.
    """

    def __init__(self, points: np.ndarray, cell: float, origin: np.ndarray | None = None) -> None:
        from .._validation import as_field, as_points, check_positive

        points = as_points("points", points)
        cell = check_positive("cell", cell)
        if origin is None and not len(points):
            raise ValueError("points is empty: give the voxel grid's origin")
        lo = points.min(axis=0) if origin is None else as_field("origin", origin, 3)
        self.dims = (2**20, 2**20, 2**20)
        self.keys = np.zeros(len(points), dtype=np.int64)
        for a in range(3):  # axis by axis: temporaries of one column
            q = np.floor((points[:, a] - lo[a]) / cell).astype(np.int64) + 1  # one empty voxel layer below: no wrap
            if q.size and (q.min() < 1 or q.max() >= self.dims[a] - 1):
                raise ValueError(f"the cloud spans more than {self.dims[a] - 2} voxels of side {cell:.3g} on an axis")
            self.keys *= self.dims[a]
            self.keys += q
        del q
        self.order = np.argsort(self.keys, kind="stable")
        self._sorted = self.keys[self.order]
        self.offsets = np.array([self.key(np.array(o)) - self.key(np.zeros(3, dtype=np.int64))
                                 for o in product((-1, 0, 1), repeat=3)], dtype=np.int64)

    def key(self, q: np.ndarray) -> np.ndarray:
        """The voxel keys of integer voxel coordinates (..., 3)."""
        q = np.asarray(q, dtype=np.int64)
        return (q[..., 0] * self.dims[1] + q[..., 1]) * self.dims[2] + q[..., 2]

    def around(self, seed_keys: np.ndarray) -> np.ndarray:
        """The voxel keys of the 27 voxels around each of ``seed_keys``, unique."""
        return np.unique((np.unique(seed_keys)[:, None] + self.offsets[None, :]).ravel())

    def rows(self, voxels: np.ndarray) -> np.ndarray:
        """The particles (sorted indices) in the voxels ``voxels`` (keys)."""
        a = np.searchsorted(self._sorted, voxels, side="left")
        b = np.searchsorted(self._sorted, voxels, side="right")
        counts = b - a
        if not counts.sum():
            return np.zeros(0, dtype=np.int64)
        starts = np.repeat(a - np.cumsum(counts) + counts, counts)
        return np.sort(self.order[starts + np.arange(counts.sum())])


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    # not BLAS's ddot: its threads spin against each other when the cores are shared
    return float(np.einsum("i,i", a, b))


def _square(name: str, A: Any) -> sp.csr_matrix:
    if not sp.issparse(A) or A.ndim != 2 or A.shape[0] != A.shape[1]:
        raise ValueError(f"{name} must be a square sparse matrix, got {type(A).__name__} of shape {np.shape(A)}")
    return sp.csr_matrix(A)


def jacobi_cg(A: sp.csr_matrix, b: np.ndarray, rtol: float, maxiter: int) -> tuple[np.ndarray, int]:
    """CG preconditioned by ``A``'s diagonal, from zero, to ``|b - A x| <= rtol |b|``; ``(x, iterations)``.

    ``A`` (n, n) sparse SPD with a positive diagonal; ``b`` (n,); ``rtol`` in (0, 1); ``maxiter`` >= 1.
    """
    from .._validation import as_field, check_int
    from ..solvers import SolverConvergenceError

    A = _square("A", A)
    b = as_field("b", b, A.shape[0])
    if not (isinstance(rtol, (int, float)) and 0.0 < rtol < 1.0):
        raise ValueError(f"rtol must lie in (0, 1), got {rtol!r}")
    maxiter = check_int("maxiter", maxiter, minimum=1)
    if not np.all(A.diagonal() > 0):
        raise ValueError("A must have a positive diagonal (an SPD matrix), got a zero or negative diagonal entry")

    dinv = 1.0 / A.diagonal()
    x = np.zeros_like(b)
    r = b.copy()
    z = dinv * r
    p = z.copy()
    dot = _dot
    rz = dot(r, z)
    stop = rtol * float(np.sqrt(dot(b, b)))
    for it in range(1, maxiter + 1):
        q = A @ p
        alpha = rz / dot(p, q)
        x += alpha * p
        r -= alpha * q
        if np.sqrt(dot(r, r)) <= stop:
            return x, it
        z = dinv * r
        rz, rz_old = dot(r, z), rz
        p *= rz / rz_old
        p += z
    raise SolverConvergenceError(f"Jacobi-CG stopped at relative residual {np.linalg.norm(r) / np.linalg.norm(b):.3g} "
                                 f"after {maxiter} iterations (rtol {rtol:g})")


class _Info:
    def __init__(self) -> None:
        self.iterations = 0
        self.rows = 0


class WindowedHeat:
    """``(M + t K) w = b`` solved on the window around ``b``'s support only (module notes); ``w`` zero outside.

    Parameters
    ----------
    A : (N, N) sparse SPD
        ``M + t K``.
    points : (N, 3) float64
    t : float
        The heat time; the window's half-width is ``BAND_WINDOW sqrt(t)``.
    """

    method = "jacobi-cg windows"

    def __init__(self, A: Any, points: np.ndarray, t: float, *, rtol: float = BAND_RTOL, maxiter: int = 5000) -> None:
        from .._validation import as_points, check_positive

        self.A = _square("A", A)
        points = as_points("points", points)
        if len(points) != self.A.shape[0]:
            raise ValueError(f"points must have one row per row of A ({self.A.shape[0]}), got {len(points)}")
        self.windows = VoxelWindows(points, BAND_WINDOW * float(np.sqrt(check_positive("t", t))))
        self.rtol, self.maxiter = rtol, maxiter
        self.info = _Info()

    def solve(self, b: np.ndarray) -> np.ndarray:
        """``w`` (N,): the solution on the window around ``b``'s nonzero entries, zero outside."""
        from .._validation import as_field

        b = as_field("b", b, self.A.shape[0])
        win = self.windows.rows(self.windows.around(self.windows.keys[b != 0]))
        x, its = jacobi_cg(self.A[win][:, win], b[win], self.rtol, self.maxiter)
        self.info.iterations, self.info.rows = its, win.size
        w = np.zeros_like(b)
        w[win] = x
        return w


def band_directions(heat: Any, rhs: np.ndarray, directions: Any, *, floor: float = BAND_FLOOR,
                    max_bands: int = 10_000) -> tuple[np.ndarray, list[int], np.ndarray]:
    """The heat method's unit directions ``X`` (N, 3), band by band (module notes).

    ``heat.solve(b)`` solves the heat step (its ``info.iterations`` read after each solve);
    ``directions(u)`` gives ``-grad u / |grad u|`` (N, 3); a band keeps the values above
    ``floor`` times its largest (:data:`BAND_FLOOR` for an iterative solve, :data:`DIRECT_FLOOR`
    for a direct one). Returns ``X``, the iterations of every band's solve and the mask (N,) of
    the particles reached: those the heat never reaches (pieces without a source) keep ``X = 0``.
    """
    from .._validation import check_finite

    rhs = check_finite("rhs", np.asarray(rhs, dtype=np.float64))
    if rhs.ndim != 1 or not np.any(rhs):
        raise ValueError(f"rhs must be a nonzero vector (N,), got shape {rhs.shape}")
    if not (isinstance(floor, (int, float)) and 0.0 < floor < 1.0):
        raise ValueError(f"floor must lie in (0, 1), got {floor!r}")
    n = rhs.size
    X = np.zeros((n, 3))
    done = np.zeros(n, dtype=bool)
    its: list[int] = []
    w = heat.solve(rhs)
    its.append(int(heat.info.iterations))
    for _ in range(max_bands):
        top = float(np.abs(w).max())
        if not top > 0:
            break
        ok = (w > floor * top) & ~done
        if not ok.any():
            break
        X[ok] = directions(w)[ok]
        done |= ok
        shell = ok & (w <= BAND_SHELL * floor * top)
        if done.all() or not shell.any():
            break
        b = np.zeros(n)
        b[shell] = w[shell] / w[shell].max()
        w = heat.solve(b)
        its.append(int(heat.info.iterations))
    return X, its, done
