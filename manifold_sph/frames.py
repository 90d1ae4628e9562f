"""Tangent frames and projection to local 2D coordinates (METHOD.md section 2).

The frame at a particle with unit normal ``n`` follows the seed's construction:
``u`` spans the intersection of the tangent plane with the plane ``y = y_i``,
``u ~ (n_z, 0, -n_x)``; when ``n`` is (nearly) parallel to ``e_y`` the plane
``x = x_i`` is used instead, ``u ~ (0, n_z, -n_y)``. Then ``v = n x u``.
Any orthonormal frame gives the same operators; this one is only a convention.
"""

from __future__ import annotations

import numpy as np

__all__ = ["tangent_frames", "check_frames", "project_pairs"]

#: Below this value of sqrt(n_x^2 + n_z^2) the normal counts as parallel to e_y.
PARALLEL_TOL = 0.1


def tangent_frames(normals) -> tuple[np.ndarray, np.ndarray]:
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
    nx, ny, nz = n[:, 0], n[:, 1], n[:, 2]
    zero = np.zeros_like(nx)
    u_y = np.stack([nz, zero, -nx], axis=1)  # tangent plane ∩ {y = y_i}
    u_x = np.stack([zero, nz, -ny], axis=1)  # tangent plane ∩ {x = x_i}
    parallel = np.hypot(nx, nz) < PARALLEL_TOL
    u = np.where(parallel[:, None], u_x, u_y)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(n, u)
    return u, v


def check_frames(normals, u, v, tol: float = 1e-10) -> None:
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


def project_pairs(points, u, v, rows, cols, candidates=None) -> np.ndarray:
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
