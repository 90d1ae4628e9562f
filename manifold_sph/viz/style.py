"""The defaults that make a picture show its field: colour limits and maps, the up axis, splat sizes, titles.

Used by every renderer of :mod:`.render` and by the command line, so that a picture looks
the same whichever way it is asked for:

- :func:`color_limits`: a robust range by default (the 2-98 % percentiles, narrowed to
  two robust standard deviations around the median when the tails are heavy, as curvature
  and Laplacians on scans have), non-finite values left out;
- :func:`field_colormap`: a diverging map centred at 0 for signed fields (each sign
  scaled on its own, so that 0 is the neutral middle colour and both ends are used),
  a sequential one otherwise;
- :func:`detect_up_axis`: the axis the object stands on (the widest footprint of its
  lowest slice), on the coordinate axes or, for a rotated cloud, its principal axes;
- :func:`splat_radii`: the radius of each point's disc, from its own spacing;
- :func:`fit_title`: a font size (and a line break) that fits a title in the window.

Examples
--------
>>> import numpy as np
>>> color_limits(np.r_[np.linspace(0.0, 1.0, 99), 50.0], robust=False)
(0.0, 50.0)
>>> color_limits(np.r_[np.linspace(0.0, 1.0, 99), 50.0], robust=True)
(0.02, 0.99)
"""

from __future__ import annotations

import numbers
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import check_positive

__all__ = [
    "NAN_COLOR",
    "DIVERGING",
    "SEQUENTIAL",
    "color_limits",
    "field_colormap",
    "detect_up_axis",
    "up_vector",
    "splat_radii",
    "fit_title",
    "colour_spread",
]

#: The colour of points whose value is NaN or infinite (e.g. particles a geodesic did not reach).
NAN_COLOR = "#3c3c3c"
#: The colour maps chosen by ``cmap="auto"``: diverging for signed fields (its middle, light
#: grey, stays visible on a white background), sequential otherwise.
DIVERGING = "coolwarm"
SEQUENTIAL = "viridis"

#: ``robust=True``: the percentage clipped at each end, and the number of robust standard
#: deviations (1.4826 median absolute deviations) around the median the range is narrowed to.
ROBUST_PERCENT = 2.0
ROBUST_SIGMAS = 2.0


def color_limits(
    values: ArrayLike, clim: tuple[float, float] | None = None, robust: float | bool | None = None
) -> tuple[float, float]:
    """Colour limits of a field: explicit, full range, or robust.

    Parameters
    ----------
    values : array_like
        A scalar field (or several stacked); NaN and inf are left out (they are drawn in
        :data:`NAN_COLOR`), but at least one value must be finite.
    clim : (float, float), optional
        Explicit limits ``(low, high)``, returned as given (``low < high``).
    robust : bool or float, optional
        ``True``: the 2-98 % percentiles, narrowed to 2 robust standard deviations
        (1.4826 median absolute deviations) around the median when the tails are heavier
        than a normal distribution's (so that the large values curvature and Laplacians
        take at the tips and creases of a scan do not wash out the rest of the picture;
        measured on the test models, ``tests/test_render.py``); a field equal to one value
        on most of the cloud (within 1e-3 of the percentile range) keeps the percentiles.
        A number ``p``: the ``p`` to ``100 - p`` percentiles only. ``None`` or ``False``:
        the full range.

    Returns
    -------
    (float, float)
        Rounded outwards to 3 significant digits of the range; a constant field
        gets a small range around its value.

    Examples
    --------
    >>> v = np.r_[np.linspace(0.0, 1.0, 99), 50.0]
    >>> color_limits(v)
    (0.0, 50.0)
    >>> color_limits(v, robust=2)
    (0.02, 0.99)
    >>> color_limits(v, clim=(0, 2))
    (0.0, 2.0)
    >>> color_limits([3.0, 3.0])
    (2.97, 3.03)
    >>> heavy = np.r_[np.linspace(-1.0, 1.0, 90), np.linspace(20.0, 40.0, 10)]
    >>> color_limits(heavy, robust=2), color_limits(heavy, robust=True)
    ((-1.0, 35.6), (-0.96, 1.78))
    """
    if clim is not None:
        if isinstance(clim, (str, bytes)) or not isinstance(clim, Sequence) or len(clim) != 2:
            raise TypeError(f"clim must be a pair (low, high) of numbers, got {clim!r}")
        if not all(isinstance(c, numbers.Real) and not isinstance(c, bool) for c in clim):
            raise TypeError(f"clim must be a pair (low, high) of numbers, got {clim!r}")
        if not all(np.isfinite(c) for c in clim):
            raise ValueError(f"clim must be finite, got {clim!r}")
        lo, hi = float(clim[0]), float(clim[1])
        if not lo < hi:
            raise ValueError(f"clim must satisfy low < high, got {clim!r}")
        return lo, hi
    v = np.asarray(values, dtype=np.float64).ravel()
    if v.size == 0:
        raise ValueError("values must hold at least one value to choose colour limits")
    v = v[np.isfinite(v)]
    if v.size == 0:
        raise ValueError("values must hold at least one finite value to choose colour limits, got only NaN or inf")
    if robust is None or robust is False:
        lo, hi = float(v.min()), float(v.max())
    else:
        p = ROBUST_PERCENT if robust is True else check_positive("robust", robust)
        if p >= 50:
            raise ValueError(f"robust must be a percentage below 50, got {robust!r}")
        lo, hi = (float(x) for x in np.percentile(v, [p, 100.0 - p]))
        if robust is True:
            med = float(np.median(v))
            sigma = 1.4826 * float(np.median(np.abs(v - med)))
            if sigma > 1e-3 * (hi - lo):  # not a field constant on most of the cloud (a heat bump on zero)
                lo, hi = max(lo, med - ROBUST_SIGMAS * sigma), min(hi, med + ROBUST_SIGMAS * sigma)
    if hi - lo <= 1e-12 * max(1.0, abs(hi), abs(lo)):
        d = 0.01 * max(abs(lo), 1e-12) if lo != 0 else 1e-3
        lo, hi = lo - d, hi + d
    # round outwards to 3 significant digits of the range: tidy colour-bar labels, nothing clipped
    e = int(np.floor(np.log10(hi - lo))) - 2
    m = 10.0**e
    digits = max(-e, 0)
    lo_r = round(np.floor(lo / m) * m, digits)
    hi_r = round(np.ceil(hi / m) * m, digits)
    return float(lo_r), float(hi_r)


