"""Small named checkers used at the public entry points.

Each checker raises ``TypeError`` or ``ValueError`` with a message naming the
argument, what it got and what was expected.
"""

from __future__ import annotations

import numbers

import numpy as np

__all__ = [
    "as_points",
    "as_field",
    "check_finite",
    "check_positive",
    "check_bool",
    "check_in",
    "check_int",
]


def _describe(a) -> str:
    a = np.asarray(a)
    return f"array of shape {a.shape} and dtype {a.dtype}"


def check_finite(name: str, a: np.ndarray) -> np.ndarray:
    """Raise ValueError if ``a`` holds NaN or inf, naming the first bad entry."""
    bad = ~np.isfinite(a)
    if bad.any():
        where = np.argwhere(bad)[0]
        count = int(bad.sum())
        raise ValueError(
            f"{name} must be finite, but it holds {count} NaN or inf value(s) "
            f"(first at index {tuple(int(i) for i in where)})"
        )
    return a


def as_points(name: str, a, dim: int | tuple[int, ...] = 3) -> np.ndarray:
    """Return ``a`` as a finite float64 array of shape (N, dim).

    ``dim`` may be a tuple of allowed widths.
    """
    dims = (dim,) if isinstance(dim, int) else tuple(dim)
    try:
        arr = np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a numeric array of shape (N, {dims[0]}), got {type(a).__name__}") from exc
    if arr.ndim != 2 or arr.shape[1] not in dims:
        want = " or ".join(f"(N, {d})" for d in dims)
        raise ValueError(f"{name} must have shape {want}, got shape {arr.shape}")
    check_finite(name, arr)
    return arr


def as_field(name: str, a, n: int, width: int | None = None) -> np.ndarray:
    """Return ``a`` as a finite float64 field of shape (n,) or (n, width)."""
    try:
        arr = np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a numeric array, got {type(a).__name__}") from exc
    want = (n,) if width is None else (n, width)
    if arr.shape != want:
        raise ValueError(f"{name} must have shape {want}, got shape {arr.shape}")
    check_finite(name, arr)
    return arr


def check_positive(name: str, value, *, allow_zero: bool = False) -> float:
    """Return ``value`` as float, raising if it is not a finite positive number."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    v = float(value)
    ok = np.isfinite(v) and (v >= 0 if allow_zero else v > 0)
    if not ok:
        kind = "non-negative" if allow_zero else "positive"
        raise ValueError(f"{name} must be a finite {kind} number, got {value!r}")
    return v


def check_int(name: str, value, *, minimum: int | None = None) -> int:
    """Return ``value`` as int, raising if it is not an integer >= ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer, got {type(value).__name__} {value!r}")
    v = int(value)
    if minimum is not None and v < minimum:
        raise ValueError(f"{name} must be at least {minimum}, got {v}")
    return v


def check_bool(name: str, value) -> bool:
    """Return ``value`` as bool, raising TypeError unless it is True or False."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {type(value).__name__} {value!r}")
    return bool(value)


def check_in(name: str, value, allowed) -> str:
    """Raise ValueError unless ``value`` is one of ``allowed``."""
    if value not in allowed:
        raise ValueError(f"{name} must be one of {sorted(allowed)!r}, got {value!r}")
    return value
