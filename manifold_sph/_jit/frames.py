"""Tangent frames and the projection to local coordinates (:mod:`manifold_sph.frames`)."""

from __future__ import annotations

import numpy as np

from .compile import U, njit

__all__ = ["frames_rows", "project_rows"]


@njit
def frames_rows(lo, hi, normals, parallel_tol, u, v):
    """:func:`manifold_sph.frames.tangent_frames` for rows ``lo:hi``: ``u`` the unit tangent in the
    plane ``y = y_i`` (or ``x = x_i`` when the normal is almost along y), ``v = n x u``."""
    for i in range(lo, hi):
        nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
        if np.hypot(nx, nz) < parallel_tol:
            a, b, c = 0.0, nz, -ny
        else:
            a, b, c = nz, 0.0, -nx
        norm = np.sqrt(a * a + b * b + c * c)
        a /= norm
        b /= norm
        c /= norm
        u[i, 0] = a
        u[i, 1] = b
        u[i, 2] = c
        v[i, 0] = ny * c - nz * b
        v[i, 1] = nz * a - nx * c
        v[i, 2] = nx * b - ny * a


# ----------------------------------------------------------------- projection
@njit
def project_rows(lo, hi, points, cand, u, v, indptr, indices, out):
    """``out[p] = ((c_j - p_i) . u_i, (c_j - p_i) . v_i)`` for the pairs ``p`` of rows ``lo:hi``."""
    for i in range(lo, hi):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        ux, uy, uz = u[i, 0], u[i, 1], u[i, 2]
        vx, vy, vz = v[i, 0], v[i, 1], v[i, 2]
        for p in range(U(indptr[i]), U(indptr[i + 1])):
            j = U(indices[p])
            dx = cand[j, 0] - px
            dy = cand[j, 1] - py
            dz = cand[j, 2] - pz
            out[p, 0] = dx * ux + dy * uy + dz * uz
            out[p, 1] = dx * vx + dy * vy + dz * vz
