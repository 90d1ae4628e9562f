"""Error measures and convergence studies (docs/method.md section 5; [1] eqs. 2.32, 2.35).

Pointwise measures (one value per point): :func:`absolute_error`,
:func:`relative_error`, :func:`phase_error`. Global measures (one number):
:func:`l2_error`, :func:`linf_error`, :func:`error_summary`. Distribution of
pointwise errors: :func:`boxplot_summary` (Tukey boxplot, as in the thesis [1]).
Convergence: :func:`fit_order` and :func:`convergence_study`.

Fields are scalar ``(N,)`` or vector ``(N, d)``; for vector fields the
pointwise error is the Euclidean norm of the difference at each point.

Examples
--------
>>> exact = np.array([1.0, 2.0, 4.0])
>>> approx = np.array([1.1, 2.0, 3.6])
>>> np.round(relative_error(approx, exact), 6)
array([0.1, 0. , 0.1])
>>> round(linf_error(approx, exact), 6)
0.1
"""

from __future__ import annotations

import math
import numbers
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import check_bool, check_finite, check_in, check_int, check_positive
from ..exceptions import ManifoldSPHWarning
from ..results import Result

__all__ = [
    "absolute_error",
    "relative_error",
    "phase_error",
    "l2_error",
    "linf_error",
    "error_summary",
    "BoxplotSummary",
    "boxplot_summary",
    "fit_order",
    "ConvergenceTable",
    "convergence_study",
]


# --- validation helpers ---------------------------------------------------------


def _as_array(name: str, a) -> np.ndarray:
    try:
        arr = np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a numeric array of shape (N,) or (N, d), got {type(a).__name__}") from exc
    return arr


