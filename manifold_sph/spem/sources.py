"""Waveforms, sources and probes for SPEM.

A waveform is a callable ``t -> value`` (vectorised over ``t``). A source
acts on a set of E particles every time Ez is updated: a *hard* source sets
Ez to the waveform value, a *soft* source adds it (an impressed current
``J = -eps/dt * value``), so waves pass through a soft source unperturbed.

Examples
--------
>>> s = Sinusoid(1e9)
>>> float(np.round(s(0.25e-9), 12))
1.0
>>> g = GaussianPulse(t0=1e-9, tau=2e-10)
>>> float(g(1e-9))
1.0
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from .._validation import check_in, check_positive

__all__ = ["Sinusoid", "GaussianPulse", "Source", "point_source", "line_source"]


@dataclass(frozen=True)
class Sinusoid:
    """``amplitude * sin(2 pi f t + phase)`` for ``t >= 0``, zero before.

    ``ramp`` > 0 multiplies by a smooth ``sin^2`` ramp over the first
    ``ramp`` periods (reduces the start-up transient).
    """

    freq: float
    amplitude: float = 1.0
    phase: float = 0.0
    ramp: float = 0.0

    def __post_init__(self) -> None:
        check_positive("freq", self.freq)
        check_positive("ramp", self.ramp, allow_zero=True)

    def __call__(self, t: ArrayLike) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)
        v = self.amplitude * np.sin(2 * np.pi * self.freq * t + self.phase)
        if self.ramp > 0:
            tr = self.ramp / self.freq
            v = v * np.where(t < tr, np.sin(0.5 * np.pi * np.clip(t, 0, None) / tr) ** 2, 1.0)
        return np.where(t >= 0, v, 0.0)


@dataclass(frozen=True)
class GaussianPulse:
    """``amplitude * exp(-((t - t0)/tau)^2) [* sin(2 pi f (t - t0))]`` (modulated when ``freq`` > 0)."""

    t0: float
    tau: float
    amplitude: float = 1.0
    freq: float = 0.0

    def __post_init__(self) -> None:
        check_positive("tau", self.tau)
        check_positive("freq", self.freq, allow_zero=True)

    def __call__(self, t: ArrayLike) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)
        s = (t - self.t0) / self.tau
        v = self.amplitude * np.exp(-s * s)
        if self.freq > 0:
            v = v * np.sin(2 * np.pi * self.freq * (t - self.t0))
        return v


@dataclass
class Source:
    """A waveform applied at E particles ``indices``: ``kind`` "hard" (set) or "soft" (add)."""

    indices: np.ndarray
    waveform: Callable[[float], ArrayLike]
    kind: str = "hard"

    def __post_init__(self) -> None:
        check_in("kind", self.kind, ("hard", "soft"))
        self.indices = np.atleast_1d(np.asarray(self.indices, dtype=np.int64))
        if self.indices.size == 0:
            raise ValueError("a source needs at least one E particle, got none")
        if not callable(self.waveform):
            raise TypeError(f"waveform must be callable t -> value, got {type(self.waveform).__name__}")


def point_source(e_points: ArrayLike, position: ArrayLike, waveform: Callable[[float], ArrayLike], kind: str = "hard",
                 max_distance: float | None = None) -> Source:
    """A source at the E particle nearest to ``position``.

    ``position`` farther than ``max_distance`` from every E particle (default:
    one spacing, the median nearest-neighbour distance of the E particles) is
    refused: a source outside the domain is a mistake, not something to snap.

    >>> e = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    >>> point_source(e, (0.9, 0.2), Sinusoid(1e9)).indices.tolist()
    [1]
    >>> point_source(e, (5.0, 5.0), Sinusoid(1e9))  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: position (5.0, 5.0) is 5.657 from the nearest E particle, farther than max_distance = 1 ...: it lies outside the domain
    """
    from scipy.spatial import cKDTree

    from .._validation import as_points

    e = as_points("e_points", e_points, dim=(1, 2))
    p = as_points("position", np.asarray(position, dtype=np.float64).reshape(1, -1), dim=e.shape[1])
    tree = cKDTree(e)
    if max_distance is None:
        max_distance = float(np.median(tree.query(e, k=2)[0][:, 1])) if len(e) > 1 else np.inf
        what = " (one spacing)"
    else:
        max_distance = check_positive("max_distance", max_distance)
        what = ""
    dist, idx = tree.query(p[0])
    if dist > max_distance:
        raise ValueError(
            f"position {tuple(float(v) for v in p[0])} is {dist:.4g} from the nearest E particle, farther than "
            f"max_distance = {max_distance:.4g}{what}: it lies outside the domain"
        )
    return Source(np.array([int(idx)]), waveform, kind)


def line_source(e_points: ArrayLike, y: float, waveform: Callable[[float], ArrayLike], kind: str = "hard",
                tol: float | None = None) -> Source:
    """A plane-wave line source: every E particle with ``|y_i - y| <= tol`` (default: the nearest row).

    ``y`` outside the rows of E particles (below the lowest or above the highest
    ``y_i``) is refused: a source outside the domain is a mistake, not something
    to snap to the nearest row.

    >>> e = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    >>> line_source(e, 0.9, Sinusoid(1e9)).indices.tolist()
    [2, 3]
    >>> line_source(e, 5.0, Sinusoid(1e9))
    Traceback (most recent call last):
    ...
    ValueError: y = 5.0 lies outside the E particles' rows, y in [0, 1]: the line source would be outside the domain
    """
    from .._validation import as_points

    e = as_points("e_points", e_points, dim=2)
    try:
        y = float(y)
    except (TypeError, ValueError):
        raise TypeError(f"y must be a number, got {type(y).__name__}") from None
    if not math.isfinite(y):
        raise ValueError(f"y must be finite, got {y!r}")
    lo, hi = float(e[:, 1].min()), float(e[:, 1].max())
    slack = 1e-9 * max(1.0, abs(lo), abs(hi))
    if not lo - slack <= y <= hi + slack:
        raise ValueError(f"y = {y!r} lies outside the E particles' rows, y in [{lo:.6g}, {hi:.6g}]: the line source "
                         f"would be outside the domain")
    dy = np.abs(e[:, 1] - y)
    if tol is None:
        tol = dy.min() + 1e-9 * max(1.0, abs(y))
    else:
        tol = check_positive("tol", tol, allow_zero=True)
    return Source(np.flatnonzero(dy <= tol), waveform, kind)
