"""Steady state of a run driven at one frequency: per-period phasors and the transient left in them.

A field driven by ``cos(w t)`` and read by a DFT at ``w`` reaches its steady
state only as the transient (the modes the switch-on excited, ringing down at
their own frequencies) decays. A dielectric cylinder is a resonator: at a
contrast of 8 its modes ring down over tens of periods, and a DFT taken after a
fixed number of periods measures the transient, not the discretisation
(docs/spem.md, "Driven runs until steady", has the measurements).

With an integer number of steps per period, the DFT of a steady field over one
whole period is the same in every period (round-off apart). :class:`PeriodPhasors`
keeps the phasor of each period and the phasor over the last ``window`` periods
(the plain DFT), with an estimate of how far that is from the steady one: once
one mode dominates what is left of the transient, the window phasor's change
from one period to the next is ``s_k = z s_(k-1)``, ``z`` a complex ratio (the
mode's decay and its phase turn against the drive over a period), so what is
left is ``s_k z / (1 - z)``: the estimate is ``|s_k| |z| / |1 - z|`` relative
to the phasor's norm, with ``z`` fitted by least squares over the last three
lags (``|1 - z|`` kept above 0.01).

The steady phasor itself is extrapolated. Stepping one period is a linear map
of the fields plus the drive's share, the same every period once the switch-on
is over, so the phasor of period ``k`` is ``p_k = p + sum_m c_m z_m^k`` over the
modes of that map: ``p``, the steady phasor, is the map's fixed point (the
frequency-domain solution of the discretisation), and every mode with
``z_m != 1`` leaves it, whether it decays (radiates) or not (a mode the layout
traps: its ``|z_m| = 1``, and no DFT window removes it). :func:`extrapolate`
eliminates the modes by reduced rank extrapolation (RRE) over the per-period
phasors since the switch-on (at most :data:`EXTRAPOLATION_PERIODS`, taken in
pairs of consecutive periods): ``p ~ sum_j g_j p_j`` with ``sum_j g_j = 1`` and
``||sum_j g_j (p_(j+1) - p_j)||`` least. Its distance from the steady phasor is
estimated by how much it moved over the last three periods, doubled
(:meth:`PeriodPhasors.steady_transient`); its gain ``sum_j |g_j|`` says how far
beyond the periods run it lies (:data:`GAIN_MAX`).

:func:`run_driven` with ``periods="auto"`` steps a case until that estimate
stays below a tolerance for two periods, until it stops falling (a drift, or
a mode growing in time: the map has no fixed point to find), or
``max_periods``, and reports the extrapolated phasor; with a fixed number of
periods it reports the plain DFT over the last ``window`` periods and its own
estimate.

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

A mode that never decays (a trapped one, at 1.3 w) is removed all the same:

>>> def trapped(n):
...     t = (n + 1) * dt
...     mode = np.cos(1.3 * w * t) * np.array([0.1, 0.2])
...     return np.array([np.cos(w * t - 0.3), 0.0]) + mode, t
>>> run = run_driven(trapped, per, w, periods="auto", ramp=0.0, window=2, tol=1e-6)
>>> run.converged, bool(np.abs(run.phasor - [np.exp(0.3j), 0.0]).max() < 1e-5)
(True, True)
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from .._validation import check_finite, check_int, check_positive

__all__ = ["PeriodPhasors", "DrivenRun", "run_driven", "steady_failures", "extrapolate", "STEADY_TOL",
           "STEADY_ACCEPT", "MAX_PERIODS", "EXTRAPOLATION_PERIODS", "GAIN_MAX", "check_periods"]

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
#: Per-period phasors (the latest) that :func:`extrapolate` combines: more remove more modes of slow decay or
#: none (docs/spem.md, "Driven runs until steady", has the measured choice).
EXTRAPOLATION_PERIODS = 33
#: :meth:`PeriodPhasors.steady_transient`: the change of the extrapolated phasor over this many periods ...
_MOVE_LAG = 3
#: ... times this factor (an upper bound of its distance from a long run's phasor in the measured cases:
#: docs/spem.md, "Driven runs until steady").
_MOVE_FACTOR = 2.0
#: :func:`steady_failures` names an extrapolation whose gain ``sum_j |g_j|`` is above this: the steady phasor
#: then lies far beyond every period run, the response of a mode of the discretisation resonating near the
#: drive frequency (docs/spem.md has the gains measured with and without such a mode).
GAIN_MAX = 10.0
#: :func:`extrapolate`'s Tikhonov floor on the differences' singular values, relative to the largest.
_RRE_FLOOR = 1e-10


def extrapolate(phasors: np.ndarray) -> np.ndarray:
    """The steady phasor of a sequence of per-period phasors, by reduced rank extrapolation (RRE).

    Parameters
    ----------
    phasors : (K, n) complex array
        The phasors of K >= 3 consecutive whole periods (after the switch-on).

    Returns
    -------
    (n,) complex array
        RRE on the pairs ``x_j = (p_j, p_(j+1))``: ``sum_j g_j x_(j+1)`` with ``sum_j g_j = 1``
        and the weights minimising ``||sum_j g_j (x_(j+1) - x_j)||`` (a Tikhonov floor of
        ``1e-10`` times the largest singular value keeps them finite when the differences are
        dependent); its second half. Exact for ``p_k = p + sum_m c_m z_m^k`` with at most
        ``min(K - 2, 2 n)`` modes ``z_m != 1`` (the cases read hundreds to thousands of
        points): pairing the periods makes the two exponentials of a standing mode (one
        shape ``c``, ``z`` and another ratio) independent vectors ``(c, z c)``, which the
        phasors alone are not. The last phasor when none changes.

    Examples
    --------
    One point, a decaying mode and an undamped one (two ratios on one shape):

    >>> k = np.arange(6)[:, None]
    >>> p = 2.0 + 0.5 * 0.9 ** k + 0.3 * np.exp(0.4j * k)
    >>> bool(np.allclose(extrapolate(p), [2.0], atol=1e-8))
    True
    """
    P = np.asarray(phasors)
    if P.ndim != 2 or P.shape[0] < 3:
        raise ValueError(f"phasors must be a (K, n) array with K >= 3 periods, got shape {P.shape}")
    return _rre(check_finite("phasors", P))[0]


def _rre(P: np.ndarray) -> tuple[np.ndarray, float]:
    """:func:`extrapolate` and its gain ``sum_j |g_j|`` (1 for an average of the periods; large when the
    steady phasor lies far beyond them: a mode with ``z`` near 1)."""
    n = P.shape[1]
    X = np.concatenate([P[:-1], P[1:]], axis=1)
    U = np.diff(X, axis=0)
    m = U.shape[0]
    R = np.linalg.qr(U.T, mode="r")  # ||U^T g|| = ||R g||: an (at most m x m) factor
    _, s, vh = np.linalg.svd(R, full_matrices=True)
    if not s[0] > 0:
        return P[-1].copy(), 1.0
    s = np.concatenate([s, np.zeros(m - s.size)])  # fewer unknowns than differences: the rest is null
    g = vh.conj().T @ ((vh @ np.ones(m)) / (s**2 + (_RRE_FLOOR * s[0]) ** 2))
    g = g / g.sum()
    return g @ X[1:, n:], float(np.abs(g).sum())


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
    settle : int
        Periods of the switch-on: the phasors of the later periods only are
        extrapolated (:meth:`steady`).

    Examples
    --------
    >>> p = PeriodPhasors(1, 4, 2 * np.pi, 1)
    >>> for n in range(8):
    ...     t = (n + 1) / 4
    ...     p.add(np.array([np.cos(2 * np.pi * t)]), t)
    >>> p.periods, np.round(p.phasor(), 12)
    (2, array([1.-0.j]))
    """

    def __init__(self, n: int, per: int, w: float, window: int, *, settle: int = 0) -> None:
        self.per = check_int("per", per, minimum=1)
        self.window = check_int("window", window, minimum=1)
        self.settle = check_int("settle", settle, minimum=0)
        self.w = check_positive("w", w)
        self._acc = np.zeros(int(n), dtype=complex)
        self._count = 0
        self._last: deque[np.ndarray] = deque(maxlen=self.window)
        self._mean: np.ndarray | None = None
        self.estimates: list[float] = []  #: the transient left after each period (:meth:`transient`)
        self._steps: deque[np.ndarray] = deque(maxlen=_LAGS + 1)
        self._history: deque[np.ndarray] = deque(maxlen=EXTRAPOLATION_PERIODS)
        self._steady: deque[np.ndarray] = deque(maxlen=_MOVE_LAG + 1)
        #: the distance of the extrapolated phasor from steady after each period (:meth:`steady_transient`)
        self.steady_estimates: list[float] = []
        #: the extrapolation's gain after the last period (:func:`extrapolate`; 1 for an average of periods)
        self.gain = math.nan
        self.periods = 0

    def add(self, values: np.ndarray, t: float) -> None:
        """One step's field ``values`` (n,) at time ``t``."""
        self._acc += values * np.exp(1j * self.w * t)
        self._count += 1
        if self._count == self.per:
            self._close()

    def _close(self) -> None:
        phasor = self._acc * (2.0 / self.per)
        self._last.append(phasor)
        self._acc = np.zeros_like(self._acc)
        self._count = 0
        self.periods += 1
        if not np.all(np.isfinite(phasor)):
            raise FloatingPointError(f"the driven field is not finite after {self.periods} periods (an unstable "
                                     "step or a non-finite source)")
        if self.periods > self.settle:
            self._history.append(phasor)
            if len(self._history) >= 3:
                steady, self.gain = _rre(np.asarray(self._history))
                self._steady.append(steady)
                if len(self._steady) > _MOVE_LAG:
                    new, old = self._steady[-1], self._steady[0]
                    norm = float(np.linalg.norm(new))
                    move = float(np.linalg.norm(new - old)) / norm if norm > 0 else math.inf
                    self.steady_estimates.append(_MOVE_FACTOR * move)
        if len(self._last) < self.window:
            return
        mean = np.mean(np.asarray(self._last), axis=0)
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

    def steady(self) -> np.ndarray:
        """The steady phasor extrapolated from the periods after ``settle`` (:func:`extrapolate`), (n,) complex."""
        if not self._steady:
            raise ValueError(f"steady: fewer than 3 whole periods after settle = {self.settle} recorded "
                             f"({self.periods})")
        return self._steady[-1]

    def steady_transient(self) -> float:
        """Estimated ``||steady() - steady|| / ||steady()||``: twice the relative change of :meth:`steady`
        over the last three periods (inf before that is known)."""
        return self.steady_estimates[-1] if self.steady_estimates else math.inf

    def stalled(self, extrapolated: bool = False) -> bool:
        """The transient does not decay: the median estimate of the last 10 periods is above 1 / 1.5 of the
        median of the 10 periods 30 earlier (a mode that grows, or a drift; with ``extrapolated=False``, the
        plain window phasor's estimate, also a mode that does not decay)."""
        e = self.steady_estimates if extrapolated else self.estimates
        if len(e) < _STALL_SPAN:
            return False
        return float(np.median(e[-10:])) > float(np.median(e[-_STALL_SPAN:-_STALL_SPAN + 10])) / _STALL_FACTOR


