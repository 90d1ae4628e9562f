"""Tangent frames and projection to local 2D coordinates (docs/method.md section 2).

The frame at a particle with unit normal ``n`` follows the construction of the thesis [1] (sec. 3.2.1):
``u`` spans the intersection of the tangent plane with the plane ``y = y_i``,
``u ~ (n_z, 0, -n_x)``; when ``n`` is (nearly) parallel to ``e_y`` the plane
``x = x_i`` is used instead, ``u ~ (0, n_z, -n_y)``. Then ``v = n x u``.
Any orthonormal frame gives the same operators; this one is only a convention.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from . import _jit
from .threads import run_chunks

__all__ = ["tangent_frames", "check_frames", "unit_rows", "project_pairs", "project_neighborhood", "PairOffsets", "FramePair"]

#: Below this value of sqrt(n_x^2 + n_z^2) the normal counts as parallel to e_y.
PARALLEL_TOL = 0.1


def tangent_frames(normals: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal tangent vectors ``(u, v)`` for unit normals.

    Parameters
    ----------
    normals : ndarray, shape (N, 3)
        Unit normals.

    Returns
    -------
    u, v : ndarray, shape (N, 3)
        ``u . n = v . n = u . v = 0``, ``|u| = |v| = 1``, ``(u, v, n)`` right-handed.

    Examples
    --------
    >>> import numpy as np
    >>> u, v = tangent_frames(np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]]))
    >>> (u + 0.0).tolist(), (v + 0.0).tolist()   # + 0.0 turns -0.0 into 0.0
    ([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0]], [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    """
    n = np.asarray(normals, dtype=np.float64)
    if _jit.ENABLED and n.ndim == 2 and n.shape[1] == 3:
        u = np.empty_like(n)
        v = np.empty_like(n)
        starts = range(0, n.shape[0], _PROJECT_ROWS)
        run_chunks(lambda c: _jit.frames_rows(starts[c], min(starts[c] + _PROJECT_ROWS, n.shape[0]), n, PARALLEL_TOL, u, v), len(starts))
        return u, v
    nx, ny, nz = n[:, 0], n[:, 1], n[:, 2]
    zero = np.zeros_like(nx)
    u_y = np.stack([nz, zero, -nx], axis=1)  # tangent plane ∩ {y = y_i}
    u_x = np.stack([zero, nz, -ny], axis=1)  # tangent plane ∩ {x = x_i}
    parallel = np.hypot(nx, nz) < PARALLEL_TOL
    u = np.where(parallel[:, None], u_x, u_y)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(n, u)
    return u, v


def unit_rows(v: np.ndarray) -> np.ndarray:
    """The rows of ``v`` (N, d) scaled to unit length; zero rows stay zero.

    Each row is first divided by its largest component, so that rows of any magnitude
    representable in float64 come out unit: the squares of a gradient of 1e-170 underflow
    (a heat method's far field), and those of 1e+170 overflow.

    Examples
    --------
    >>> unit_rows(np.array([[3e-200, 4e-200], [0.0, 0.0], [3e200, -4e200]])).tolist()
    [[0.6, 0.8], [0.0, 0.0], [0.6, -0.8]]
    """
    v = np.asarray(v, dtype=np.float64)
    big = np.abs(v).max(axis=-1, keepdims=True)
    w = v / np.where(big > 0, big, 1.0)
    n = np.linalg.norm(w, axis=-1, keepdims=True)
    return w / np.where(n > 0, n, 1.0)


def check_frames(normals: ArrayLike, u: np.ndarray, v: np.ndarray, tol: float = 1e-10) -> None:
    """Raise ValueError unless ``(u, v, n)`` are orthonormal at every particle."""
    n = np.asarray(normals)
    checks = {
        "|u| - 1": np.abs(np.einsum("ij,ij->i", u, u) - 1),
        "|v| - 1": np.abs(np.einsum("ij,ij->i", v, v) - 1),
        "u.v": np.abs(np.einsum("ij,ij->i", u, v)),
        "u.n": np.abs(np.einsum("ij,ij->i", u, n)),
        "v.n": np.abs(np.einsum("ij,ij->i", v, n)),
    }
    for name, dev in checks.items():
        if dev.size and dev.max() > tol:
            i = int(dev.argmax())
            raise ValueError(f"tangent frame is not orthonormal: {name} = {dev[i]:.3e} at particle {i} (tolerance {tol:g})")


