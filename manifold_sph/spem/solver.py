"""Leap-frog SPEM solvers: 2D TMz (Ez, Hx, Hy) and the 1D line (Ex, Hy).

Ez lives at integer times ``n dt``, H at half times (docs/method.md section 7):

    Ez^{n+1}     = ca Ez^n + cb (dHy/dx - dHx/dy)^{n+1/2}
    Hx^{n+3/2}   = da Hx^{n+1/2} - db dEz/dy^{n+1}
    Hy^{n+3/2}   = da Hy^{n+1/2} + db dEz/dx^{n+1}

with the cross-set CSPM derivative matrices of :mod:`.operators`, assembled
once. Ez is split into Ezx + Ezy everywhere (Berenger); outside the PML the
split is exact and costs two vector additions. ``ca, cb`` include the
material conductivity sigma and the PML sigma_x / sigma_y (semi-implicit
average, unconditionally stable for any sigma); ``da, db`` the matched
magnetic conductivity ``sigma* = sigma mu0/eps0`` (Hx is damped by the
y-layer, Hy by the x-layer).

Examples
--------
>>> from manifold_sph.spem import yee_layout, TMzSolver
>>> s = TMzSolver(yee_layout((0, 0.1, 0, 0.1), 0.01))
>>> round(s.courant, 3), s.n_particles
(0.9, 341)
>>> TMzSolver(yee_layout((0, 0.1, 0, 0.1), 0.01), dt=1e-10)
Traceback (most recent call last):
...
ValueError: dt = 1e-10 s violates the CFL condition S = sqrt(2) c dt / h_min = 6.057 > 1 (h_min = 0.007 m); use dt <= 1.651e-11 s
"""

from __future__ import annotations

import math
import time as _time

import numpy as np
import scipy.sparse as sp

from .._validation import check_in, check_int, check_positive
from .constants import C0, EPS0, MU0
from .layouts import Layout
from .operators import cross_gradient, sbp_correct
from .pml import PML
from .sources import Source

__all__ = ["TMzSolver", "Line1DSolver", "cfl_number", "DEFAULT_H_RATIO"]

#: Default smoothing length over spacing (cubic kernel, support 2h = 1.4 dr:
#: the nearest cross neighbours and the next row/column).
DEFAULT_H_RATIO = 0.7


def cfl_number(dt: float, h_min: float) -> float:
    """``S = sqrt(2) c dt / h_min`` ([2] eq. 3.16)."""
    return math.sqrt(2.0) * C0 * dt / h_min


def _per_particle(name, value, points, *, positive=True, allow_zero=False):
    """A scalar, an (N,) array or a callable of the (N, d) points -> float64 (N,)."""
    n = len(points)
    v = value(points) if callable(value) else value
    try:
        arr = np.broadcast_to(np.asarray(v, dtype=np.float64), (n,)).copy()
    except ValueError:
        raise ValueError(f"{name} must be a scalar or an array of shape ({n},), got shape {np.shape(v)}") from None
    bad = ~np.isfinite(arr) | ((arr < 0) if allow_zero else (arr <= 0)) if positive else ~np.isfinite(arr)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        kind = "non-negative" if allow_zero else "positive"
        raise ValueError(f"{name} must be finite and {kind} at every particle, got {float(arr[k])!r} at particle {k}")
    return arr


def _volumes(points, h, kernel):
    """Relative particle volumes ``mean(S) / S_i`` with ``S_i = sum_j w(|x_ij|/h)`` (Shepard density)."""
    from scipy.spatial import cKDTree

    from ..kernels import get_kernel

    k = get_kernel(kernel)
    tree = cKDTree(points)
    D = tree.sparse_distance_matrix(tree, k.support * h, output_type="coo_matrix")
    S = np.bincount(D.row, weights=k.w(D.data / h), minlength=len(points)) + k.w(0.0)
    return (S.mean() / S)[:, None]