class DrivenRun(NamedTuple):
    """What :func:`run_driven` measured."""

    phasor: np.ndarray  #: (n,) complex: the extrapolated steady phasor ("auto") or the DFT over the last window
    steps: int  #: steps taken
    periods: float  #: periods run (steps / per)
    transient: float  #: estimated transient left in ``phasor``, relative to its L2 norm
    converged: bool  #: ``periods="auto"``: the estimate fell below ``tol``; fixed periods: it is below ``tol``
    stalled: bool = False  #: the estimate stopped falling (:meth:`PeriodPhasors.stalled`)
    extrapolated: bool = False  #: ``phasor`` is :meth:`PeriodPhasors.steady` (``periods="auto"``)
    gain: float = 1.0  #: the extrapolation's gain (:data:`GAIN_MAX`); 1 for a plain DFT


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
        ``round(window * per)`` steps, its transient :meth:`PeriodPhasors.transient`), or ``"auto"``:
        whole periods until :meth:`PeriodPhasors.steady_transient` stays below ``tol``
        for two periods (or ``max_periods``); the phasor is then the extrapolated
        :meth:`PeriodPhasors.steady`.
    ramp : float
        Periods of the drive's switch-on (their phasors are not extrapolated).
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
    tracker = PeriodPhasors(len(values), per, w, whole, settle=math.ceil(ramp))
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
                settled = settled + 1 if tracker.steady_transient() <= tol else 0
                if settled >= _SETTLED or (tracker.periods >= start + _STALL_SPAN and tracker.stalled(True)):
                    break
        est = tracker.steady_transient()
        return DrivenRun(tracker.steady(), n, n / per, est, est <= tol, est > tol and tracker.stalled(True), True,
                         tracker.gain)
    steps = int(round(float(periods) * per))
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

    A run is certified when its transient is at most :data:`STEADY_ACCEPT` times ``tol`` (``"auto"`` stops
    at ``tol``; a fixed length's undamped remnant at that level limits its phasor without growing) and its
    extrapolation's gain is at most :data:`GAIN_MAX`.
    """
    if run.transient <= STEADY_ACCEPT * tol:
        if run.gain > GAIN_MAX:
            return (f"the steady phasor was extrapolated far beyond the {run.periods:g} periods run (gain "
                    f"{run.gain:.3g}, accepted up to {GAIN_MAX:g}): a mode of the discretisation resonates near "
                    "the drive frequency (a finer spacing may remove it)",)
        return ()
    if run.stalled:
        what = "a drift or a growing mode" if run.extrapolated else "a drift or an undamped mode"
        return (f"the phasor is not steady: the transient left, estimated at {run.transient:.2g} of its norm "
                f"(accepted up to {STEADY_ACCEPT * tol:g}), stopped decaying by {run.periods:g} periods ({what}; "
                "a finer spacing may remove it)",)
    how = (f"when periods='auto' stopped at max_periods = {run.periods:g}" if periods == "auto"
           else f"after the fixed {run.periods:g} periods")
    return (f"the phasor is not steady: the transient left is estimated at {run.transient:.2g} of its norm "
            f"{how} (accepted up to {STEADY_ACCEPT * tol:g}); run longer: periods='auto' (--periods auto) "
            "or a larger steady_tol",)
