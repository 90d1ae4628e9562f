"""Array helpers shared by the normals modules."""

from __future__ import annotations

import numpy as np

__all__ = ["unique_sorted"]


def unique_sorted(x: np.ndarray, return_inverse: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """The sorted distinct values of the integer array ``x`` (and the index of each entry's value).

    The same as ``np.unique`` (the inverse flat), by one sort: numpy 2's ``np.unique`` without
    ``return_inverse`` hashes, which for the 2.4 million edge keys of 100,000 points with 24
    neighbours took 2-7 s where one sort takes 0.02-0.06 s (2 busy cores).

    Examples
    --------
    >>> unique_sorted(np.array([5, 3, 5, 1]))
    array([1, 3, 5])
    >>> unique_sorted(np.array([5, 3, 5, 1]), return_inverse=True)[1]
    array([2, 1, 2, 0])
    """
    x = np.asarray(x).ravel()
    order = np.argsort(x) if return_inverse else None
    s = x[order] if return_inverse else np.sort(x)
    first = np.empty(s.size, dtype=bool)
    first[:1] = True
    first[1:] = s[1:] != s[:-1]
    u = s[first]
    if not return_inverse:
        return u
    inv = np.empty(x.size, dtype=np.int64)
    inv[order] = np.cumsum(first) - 1
    return u, inv
