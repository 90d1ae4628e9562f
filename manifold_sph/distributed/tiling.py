"""Cutting a cloud into tiles: a k-d split or a regular grid, and the geometry of tile boxes."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["MIN_TILE_POINTS", "all_rows", "grid_tiles", "kd_tiles", "margin"]

#: A grid's neighbouring non-empty cells are merged until each tile owns at least this many
#: particles (a tile of a few particles costs a whole halo, and a fine grid of a small cloud
#: would otherwise make thousands of tasks).
MIN_TILE_POINTS = 64


def kd_tiles(pts: np.ndarray, tile_points: int, lo: np.ndarray, hi: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
    """k-d split at medians along the box's longest side until every leaf holds at most ``tile_points``.

    Returns the permutation (leaves in depth-first order, contiguous) and the leaf boxes (T, 2, 3).
    """
    order, boxes = [], []
    stack = [(np.arange(pts.shape[0]), lo.copy(), hi.copy())]
    while stack:
        idx, blo, bhi = stack.pop()
        if idx.size <= tile_points:
            order.append(idx)
            boxes.append(np.stack([blo, bhi]))
            continue
        ax = int(np.argmax(bhi - blo))
        c = pts[idx, ax]
        m = idx.size // 2
        part = np.argpartition(c, m)
        left, right = idx[part[:m]], idx[part[m:]]
        cut = 0.5 * (float(c[part[:m]].max()) + float(c[part[m:]].min()))
        lhi, rlo = bhi.copy(), blo.copy()
        lhi[ax] = rlo[ax] = cut
        stack.append((right, rlo, bhi))  # popped after the left half: depth-first, left first
        stack.append((left, blo, lhi))
    return order, np.array(boxes)


def grid_tiles(pts: np.ndarray, grid: ArrayLike, lo: np.ndarray, hi: np.ndarray,
               min_points: int = MIN_TILE_POINTS) -> tuple[list[np.ndarray], np.ndarray]:
    """A regular ``nx x ny x nz`` grid over the bounding box, without its empty cells.

    Non-empty cells are taken in ``(i, j, k)`` order and merged with the next ones until a
    tile owns at least ``min_points`` particles (the last tile joins the one before if it is
    short); a merged tile's box is the bounding box of its cells. Cells may be thinner than
    the kernel support: the halo handles that. The work is proportional to the non-empty
    cells, so a fine grid over a small cloud costs little.

    Returns the permutation (tiles contiguous) and the tile boxes (T, 2, 3).
    """
    g = np.asarray(grid, dtype=np.int64)
    span = np.where(hi > lo, hi - lo, 1.0)
    cell = np.minimum(((pts - lo) / span * g).astype(np.int64), g - 1)
    lin = (cell[:, 0] * g[1] + cell[:, 1]) * g[2] + cell[:, 2]
    srt = np.argsort(lin, kind="stable")
    used, starts, counts = np.unique(lin[srt], return_index=True, return_counts=True)
    ijk = np.stack(np.unravel_index(used, tuple(g)), axis=1)
    width = (hi - lo) / g
    cell_lo = lo + ijk * width
    cell_hi = np.where(ijk + 1 == g, hi, lo + (ijk + 1) * width)
    groups, cur, acc = [], [], 0
    for c in range(used.size):
        cur.append(c)
        acc += int(counts[c])
        if acc >= min_points:
            groups.append(cur)
            cur, acc = [], 0
    if cur:
        if groups:
            groups[-1].extend(cur)
        else:
            groups.append(cur)
    order, boxes = [], []
    for grp in groups:
        order.append(np.concatenate([srt[starts[c] : starts[c] + counts[c]] for c in grp]))
        boxes.append([cell_lo[grp].min(axis=0), cell_hi[grp].max(axis=0)])
    return order, np.array(boxes, dtype=np.float64).reshape(-1, 2, 3)


def margin(p: np.ndarray, elo: np.ndarray, ehi: np.ndarray, glo: np.ndarray, ghi: np.ndarray) -> np.ndarray:
    """Distance from each point to the faces of the box ``[elo, ehi]`` that lie inside the cloud's bounding box.

    Faces on or beyond the bounding box bound nothing (no point lies beyond them): they count as infinitely far.
    """
    m = np.full(p.shape[0], np.inf)
    for a in range(3):
        if elo[a] > glo[a]:
            m = np.minimum(m, p[:, a] - elo[a])
        if ehi[a] < ghi[a]:
            m = np.minimum(m, ehi[a] - p[:, a])
    return m


def all_rows(ok: np.ndarray, indptr: np.ndarray, indices: np.ndarray, rows: int) -> np.ndarray:
    """``out[i] = all(ok[indices[indptr[i]:indptr[i+1]]])`` for the first ``rows`` rows (empty rows give True)."""
    if rows == 0:
        return np.zeros(0, dtype=bool)
    bad = (~ok[indices[: indptr[rows]]]).astype(np.int64)
    owner = np.repeat(np.arange(rows), np.diff(indptr[: rows + 1]))
    return np.bincount(owner, weights=bad, minlength=rows) == 0
