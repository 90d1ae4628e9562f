"""Small named checkers used at the public entry points.

Each checker raises ``TypeError`` or ``ValueError`` with a message naming the
argument, what it got and what was expected.
"""

from __future__ import annotations

import numbers
import os
from collections.abc import Collection
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "as_points",
    "as_field",
    "check_finite",
    "check_positive",
    "check_bool",
    "check_in",
    "check_int",
    "check_real_array",
    "check_output_path",
    "check_spread",
    "as_positive_field",
]


def describe(a: ArrayLike) -> str:
    """``a``'s shape and dtype, for error messages."""
    arr = np.asarray(a)
    return f"array of shape {arr.shape} and dtype {arr.dtype}"


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


def check_real_array(name: str, a: ArrayLike) -> ArrayLike:
    """Raise TypeError for complex data or a masked array with masked entries; return ``a``.

    numpy would otherwise drop the imaginary part (with only a ``ComplexWarning``)
    or the mask (silently) on the conversion to float64. A masked array without
    masked entries is returned as its plain data.

    Examples
    --------
    >>> import numpy as np
    >>> check_real_array("f", np.array([1 + 2j]))
    Traceback (most recent call last):
    ...
    TypeError: f must be real, got complex data (dtype complex128); pass its .real or abs() explicitly
    >>> check_real_array("f", np.ma.masked_invalid([1.0, np.nan]))
    Traceback (most recent call last):
    ...
    TypeError: f is a masked array with 1 masked entry(ies); pass .filled(value) or .compressed() explicitly
    """
    if np.ma.isMaskedArray(a):
        masked = int(np.ma.count_masked(a))
        if masked:
            raise TypeError(
                f"{name} is a masked array with {masked} masked entry(ies); "
                "pass .filled(value) or .compressed() explicitly"
            )
        a = np.ma.getdata(a)
    if np.iscomplexobj(a) or (isinstance(a, (list, tuple)) and _has_complex(a)):
        dtype = getattr(a, "dtype", "complex")
        raise TypeError(f"{name} must be real, got complex data (dtype {dtype}); pass its .real or abs() explicitly")
    return a


def _has_complex(seq) -> bool:
    """Whether a (nested) list or tuple holds a Python or numpy complex number."""
    try:
        return np.asarray(seq).dtype.kind == "c"
    except (TypeError, ValueError):
        return False


def check_output_path(name: str, path: str | os.PathLike[str], overwrite: bool, *, hint: str = "overwrite=True") -> Path:
    """Check, before any work, that ``path`` can be written: the one overwrite guard.

    Raises ``IsADirectoryError`` if ``path`` is an existing folder (no overwrite can
    help), ``FileNotFoundError`` if its folder does not exist and ``FileExistsError``
    if it exists and ``overwrite`` is false (the message suggests ``hint``).

    Examples
    --------
    >>> import tempfile, os
    >>> d = tempfile.mkdtemp()
    >>> check_output_path("path", d, True)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    IsADirectoryError: path ... is a folder; give a file name inside it
    >>> check_output_path("path", os.path.join(d, "no", "f.ply"), False)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    FileNotFoundError: path ...: the folder ... does not exist
    """
    p = Path(os.fspath(path))
    if p.is_dir():
        raise IsADirectoryError(f"{name} {str(p)!r} is a folder; give a file name inside it")
    parent = p.parent
    if not parent.is_dir():
        raise FileNotFoundError(f"{name} {str(p)!r}: the folder {str(parent)!r} does not exist")
    if (p.exists() or p.is_symlink()) and not overwrite:
        raise FileExistsError(f"{name} {str(p)!r} exists; pass {hint} to replace it")
    return p


def as_points(name: str, a: ArrayLike, dim: int | tuple[int, ...] = 3) -> np.ndarray:
    """Return ``a`` as a finite float64 array of shape (N, dim).

    ``dim`` may be a tuple of allowed widths.
    """
    dims = (dim,) if isinstance(dim, int) else tuple(dim)
    a = check_real_array(name, a)
    try:
        raw = np.asarray(a)
        arr = np.asarray(raw, dtype=np.float64)  # no copy of float64 input
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a numeric array of shape (N, {dims[0]}), got {type(a).__name__}") from exc
    if raw.dtype == np.bool_:  # a mask passed for the coordinates
        raise TypeError(f"{name} must be numeric coordinates, got a bool array (a mask?)")
    if arr.ndim != 2 or arr.shape[1] not in dims:
        want = " or ".join(f"(N, {d})" for d in dims)
        raise ValueError(f"{name} must have shape {want}, got shape {arr.shape}")
    check_finite(name, arr)
    return arr