def _check_dt(dt, h_min, courant):
    if dt is None:
        courant = check_positive("courant", courant)
        if courant > 1:
            raise ValueError(f"courant must be at most 1 (CFL), got {courant}")
        return courant * h_min / (math.sqrt(2.0) * C0)
    dt = check_positive("dt", dt)
    S = cfl_number(dt, h_min)
    if S > 1.0 + 1e-12:
        raise ValueError(
            f"dt = {dt:.4g} s violates the CFL condition S = sqrt(2) c dt / h_min = {S:.3f} > 1 "
            f"(h_min = {h_min:.4g} m); use dt <= {h_min / (math.sqrt(2.0) * C0):.4g} s"
        )
    return dt


class _Leapfrog:
    """Shared run loop: probes, snapshots, progress."""

    def run(self, steps=None, *, t_end=None, probes=None, snapshot_every=None, progress=False):
        """Advance ``steps`` steps (or up to time ``t_end``), recording probes and snapshots.

        Parameters
        ----------
        steps : int, optional
        t_end : float, optional
            Alternative to ``steps``: ``ceil((t_end - t) / dt)`` steps.
        probes : (P,) int array, optional
            Indices of E particles whose field is recorded after every step.
        snapshot_every : int, optional
            Store a copy of the E field every this many steps.
        progress : bool
            Show a tqdm bar.

        Returns
        -------
        dict
            ``times`` (steps,), ``probes`` (steps, P), ``snapshots`` list of
            (time, field), ``seconds`` wall time.
        """
        if (steps is None) == (t_end is None):
            raise ValueError("give exactly one of steps and t_end")
        if steps is None:
            t_end = check_positive("t_end", t_end, allow_zero=True)
            steps = max(0, int(math.ceil((t_end - self.t) / self.dt - 1e-9)))
        steps = check_int("steps", steps, minimum=0)
        probes = np.zeros(0, dtype=np.int64) if probes is None else np.atleast_1d(np.asarray(probes, dtype=np.int64))
        if probes.size and (probes.min() < 0 or probes.max() >= self.n_e):
            raise ValueError(f"probes must be E particle indices in [0, {self.n_e}), got {probes.tolist()}")
        times = np.empty(steps)
        series = np.empty((steps, probes.size))
        snaps = []
        it = range(steps)
        if progress:
            from tqdm import tqdm

            it = tqdm(it, desc="spem", unit="step")
        t0 = _time.perf_counter()
        for n in it:
            self.step()
            times[n] = self.t
            if probes.size:
                series[n] = self.e_field[probes]
            if snapshot_every and (n + 1) % snapshot_every == 0:
                snaps.append((self.t, self.e_field.copy()))
        return {"times": times, "probes": series, "snapshots": snaps, "seconds": _time.perf_counter() - t0}


