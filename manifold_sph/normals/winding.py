"""Generalised winding numbers of an oriented point cloud (Barill et al. 2018).

``w(q) = sum_j a_j n_j . (p_j - q) / (4 pi |p_j - q|^3)`` is 1 inside a closed surface with
outward normals and 0 outside. :func:`winding_numbers` sums it per label with a two-level cell
approximation (exact over near cells, one dipole per cell and label far), compiled with numba
(:func:`winding_rows`) and run on threads; without numba a dense numpy sum.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .. import _jit
from .._jit.compile import numba  # None where numba is not installed
from ..threads import run_chunks
from .arrays import unique_sorted

__all__ = ["best_signs", "integer_signs", "objective", "winding_numbers", "winding_rows"]


def winding_numbers(queries: np.ndarray, points: np.ndarray, normals: np.ndarray, area: np.ndarray, eps: np.ndarray, label: np.ndarray,
                    n_labels: int, theta: float = 0.5, per_cell: int = 32) -> np.ndarray:
    """``out[q, l]``: generalised winding number at ``queries[q]`` of the particles labelled ``l``.

    ``sum_j a_j n_j . (p_j - q) / (4 pi (|p_j - q|^2 + eps_j^2)^(3/2))``, summed exactly over
    cells near the query and as one dipole per (cell, label) over cells whose radius is below
    ``theta`` times their distance (compiled, on threads); without numba a dense numpy sum.
    """
    Q = np.ascontiguousarray(queries, dtype=np.float64)
    P = np.ascontiguousarray(points, dtype=np.float64)
    An = np.ascontiguousarray(area[:, None] * normals)
    eps2 = np.ascontiguousarray(eps**2)
    label = np.ascontiguousarray(label, dtype=np.int64)
    out = np.zeros((Q.shape[0], n_labels))
    if not _jit.ENABLED:
        onehot = sp.csr_matrix((np.ones(P.shape[0]), (np.arange(P.shape[0]), label)), shape=(P.shape[0], n_labels))
        for lo in range(0, Q.shape[0], 256):
            r = P[None, :, :] - Q[lo : lo + 256, None, :]
            r2 = np.einsum("qjk,qjk->qj", r, r) + eps2[None, :]
            f = np.einsum("qjk,jk->qj", r, An) / (4 * np.pi * r2 * np.sqrt(r2))
            out[lo : lo + 256] = (onehot.T @ f.T).T
        return out
    # cells of about per_cell particles
    L = max(np.sqrt(per_cell * float(np.mean(area))), 1e-300)
    key = np.floor((P - P.min(axis=0)) / L).astype(np.int64)
    dims = key.max(axis=0) + 1
    lin = (key[:, 0] * dims[1] + key[:, 1]) * dims[2] + key[:, 2]
    _, cell = unique_sorted(lin, return_inverse=True)
    cell = cell.ravel()
    nc = int(cell.max()) + 1
    order = np.argsort(cell, kind="stable").astype(np.int64)
    cstart = np.concatenate([[0], np.cumsum(np.bincount(cell, minlength=nc))]).astype(np.int64)
    wsum = np.bincount(cell, weights=area, minlength=nc)
    ccen = np.stack([np.bincount(cell, weights=area * P[:, a], minlength=nc) for a in range(3)], axis=1) / wsum[:, None]
    d2 = np.einsum("ij,ij->i", P - ccen[cell], P - ccen[cell])
    crad2 = np.zeros(nc)
    np.maximum.at(crad2, cell, d2)
    akey = cell * n_labels + label
    ukey, ainv = unique_sorted(akey, return_inverse=True)
    ainv = ainv.ravel()
    na = ukey.size
    aw = np.bincount(ainv, weights=area, minlength=na)
    apos = np.stack([np.bincount(ainv, weights=area * P[:, a], minlength=na) for a in range(3)], axis=1) / aw[:, None]
    adip = np.stack([np.bincount(ainv, weights=An[:, a], minlength=na) for a in range(3)], axis=1)
    alab = (ukey % n_labels).astype(np.int64)
    aptr = np.searchsorted(ukey // n_labels, np.arange(nc + 1)).astype(np.int64)
    nq = Q.shape[0]
    n_chunks = max(1, min(64, nq // 64))
    bounds = np.linspace(0, nq, n_chunks + 1).astype(np.int64)

    def job(c):
        winding_rows(bounds[c], bounds[c + 1], Q, P, An, eps2, label, order, cstart, ccen, crad2, aptr, alab, apos, adip, theta**2, out)

    run_chunks(job, n_chunks)
    return out


def best_signs(H: np.ndarray, g: np.ndarray, blocks: np.ndarray, margin: np.ndarray | None = None) -> np.ndarray:
    """Greedy minimum of ``s^T H s - 2 g^T s`` over s in {-1, 1}^n from s = 1 (diagonal of H ignored).

    Moves: single entries, and whole blocks (rows of the 0/1 matrix ``blocks``). An entry
    with a ``margin`` leaves +1 only where that lowers the energy by more than its margin.
    """
    H = H.copy()
    np.fill_diagonal(H, 0.0)
    s = np.ones(H.shape[0])
    tol = 1e-12 * (np.abs(H).sum() + np.abs(g).sum() + 1e-300)
    for _ in range(4 * H.shape[0] + 20):
        Hs = H @ s
        d1 = 4.0 * s * (g - Hs)  # energy change of flipping one entry
        if margin is not None:
            d1 = d1 + np.where(s > 0, margin, 0.0)
        j = int(np.argmin(d1))
        if d1[j] < -tol:
            s[j] = -s[j]
            continue
        X = blocks * s[None, :]
        dB = -4.0 * X @ Hs + 4.0 * np.einsum("bi,bi->b", X @ H, X) + 4.0 * X @ g
        b = int(np.argmin(dB)) if dB.size else -1
        if b >= 0 and dB[b] < -tol:
            s[blocks[b] > 0] *= -1.0
            continue
        break
    return s


def objective(W: np.ndarray, label: np.ndarray, omega: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``H, g`` of ``sum_p omega_p [(w_in - w_out - 1)^2 + (w_in + w_out - 1)^2]`` in the signs of the labels.

    ``W`` (2 m, L): the winding number of every label at the inner probes (first ``m`` rows) and
    the outer probes of ``m`` particles of labels ``label`` (m,), weights ``omega`` (m,). Flipping
    label ``l`` negates its field and swaps the probes of its own particles, so the objective is
    ``s^T H s - 2 g^T s`` plus a constant in the signs ``s`` (:func:`best_signs`).
    """
    m = label.size
    w_in, w_out = W[:m], W[m:]
    D, S = w_in - w_out, w_in + w_out
    M = np.zeros((W.shape[1], W.shape[1]))
    np.add.at(M, label, omega[:, None] * D)
    H = D.T @ (omega[:, None] * D) + S.T @ (omega[:, None] * S) - (M + M.T)
    return H, omega @ S


