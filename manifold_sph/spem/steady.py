"""Steady state of a run driven at one frequency: per-period phasors and the transient left in them.

A field driven by ``cos(w t)`` and read by a DFT at ``w`` reaches its steady
state only as the transient (the modes the switch-on excited, ringing down at
their own frequencies) decays. A dielectric cylinder is a resonator: at a
contrast of 8 its modes ring down over tens of periods, and a DFT taken after a
fixed number of periods measures the transient, not the discretisation
(docs/spem.md, "Driven runs until steady", has the measurements).

With an integer number of steps per period, the DFT of a steady field over one
whole period is the same in every period (round-off apart). :class:`PeriodPhasors`
keeps the phasor of each period, the phasor over the last ``window`` periods
(what the cases report), and estimates how far that phasor still is from the
steady one. Once one mode dominates what is left of the transient, the window
phasor's change from one period to the next is ``s_k = z s_(k-1)``, ``z`` a
complex ratio (the mode's decay and its phase turn against the drive over a
period), so what is left is ``s_k z / (1 - z)``: the estimate is
``|s_k| |z| / |1 - z|`` relative to the phasor's norm, with ``z`` fitted by
least squares over the last three lags (``|1 - z|`` kept above 0.01).
:func:`run_driven` steps a case until the estimate
stays below a tolerance for two periods (``periods="auto"``), until it stops
falling (an undamped mode or a drift), or for a fixed number of periods.

Examples
--------
>>> import numpy as np
>>> w, per = 2 * np.pi, 40
>>> dt = 1.0 / per
>>> def advance(n):  # a steady response plus a mode ringing down at 1.3 w
...     t = (n + 1) * dt
...     return np.array([np.cos(w * t - 0.3) + np.exp(-0.2 * t) * np.cos(1.3 * w * t)]), t
>>> run = run_driven(advance, per, w, periods="auto", ramp=0.0, window=2, tol=1e-6)
>>> run.converged, bool(abs(run.phasor[0] - np.exp(0.3j)) < 1e-5)
(True, True)
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from .._validation import check_int, check_positive

__all__ = ["PeriodPhasors", "DrivenRun", "run_driven", "steady_failures", "STEADY_TOL", "STEADY_ACCEPT",
           "MAX_PERIODS", "check_periods"]

#: ``periods="auto"`` stops once the estimated transient left in the phasor is below this share of its L2 norm.
STEADY_TOL = 1e-4
#: :func:`steady_failures` accepts a transient up to this many times the tolerance.
STEADY_ACCEPT = 10.0
#: ``periods="auto"`` stops here at the latest (the result then says it did not converge).
MAX_PERIODS = 400.0
#: The estimate's ``|1 - z|`` is kept above ``1 - _Q_MAX`` (a change that does not shrink or turn counts as
#: a transient that decays by this ratio a period).
_Q_MAX = 0.99
#: Period-to-period lags the transient's decay ratio is fitted over.
_LAGS = 3
#: :meth:`PeriodPhasors.stalled`: the estimate must fall by this factor over this many periods.
_STALL_FACTOR = 1.5
_STALL_SPAN = 40
#: Consecutive periods the estimate must stay below the tolerance.
_SETTLED = 2


def check_periods(periods: float | str) -> float | str:
    """``periods``: ``"auto"`` or a positive finite number (TypeError or ValueError naming the argument)."""
    if isinstance(periods, str):
        if periods != "auto":
            raise ValueError(f"periods must be 'auto' or a positive number, got {periods!r}")
        return periods
    return check_positive("periods", periods)


class PeriodPhasors:
    """The DFT phasor at ``w`` of each whole period of a field, and the transient left in their mean.

    Parameters
    ----------
    n : int
        Points the field is read at.
    per : int
        Steps per period (the period is ``per`` steps exactly).
    w : float
        Angular drive frequency.
    window : int
        Periods the reported phasor averages (the last ``window``).

    Examples
    --------
    >>> p = PeriodPhasors(1, 4, 2 * np.pi, 1)
    >>> for n in range(8):
    ...     t = (n + 1) / 4
    ...     p.add(np.array([np.cos(2 * np.pi * t)]), t)
    >>> p.periods, np.round(p.phasor(), 12)
    (2, array([1.-0.j]))
    """

    def __init__(self, n: int, per: int, w: float, window: int) -> None:
        self.per = check_int("per", per, minimum=1)
        self.window = check_int("window", window, minimum=1)
        self.w = check_positive("w", w)
        self._acc = np.zeros(int(n), dtype=complex)
        self._count = 0
        self._last: deque[np.ndarray] = deque(maxlen=self.window)
        self._mean: np.ndarray | None = None
        self.estimates: list[float] = []  #: the transient left after each period (:meth:`transient`)
        self._steps: deque[np.ndarray] = deque(maxlen=_LAGS + 1)
        self.periods = 0

    def add(self, values: np.ndarray, t: float) -> None:
        """One step's field ``values`` (n,) at time ``t``."""
        self._acc += values * np.exp(1j * self.w * t)
        self._count += 1
        if self._count == self.per:
            self._close()

    def _close(self) -> None:
        self._last.append(self._acc * (2.0 / self.per))
        self._acc = np.zeros_like(self._acc)
        self._count = 0
        self.periods += 1
        if len(self._last) < self.window:
            return
        mean = np.mean(np.asarray(self._last), axis=0)
        if not np.all(np.isfinite(mean)):
            raise FloatingPointError(f"the driven field is not finite after {self.periods} periods (an unstable "
                                     "step or a non-finite source)")
        if self._mean is not None:
            step = mean - self._mean
            norm = float(np.linalg.norm(mean))
            change = float(np.linalg.norm(step)) / norm if norm > 0 else math.inf
            self._steps.append(step)
            if len(self._steps) >= 2 and math.isfinite(change):
                # the transient's ratio from one period to the next, fitted over the last lags:
                # step_k = z step_(k-1) for one decaying mode, so what is left is step_k z / (1 - z)
                pairs = list(zip(list(self._steps)[:-1], list(self._steps)[1:]))
                den = sum(float(np.vdot(a, a).real) for a, _ in pairs)
                z = sum(complex(np.vdot(a, b)) for a, b in pairs) / den if den > 0 else 0j
                self.estimates.append(change * abs(z) / max(abs(1.0 - z), 1.0 - _Q_MAX))
        self._mean = mean

    def phasor(self) -> np.ndarray:
        """The mean phasor of the last ``window`` whole periods, (n,) complex."""
        if self._mean is None:
            raise ValueError(f"phasor: fewer than window = {self.window} whole periods recorded "
                             f"({self.periods})")
        return self._mean

    def transient(self) -> float:
        """Estimated ``||phasor - steady|| / ||phasor||`` after the last period (inf before three are known)."""
        if len(self.estimates) < _LAGS:
            return math.inf
        return self.estimates[-1]

    def stalled(self) -> bool:
        """The transient does not decay: the median estimate of the last 10 periods is above 1 / 1.5 of the
        median of the 10 periods 30 earlier (an undamped mode or a growing drift)."""
        e = self.estimates
        if len(e) < _STALL_SPAN:
            return False
        return float(np.median(e[-10:])) > float(np.median(e[-_STALL_SPAN:-_STALL_SPAN + 10])) / _STALL_FACTOR