class TMzSolver(_Leapfrog):
    """SPEM for 2D TMz waves on an E set and H sets (the thesis [2], chapter 3).

    Parameters
    ----------
    layout : Layout
        Particle sets (see :mod:`.layouts`); ``layout.e_fixed`` E particles
        are held at Ez = 0 (PEC; no particles beyond = conductor).
    h : float, optional
        Smoothing length (default ``h_ratio * layout.dr``).
    h_ratio : float
        ``h / dr`` when ``h`` is not given (default 0.7 with the cubic kernel).
    kernel : str
        Kernel name (default "cubic", as in [2]).
    form : {"fpm", "cspm", "diagonal"}
        Derivative system (:func:`.operators.cross_gradient`); "diagonal"
        reproduces the scalar ratios of [2].
    eps_r, mu_r, sigma : float, array or callable
        Relative permittivity and conductivity (S/m) per E particle,
        relative permeability per H particle.
    pml : PML, optional
        Absorbing layers.
    dt : float, optional
        Time step; refused above the CFL limit ``h_min / (sqrt(2) c)``.
    courant : float
        ``S`` used when ``dt`` is None (default 0.9).
    sources : sequence of Source
        Hard sources replace Ez at their particles (which are then not
        updated), soft sources add to it.
    coupling : {"direct", "adjoint", "sbp"}
        "direct" (default): every set's derivatives by its own CSPM system.
        First-order consistent everywhere and stable on lattices, but on
        irregular layouts (jittered, Poisson) the pair is not skew-adjoint,
        its spectrum is complex and the run blows up within a few hundred
        steps. "adjoint": H rows = the negative adjoint ``-V_H^-1 D^T V_E``
        of the E rows (energy-conserving, stable, but inconsistent on
        irregular layouts). "sbp": the E rows are first corrected
        (:func:`.operators.sbp_correct`) so that their negative adjoint is
        consistent as well: stable and consistent away from walls and
        sources; use it for irregular layouts, with ``h_ratio`` about 0.8-1.
        For the energy-conserving couplings dt is also bounded by the
        computed spectral limit (:meth:`stability_limit`).
    boundary_rows : {"adjoint", "direct"}
        With "sbp": H rows next to PEC or driven E particles from the adjoint
        (stable, default) or from their own CSPM rows (consistent there, but
        unstable on irregular layouts).
    workers : int
        2 runs the two independent sparse products of each half step on two
        threads (scipy releases the GIL in them).
    """

    def __init__(self, layout: Layout, *, h=None, h_ratio: float = DEFAULT_H_RATIO, kernel="cubic", form="fpm",
                 eps_r=1.0, mu_r=1.0, sigma=0.0, pml: PML | None = None, dt=None, courant: float = 0.9, sources=(),
                 coupling: str = "direct", workers: int = 1, boundary_rows: str = "adjoint"):
        if not isinstance(layout, Layout):
            raise TypeError(f"layout must be a Layout, got {type(layout).__name__}")
        self.layout = layout
        self.h = check_positive("h", h) if h is not None else check_positive("h_ratio", h_ratio) * layout.dr
        self.kernel, self.form = kernel, form
        e, hx, hy = layout.e, layout.hx, layout.hy
        self.n_e = len(e)
        self.sources = list(sources)
        for src in self.sources:
            if not isinstance(src, Source):
                raise TypeError(f"sources must be Source objects, got {type(src).__name__}")
            if src.indices.min() < 0 or src.indices.max() >= self.n_e:
                raise ValueError(f"source indices must lie in [0, {self.n_e}), got {src.indices.min()}..{src.indices.max()}")
        # E particles that are updated: not PEC, not driven by a hard source
        driven = np.zeros(self.n_e, dtype=bool)
        for src in self.sources:
            if src.kind == "hard":
                driven[src.indices] = True
        self.free = np.flatnonzero(~layout.e_fixed & ~driven)
        if self.free.size == 0:
            raise ValueError("every E particle is fixed (PEC) or driven: no E particle left to update")
        ef = e[self.free]
        kw = dict(kernel=kernel, form=form)
        if layout.shared:
            Dx, Dy = cross_gradient(ef, hx, self.h, row_name="E particles", col_name="H particles", **kw)
            self.Dx_e, self.Dy_e = Dx, Dy
            Hx_, Hy_ = cross_gradient(hx, e, self.h, row_name="H particles", col_name="E particles", **kw)
            self.Dy_hx, self.Dx_hy = Hy_, Hx_
        else:
            self.Dx_e = cross_gradient(ef, hy, self.h, row_name="E particles", col_name="Hy particles", **kw)[0]
            self.Dy_e = cross_gradient(ef, hx, self.h, row_name="E particles", col_name="Hx particles", **kw)[1]
            self.Dy_hx = cross_gradient(hx, e, self.h, row_name="Hx particles", col_name="E particles", **kw)[1]
            self.Dx_hy = cross_gradient(hy, e, self.h, row_name="Hy particles", col_name="E particles", **kw)[0]
        check_in("coupling", coupling, ("direct", "adjoint", "sbp"))
        check_in("boundary_rows", boundary_rows, ("adjoint", "direct"))
        self.coupling = coupling
        if coupling == "sbp":
            # E rows corrected so that their negative adjoint is consistent too
            # (operators.sbp_correct); H rows = that adjoint. The driven (hard
            # source) E particles get rows as well, so that H rows next to a
            # source stay consistent; their values are imposed, so the
            # homogeneous part of the scheme is still exactly skew-adjoint.
            vol_all = _volumes(e, self.h, kernel)[:, 0]
            vx, vy = _volumes(hx, self.h, kernel)[:, 0], _volumes(hy, self.h, kernel)[:, 0]
            rows_sd = np.flatnonzero(~layout.e_fixed)
            try:
                Dx_sd = cross_gradient(e[rows_sd], hy, self.h, **kw)[0]
                Dy_sd = cross_gradient(e[rows_sd], hx, self.h, **kw)[1]
                touch = layout.e_fixed.astype(float)
            except ValueError:  # degenerate driven rows (a source on a wall): treat them as boundary data
                rows_sd, Dx_sd, Dy_sd = self.free, self.Dx_e, self.Dy_e
                touch = np.ones(self.n_e)
                touch[self.free] = 0.0
            keep = np.zeros(self.n_e)
            keep[driven] = 1.0
            keep[rows_sd] = 0.0
            Kd = sp.diags(keep)  # driven columns not covered by the adjoint
            inner_x = (abs(self.Dy_hx) @ touch) == 0
            inner_y = (abs(self.Dx_hy) @ touch) == 0
            v_sd = vol_all[rows_sd]
            Dy_sd = sbp_correct(Dy_sd, e[rows_sd], hx, 1, v_sd, vx, inner_x, scale=layout.dr)
            Dx_sd = sbp_correct(Dx_sd, e[rows_sd], hy, 0, v_sd, vy, inner_y, scale=layout.dr)
            where = np.full(self.n_e, -1)
            where[rows_sd] = np.arange(len(rows_sd))
            self.Dy_e, self.Dx_e = Dy_sd[where[self.free]], Dx_sd[where[self.free]]
            Gy = self._expand(-(Dy_sd.T.multiply(v_sd[None, :])).tocsr().multiply(1.0 / vx[:, None]), rows_sd)
            Gx = self._expand(-(Dx_sd.T.multiply(v_sd[None, :])).tocsr().multiply(1.0 / vy[:, None]), rows_sd)
            if boundary_rows == "direct":
                # H rows touching PEC (or degenerate driven) E particles keep their
                # own consistent CSPM rows (skew-adjointness is lost only there)
                bx, by = sp.diags((~inner_x).astype(float)), sp.diags((~inner_y).astype(float))
                ix, iy = sp.diags(inner_x.astype(float)), sp.diags(inner_y.astype(float))
                self.Dy_hx = (ix @ (Gy + self.Dy_hx @ Kd) + bx @ self.Dy_hx).tocsr()
                self.Dx_hy = (iy @ (Gx + self.Dx_hy @ Kd) + by @ self.Dx_hy).tocsr()
            else:
                self.Dy_hx = (Gy + self.Dy_hx @ Kd).tocsr()
                self.Dx_hy = (Gx + self.Dx_hy @ Kd).tocsr()
        if coupling == "adjoint":
            # H rows from the negative adjoint of the E rows: -V_H^-1 D^T V_E.
            # The semi-discrete scheme then conserves a discrete energy, which
            # keeps irregular layouts stable.
            # Columns of driven (hard-source) E particles keep the direct
            # weights: they are boundary data, not unknowns.
            vol_e = _volumes(e, self.h, kernel)[self.free, 0]
            keep = np.zeros(self.n_e)
            keep[driven] = 1.0
            Kd = sp.diags(keep)
            self.Dy_hx = (self._expand(-(self.Dy_e.T.multiply(vol_e[None, :])).tocsr()
                                       / _volumes(hx, self.h, kernel)) + self.Dy_hx @ Kd).tocsr()
            self.Dx_hy = (self._expand(-(self.Dx_e.T.multiply(vol_e[None, :])).tocsr()
                                       / _volumes(hy, self.h, kernel)) + self.Dx_hy @ Kd).tocsr()
        self.dt = _check_dt(dt, self.h, courant)
        self.eps_r = _per_particle("eps_r", eps_r, e)
        self.sigma = _per_particle("sigma", sigma, e, allow_zero=True)
        self.mu_r_x = _per_particle("mu_r", mu_r, hx)
        self.mu_r_y = self.mu_r_x if layout.shared else _per_particle("mu_r", mu_r, hy)
        self.dt_stable = None
        if coupling != "direct":
            # The CFL rule S <= 1 is not enough on irregular layouts: bound dt
            # by the spectral radius of the lossless E -> E operator.
            self.dt_stable = self.stability_limit()
            if dt is None:
                self.dt = min(self.dt, courant * self.dt_stable)
            elif self.dt > self.dt_stable:
                raise ValueError(
                    f"dt = {self.dt:.4g} s exceeds the stability limit 2/sqrt(rho) = {self.dt_stable:.4g} s of "
                    f"the {coupling} operators on this layout; use dt <= {self.dt_stable:.4g} s"
                )
        self.courant = cfl_number(self.dt, self.h)
        self.pml = pml
        if pml is not None and not isinstance(pml, PML):
            raise TypeError(f"pml must be a PML or None, got {type(pml).__name__}")
        zeros_e = np.zeros(self.n_e)
        sx_e, sy_e = pml.sigma(e) if pml else (zeros_e, zeros_e)
        _, sy_hx = pml.sigma(hx) if pml else (None, np.zeros(len(hx)))
        sx_hy, _ = pml.sigma(hy) if pml else (np.zeros(len(hy)), None)
        self._sigmas = (self.sigma + sx_e, self.sigma + sy_e, sy_hx * MU0 / EPS0, sx_hy * MU0 / EPS0)
        self._update_coefficients()
        self.workers = check_int("workers", workers, minimum=1)
        self._pool = None
        if self.workers > 1:
            from concurrent.futures import ThreadPoolExecutor

            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="spem")
        self.reset()

    def _update_coefficients(self):
        sxe, sye, sxh, syh = self._sigmas
        eps = EPS0 * self.eps_r
        self.ca_x, self.cb_x = self._coefficients(sxe, eps)
        self.ca_y, self.cb_y = self._coefficients(sye, eps)
        self.da_x, self.db_x = self._coefficients(sxh, MU0 * self.mu_r_x)
        self.da_y, self.db_y = self._coefficients(syh, MU0 * self.mu_r_y)
        fr = self.free
        self._cax, self._cbx, self._cay, self._cby = self.ca_x[fr], self.cb_x[fr], self.ca_y[fr], self.cb_y[fr]

    def set_dt(self, dt: float):
        """Change the time step (checked against the CFL rule and, if computed, the stability limit).

        Call it before ``set_initial`` / ``run``; the fields are not rescaled.
        """
        dt = _check_dt(dt, self.h, 1.0)
        if self.dt_stable is not None and dt > self.dt_stable:
            raise ValueError(f"dt = {dt:.4g} s exceeds the stability limit {self.dt_stable:.4g} s of this layout")
        self.dt = dt
        self.courant = cfl_number(dt, self.h)
        self._update_coefficients()

    def stability_limit(self) -> float:
        """Largest stable leap-frog dt, ``2 / sqrt(rho)``, rho the spectral radius of the lossless E -> E operator.

        Exact for the energy-conserving couplings ("adjoint", "sbp"), an
        estimate for "direct" (whose spectrum may be complex).
        """
        from scipy.sparse.linalg import ArpackNoConvergence, eigs

        fr = self.free
        inv_eps = 1.0 / (EPS0 * self.eps_r[fr])
        L = sp.diags(inv_eps) @ (self.Dx_e @ sp.diags(1.0 / (MU0 * self.mu_r_y)) @ self.Dx_hy[:, fr]
                                 + self.Dy_e @ sp.diags(1.0 / (MU0 * self.mu_r_x)) @ self.Dy_hx[:, fr])
        try:
            rho = float(np.abs(eigs(L, k=1, which="LM", return_eigenvectors=False, tol=1e-4, maxiter=5000)).max())
        except ArpackNoConvergence as exc:  # pragma: no cover - fall back to a Gershgorin bound
            rho = float(abs(L).sum(axis=1).max()) if not len(exc.eigenvalues) else float(np.abs(exc.eigenvalues).max())
        return 2.0 / math.sqrt(rho)

    def _expand(self, D, cols=None):
        """Columns over the E particles ``cols`` (default: the free ones) -> columns over every E particle."""
        cols = self.free if cols is None else cols
        P = sp.csr_matrix((np.ones(len(cols)), (cols, np.arange(len(cols)))), shape=(self.n_e, len(cols)))
        return (sp.csr_matrix(D) @ P.T).tocsr()

    def _coefficients(self, s, m):
        a = s * self.dt / (2.0 * m)
        return (1.0 - a) / (1.0 + a), (self.dt / m) / (1.0 + a)

    @property
    def n_particles(self) -> int:
        """Number of particles (E plus distinct H)."""
        return self.layout.n_particles

    def reset(self):
        """Zero every field and set t = 0."""
        self.ezx = np.zeros(self.n_e)
        self.ezy = np.zeros(self.n_e)
        self.hx = np.zeros(len(self.layout.hx))
        self.hy = np.zeros(len(self.layout.hy))
        self.t = 0.0
        self.n = 0

    @property
    def e_field(self) -> np.ndarray:
        """Ez = Ezx + Ezy at the E particles (time ``t``)."""
        return self.ezx + self.ezy

    def probe_indices(self, xy) -> np.ndarray:
        """Indices of the E particles nearest to the points ``xy`` (P, 2), for ``run(probes=...)``."""
        from .._validation import as_points

        q = as_points("xy", np.atleast_2d(np.asarray(xy, dtype=np.float64)), dim=2)
        d2 = ((self.layout.e[None, :, :] - q[:, None, :]) ** 2).sum(axis=2)
        return np.argmin(d2, axis=1)

    def set_initial(self, ez0, hx0=None, hy0=None):
        """Start from Ez(0) = ez0 (and H(0)), with H advanced half a step.

        ``H^{1/2} = H(0) + dt/2 dH/dt(0)``, second-order accurate when
        H(0) = 0 (fields even in time, as in the cavity case).
        """
        from .._validation import as_field

        self.reset()
        ez0 = as_field("ez0", ez0, self.n_e).copy()
        ez0[self.layout.e_fixed] = 0.0
        self.ezx, self.ezy = ez0.copy(), np.zeros(self.n_e)
        self.hx = np.zeros(len(self.layout.hx)) if hx0 is None else as_field("hx0", hx0, len(self.layout.hx)).copy()
        self.hy = np.zeros(len(self.layout.hy)) if hy0 is None else as_field("hy0", hy0, len(self.layout.hy)).copy()
        self.hx -= 0.5 * self.db_x * (self.Dy_hx @ ez0)
        self.hy += 0.5 * self.db_y * (self.Dx_hy @ ez0)

    def _pair(self, A, x, B, y):
        """``A @ x`` and ``B @ y``, on two threads when ``workers`` > 1 (scipy's sparse products release the GIL)."""
        if self._pool is None:
            return A @ x, B @ y
        fa = self._pool.submit(A.dot, x)
        b = B @ y
        return fa.result(), b

    def step(self):
        """One leap-frog step: Ez to t + dt, then H to t + 3 dt / 2."""
        fr = self.free
        dhy, dhx = self._pair(self.Dx_e, self.hy, self.Dy_e, self.hx)
        self.ezx[fr] = self._cax * self.ezx[fr] + self._cbx * dhy
        self.ezy[fr] = self._cay * self.ezy[fr] - self._cby * dhx
        self.t = (self.n + 1) * self.dt
        self.n += 1
        for s in self.sources:
            v = s.waveform(self.t)
            if s.kind == "hard":
                self.ezx[s.indices] = v
                self.ezy[s.indices] = 0.0
            else:
                self.ezx[s.indices] += v
        ez = self.ezx + self.ezy
        dex, dey = self._pair(self.Dy_hx, ez, self.Dx_hy, ez)
        self.hx = self.da_x * self.hx - self.db_x * dex
        self.hy = self.da_y * self.hy + self.db_y * dey


