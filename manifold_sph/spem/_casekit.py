"""Helpers shared by the validation cases (:mod:`.cases`, :mod:`.cases2d`): error measure, timing, snapshots, dt fitting.

Both case modules import from here and :mod:`.cases` imports :mod:`.cases2d`
(one direction, no import cycle).

>>> relative_error([1.0, 2.0], [1.0, 4.0])
0.25
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
from numpy.typing import ArrayLike

from .._validation import check_int
from .results import FieldHistory

__all__ = ["relative_error"]


def relative_error(numerical: ArrayLike, exact: ArrayLike) -> float:
    """mean |numerical - exact| / max |exact| (the issue's error measure)."""
    numerical = np.asarray(numerical, dtype=np.float64)
    exact = np.asarray(exact, dtype=np.float64)
    scale = np.abs(exact).max()
    if not scale > 0:
        raise ValueError("the exact field is identically zero on the evaluation points; the error is undefined")
    return float(np.abs(numerical - exact).mean() / scale)


def _timed(fn):
    """Report the total wall time as ``seconds`` (the case sets ``step_seconds``, the stepping alone)."""
    import functools

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        return dataclasses.replace(out, seconds=time.perf_counter() - t0)

    return wrapper


def _every(steps, frames):
    frames = check_int("frames", frames, minimum=0)
    return max(1, steps // frames) if frames else None


def _fields(points, field, t, res, frames, exact=None):
    """The picture data of a case (:class:`.results.FieldHistory`), or None without ``frames``."""
    if not frames:
        return None
    if len(res.snapshots):
        return FieldHistory(points, res.snapshot_times, res.snapshots, exact)
    return FieldHistory(points, np.array([t]), field.copy()[None], exact)


def _fitted(solver, t_end):
    """Shrink the solver's dt so that an integer number of steps ends exactly at ``t_end``."""
    dt, steps = _fit_dt(t_end, solver.dt)
    solver.set_dt(dt)
    return dt, steps


def _fit_dt(t_end, dt_max):
    steps = max(1, int(math.ceil(t_end / dt_max - 1e-9)))
    return t_end / steps, steps