def check_spread(name: str, points: np.ndarray) -> None:
    """Raise ValueError when finite ``points`` (N, D) lie on one line: a surface (or a planar domain)
    needs points spread in two directions, and the local fits of a line are singular.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.linspace(0, 1, 20)
    >>> check_spread("points", np.column_stack([t, 2 * t, 1 - t]))  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: points lie on one line ...
    """
    mean = points.mean(axis=0)
    c = points - mean
    size = float(np.max(np.abs(c))) if c.size else 0.0
    if size > 0:
        c /= size  # scale-free: the coordinates' units do not matter
        d = np.linalg.eigh(c.T @ c)[1][:, -1]  # the principal direction
        off = np.max(np.abs(c - np.outer(c @ d, d)), axis=1)
        # each point on the line to the round-off of its own coordinates and of the centring
        tol = 64 * np.finfo(np.float64).eps * (np.max(np.abs(points), axis=1) + float(np.max(np.abs(mean)))) / size
    if size == 0 or bool(np.all(off <= tol)):
        raise ValueError(
            f"{name} lie on one line (or at one point): a surface needs points spread in two directions, "
            f"got {len(points)} collinear points"
        )


def as_field(name: str, a: ArrayLike, n: int, width: int | None = None) -> np.ndarray:
    """Return ``a`` as a finite float64 field of shape (n,) or (n, width).

    Complex data and masked arrays with masked entries raise ``TypeError``
    (:func:`check_real_array`).
    """
    a = check_real_array(name, a)
    try:
        arr = np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a numeric array, got {type(a).__name__}") from exc
    want = (n,) if width is None else (n, width)
    if arr.shape != want:
        raise ValueError(f"{name} must have shape {want}, got shape {arr.shape}")
    check_finite(name, arr)
    return arr


def as_positive_field(name: str, a: ArrayLike, n: int) -> np.ndarray:
    """Return ``a`` as a float64 array of shape (n,) of finite positive values.

    The message names the actual problem: the shape, or how many values are not
    finite or not positive and the first of them.

    Examples
    --------
    >>> as_positive_field("h", [0.1, -2.0, 0.3], 3)
    Traceback (most recent call last):
    ...
    ValueError: h must be positive, but 1 of its 3 value(s) are <= 0 (first at index 1: -2.0)
    >>> as_positive_field("h", [0.1, 0.2], 3)
    Traceback (most recent call last):
    ...
    ValueError: h must have shape (3,), got shape (2,)
    """
    arr = as_field(name, a, n)
    bad = arr <= 0
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"{name} must be positive, but {int(bad.sum())} of its {n} value(s) are <= 0 "
            f"(first at index {i}: {float(arr[i])!r})"
        )
    return arr


def check_positive(name: str, value: object, *, allow_zero: bool = False) -> float:
    """Return ``value`` as float, raising if it is not a finite positive number."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    v = float(value)
    ok = np.isfinite(v) and (v >= 0 if allow_zero else v > 0)
    if not ok:
        kind = "non-negative" if allow_zero else "positive"
        raise ValueError(f"{name} must be a finite {kind} number, got {value!r}")
    return v


def check_int(name: str, value: object, *, minimum: int | None = None) -> int:
    """Return ``value`` as int, raising if it is not an integer >= ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer, got {type(value).__name__} {value!r}")
    v = int(value)
    if minimum is not None and v < minimum:
        raise ValueError(f"{name} must be at least {minimum}, got {v}")
    return v


def check_bool(name: str, value: object) -> bool:
    """Return ``value`` as bool, raising TypeError unless it is True or False."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {type(value).__name__} {value!r}")
    return bool(value)


def check_in(name: str, value: Any, allowed: Collection[Any]) -> str:
    """Raise ValueError unless ``value`` is one of ``allowed``."""
    if value not in allowed:
        raise ValueError(f"{name} must be one of {sorted(allowed)!r}, got {value!r}")
    return value