class Line1DSolver(_Leapfrog):
    """SPEM on a line: Ex on E particles, Hy on H particles ([2] sec. 4.2).

    ``dEx/dt = -(1/eps) dHy/dz``, ``dHy/dt = -(1/mu) dEx/dz``; the end E
    particles are held at zero (PEC) unless ``fixed_ends=False``.

    Examples
    --------
    >>> from manifold_sph.spem import line_layout
    >>> e, h = line_layout(0.0, 1.0, 0.01)
    >>> s = Line1DSolver(e, h, h=0.018)
    >>> s.n_e, len(s.h_points)
    (101, 100)
    """

    def __init__(self, e_points, h_points, *, h, kernel="cubic", form="fpm", eps_r=1.0, mu_r=1.0, dt=None,
                 courant: float = 0.9, sources=(), fixed_ends: bool = True):
        self.e_points = np.asarray(e_points, dtype=np.float64).reshape(-1, 1)
        self.h_points = np.asarray(h_points, dtype=np.float64).reshape(-1, 1)
        self.h = check_positive("h", h)
        self.n_e = len(self.e_points)
        fixed = np.zeros(self.n_e, bool)
        if fixed_ends and self.n_e:
            fixed[np.argmin(self.e_points[:, 0])] = fixed[np.argmax(self.e_points[:, 0])] = True
        self.fixed = fixed
        self.free = np.flatnonzero(~fixed)
        self.D_e = cross_gradient(self.e_points[self.free], self.h_points, self.h, kernel=kernel, form=form,
                                  row_name="E particles", col_name="H particles")[0]
        self.D_h = cross_gradient(self.h_points, self.e_points, self.h, kernel=kernel, form=form,
                                  row_name="H particles", col_name="E particles")[0]
        self.dt = _check_dt(dt, self.h, courant)
        self.courant = cfl_number(self.dt, self.h)
        self.eps = EPS0 * _per_particle("eps_r", eps_r, self.e_points)
        self.mu = MU0 * _per_particle("mu_r", mu_r, self.h_points)
        self.sources = list(sources)
        self.ex = np.zeros(self.n_e)
        self.hy = np.zeros(len(self.h_points))
        self.t = 0.0
        self.n = 0

    @property
    def e_field(self):
        """Ex at the E particles."""
        return self.ex

    def step(self):
        """One leap-frog step."""
        fr = self.free
        self.ex[fr] -= self.dt / self.eps[fr] * (self.D_e @ self.hy)
        self.n += 1
        self.t = self.n * self.dt
        for s in self.sources:
            v = s.waveform(self.t)
            if s.kind == "hard":
                self.ex[s.indices] = v
            else:
                self.ex[s.indices] += v
        self.hy -= self.dt / self.mu * (self.D_h @ self.ex)
