"""What every result type shares: a dataclass with ``to_dict()`` and a short ``repr``.

The convention (docs/conventions.md, "Results"): a function that returns more than one
array returns a small frozen dataclass with named fields that derives from
:class:`Result`; a function that computes one array returns the array. ``to_dict()``
gives the fields as a dict (arrays stay arrays); ``to_dict(json=True)`` gives the same
fields ready for :func:`json.dumps` (arrays as lists, NaN and inf as None); the ``repr``
shows arrays by shape.

Examples
--------
>>> import dataclasses
>>> import numpy as np
>>> @dataclasses.dataclass(frozen=True, repr=False)
... class Demo(Result):
...     error: float
...     u: np.ndarray
>>> Demo(0.5, np.zeros(3))
Demo(error=0.5, u=<array (3,) float64>)
>>> sorted(Demo(0.5, np.zeros(3)).to_dict())
['error', 'u']
>>> Demo(float("nan"), np.arange(2)).to_dict(json=True)
{'error': None, 'u': [0, 1]}
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

__all__ = ["Result", "jsonable", "short_repr", "to_dict"]


def to_dict(result: Any, *, skip: tuple[str, ...] = ()) -> dict[str, Any]:
    """The dataclass's fields as a dict (not recursive: arrays stay arrays), without ``skip``."""
    return {f.name: getattr(result, f.name) for f in dataclasses.fields(result) if f.name not in skip}


def jsonable(value: Any) -> Any:
    """``value`` made ready for :func:`json.dumps`, recursively: arrays and tuples as lists,
    numpy scalars as Python numbers, NaN and inf as None, results as their ``to_dict(json=True)``."""
    if isinstance(value, Result):
        return value.to_dict(json=True)
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value


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


class Result:
    """Base of every result dataclass: ``to_dict()`` (all fields, arrays as arrays) and a short repr.

    Declare subclasses with ``@dataclass(frozen=True, repr=False)`` (``repr=False`` keeps
    this short repr). A subclass leaves fields out of ``to_dict`` by naming them in the class
    attribute ``_dict_skip`` (a tuple of field names).
    """

    _dict_skip: tuple[str, ...] = ()

    def to_dict(self, *, json: bool = False) -> dict[str, Any]:
        """The fields as a dict: arrays stay arrays, or with ``json=True`` everything as
        :func:`jsonable` makes it (what ``--json`` prints)."""
        d = to_dict(self, skip=self._dict_skip)
        return jsonable(d) if json else d

    def __repr__(self) -> str:
        return short_repr(self)
