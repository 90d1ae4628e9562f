"""The run contract of every SPEM solver: :class:`Leapfrog.run` returns a :class:`.results.RunResult`.

A solver derives from :class:`Leapfrog` and defines ``step()`` (one leap-frog
step, advancing ``t`` by ``dt``) and ``field`` (the scalar field it records:
Ez for TMz, Ex on the line, Hz for TEz). ``run`` records that field at the
``probes=`` particles after every step and a copy of the whole field ``every=``
steps.

Examples
--------
>>> from manifold_sph.spem import TEzSolver, TMzSolver, tez_layout, yee_layout
>>> out = TMzSolver(yee_layout((0, 0.1, 0, 0.1), 0.01)).run(10, probes=[3], every=5)
>>> out.probes.shape, out.snapshots.shape
((10, 1), (2, 121))
>>> TEzSolver(tez_layout((0, 0.1, 0, 0.1), 0.01)).run(4, probes=[0, 1]).probes.shape
(4, 2)
"""

from __future__ import annotations

import math
import time

import numpy as np
from numpy.typing import ArrayLike

from .._validation import check_int, check_positive
from .results import RunResult

__all__ = ["Leapfrog"]


class Leapfrog:
    """Base of the SPEM solvers: the shared run loop (probes, snapshots, progress)."""

    t: float
    dt: float

    @property
    def field(self) -> np.ndarray:
        """The scalar field that ``run`` records (at time ``t``)."""
        raise NotImplementedError

    def step(self) -> None:
        """One leap-frog step (``t`` to ``t + dt``)."""
        raise NotImplementedError

    def run(self, steps: int | None = None, *, t_end: float | None = None, probes: ArrayLike | None = None,
            every: int | None = None, progress: bool = False) -> RunResult:
        """Advance ``steps`` steps (or up to time ``t_end``), recording probes and snapshots of :attr:`field`.

        Parameters
        ----------
        steps : int, optional
        t_end : float, optional
            Alternative to ``steps``: ``ceil((t_end - t) / dt)`` steps.
        probes : (P,) int array, optional
            Indices of the particles of :attr:`field` recorded after every step.
        every : int, optional
            Store a copy of :attr:`field` every this many steps (>= 1).
        progress : bool
            Show a tqdm bar.

        Returns
        -------
        RunResult
            ``times`` (steps,), ``probes`` (steps, P), ``snapshots`` (S, n) at
            ``snapshot_times`` (S,), ``seconds`` wall time of the steps.
        """
        if (steps is None) == (t_end is None):
            raise ValueError("give exactly one of steps and t_end")
        if steps is None:
            t_end = check_positive("t_end", t_end, allow_zero=True)
            steps = max(0, int(math.ceil((t_end - self.t) / self.dt - 1e-9)))
        steps = check_int("steps", steps, minimum=0)
        if every is not None:
            every = check_int("every", every, minimum=1)
        n = len(self.field)
        probes = np.zeros(0, dtype=np.int64) if probes is None else np.atleast_1d(np.asarray(probes, dtype=np.int64))
        if probes.size and (probes.min() < 0 or probes.max() >= n):
            raise ValueError(f"probes must be particle indices in [0, {n}), got {probes.tolist()}")
        times = np.empty(steps)
        series = np.empty((steps, probes.size))
        snaps = []
        it = range(steps)
        if progress:
            from tqdm import tqdm

            it = tqdm(it, desc="spem", unit="step")
        t0 = time.perf_counter()
        for k in it:
            self.step()
            times[k] = self.t
            if probes.size:
                series[k] = self.field[probes]
            if every and (k + 1) % every == 0:
                snaps.append((self.t, self.field.copy()))
        seconds = time.perf_counter() - t0
        return RunResult(times, series, np.array([f for _, f in snaps]).reshape(len(snaps), n),
                         np.array([t for t, _ in snaps], dtype=np.float64), seconds)