class DrivenRun(NamedTuple):
    """What :func:`run_driven` measured."""

    phasor: np.ndarray  #: (n,) complex: the DFT phasor over the last window
    steps: int  #: steps taken
    periods: float  #: periods run (steps / per)
    transient: float  #: estimated transient left in ``phasor``, relative to its L2 norm
    converged: bool  #: ``periods="auto"``: the estimate fell below ``tol``; fixed periods: it is below ``tol``
    stalled: bool = False  #: the estimate stopped falling (:meth:`PeriodPhasors.stalled`)


def run_driven(advance: Callable[[int], tuple[np.ndarray, float]], per: int, w: float, *, periods: float | str,
               ramp: float, window: float, tol: float = STEADY_TOL, max_periods: float = MAX_PERIODS) -> DrivenRun:
    """Step a driven case for a fixed number of periods or until its phasor is steady.

    Parameters
    ----------
    advance : callable
        ``advance(n)`` takes step ``n`` (0, 1, ...) and returns the field at the
        evaluation points, (n_points,), and the time it belongs to.
    per : int
        Steps per period.
    w : float
        Angular drive frequency.
    periods : float or "auto"
        A fixed length (the phasor is the DFT over the last ``window`` periods,
        ``round(window * per)`` steps), or ``"auto"``:
        whole periods until :meth:`PeriodPhasors.transient` stays below ``tol``
        for two periods after the ``ramp`` (or ``max_periods``).
    ramp : float
        Periods of the drive's switch-on (no estimate is read before it ends).
    window : float
        Periods of the DFT; ``"auto"`` uses ``round(window)`` whole periods (at least 1).
    tol, max_periods : float
        ``"auto"``'s tolerance and longest run.

    Returns
    -------
    DrivenRun
    """
    if not callable(advance):
        raise TypeError(f"advance must be callable, got {type(advance).__name__}")
    periods = check_periods(periods)
    tol = check_positive("tol", tol)
    max_periods = check_positive("max_periods", max_periods)
    whole = max(1, int(round(window)))
    if periods == "auto" and ramp + whole + 1 > max_periods:
        raise ValueError(f"the DFT window (dft_periods) must leave a period after the ramp within max_periods: "
                         f"ramp + window + 1 <= {max_periods:g}, got ramp {ramp:g} and window {whole}")
    values, t = advance(0)  # the first step gives the number of points
    tracker = PeriodPhasors(len(values), per, w, whole)
    tracker.add(values, t)
    if periods == "auto":
        start = math.ceil(ramp) + whole
        limit = max(int(math.ceil(max_periods)), start + 5) * per
        settled = 0
        n = 1
        while n < limit:
            tracker.add(*advance(n))
            n += 1
            if n % per == 0 and tracker.periods >= start:
                settled = settled + 1 if tracker.transient() <= tol else 0
                if settled >= _SETTLED or (tracker.periods >= start + _STALL_SPAN and tracker.stalled()):
                    break
        est = tracker.transient()
        return DrivenRun(tracker.phasor(), n, n / per, est, est <= tol, est > tol and tracker.stalled())
    steps = int(round(periods * per))
    n_dft = int(round(window * per))
    acc = np.zeros(len(values), dtype=complex)
    if steps - n_dft <= 0:
        acc += values * np.exp(1j * w * t)
    for n in range(1, steps):
        values, t = advance(n)
        tracker.add(values, t)
        if n >= steps - n_dft:
            acc += values * np.exp(1j * w * t)
    est = tracker.transient()
    return DrivenRun(acc * (2.0 / n_dft), steps, steps / per, est, est <= tol, est > tol and tracker.stalled())


def steady_failures(run: DrivenRun, periods: float | str, tol: float) -> tuple[str, ...]:
    """The certificate sentence of a run whose phasor is not steady (empty when it is).

    A run is certified when its transient is at most :data:`STEADY_ACCEPT` times ``tol``: ``"auto"`` stops
    at ``tol``, and a transient that stops decaying there (an undamped remnant) limits the phasor to that
    level without growing.
    """
    if run.transient <= STEADY_ACCEPT * tol:
        return ()
    if run.stalled:
        return (f"the phasor is not steady: the transient left, estimated at {run.transient:.2g} of its norm "
                f"(accepted up to {STEADY_ACCEPT * tol:g}), stopped decaying by {run.periods:g} periods (a drift "
                "or an undamped mode; a finer spacing may remove it)",)
    how = (f"when periods='auto' stopped at max_periods = {run.periods:g}" if periods == "auto"
           else f"after the fixed {run.periods:g} periods")
    return (f"the phasor is not steady: the transient left is estimated at {run.transient:.2g} of its norm "
            f"{how} (accepted up to {STEADY_ACCEPT * tol:g}); run longer: periods='auto' (--periods auto) "
            "or a larger steady_tol",)
