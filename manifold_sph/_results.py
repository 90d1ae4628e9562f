"""What every result type shares: plain frozen dataclasses, and the 0.1 access kept until 0.3.

The convention (README, "Results"): a function that returns more than one array
returns a small frozen dataclass with named fields (:class:`manifold_sph.pde.Solution`,
:class:`manifold_sph.spem.RunResult`, the ``*Result`` classes of
:mod:`manifold_sph.spem.results`); a function that computes one array returns the
array. ``to_dict()`` gives the JSON-ready fields.

In 0.1 the time steppers returned an array or a ``Snapshots`` tuple depending on
``every=``, and SPEM returned dicts. That use keeps working until 0.3, with a
DeprecationWarning naming the attribute to use instead: :class:`DictAccess`
(``res["error"]`` -> ``res.error``) and :class:`LegacyArray` (a
:class:`~manifold_sph.pde.Solution` in arithmetic or indexed like the final array).

Examples
--------
>>> import dataclasses, warnings
>>> @dataclasses.dataclass(frozen=True)
... class Demo(DictAccess):
...     error: float
>>> with warnings.catch_warnings(record=True) as w:
...     warnings.simplefilter("always")
...     Demo(0.5)["error"], str(w[0].message)
(0.5, "Demo['error'] is deprecated (results are dataclasses since 0.2): use .error")
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import ItemsView, Iterator, KeysView
from typing import Any

import numpy as np
from numpy.typing import DTypeLike
from numpy.lib.mixins import NDArrayOperatorsMixin

__all__ = ["DictAccess", "LegacyArray", "short_repr", "to_dict"]


def _deprecated(message: str) -> None:
    warnings.warn(message, DeprecationWarning, stacklevel=3)


def to_dict(result: Any, *, skip: tuple[str, ...] = ()) -> dict[str, Any]:
    """The dataclass's fields as a dict (not recursive: arrays stay arrays), without ``skip``."""
    return {f.name: getattr(result, f.name) for f in dataclasses.fields(result) if f.name not in skip}


def short_repr(result: Any) -> str:
    """``Name(field=value, ...)`` with arrays shown by shape (results hold large arrays)."""

    def show(v: Any) -> str:
        if isinstance(v, np.ndarray):
            return f"<array {v.shape} {v.dtype}>"
        if isinstance(v, float):
            return f"{v:.6g}"
        return repr(v)

    shown = ", ".join(f"{f.name}={show(getattr(result, f.name))}" for f in dataclasses.fields(result) if f.repr)
    return f"{type(result).__name__}({shown})"


class DictAccess:
    """0.1's dict access on a result dataclass (until 0.3): ``res["key"]`` warns and reads ``res.key``.

    A class maps old key names with ``_LEGACY_KEYS = {"old": callable(self)}``; a
    field whose value is None counts as an absent key (0.1 left such keys out).
    """

    _LEGACY_KEYS: dict = {}

    def _legacy(self) -> dict[str, Any]:
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.repr}
        out = {k: v for k, v in out.items() if v is not None}
        for key, fn in type(self)._LEGACY_KEYS.items():
            value = fn(self)
            if value is not None:
                out[key] = value
        return out

    def _warn(self, key: str) -> None:
        name = type(self).__name__
        new = f".{key}" if key in {f.name for f in dataclasses.fields(self)} else "the attributes or to_dict()"
        _deprecated(f"{name}[{key!r}] is deprecated (results are dataclasses since 0.2): use {new}")

    def __getitem__(self, key: str) -> Any:
        self._warn(key)
        return self._legacy()[key]

    def get(self, key: str, default: Any = None) -> Any:
        """Deprecated dict access (until 0.3)."""
        self._warn(key)
        return self._legacy().get(key, default)

    def __contains__(self, key: object) -> bool:
        self._warn(str(key))
        return key in self._legacy()

    def keys(self) -> KeysView[str]:
        """Deprecated dict access (until 0.3): use ``to_dict()``."""
        _deprecated(f"{type(self).__name__}['...'] is deprecated (results are dataclasses since 0.2): use to_dict()")
        return self._legacy().keys()

    def items(self) -> ItemsView[str, Any]:
        """Deprecated dict access (until 0.3): use ``to_dict()``."""
        _deprecated(f"{type(self).__name__}['...'] is deprecated (results are dataclasses since 0.2): use to_dict()")
        return self._legacy().items()


_ARRAY_MESSAGE = ("Solution used as an array is deprecated (pde.heat and pde.wave return a Solution since 0.2): "
                  "use .u for the final state")
_TUPLE_MESSAGE = ("Solution used as a (snapshots, times) tuple is deprecated (pde.heat and pde.wave return a "
                  "Solution since 0.2): use .snapshots and .times")


class LegacyArray(NDArrayOperatorsMixin):
    """0.1's return values of ``heat``/``wave`` (until 0.3), on a :class:`~manifold_sph.pde.Solution`.

    Without ``every=`` they returned the final array: arithmetic, numpy functions,
    indexing, ``len`` and ndarray attributes (``.shape``, ``.max()``) act on ``.u``.
    With ``every=`` they returned ``Snapshots(snapshots, times)``: indexing and
    unpacking act on that pair. Each use warns (DeprecationWarning).
    """

    _legacy_kind: str  # "array" or "snapshots", set by the solver

    def _legacy_value(self) -> Any:
        if self._legacy_kind == "array":
            _deprecated(_ARRAY_MESSAGE)
            return self.u
        _deprecated(_TUPLE_MESSAGE)
        return (self.snapshots, self.times)

    def __array__(self, dtype: DTypeLike = None, copy: bool | None = None) -> np.ndarray:
        if self._legacy_kind != "array":
            raise TypeError("a Solution is not an array: use .u (the final state) or .snapshots")
        _deprecated(_ARRAY_MESSAGE)
        return np.asarray(self.u, dtype=dtype)

    def __array_ufunc__(self, ufunc: np.ufunc, method: str, *inputs: Any, **kwargs: Any) -> Any:
        if self._legacy_kind != "array":
            return NotImplemented
        _deprecated(_ARRAY_MESSAGE)
        inputs = tuple(x.u if isinstance(x, LegacyArray) else x for x in inputs)
        return getattr(ufunc, method)(*inputs, **kwargs)

    def __getitem__(self, key: Any) -> Any:
        return self._legacy_value()[key]

    def __len__(self) -> int:
        return len(self._legacy_value())

    def __bool__(self) -> bool:
        return True

    def __iter__(self) -> Iterator[Any]:
        return iter(self._legacy_value())

    def __getattr__(self, name: str) -> Any:
        # only for names the dataclass lacks; private and dunder lookups (copy, pickle) never forward
        if name.startswith("_") or self.__dict__.get("_legacy_kind") != "array" or not hasattr(np.ndarray, name):
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        _deprecated(_ARRAY_MESSAGE)
        return getattr(self.u, name)