def _pair(approx, exact, *, vectors: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Validate a pair of fields: same shape, (N,) or (N, d), N >= 1, finite."""
    a = _as_array("approx", approx)
    e = _as_array("exact", exact)
    if a.shape != e.shape:
        raise ValueError(f"approx and exact must have the same shape, got approx shape {a.shape} and exact shape {e.shape}")
    if vectors:
        if a.ndim != 2:
            raise ValueError(f"approx and exact must be vector fields of shape (N, d), got shape {a.shape}")
    elif a.ndim not in (1, 2):
        raise ValueError(f"approx and exact must have shape (N,) or (N, d), got shape {a.shape}")
    if a.shape[0] == 0:
        raise ValueError("approx and exact must hold at least one point, got N = 0")
    check_finite("approx", a)
    check_finite("exact", e)
    return a, e


def _pointwise_norm(a: np.ndarray) -> np.ndarray:
    return np.abs(a) if a.ndim == 1 else np.linalg.norm(a, axis=1)


# --- pointwise measures ---------------------------------------------------------


def absolute_error(approx: ArrayLike, exact: ArrayLike) -> np.ndarray:
    """Pointwise absolute error ``e_a = |approx - exact|`` ([1] eq. 2.32).

    Parameters
    ----------
    approx, exact : array_like, shape (N,) or (N, d)
        Approximate and exact fields, same shape, finite.

    Returns
    -------
    numpy.ndarray, shape (N,)
        ``|approx_i - exact_i|``; for vector fields the Euclidean norm of the
        difference at each point.

    Raises
    ------
    ValueError
        Shapes differ, wrong number of dimensions, or NaN/inf in an input.

    Examples
    --------
    >>> absolute_error([[3.0, 0.0], [1.0, 1.0]], [[0.0, 4.0], [1.0, 1.0]])
    array([5., 0.])
    """
    a, e = _pair(approx, exact)
    return _pointwise_norm(a - e)


def relative_error(approx: ArrayLike, exact: ArrayLike, floor: float = 1e-6) -> np.ndarray:
    """Pointwise relative error ``|approx - exact| / max(|exact|, floor)``.

    The thesis [1] (eq. 2.32) uses a lower bound of ``1e-6`` on ``|exact|`` to avoid
    dividing by (nearly) zero; that is the ``floor`` here. Where
    ``|exact| < floor`` the value is the absolute error divided by ``floor``.

    Parameters
    ----------
    approx, exact : array_like, shape (N,) or (N, d)
        Approximate and exact fields (norms per point for vector fields).
    floor : float, optional
        Positive lower bound applied to ``|exact|`` (default 1e-6).

    Returns
    -------
    numpy.ndarray, shape (N,)

    Examples
    --------
    >>> relative_error([2.0, 1e-7], [1.0, 0.0], floor=1e-6)
    array([1. , 0.1])
    """
    floor = check_positive("floor", floor)
    a, e = _pair(approx, exact)
    return _pointwise_norm(a - e) / np.maximum(_pointwise_norm(e), floor)


def phase_error(approx: ArrayLike, exact: ArrayLike, floor: float = 1e-12) -> np.ndarray:
    """Pointwise angle, in radians, between approximate and exact vectors ([1] eq. 2.35).

    ``e_f = arccos(<a, e> / (|a| |e|))``, evaluated as
    ``2 atan2(|a^ - e^|, |a^ + e^|)`` on the unit vectors (accurate also
    for tiny and near-pi angles). Values lie in ``[0, pi]``.

    The angle is undefined when a vector is zero ([1] leaves it out).
    NaN-free rule used here, with ``|v| < floor`` meaning "zero":

    - both vectors zero: 0 (they agree);
    - exactly one zero: ``pi / 2`` (no direction information: orthogonal,
      the mean angle to a uniformly random direction).

    Parameters
    ----------
    approx, exact : array_like, shape (N, d)
        Vector fields, same shape.
    floor : float, optional
        Norm below which a vector counts as zero (absolute, default 1e-12).

    Returns
    -------
    numpy.ndarray, shape (N,)

    Examples
    --------
    >>> a = [[1.0, 0.0], [0.0, 0.0], [0.0, 0.0], [1.0, 1.0]]
    >>> e = [[0.0, 2.0], [0.0, 0.0], [1.0, 0.0], [2.0, 2.0]]
    >>> np.round(phase_error(a, e) / np.pi, 6)
    array([0.5, 0. , 0.5, 0. ])
    """
    floor = check_positive("floor", floor)
    a, e = _pair(approx, exact, vectors=True)
    na = np.linalg.norm(a, axis=1)
    ne = np.linalg.norm(e, axis=1)
    za, ze = na < floor, ne < floor
    ua = a / np.where(za, 1.0, na)[:, None]
    ue = e / np.where(ze, 1.0, ne)[:, None]
    ang = 2.0 * np.arctan2(np.linalg.norm(ua - ue, axis=1), np.linalg.norm(ua + ue, axis=1))
    ang = np.where(za | ze, np.where(za & ze, 0.0, 0.5 * np.pi), ang)
    return ang


# --- global measures --------------------------------------------------------------


def _zero_exact(kind: str) -> ValueError:
    return ValueError(f"the relative {kind} error is undefined: exact is identically zero; use relative=False")


def l2_error(approx: ArrayLike, exact: ArrayLike, relative: bool = True) -> float:
    """Global L2 error.

    - ``relative=True``: ``sqrt(sum_i |a_i - e_i|^2) / sqrt(sum_i |e_i|^2)``
      (ratio of Frobenius norms; ``|.|`` is the Euclidean norm per point for
      vector fields).
    - ``relative=False``: root mean square of the pointwise absolute error,
      ``sqrt(mean_i |a_i - e_i|^2)``.

    No area weights: with a uniform sampling this is the discrete L2 norm up
    to a constant factor (which cancels in the relative form).

    Raises
    ------
    ValueError
        Relative error with ``exact`` identically zero, or bad input.

    Examples
    --------
    >>> round(l2_error([1.0, 3.0], [0.0, 4.0]), 6)
    0.353553
    >>> round(l2_error([1.0, 3.0], [0.0, 4.0], relative=False), 6)
    1.0
    """
    relative = check_bool("relative", relative)
    a, e = _pair(approx, exact)
    diff2 = np.square(_pointwise_norm(a - e))
    if not relative:
        return float(np.sqrt(diff2.mean()))
    den = float(np.sqrt(np.square(_pointwise_norm(e)).sum()))
    if den == 0.0:
        raise _zero_exact("L2")
    return float(np.sqrt(diff2.sum())) / den


def linf_error(approx: ArrayLike, exact: ArrayLike, relative: bool = True) -> float:
    """Global maximum error.

    - ``relative=True``: ``max_i |a_i - e_i| / max_i |e_i|``;
    - ``relative=False``: ``max_i |a_i - e_i|``

    (``|.|`` the Euclidean norm per point for vector fields).

    Examples
    --------
    >>> linf_error([1.0, 3.0], [0.0, 4.0])
    0.25
    >>> linf_error([1.0, 3.0], [0.0, 4.0], relative=False)
    1.0
    """
    relative = check_bool("relative", relative)
    a, e = _pair(approx, exact)
    num = float(_pointwise_norm(a - e).max())
    if not relative:
        return num
    den = float(_pointwise_norm(e).max())
    if den == 0.0:
        raise _zero_exact("Linf")
    return num / den


def _as_mask(mask, n: int) -> np.ndarray:
    """Boolean mask of length n from a boolean mask or an array of indices."""
    m = np.asarray(mask)
    if m.dtype == bool:
        if m.shape != (n,):
            raise ValueError(f"mask must be a boolean array of shape ({n},) or an array of indices, got shape {m.shape}")
        return m
    if m.ndim != 1 or (m.size and not np.issubdtype(m.dtype, np.integer)):
        raise TypeError(f"mask must be a boolean array of shape ({n},) or a 1-D array of integer indices, "
                        f"got {m.dtype} array of shape {m.shape}")
    if m.size and (m.min() < -n or m.max() >= n):
        raise ValueError(f"mask indices must lie in [-{n}, {n}), got range [{m.min()}, {m.max()}]")
    out = np.zeros(n, dtype=bool)
    out[m.astype(np.intp)] = True
    return out


def error_summary(approx: ArrayLike, exact: ArrayLike, mask: ArrayLike | None = None) -> dict[str, Any]:
    """Global errors of a field in one dictionary.

    Parameters
    ----------
    approx, exact : array_like, shape (N,) or (N, d)
        Approximate and exact fields.
    mask : array_like of bool, shape (N,), or of int indices, optional
        Points to include (e.g. interior points away from a boundary);
        default all.

    Returns
    -------
    dict
        ``l2_rel``, ``linf_rel``, ``l2_abs``, ``linf_abs`` (as in
        :func:`l2_error` and :func:`linf_error`, float), ``argmax`` (index
        into the full, unmasked arrays of the point with the largest absolute
        error, int) and ``n`` (number of points used, int).

    Examples
    --------
    >>> s = error_summary([1.0, 3.0, 9.0], [0.0, 4.0, 1.0], mask=[True, True, False])
    >>> s["linf_abs"], s["argmax"], s["n"]
    (1.0, 0, 2)
    """
    a, e = _pair(approx, exact)
    n_all = a.shape[0]
    sel = np.ones(n_all, dtype=bool) if mask is None else _as_mask(mask, n_all)
    idx = np.flatnonzero(sel)
    if idx.size == 0:
        raise ValueError("mask selects no points; at least one is needed")
    a, e = a[idx], e[idx]
    abs_err = _pointwise_norm(a - e)
    return {
        "l2_rel": l2_error(a, e, relative=True),
        "linf_rel": linf_error(a, e, relative=True),
        "l2_abs": l2_error(a, e, relative=False),
        "linf_abs": float(abs_err.max()),
        "argmax": int(idx[int(np.argmax(abs_err))]),
        "n": int(idx.size),
    }


# --- boxplot ----------------------------------------------------------------------


@dataclass(frozen=True, repr=False)
class BoxplotSummary(Result):
    """Tukey boxplot statistics of a sample of pointwise errors ([1] fig. 14).

    Attributes
    ----------
    q1, median, q3 : float
        Quartiles (``numpy.percentile``, linear interpolation).
    iqr : float
        ``q3 - q1``.
    whisker_low, whisker_high : float
        Most extreme data values within ``[q1 - 1.5 iqr, q3 + 1.5 iqr]``.
    outliers : numpy.ndarray of int
        Indices (into the input) of the values outside that interval, sorted.
    n : int
        Sample size.

    Examples
    --------
    >>> b = boxplot_summary([1.0, 2.0, 3.0, 4.0, 100.0])
    >>> b.median, b.whisker_high, b.outliers.tolist()
    (3.0, 4.0, [4])
    >>> b.to_dict(json=True)["outliers"]
    [4]
    """

    q1: float
    median: float
    q3: float
    iqr: float
    whisker_low: float
    whisker_high: float
    outliers: np.ndarray
    n: int



def boxplot_summary(errors: ArrayLike) -> BoxplotSummary:
    """Tukey boxplot of a sample: quartiles, whiskers and outliers.

    Outliers are the values above ``q3 + 1.5 (q3 - q1)`` or below
    ``q1 - 1.5 (q3 - q1)`` ([1] sec. 2.3); the whiskers are the most
    extreme values that are not outliers.

    Parameters
    ----------
    errors : array_like, shape (N,)
        Finite sample, N >= 1 (typically pointwise errors).

    Returns
    -------
    BoxplotSummary

    Examples
    --------
    >>> b = boxplot_summary([0.0, 1.0, 2.0, 3.0, 4.0, -20.0])
    >>> b.q1, b.q3, b.whisker_low, b.outliers.tolist()
    (0.25, 2.75, 0.0, [5])
    """
    x = _as_array("errors", errors)
    if x.ndim != 1 or x.size == 0:
        raise ValueError(f"errors must be a non-empty 1-D array of shape (N,), got shape {x.shape}")
    check_finite("errors", x)
    q1, med, q3 = (float(v) for v in np.percentile(x, [25.0, 50.0, 75.0]))
    iqr = q3 - q1
    lo, hi = q1 - 1.5 * iqr, q3 + 1.5 * iqr
    out = (x < lo) | (x > hi)
    inside = x[~out]  # never empty: the median lies inside [q1, q3]
    return BoxplotSummary(
        q1=q1,
        median=med,
        q3=q3,
        iqr=iqr,
        whisker_low=float(inside.min()),
        whisker_high=float(inside.max()),
        outliers=np.flatnonzero(out),
        n=int(x.size),
    )


# --- convergence --------------------------------------------------------------------


def _check_sizes(sizes, kind: str) -> np.ndarray:
    try:
        s = np.asarray(sizes, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"sizes must be a 1-D numeric array, got {type(sizes).__name__}") from exc
    if s.ndim != 1 or s.size < 2:
        raise ValueError(f"sizes must be a 1-D array with at least 2 entries to fit an order, got shape {s.shape}")
    check_finite("sizes", s)
    if np.any(s <= 0):
        i = int(np.flatnonzero(s <= 0)[0])
        raise ValueError(f"sizes must be positive, got sizes[{i}] = {float(s[i])!r}")
    steps = np.diff(s)
    if kind == "N" and not np.all(steps > 0):
        raise ValueError(f"sizes must be strictly increasing for kind='N', got {s.tolist()}")
    if kind == "h" and not (np.all(steps > 0) or np.all(steps < 0)):
        raise ValueError(f"sizes must be strictly monotonic (increasing or decreasing) for kind='h', got {s.tolist()}")
    return s


def _check_errors(name: str, e, n: int) -> np.ndarray:
    try:
        arr = np.asarray(e, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a 1-D numeric array, got {type(e).__name__}") from exc
    if arr.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},) to match sizes, got shape {arr.shape}")
    check_finite(name, arr)
    if np.any(arr <= 0):
        i = int(np.flatnonzero(arr <= 0)[0])
        raise ValueError(
            f"{name} must be positive to fit an order on a log scale, got {name}[{i}] = {float(arr[i])!r} "
            "(a zero or negative error cannot be fitted)"
        )
    return arr


def _order_factor(kind: str, dim: int) -> float:
    """Multiply d log(e) / d log(size) by this to get the order p in e ~ h^p."""
    return -float(dim) if kind == "N" else 1.0


def fit_order(sizes: ArrayLike, errors: ArrayLike, kind: str = "N", dim: int = 2) -> float:
    """Convergence order from a least-squares fit of log(error) on log(size).

    Parameters
    ----------
    sizes : array_like, shape (M,), M >= 2
        Problem sizes: numbers of points N (``kind="N"``, strictly
        increasing) or spacings h (``kind="h"``, strictly monotonic).
    errors : array_like, shape (M,)
        Positive errors at those sizes.
    kind : {"N", "h"}
        ``"N"``: h ~ N^(-1/dim), so ``order = -dim * slope`` of log e vs
        log N. ``"h"``: ``order = slope`` of log e vs log h.
    dim : int
        Dimension of the point set (2 for surfaces and planar domains).

    Returns
    -------
    float
        p in ``error ~ C h^p``.

    Raises
    ------
    ValueError
        Fewer than 2 sizes, sizes not positive or not monotonic, shapes
        differ, or an error is zero, negative or not finite (the message
        names the entry).

    Examples
    --------
    >>> N = np.array([100, 400, 1600])
    >>> round(fit_order(N, 3.0 / N), 12)
    2.0
    >>> round(fit_order([0.1, 0.05], [4e-2, 1e-2], kind="h"), 12)
    2.0
    """
    check_in("kind", kind, ("N", "h"))
    dim = check_int("dim", dim, minimum=1)
    s = _check_sizes(sizes, kind)
    e = _check_errors("errors", errors, s.size)
    slope = np.polyfit(np.log(s), np.log(e), 1)[0]
    return float(_order_factor(kind, dim) * slope)


def _fmt_order(p: float) -> str:
    return "-" if not np.isfinite(p) else f"{p:.2f}"


@dataclass(repr=False)
class ConvergenceTable(Result):
    """Result of :func:`convergence_study`.

    Attributes
    ----------
    sizes : numpy.ndarray, shape (M,)
        The sizes, in the order run.
    errors : dict of str -> numpy.ndarray, shape (M,)
        Each named error at each size.
    orders : dict of str -> float
        Order fitted over all sizes (:func:`fit_order`); NaN when an error
        is not positive at some size (a warning says which).
    local_orders : dict of str -> numpy.ndarray, shape (M - 1,)
        Orders between consecutive sizes; NaN where undefined.
    kind : {"N", "h"}
    dim : int

    Examples
    --------
    >>> t = convergence_study([100, 400], lambda n: {"e": 1.0 / n})
    >>> round(t.orders["e"], 12)
    2.0
    >>> import json
    >>> d = json.loads(json.dumps(t.to_dict(json=True)))
    >>> d["sizes"], round(d["orders"]["e"], 12)
    ([100, 400], 2.0)
    """

    sizes: np.ndarray
    errors: dict[str, np.ndarray]
    orders: dict[str, float]
    local_orders: dict[str, np.ndarray]
    kind: str = "N"
    dim: int = 2
    names: list[str] = field(default_factory=list)

    def to_text(self) -> str:
        """Plain aligned table: sizes, each error (%.3e) and local orders, then fitted orders.

        Examples
        --------
        >>> t = convergence_study([100, 400], lambda n: {"e": 1.0 / n})
        >>> print(t.to_text())
          N          e  order
        100  1.000e-02      -
        400  2.500e-03   2.00
        fitted order:  e 2.00
        """
        head = ["N" if self.kind == "N" else "h"]
        for name in self.names:
            head += [name, "order"]
        rows = []
        for k, s in enumerate(self.sizes):
            size = f"{s:g}" if self.kind == "N" else f"{s:.4g}"
            row = [size]
            for name in self.names:
                row.append(f"{self.errors[name][k]:.3e}")
                row.append("-" if k == 0 else _fmt_order(self.local_orders[name][k - 1]))
            rows.append(row)
        widths = [max(len(r[c]) for r in [head, *rows]) for c in range(len(head))]
        lines = ["  ".join(cell.rjust(w) for cell, w in zip(r, widths)) for r in [head, *rows]]
        fitted = "  ".join(f"{name} {_fmt_order(self.orders[name])}" for name in self.names)
        lines.append(f"fitted order:  {fitted}")
        return "\n".join(lines)



def convergence_study(
    sizes: Sequence[float] | np.ndarray, run: Callable[[Any], Mapping[str, float]], kind: str = "N", dim: int = 2
) -> ConvergenceTable:
    """Run a computation at several sizes and fit convergence orders.

    Parameters
    ----------
    sizes : sequence, length M >= 2
        Sizes passed to ``run`` one by one, as given (numbers of points,
        strictly increasing, for ``kind="N"``; spacings, strictly monotonic,
        for ``kind="h"``).
    run : callable
        ``run(size) -> Mapping[str, float]`` of named errors, e.g.
        ``{"l2_rel": ..., "linf_rel": ...}``; the same names at every size.
    kind : {"N", "h"}
        How sizes relate to h (see :func:`fit_order`).
    dim : int
        Dimension of the point set, for ``kind="N"``.

    Returns
    -------
    ConvergenceTable
        Errors per name, fitted orders over all sizes and local orders
        between consecutive sizes. A name with a zero or negative error at
        some size gets NaN orders where they are undefined and a
        ``RuntimeWarning`` naming it (the study is not thrown away).

    Examples
    --------
    >>> t = convergence_study([100, 400, 1600], lambda n: {"l2": 2.0 / n, "max": 1.0 / np.sqrt(n)})
    >>> {k: round(v, 12) for k, v in t.orders.items()}
    {'l2': 2.0, 'max': 1.0}
    """
    check_in("kind", kind, ("N", "h"))
    dim = check_int("dim", dim, minimum=1)
    s = _check_sizes(sizes, kind)
    if not callable(run):
        raise TypeError(f"run must be a callable run(size) -> dict of errors, got {type(run).__name__}")
    raw_sizes = [v.item() if isinstance(v, np.generic) else v for v in sizes]
    results = []
    names: list[str] | None = None
    for size in raw_sizes:
        out = run(size)
        if not isinstance(out, Mapping):
            raise TypeError(f"run({size!r}) must return a mapping of error names to numbers, got {type(out).__name__}")
        if not out:
            raise ValueError(f"run({size!r}) returned no errors")
        if names is None:
            names = list(out)
        elif set(out) != set(names):
            raise ValueError(f"run({size!r}) returned errors {sorted(out)!r}, but the first size returned {sorted(names)!r}")
        row: dict[str, float] = {}
        for k in names:
            v = out[k]
            if isinstance(v, np.ndarray) and v.ndim == 0:
                v = v.item()
            if isinstance(v, bool) or not isinstance(v, numbers.Real):
                raise TypeError(f"run({size!r})[{k!r}] must be a real number, got {type(v).__name__}")
            if not math.isfinite(float(v)):
                raise ValueError(f"run({size!r})[{k!r}] must be finite, got {float(v)!r}")
            row[k] = float(v)
        results.append(row)
    assert names is not None  # sizes is not empty (checked above)
    errors = {k: np.array([r[k] for r in results]) for k in names}
    factor = _order_factor(kind, dim)
    logs = np.log(s)
    orders: dict[str, float] = {}
    local: dict[str, np.ndarray] = {}
    for k in names:
        e = errors[k]
        pos = e > 0
        with np.errstate(divide="ignore", invalid="ignore"):
            le = np.where(pos, np.log(np.where(pos, e, 1.0)), np.nan)
        local[k] = factor * np.diff(le) / np.diff(logs)
        if pos.all():
            orders[k] = float(factor * np.polyfit(logs, le, 1)[0])
        else:
            i = int(np.flatnonzero(~pos)[0])
            warnings.warn(
                f"error {k!r} is {float(e[i])!r} at size {raw_sizes[i]!r}: a zero or negative error cannot be fitted; "
                "its order is NaN",
                ManifoldSPHWarning,
                stacklevel=2,
            )
            orders[k] = float("nan")
    size_arr = np.asarray(raw_sizes)
    if not np.issubdtype(size_arr.dtype, np.number):
        size_arr = s
    return ConvergenceTable(
        sizes=size_arr, errors=errors, orders=orders, local_orders=local, kind=kind, dim=dim, names=names
    )