def project_pairs(
    points: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
    candidates: np.ndarray | None = None,
) -> np.ndarray:
    """Local 2D coordinates of each neighbour ``j`` seen from its row particle ``i``.

    Parameters
    ----------
    points : ndarray, shape (N, 3)
    u, v : ndarray, shape (N, 3)
        Tangent frames of the row particles.
    rows, cols : ndarray, shape (P,)
        Pair indices; ``cols`` index ``candidates`` (default ``points``).

    Returns
    -------
    ndarray, shape (P, 2)
        ``((p_j - p_i) . u_i, (p_j - p_i) . v_i)``.
    """
    cand = points if candidates is None else candidates
    d = cand[cols] - points[rows]
    return np.stack([np.einsum("ij,ij->i", d, u[rows]), np.einsum("ij,ij->i", d, v[rows])], axis=1)


#: Rows per chunk of :func:`project_neighborhood`.
_PROJECT_ROWS = 4096


def project_neighborhood(
    points: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
    indptr: np.ndarray,
    indices: np.ndarray,
    candidates: np.ndarray | None = None,
    workers: int = -1,
) -> np.ndarray:
    """:func:`project_pairs` for CSR neighbour lists, in row chunks on threads.

    Same result as ``project_pairs(points, u, v, rows, indices, candidates)``
    with ``rows`` the row of every pair, without any (P, 3) temporaries: each
    chunk works on its rows' neighbour slots.

    Parameters
    ----------
    points : ndarray, shape (N, 3)
    u, v : ndarray, shape (N, 3)
    indptr : ndarray, shape (N + 1,)
    indices : ndarray, shape (P,)
        Column (index into ``candidates``) of every pair, row by row.
    candidates : ndarray, shape (M, 3), optional
    workers : int
        Threads (-1: :func:`manifold_sph.threads.get_num_threads`).

    Returns
    -------
    ndarray, shape (P, 2)

    Examples
    --------
    >>> import numpy as np
    >>> p = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]])
    >>> u, v = tangent_frames(np.array([[0.0, 0.0, 1.0]] * 2))
    >>> project_neighborhood(p, u, v, np.array([0, 2, 3]), np.array([0, 1, 1])).tolist()
    [[0.0, 0.0], [1.0, 2.0], [0.0, 0.0]]
    """
    cand = points if candidates is None else candidates
    n = indptr.size - 1
    out = np.empty((indices.size, 2))
    starts = list(range(0, n, _PROJECT_ROWS))

    if _jit.ENABLED and points.shape[1] == 3:
        pts = np.asarray(points, dtype=np.float64)
        cnd = np.asarray(cand, dtype=np.float64)
        run_chunks(
            lambda c: _jit.project_rows(starts[c], min(starts[c] + _PROJECT_ROWS, n), pts, cnd, u, v, indptr, indices, out),
            len(starts),
            workers,
        )
        return out

    def chunk(lo):
        hi = min(lo + _PROJECT_ROWS, n)
        first = indptr[lo:hi]
        counts = indptr[lo + 1 : hi + 1] - first
        k = int(counts.max()) if counts.size else 0
        valid = np.arange(k)[None, :] < counts[:, None]
        pos = np.where(valid, first[:, None] + np.arange(k)[None, :], 0)
        d = cand[indices[pos]] - points[lo:hi, None, :]
        p0, p1 = indptr[lo], indptr[hi]
        out[p0:p1, 0] = np.einsum("nkd,nd->nk", d, u[lo:hi])[valid]
        out[p0:p1, 1] = np.einsum("nkd,nd->nk", d, v[lo:hi])[valid]

    run_chunks(lambda c: chunk(starts[c]), len(starts), workers)
    return out