def field_colormap(lo: float, hi: float, cmap: Any = "auto") -> Any:
    """The colour map of a field drawn between ``lo`` and ``hi``.

    ``cmap="auto"``: for a signed range (``lo < 0 < hi``) :data:`DIVERGING` with its middle
    at 0, each sign stretched over its own half (a two-slope map: -2 and 30 both get the
    deepest colours, 0 the middle one), else :data:`SEQUENTIAL`. Any other value (a
    matplotlib name or colour map) is returned as given.

    Examples
    --------
    >>> field_colormap(0.0, 1.0)
    'viridis'
    >>> cm = field_colormap(-1.0, 3.0)
    >>> [round(float(c), 2) for c in cm(0.25)[:3]] == [round(float(c), 2) for c in cm(0.5)[:3]]
    False
    """
    if not (isinstance(cmap, str) and cmap == "auto"):
        return cmap
    if not lo < 0 < hi:
        return SEQUENTIAL
    from matplotlib import colormaps
    from matplotlib.colors import ListedColormap

    base = colormaps[DIVERGING]
    x = np.linspace(lo, hi, 256)
    pos = np.where(x < 0, 0.5 * (1.0 - x / lo), 0.5 + 0.5 * x / hi)
    return ListedColormap(base(pos), name=f"{DIVERGING}_centred")


# ----------------------------------------------------------------------------- up axis
_AXES = {"x": 0, "y": 1, "z": 2}
#: The slice of the object (fraction of its height) whose footprint says which way is down.
_FOOT_SLICE = 0.03


def _footprint(points: np.ndarray, axis: np.ndarray, others: np.ndarray) -> float:
    """The area of the lowest slice of ``points`` along ``axis`` (its 2D convex hull in the
    directions ``others``), relative to the object's extent in those directions."""
    from scipy.spatial import ConvexHull, QhullError

    h = points @ axis
    low = points[h <= h.min() + _FOOT_SLICE * np.ptp(h)] @ others.T
    ext = np.ptp(points @ others.T, axis=0)
    if len(low) < 3 or ext.min() <= 0:
        return 0.0
    try:
        return float(ConvexHull(low).volume / (ext[0] * ext[1]))
    except (QhullError, ValueError):
        return 0.0


def _as_xyz(points: Any) -> np.ndarray:
    from ..pointcloud import as_cloud, is_point_array

    p = np.asarray(points if is_point_array(points) else as_cloud(points).points, dtype=np.float64)
    if p.ndim == 2 and p.shape[1] == 2:
        p = np.column_stack([p, np.zeros(len(p))])
    return p