def integer_signs(W: np.ndarray, label: np.ndarray, s0: np.ndarray, weight: np.ndarray, blocks: np.ndarray | None = None,
                  max_moves: int | None = None) -> np.ndarray:
    """Signs of the labels that make the winding number a whole number of parts at the probes, greedily.

    For outward normals of closed parts that may cross each other, the winding number at a point
    is the number of parts containing it: across a particle it drops by 1 (``w_in - w_out = 1``)
    and just outside it is a whole number (``w_out`` in 0, 1, 2, ...). Each probe pair costs
    ``(w_in - w_out - 1)^2 + dist(w_out, {0, 1, 2, ...})^2``. Unlike the target ``w_in + w_out = 1``
    of :func:`objective`, a part crossing another is not pushed to flip where it lies inside it.

    Parameters
    ----------
    W : ndarray, shape (2 m, L)
        Field of every label, with the signs ``s0``, at the inner probes (first ``m`` rows) and the
        outer probes of ``m`` particles.
    label : ndarray of int, shape (m,)
        The label of each probed particle (a flipped label swaps its own probes).
    s0 : ndarray, shape (L,)
        The starting signs (+1: as in ``W``); moves flip single labels, or the rows of ``blocks``.
    weight : ndarray, shape (m,)
        Weight of each probe pair (its particle's area).

    Returns
    -------
    ndarray, shape (L,)
        The signs (+1 or -1) relative to those of ``W``.
    """
    m = label.size
    Win, Wout = W[:m], W[m:]
    n_labels = W.shape[1]
    s = np.asarray(s0, dtype=np.float64).copy()
    blocks = np.zeros((0, n_labels)) if blocks is None else blocks
    moves = np.vstack([np.eye(n_labels), blocks]) if blocks.size else np.eye(n_labels)
    own = np.zeros((m, moves.shape[0]), dtype=bool)
    own[np.arange(m)] = moves[:, label].T > 0

    def cost(a, b):
        whole = np.maximum(np.round(b), 0.0)
        return (a - b - 1.0) ** 2 + (b - whole) ** 2

    def fields(signs):
        a = Win @ signs
        b = Wout @ signs
        flipped = signs[label] < 0  # a flipped label's probes swap sides
        return np.where(flipped, b, a), np.where(flipped, a, b)

    a, b = fields(s)
    current = weight @ cost(a, b)
    for _ in range(moves.shape[0] if max_moves is None else max_moves):
        # the field after each move: minus twice the moved labels' contributions, own probes swapped
        dA = np.hstack([Win * s[None, :], Win @ (blocks * s[None, :]).T])
        dB = np.hstack([Wout * s[None, :], Wout @ (blocks * s[None, :]).T])
        fa = s[label] < 0
        raw_in = np.where(fa, b, a)  # the field at the (fixed) inner and outer probe locations
        raw_out = np.where(fa, a, b)
        new_in = raw_in[:, None] - 2.0 * dA
        new_out = raw_out[:, None] - 2.0 * dB
        flip_own = own ^ fa[:, None]  # the probe's particle flipped after the move
        A = np.where(flip_own, new_out, new_in)
        B = np.where(flip_own, new_in, new_out)
        total = weight @ cost(A, B)
        j = int(np.argmin(total))
        if total[j] >= current - 1e-12 * (abs(current) + 1e-300):
            break
        s[moves[j] > 0] *= -1.0
        a, b = fields(s)
        current = weight @ cost(a, b)
    return s