class PairOffsets:
    """Pair offsets in the row particles' tangent planes, projected on demand instead of stored.

    The (P, 2) array of :func:`project_neighborhood` is the largest array of a
    build (16 bytes a pair: 430 MB for a million points with 27 neighbours). The
    build steps read it in row ranges (:meth:`rows`) or at a few pair positions
    (:meth:`at`), each projected when asked, with the same arithmetic as
    :func:`project_neighborhood`, so the values are identical to the stored array's.

    Parameters
    ----------
    points, u, v : ndarray, shape (N, 3)
    indptr : ndarray, shape (N + 1,)
    indices : ndarray, shape (P,)

    Examples
    --------
    >>> import numpy as np
    >>> p = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]])
    >>> u, v = tangent_frames(np.array([[0.0, 0.0, 1.0]] * 2))
    >>> xy = PairOffsets(p, u, v, np.array([0, 2, 3]), np.array([0, 1, 1]))
    >>> xy.shape, xy.rows(0, 1).tolist(), xy.at(np.array([1])).tolist()
    ((3, 2), [[0.0, 0.0], [1.0, 2.0]], [[1.0, 2.0]])
    >>> np.array_equal(xy.full(), project_neighborhood(p, u, v, np.array([0, 2, 3]), np.array([0, 1, 1])))
    True
    """

    def __init__(self, points: np.ndarray, u: np.ndarray, v: np.ndarray, indptr: np.ndarray, indices: np.ndarray) -> None:
        self.points, self.u, self.v, self.indptr, self.indices = points, u, v, indptr, indices

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.indices.size), 2)

    def rows(self, lo: int, hi: int) -> np.ndarray:
        """(indptr[hi] - indptr[lo], 2) offsets of the pairs of rows ``lo:hi``, on one thread."""
        ip = self.indptr[lo : hi + 1]
        return project_neighborhood(self.points[lo:hi], self.u[lo:hi], self.v[lo:hi], ip - ip[0],
                                    self.indices[ip[0] : ip[-1]], candidates=self.points, workers=1)

    def at(self, pos: np.ndarray) -> np.ndarray:
        """(len(pos), 2) offsets of the pairs at positions ``pos``."""
        pos = np.asarray(pos)
        flat = pos.ravel()
        r = np.searchsorted(self.indptr, flat, side="right") - 1
        # each pair its own row: the same kernel (and rounding) as project_neighborhood
        out = project_neighborhood(self.points[r], self.u[r], self.v[r], np.arange(flat.size + 1), self.indices[flat],
                                   candidates=self.points, workers=1)
        return out.reshape(pos.shape + (2,))

    def full(self, workers: int = -1) -> np.ndarray:
        """The whole (P, 2) array (allocated anew on every call)."""
        return project_neighborhood(self.points, self.u, self.v, self.indptr, self.indices, workers=workers)


def offsets_of_rows(xy: np.ndarray | PairOffsets, indptr: np.ndarray, lo: int, hi: int) -> np.ndarray:
    """The offsets of the pairs of rows ``lo:hi`` from a (P, 2) array or a :class:`PairOffsets`."""
    if isinstance(xy, PairOffsets):
        return xy.rows(lo, hi)
    return xy[indptr[lo] : indptr[hi]]


def offsets_at(xy: np.ndarray | PairOffsets, pos: np.ndarray) -> np.ndarray:
    """The offsets at pair positions ``pos`` (any shape) from an array or a :class:`PairOffsets`."""
    if isinstance(xy, PairOffsets):
        return xy.at(pos)
    return xy[pos]


def offsets_array(xy: np.ndarray | PairOffsets) -> np.ndarray:
    """The whole (P, 2) array from an array or a :class:`PairOffsets`."""
    return xy.full() if isinstance(xy, PairOffsets) else xy


class FramePair:
    """The frames ``(u, v)`` read as an (N, 2, D) array without stacking them (a copy of 48 bytes a
    particle): ``frames[idx, k]`` is ``(u, v)[k][idx]``, for any row index ``idx`` and ``k`` in {0, 1}.

    Examples
    --------
    >>> u, v = tangent_frames(np.array([[0.0, 0.0, 1.0]] * 3))
    >>> e = FramePair(u, v)
    >>> e.shape, bool(np.array_equal(e[[2, 0], 1], np.stack([u, v], axis=1)[[2, 0], 1]))
    ((3, 2, 3), True)
    """

    def __init__(self, u: np.ndarray, v: np.ndarray) -> None:
        if u.shape != v.shape or u.ndim != 2:
            raise ValueError(f"u and v must be (N, D) arrays of one shape, got {u.shape} and {v.shape}")
        self._uv = (u, v)
        self.shape = (u.shape[0], 2, u.shape[1])

    def __getitem__(self, key: tuple) -> np.ndarray:
        rows, k = key
        return self._uv[k][rows]