def detect_up_axis(points: ArrayLike) -> str | tuple[float, float, float]:
    """The up axis of a cloud: the direction it stands on.

    The object is taken to rest on the end of the axis whose lowest slice (3 % of the
    height) covers the widest area (hooves, wheels, the base of a bust, the bottom of a
    teapot; a head, a nose, a bumper are narrow). Among the coordinate axes y and z
    (x is never up: no file convention has it); a near tie (within 25 %) goes to z for
    clouds flat in z or as wide in every direction (the package's shapes, tori), else to
    the longer of y and z (y when they are within 5 %: the graphics convention). A planar cloud
    is seen from its normal; a flat one (smallest principal axis below 2 % of the largest: terrain, a wall) turned more than 10 degrees
    off the coordinate axes from its principal normal, returned as a unit vector.

    Measured on the test models (``tests/test_render.py``): cow, homer, cheburashka,
    teapot, beetle, the bunny and Igea y; a horse and the Nefertiti bust (z up in their
    files) z; the planar alligator z.

    Parameters
    ----------
    points : array_like (N, 3) or (N, 2), or anything point-like (:func:`manifold_sph.as_cloud`)

    Returns
    -------
    str or (float, float, float)
        ``"y"`` or ``"z"`` (``"x"`` for a cloud planar in x), or a unit vector for a turned flat cloud.

    Examples
    --------
    >>> from manifold_sph.reference import shapes
    >>> detect_up_axis(shapes.torus(400).points), detect_up_axis(shapes.sphere(400).points)
    ('z', 'z')
    >>> rng = np.random.default_rng(0)
    >>> legs = np.concatenate([rng.random((400, 3)) * [0.1, 1.0, 0.1] + [dx, 0, dz]
    ...                        for dx in (0, 0.9) for dz in (0, 0.5)])
    >>> table = np.concatenate([legs, rng.random((1600, 3)) * [1.0, 0.05, 0.6] + [0, 1.0, 0]])
    >>> detect_up_axis(table)       # stands on its four legs, y up
    'y'
    >>> detect_up_axis(table[:, [0, 2, 1]])
    'z'
    """
    p = _as_xyz(points)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < 4:
        return "z"
    if len(p) > 20000:  # the footprint needs the shape, not every point
        p = p[np.random.default_rng(0).choice(len(p), 20000, replace=False)]
    ext = np.ptp(p, axis=0)
    top = float(ext.max())
    if top <= 0:
        return "z"
    if ext.min() <= 1e-6 * top:  # planar: seen from its normal
        return "xyz"[int(np.argmin(ext))]
    centred = p - p.mean(axis=0)
    _, sv, vt = np.linalg.svd(centred[:: max(1, len(p) // 5000)], full_matrices=False)
    if sv[-1] <= 0.02 * sv[0] and np.abs(vt[-1]).max() < np.cos(np.radians(10.0)):
        n = vt[-1] * (1.0 if vt[-1][2] >= 0 else -1.0)  # a flat cloud turned off the axes: its normal, towards +z
        return float(n[0]), float(n[1]), float(n[2])
    eye = np.eye(3)
    fy = _footprint(p, eye[1], eye[[0, 2]])
    fz = _footprint(p, eye[2], eye[[0, 1]])
    if max(fy, fz) > 1.25 * min(fy, fz) + 0.02:
        return "y" if fy > fz else "z"
    if ext[2] <= 0.25 * top or np.ptp(ext) <= 0.05 * top:
        return "z"
    return "z" if ext[2] > 1.05 * ext[1] else "y"


def up_vector(points: ArrayLike, up: Any = "auto") -> np.ndarray:
    """The up direction as a unit vector from ``up``: "auto" (:func:`detect_up_axis`), "x", "y",
    "z" (a leading "-" turns it over), or a 3-vector."""
    if isinstance(up, str):
        axis = up.lstrip("+-")
        if axis not in ("auto", "x", "y", "z") or (axis == "auto" and up != "auto"):
            raise ValueError(f"up must be one of 'auto', 'x', 'y', 'z' (or '-x', '-y', '-z') or a 3-vector, got {up!r}")
        if axis == "auto":
            found = detect_up_axis(points)
            return up_vector(points, found)
        v = np.eye(3)[_AXES[axis]]
        return -v if up.startswith("-") else v
    if isinstance(up, (bool, numbers.Number)) or up is None:
        raise TypeError(f"up must be one of 'auto', 'x', 'y', 'z' (a string) or a 3-vector, got {type(up).__name__} {up!r}")
    try:
        v = np.asarray(up, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"up must be one of 'auto', 'x', 'y', 'z' (a string) or a 3-vector, got {up!r}") from None
    if v.shape != (3,) or not np.all(np.isfinite(v)) or not np.linalg.norm(v) > 0:
        raise ValueError(f"up must be a non-zero finite 3-vector, got {up!r}")
    return v / np.linalg.norm(v)


# ----------------------------------------------------------------------------- sizes and titles
def splat_radii(points: np.ndarray, k: int = 6, factor: float = 0.7) -> np.ndarray:
    """Disc radius of each point: ``factor`` times its distance to its ``k``-th nearest neighbour,
    enough to close the gaps between neighbours on adaptive and random samples without
    covering the next part of a thin object."""
    from scipy.spatial import cKDTree

    n = len(points)
    if n < 2:
        return np.ones(n)
    kk = min(k, n - 1)
    d, _ = cKDTree(points).query(points, k=kk + 1)
    r = factor * d[:, kk]
    positive = r[r > 0]
    fallback = float(np.median(positive)) if positive.size else 1.0
    return np.where(r > 0, r, fallback)


#: Width of one character in pixels per point of font size (VTK's default Arial, measured).
_CHAR_WIDTH = 1.35


def fit_title(text: str, width: int, largest: int, smallest: int = 6, max_lines: int = 3) -> tuple[str, int]:
    """``(text, font size)`` that fits ``width`` pixels: one line in the largest size up to
    ``largest`` if that is at least ``smallest``, else broken at spaces into up to
    ``max_lines`` lines (the last one shortened with "..." if even that is too long).

    Examples
    --------
    >>> fit_title("H", 640, 12)
    ('H', 12)
    >>> fit_title("mean curvature H (msph) of a very long file name.ply", 800, 12)
    ('mean curvature H (msph) of a very long file name.ply', 10)
    >>> fit_title("mean curvature H (msph) of a very long file name.ply", 400, 12)
    ('mean curvature H (msph) of\\na very long file name.ply', 10)
    """
    import textwrap

    text = " ".join(str(text).split())

    def size_for(lines: list[str]) -> int:
        longest = max((len(line) for line in lines), default=1) or 1
        return int(min(largest, np.floor(0.94 * width / (_CHAR_WIDTH * longest))))

    if size_for([text]) >= smallest:
        return text, size_for([text])
    room = max(int(0.94 * width / (_CHAR_WIDTH * smallest)), 4)  # characters a line holds at the smallest size
    for n in range(2, max_lines + 1):
        lines = textwrap.wrap(text, width=max(-(-len(text) // n), 1), break_long_words=False)
        if len(lines) <= n and size_for(lines) >= smallest:
            return "\n".join(lines), size_for(lines)
    lines = textwrap.wrap(text, width=room, break_long_words=True)
    if len(lines) > max_lines:
        lines = lines[:max_lines]
        lines[-1] = lines[-1][: room - 3].rstrip() + "..."
    return "\n".join(lines), max(size_for(lines), smallest)


def colour_spread(image: np.ndarray, cmap: Any, background: tuple[int, int, int] = (255, 255, 255),
                  bins: int = 16) -> float:
    """How much of the colour map the object's pixels of a rendered picture use: the entropy
    (bits) of the colour-map positions of its pixels, ``log2(bins)`` when every part of the
    map is equally used, 0 for a picture of one colour.

    Each pixel not of the background colour (nor too dark to tell) is given the position
    in ``cmap`` (a name or colour map, as passed to the renderer, e.g. the result of
    :func:`field_colormap`) of the map colour with the nearest chromaticity (colour divided
    by brightness, which shading does not change).
    """
    from matplotlib import colormaps

    cm = colormaps[cmap] if isinstance(cmap, str) else cmap
    lut = np.asarray(cm(np.linspace(0.0, 1.0, 256)))[:, :3] * 255.0
    img = np.asarray(image, dtype=np.float64)[..., :3].reshape(-1, 3)
    bright = img.sum(axis=1)
    obj = (np.abs(img - np.asarray(background, dtype=np.float64)).max(axis=1) > 12) & (bright > 60)
    if not obj.any():
        return 0.0
    chroma = img[obj] / bright[obj, None]
    lut_chroma = lut / np.maximum(lut.sum(axis=1), 1e-9)[:, None]
    from scipy.spatial import cKDTree

    _, idx = cKDTree(lut_chroma).query(chroma)
    hist, _ = np.histogram(idx / 255.0, bins=bins, range=(0.0, 1.0))
    p = hist[hist > 0] / hist.sum()
    return float(-(p * np.log2(p)).sum())