@(numba.njit(nogil=True, cache=True, fastmath=True, error_model="numpy") if numba is not None else (lambda f: f))
def winding_rows(lo: int, hi: int, Q: np.ndarray, P: np.ndarray, An: np.ndarray, eps2: np.ndarray, label: np.ndarray, order: np.ndarray,
                 cstart: np.ndarray, ccen: np.ndarray, crad2: np.ndarray, aptr: np.ndarray, alab: np.ndarray, apos: np.ndarray,
                 adip: np.ndarray, theta2: float, out: np.ndarray) -> None:
    """Winding number per label at queries ``lo:hi``: exact over near cells, one dipole per (cell, label) far."""
    c4 = 1.0 / (4.0 * np.pi)
    for i in range(lo, hi):
        qx, qy, qz = Q[i, 0], Q[i, 1], Q[i, 2]
        for c in range(ccen.shape[0]):
            dx = ccen[c, 0] - qx
            dy = ccen[c, 1] - qy
            dz = ccen[c, 2] - qz
            if (dx * dx + dy * dy + dz * dz) * theta2 > crad2[c]:
                for a in range(aptr[c], aptr[c + 1]):
                    rx = apos[a, 0] - qx
                    ry = apos[a, 1] - qy
                    rz = apos[a, 2] - qz
                    r2 = rx * rx + ry * ry + rz * rz
                    out[i, alab[a]] += c4 * (adip[a, 0] * rx + adip[a, 1] * ry + adip[a, 2] * rz) / (r2 * np.sqrt(r2))
            else:
                for s in range(cstart[c], cstart[c + 1]):
                    j = order[s]
                    rx = P[j, 0] - qx
                    ry = P[j, 1] - qy
                    rz = P[j, 2] - qz
                    r2 = rx * rx + ry * ry + rz * rz + eps2[j]
                    out[i, label[j]] += c4 * (An[j, 0] * rx + An[j, 1] * ry + An[j, 2] * rz) / (r2 * np.sqrt(r2))
