"""What the validation cases share: the error measures, snapshot and time-step helpers, the DFT phasor.

Examples
--------
>>> relative_error([1.0, 2.0], [1.0, 2.5])
0.1
>>> round(l2_error([1.0, 1j], [1.0, 0.9j]), 6)  # 0.1 / sqrt(1 + 0.81)
0.074329
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from ..._validation import check_int
from ..results import FieldHistory, RunResult

if TYPE_CHECKING:
    pass

__all__ = ["relative_error", "l2_error", "dft_phasor", "timed", "check_every", "field_history", "fit_dt",
           "fit_solver_dt"]


def relative_error(numerical: ArrayLike, exact: ArrayLike) -> float:
    """mean |numerical - exact| / max |exact| (the error measure of every TMz case)."""
    numerical = np.asarray(numerical, dtype=np.float64)
    exact = np.asarray(exact, dtype=np.float64)
    scale = np.abs(exact).max()
    if not scale > 0:
        raise ValueError("the exact field is identically zero on the evaluation points; the error is undefined")
    return float(np.abs(numerical - exact).mean() / scale)


def l2_error(numerical: ArrayLike, exact: ArrayLike) -> float:
    """Relative L2 error ``||numerical - exact|| / ||exact||`` (complex arrays allowed).

    >>> round(l2_error([1.0, 1j], [1.0, 0.9j]), 6)  # 0.1 / sqrt(1 + 0.81)
    0.074329
    """
    a = np.asarray(numerical, dtype=complex)
    b = np.asarray(exact, dtype=complex)
    nb = float(np.linalg.norm(b))
    if not nb > 0:
        raise ValueError("the exact field is identically zero on the evaluation points; the error is undefined")
    return float(np.linalg.norm(a - b)) / nb


def dft_phasor(samples: ArrayLike, times: ArrayLike, freq: float) -> np.ndarray:
    """Complex amplitude ``P`` of ``Re(P exp(-i w t))`` from samples over whole periods: ``(2/N) sum s exp(i w t)``.

    >>> t = np.arange(40) / 40e9
    >>> complex(np.round(dft_phasor(np.cos(2 * np.pi * 1e9 * t - 0.3)[:, None], t, 1e9)[0], 12))
    (0.955336489126+0.295520206661j)
    """
    s = np.asarray(samples, dtype=np.float64)
    t = np.asarray(times, dtype=np.float64)
    return (2.0 / len(t)) * (np.exp(2j * np.pi * freq * t) @ s.reshape(len(t), -1))


def timed(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Report the total wall time as ``seconds`` (the case sets ``step_seconds``, the stepping alone)."""
    import functools

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        return dataclasses.replace(out, seconds=time.perf_counter() - t0)

    return wrapper


def check_every(every: int | None) -> int | None:
    """A case's ``every=``: save the E field every this many steps (None: the final state only)."""
    return None if every is None else check_int("every", every, minimum=1)


def field_history(points: np.ndarray, field: np.ndarray, t: float, res: RunResult,
                  exact: np.ndarray | None = None) -> FieldHistory:
    """The picture data of a case (:class:`.results.FieldHistory`): the snapshots the run saved
    (``every=``) and always the final state."""
    times, snaps = np.asarray(res.snapshot_times, dtype=np.float64), np.asarray(res.snapshots)
    if not len(times) or not np.isclose(times[-1], t, rtol=1e-12, atol=0.0):
        times = np.append(times, t)
        snaps = np.vstack([snaps.reshape(-1, field.size), field.copy()[None]])
    return FieldHistory(points, times, snaps, exact)


def fit_solver_dt(solver: Any, t_end: float) -> tuple[float, int]:
    """Shrink the solver's dt so that an integer number of steps ends exactly at ``t_end``."""
    dt, steps = fit_dt(t_end, solver.dt)
    solver.set_dt(dt)
    return dt, steps


def fit_dt(t_end: float, dt_max: float) -> tuple[float, int]:
    steps = max(1, int(math.ceil(t_end / dt_max - 1e-9)))
    return t_end / steps, steps
