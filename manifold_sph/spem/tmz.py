"""The leap-frog SPEM solver of 2D TMz waves (Ez, Hx, Hy).

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
y-layer, Hy by the x-layer). ``run`` is the contract of every SPEM solver
(:class:`.stepping.Leapfrog`): it returns a :class:`.results.RunResult`.

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
import sys
import time as _time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike

from .. import _jit
from .._validation import check_in, check_int, check_positive
from ..kernels import get_kernel
from . import compiled
from .constants import C0, EPS0, MU0
from .layouts import Layout
from .mirror import check_mirror_planes, folded_gradient, mirror_reach
from .operators import (
    COUPLINGS,
    DEFAULT_COUPLING,
    DEFAULT_H_RATIO,
    MIMETIC_H_RATIO,
    SBP_LAYERS,
    cross_gradient,
    nearest_plane,
    sbp_pair,
)
from .pml import PML
from .sources import Source
from .stability import (
    SPECTRUM_TOL,
    STABILITY_MARGIN,
    cfl_number,
    check_dt,
    leapfrog_growth,
    per_particle,
    spectral_radius_bound,
)
from .stepping import Leapfrog

if TYPE_CHECKING:
    from ..kernels import Kernel

__all__ = ["TMzSolver", "DENSE_SPECTRUM", "THREADED_STEP", "DRIVEN_ROW_LIMIT", "PML_H_RATIO_MAX", "CONSISTENCY_MARGIN"]


#: Up to this many free E particles the "direct" spectrum is computed densely.
DENSE_SPECTRUM = 900


#: Largest ``h / dr`` at which the split-field PML is validated with the lattice-type couplings ("sbp",
#: "adjoint", "direct"). Measured (``run_pml``, 10 cells, order 3, R = 1e-6, Yee lattice): the normal
#: reflection is -90.7 / -90.6 / -38.7 / -17.8 dB at h/dr 0.7 / 0.8 / 1.0 / 1.3 (-63.5 dB at 1.0 with 20
#: cells): the layer reflects more as the support widens, and a thicker layer recovers only part of it.
PML_H_RATIO_MAX = 0.8
#: :meth:`TMzSolver.interior_consistency_residual`: rows this many kernel supports (kappa h) and more from
#: every PEC and driven E particle. An "adjoint" E row is the transpose of the H rows within one support,
#: which see E particles within one more: two supports from a wall no row of any coupling sees it.
CONSISTENCY_MARGIN = 2.0
#: "sbp": a driven E particle whose derivative weights sum above this over ``dr`` (a one-sided,
#: nearly singular system: a source row on the edge of an irregular layout) is boundary data, as on
#: the lattice where that system is singular (the lattice interior sums to about 2-4).
DRIVEN_ROW_LIMIT = 50.0
#: With ``workers`` > 1 the stencil step runs on threads from this many E particles on.
THREADED_STEP = 20000


#: CPython's reference count (None elsewhere: the compiled step then never updates H in place).
_refcount = getattr(sys, "getrefcount", None)


def _chunks(run_rows, n_rest, parts):
    """``parts`` ranges ``(q0, q1, r0, r1)`` of runs (``run_rows`` rows each) and of ``n_rest`` CSR rows, of
    about equal rows each."""
    cum = np.concatenate([[0], np.cumsum(run_rows)])
    qs = np.searchsorted(cum, np.linspace(0, cum[-1], parts + 1)).clip(0, len(run_rows))
    qs[0], qs[-1] = 0, len(run_rows)
    rs = np.linspace(0, n_rest, parts + 1).round().astype(np.int64)
    return [(int(qs[c]), int(qs[c + 1]), int(rs[c]), int(rs[c + 1])) for c in range(parts)]


class TMzSolver(Leapfrog):
    """SPEM for 2D TMz waves on an E set and H sets (the thesis [2], chapter 3).

    Parameters
    ----------
    layout : Layout
        Particle sets (see :mod:`.layouts`); ``layout.e_fixed`` E particles
        are held at Ez = 0 (PEC; no particles beyond = conductor).
    h : float, optional
        Smoothing length (default ``h_ratio * layout.dr``).
    h_ratio : float, optional
        ``h / dr`` when ``h`` is not given (default: the layout's ``h_ratio``, else 0.7 with the cubic kernel;
        1.5 with "mimetic").
    kernel : str
        Kernel name (default "cubic", as in [2]).
    form : {"fpm", "cspm", "diagonal"}
        Derivative system (:func:`.operators.cross_gradient`); "diagonal"
        reproduces the scalar ratios of [2].
    eps_r, mu_r, sigma : float, array or callable
        Relative permittivity and conductivity (S/m) per E particle,
        relative permeability per H particle; ``eps_r``, ``mu_r`` finite
        and > 0, ``sigma`` finite and >= 0.
    pml : PML, optional
        Absorbing layers.
    dt : float, optional
        Time step; refused above the CFL limit ``h / (sqrt(2) c_max)``,
        ``c_max = c0 / sqrt(min eps_r min mu_r)`` the fastest wave speed,
        and above the spectral limit of the operators (:meth:`stability_limit`).
    courant : float
        Fraction of the smaller of the two limits used when ``dt`` is None
        (default 0.9).
    sources : sequence of Source
        Hard sources replace Ez at their particles (which are then not
        updated), soft sources add to it.
    coupling : {"sbp", "mimetic", "adjoint", "direct"}
        "mimetic": the E -> H gradient is a moving-least-squares fit exact
        for quadratic fields and the E rows its negative adjoint in the
        particle volumes, ``-V_E^-1 G^T V_H``; the volumes and the gradient
        are corrected together (:mod:`.mimetic`) so that the E rows are exact
        for linear fields too (the discrete divergence theorem). Energy-
        conserving like "sbp" and second order on irregular layouts; the
        energy is ``sum V_E eps Ez^2 + sum V_H mu H^2`` (``vol_e``,
        ``vol_hx``, ``vol_hy``, in units of dr^2).
        "sbp" (default): the E rows are corrected (:func:`.operators.sbp_pair`)
        so that the H rows, their negative adjoint plus a boundary closure on
        the PEC particles, are exact for linear fields as well. The pair is
        skew-adjoint: leap-frog conserves a discrete energy on every layout,
        material and ``h_ratio`` (proven; dt bounded by the computed spectral
        radius). "adjoint": H rows = the negative adjoint of the CSPM E rows
        (energy-conserving, but inconsistent next to walls and on irregular
        layouts). "direct": every set's derivatives by its own CSPM system;
        no energy bound, so its spectrum is computed before stepping and the
        solver is refused (ValueError) when a leap-frog mode would grow
        (complex or positive eigenvalues: irregular layouts, wide kernels,
        curved walls).
    workers : int
        2 runs the two independent sparse products of each half step on two
        threads (scipy releases the GIL in them); the compiled stencil step
        cuts each half step into ``workers`` chunks of rows on threads from
        :data:`THREADED_STEP` E particles on (the same numbers; on the shared
        2-core test machine it did not pay: 5.2 against 4.6 ns per unknown and
        step at 4.8e5 unknowns, measured).
    sbp_layers : int or None
        "sbp": rings of pairs around the unmet conditions that the correction
        may change (default 2; None: the whole operator, better next to curved
        walls at fine resolution but a slower set-up; :data:`.operators.SBP_LAYERS`).
    mimetic_fast : bool
        "mimetic": correct only pairs closer than 2 spacings and keep ``G`` exact for
        quadratics instead of cubics (:data:`.mimetic.FAST`): a faster set-up (plane wave
        at 20 particles per wavelength 48 -> 33 s, measured), the same energy
        conservation; a larger phase error on coarse Poisson layouts.
    mirror : float or pair of float, optional
        x values of mirror (perfect magnetic conductor) walls: each derivative matrix takes mirror
        images of its columns across these planes, Ez and Hx even, Hy odd (:mod:`.mirror`); no
        particle beyond them is needed. Exact for any TMz field with ``Hy = 0`` on the planes (a
        plane wave travelling along y). With "sbp" the rows and columns whose support reaches a plane
        are fitted on the linear fields that meet the mirror conditions (``sbp_pair(planes=)``), so the
        pair is exact there on those fields and keeps the stable step of the layout. Every particle
        must lie at least :data:`.mirror.MIRROR_GAP` spacings from a plane, between the planes; not
        with the "mimetic" coupling.
    pml_check : bool
        Refuse a PML with ``h / dr`` above :data:`PML_H_RATIO_MAX` (couplings other than "mimetic"), where
        the layer no longer absorbs (default True).
    stencil : bool
        Apply the rows that repeat one stencil (same column offsets, weights
        equal to :data:`.stencil.RTOL` times the largest entry, same update
        coefficients: the lattice interior, each PML line) as runs of a
        fixed-stencil kernel, the other rows in CSR form (:mod:`.stencil`;
        default True). Those rows use their pattern's weights, so the fields
        differ from the plain CSR step (``stencil=False``) by round-off only.

    Attributes
    ----------
    dt_stable : float
        ``2 / sqrt(rho)``, rho the spectral radius of the lossless E -> E operator.
    growth : float
        "direct" only: the measured per-step leap-frog amplification at ``dt`` (1 when stable).
    """

    def __init__(self, layout: Layout, *, h: float | None = None, h_ratio: float | None = None,
                 kernel: str | Kernel | type[Kernel] = "cubic", form: str = "fpm",
                 eps_r: float | ArrayLike | Callable[[np.ndarray], ArrayLike] = 1.0,
                 mu_r: float | ArrayLike | Callable[[np.ndarray], ArrayLike] = 1.0,
                 sigma: float | ArrayLike | Callable[[np.ndarray], ArrayLike] = 0.0,
                 pml: PML | None = None, dt: float | None = None, courant: float = 0.9, sources: Sequence[Source] = (),
                 coupling: str = DEFAULT_COUPLING, workers: int = 1, sbp_layers: int | None = SBP_LAYERS,
                 mimetic_fast: bool = False, stencil: bool = True, pml_check: bool = True,
                 mirror: float | Sequence[float] | None = None) -> None:
        if not isinstance(layout, Layout):
            raise TypeError(f"layout must be a Layout, got {type(layout).__name__}")
        if pml is not None and not isinstance(pml, PML):
            raise TypeError(f"pml must be a PML or None, got {type(pml).__name__}")
        self.layout, self.pml = layout, pml
        self.coupling = check_in("coupling", coupling, COUPLINGS)
        if not isinstance(mimetic_fast, (bool, np.bool_)):
            raise TypeError(f"mimetic_fast must be a bool, got {type(mimetic_fast).__name__}")
        self.mimetic_fast = bool(mimetic_fast)
        if not isinstance(stencil, (bool, np.bool_)):
            raise TypeError(f"stencil must be a bool, got {type(stencil).__name__}")
        self.stencil = bool(stencil)
        if h_ratio is None and h is None:
            h_ratio = MIMETIC_H_RATIO if self.coupling == "mimetic" else (layout.h_ratio or DEFAULT_H_RATIO)
        self.h = check_positive("h", h) if h is not None else check_positive("h_ratio", h_ratio) * layout.dr
        if pml is not None and pml_check:
            self.check_pml_support(self.h / layout.dr, self.coupling)
        self.kernel, self.form = kernel, form
        self.mirror = check_mirror_planes(mirror, [("E particles", layout.e), ("Hx particles", layout.hx),
                                                   ("Hy particles", layout.hy)], layout.dr)
        if self.mirror and self.coupling == "mimetic":
            raise ValueError("mirror walls are not available with coupling='mimetic' (its operators come from a "
                             "global fit without mirror images); use coupling='sbp', 'adjoint' or 'direct'")
        self.workers = check_int("workers", workers, minimum=1)
        self.sbp_layers = None if sbp_layers is None else check_int("sbp_layers", sbp_layers, minimum=0)
        self.n_e = len(layout.e)
        self._set_materials(eps_r, mu_r, sigma)
        self._set_sources(sources)
        self._assemble()
        self._set_time_step(dt, courant)
        self._set_losses()
        self._pool = None
        if self.workers > 1:
            from concurrent.futures import ThreadPoolExecutor

            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="spem")
        self.reset()

    @staticmethod
    def check_pml_support(h_ratio: float, coupling: str) -> None:
        """Refuse (ValueError) a support ``h / dr`` outside the range where the split-field PML absorbs with
        ``coupling`` (:data:`PML_H_RATIO_MAX` for "sbp", "adjoint", "direct"; "mimetic" is not limited)."""
        if coupling != "mimetic" and h_ratio > PML_H_RATIO_MAX * (1 + 1e-9):
            raise ValueError(
                f"h_ratio = {h_ratio:.3g} is outside the range where the split-field PML absorbs with the "
                f"{coupling!r} coupling (h_ratio <= {PML_H_RATIO_MAX}: a 10-cell layer reflects -89 dB at 0.7 and "
                f"0.8, -38 dB at 1.0, -15 dB at 1.3); use h_ratio <= {PML_H_RATIO_MAX}, coupling='mimetic', "
                f"or pml_check=False to run anyway"
            )

    # ------------------------------------------------------------------ set-up steps
    def _set_materials(self, eps_r, mu_r, sigma):
        """eps_r, sigma per E particle and mu_r per H particle (finite, > 0 / >= 0); the fastest speed c_max."""
        lay = self.layout
        self.eps_r = per_particle("eps_r", eps_r, lay.e)
        self.sigma = per_particle("sigma", sigma, lay.e, allow_zero=True)
        self.mu_r_x = per_particle("mu_r", mu_r, lay.hx)
        self.mu_r_y = self.mu_r_x if lay.shared else per_particle("mu_r", mu_r, lay.hy)
        slowest = float(self.eps_r.min()) * float(min(self.mu_r_x.min(), self.mu_r_y.min()))
        self.c_max = C0 / math.sqrt(slowest)

    def _set_sources(self, sources):
        """Check the sources; ``free`` = the E particles updated by the scheme (not PEC, not hard-driven)."""
        self.sources = list(sources)
        driven = np.zeros(self.n_e, dtype=bool)
        for src in self.sources:
            if not isinstance(src, Source):
                raise TypeError(f"sources must be Source objects, got {type(src).__name__}")
            if src.indices.min() < 0 or src.indices.max() >= self.n_e:
                raise ValueError(f"source indices must lie in [0, {self.n_e}), got {src.indices.min()}..{src.indices.max()}")
            if src.kind == "hard":
                driven[src.indices] = True
        self.driven = driven
        self.free = np.flatnonzero(~self.layout.e_fixed & ~driven)
        if self.free.size == 0:
            raise ValueError("every E particle is fixed (PEC) or driven: no E particle left to update")

    def _gradient(self, rows, cols, axis, row_name, col_name):
        if self.mirror:
            # Hy (the x derivative's H columns) is odd about a mirror plane, Ez and Hx even
            lay = self.layout
            return folded_gradient(rows, cols, self.h, axis, planes=self.mirror, odd=cols is not lay.e and axis == 0,
                                   spacing=lay.dr, y_range=tuple(lay.bounds[2:4]), kernel=self.kernel,
                                   form=self.form, row_name=row_name, col_name=col_name)
        return cross_gradient(rows, cols, self.h, kernel=self.kernel, form=self.form, row_name=row_name,
                              col_name=col_name)[axis]

    def _assemble(self):
        """The four derivative matrices: E rows (free E particles) and H rows (over every E particle)."""
        lay = self.layout
        e, hx, hy = lay.e, lay.hx, lay.hy
        nx, ny = ("H particles", "H particles") if lay.shared else ("Hx particles", "Hy particles")
        self.vol_e = np.ones(len(self.free))
        if self.coupling == "sbp":
            self._assemble_sbp()
            return
        if self.coupling == "mimetic":
            self._assemble_mimetic()
            return
        ef = e[self.free]
        self.Dx_e = self._gradient(ef, hy, 0, "E particles", ny)
        self.Dy_e = self._gradient(ef, hx, 1, "E particles", nx)
        self.Dy_hx = self._gradient(hx, e, 1, nx, "E particles")
        self.Dx_hy = self._gradient(hy, e, 0, ny, "E particles")
        if self.coupling == "adjoint":
            # H rows at the free columns: the negative adjoint of the E rows (equal
            # volumes); the PEC and driven columns keep their CSPM weights (those
            # particles carry boundary data, not unknowns).
            keep = sp.diags((~np.isin(np.arange(self.n_e), self.free)).astype(float))
            self.Dy_hx = (self._expand(-self.Dy_e.T) + self.Dy_hx @ keep).tocsr()
            self.Dx_hy = (self._expand(-self.Dx_e.T) + self.Dx_hy @ keep).tocsr()

    def _assemble_sbp(self, degree=1):
        """E rows over every non-PEC E particle corrected by :func:`.operators.sbp_pair`; H rows their adjoint
        plus the corrected closure on the PEC particles."""
        lay = self.layout
        e, hx, hy = lay.e, lay.hx, lay.hy
        nx, ny = ("H particles", "H particles") if lay.shared else ("Hx particles", "Hy particles")
        # Rows: the free and the driven E particles (so that H rows next to a
        # source stay consistent); driven particles on a wall, whose one-sided
        # derivative system is singular (on a lattice) or nearly so (weights above
        # DRIVEN_ROW_LIMIT / dr on irregular layouts), join the PEC particles as boundary data.
        boundary = lay.e_fixed
        try:
            Ds = [self._gradient(e[~boundary], cols, axis, "E particles", name)
                  for axis, cols, name in ((0, hy, ny), (1, hx, nx))]
            driven_rows = np.flatnonzero(self.driven[~boundary])
            if driven_rows.size and max(float(abs(D[driven_rows]).sum(axis=1).max()) for D in Ds) * lay.dr \
                    > DRIVEN_ROW_LIMIT:
                raise ValueError("a driven particle's derivative system is nearly singular")
        except ValueError:
            boundary = lay.e_fixed | self.driven
            Ds = [self._gradient(e[~boundary], cols, axis, "E particles", name)
                  for axis, cols, name in ((0, hy, ny), (1, hx, nx))]
        rows, wall = np.flatnonzero(~boundary), np.flatnonzero(boundary)
        er, ew = e[rows], e[wall]
        ones_r = np.ones(len(rows))
        # next to mirror planes the pair is fitted on the mirror-compatible fields (Ez, Hx even, Hy odd): the rows
        # and columns whose support reaches a plane
        reach = get_kernel(self.kernel).support * self.h if self.mirror else 0.0
        out = []
        for D, (axis, cols, name) in zip(Ds, ((0, hy, ny), (1, hx, nx))):
            B = self._gradient(cols, e, axis, name, "E particles")[:, wall] if len(wall) else None
            D, B = sbp_pair(D, er, cols, axis, ones_r, np.ones(len(cols)), B, ew if len(wall) else None,
                            scale=lay.dr, degree=degree, layers=self.sbp_layers, planes=self.mirror,
                            odd_cols=axis == 0, reach=reach)
            G = self._expand(-D.T, rows)
            if B is not None:
                G = G + self._expand(B, wall)
            where = np.full(self.n_e, -1)
            where[rows] = np.arange(len(rows))
            out.append((D[where[self.free]].tocsr(), G.tocsr()))
        (self.Dx_e, self.Dx_hy), (self.Dy_e, self.Dy_hx) = out

    def _assemble_mimetic(self):
        """G (E -> H) exact for quadratics, D = -V_E^-1 G^T V_H exact for linear fields (:mod:`.mimetic`)."""
        from .mimetic import mimetic_operators

        lay = self.layout
        free = np.zeros(self.n_e, bool)
        free[self.free] = True
        t0 = _time.perf_counter()
        ops = mimetic_operators(lay.e, free, [(lay.hy, 0), (lay.hx, 1)], self.h, kernel=self.kernel,
                                scale=lay.dr, fast=self.mimetic_fast)
        (self.Dx_hy, self.Dx_e), (self.Dy_hx, self.Dy_e) = ops.pairs
        self.vol_e = ops.vol_e[self.free] / lay.dr**2
        self.vol_hy, self.vol_hx = (v / lay.dr**2 for v in ops.vol_h)
        self.mimetic = ops
        self.assembly_seconds = _time.perf_counter() - t0

    def _set_time_step(self, dt, courant):
        """dt from (or checked against) the CFL rule at the fastest speed and the spectral limit."""
        self.dt = check_dt(dt, self.h, courant, self.c_max)
        self.dt_stable = self.stability_limit()
        self.growth = 1.0
        if dt is None:
            self.dt = min(self.dt, courant * self.dt_stable)
        elif self.dt >= self.dt_stable:
            raise ValueError(
                f"dt = {self.dt:.4g} s exceeds the stability limit 2/sqrt(rho) = {self.dt_stable:.4g} s of "
                f"the {self.coupling} operators on this layout; use dt < {self.dt_stable:.4g} s"
            )
        if self.coupling == "direct":
            self._check_direct_spectrum()
        self.courant = cfl_number(self.dt, self.h, self.c_max)

    def _set_losses(self):
        """Material and PML conductivities -> the semi-implicit update coefficients."""
        lay, pml = self.layout, self.pml
        zeros_e = np.zeros(self.n_e)
        sx_e, sy_e = pml.sigma(lay.e) if pml else (zeros_e, zeros_e)
        _, sy_hx = pml.sigma(lay.hx) if pml else (None, np.zeros(len(lay.hx)))
        sx_hy, _ = pml.sigma(lay.hy) if pml else (np.zeros(len(lay.hy)), None)
        self._sigmas = (self.sigma + sx_e, self.sigma + sy_e, sy_hx * MU0 / EPS0, sx_hy * MU0 / EPS0)
        self._update_coefficients()

    # ------------------------------------------------------------------ stability
    def _lossless_operator(self):
        """The lossless E -> E operator ``L`` on the free particles (``E'' = L E``), as (L, symmetric form or None).

        For the energy-conserving couplings ``S = eps^(1/2) L eps^(-1/2)`` is
        symmetric negative semi-definite; it is returned so that its extreme
        eigenvalue can be computed by the symmetric Lanczos method.
        """
        fr = self.free
        A = self.Dx_e @ sp.diags(1.0 / (MU0 * self.mu_r_y)) @ self.Dx_hy[:, fr] \
            + self.Dy_e @ sp.diags(1.0 / (MU0 * self.mu_r_x)) @ self.Dy_hx[:, fr]
        eps = EPS0 * self.eps_r[fr]
        L = (sp.diags(1.0 / eps) @ A).tocsr()
        if self.coupling == "direct":
            return L, None
        v = self.vol_e  # the energy weights (1 but for the "mimetic" coupling)
        S = (sp.diags((v / eps) ** 0.5) @ A @ sp.diags((v * eps) ** -0.5)).tocsr()
        return L, 0.5 * (S + S.T)

    def stability_limit(self) -> float:
        """Largest stable leap-frog dt, ``2 / sqrt(rho)``, rho the spectral radius of the lossless E -> E operator.

        For the energy-conserving couplings ("sbp", "mimetic", "adjoint"),
        whose eigenvalues are real and non-positive by construction, rho is
        bounded from above by :func:`spectral_radius_bound` (Lanczos on the
        symmetric form; at least a 0.5 % margin). For "direct" the spectrum may
        be complex and no dt is stable then: :meth:`_check_direct_spectrum`
        decides.
        """
        from scipy.sparse.linalg import ArpackNoConvergence, eigs

        L, S = self._lossless_operator()
        if S is not None:
            estimate, bound = spectral_radius_bound(S)
            return 2.0 / math.sqrt(max(bound, estimate * (1.0 + STABILITY_MARGIN)))
        try:
            rho = float(np.abs(eigs(L, k=1, which="LM", return_eigenvectors=False, tol=1e-6,
                                    maxiter=20000)).max())
        except ArpackNoConvergence:  # pragma: no cover - the Gershgorin bound is safe
            rho = float(abs(L).sum(axis=1).max())
        return 2.0 / math.sqrt(rho * (1.0 + STABILITY_MARGIN))

    def _check_direct_spectrum(self):
        """Refuse the "direct" coupling when some leap-frog mode grows at this dt (measured spectrum).

        Every eigenvalue (dense) up to :data:`DENSE_SPECTRUM` free particles.
        Above, ARPACK gives only the eigenvalues of largest modulus, largest
        imaginary part and those nearest 0 (shift-invert): a partial check,
        said in a ManifoldSPHWarning (the "sbp" coupling has a proven bound).
        """
        import warnings

        from scipy.sparse.linalg import ArpackError, ArpackNoConvergence, eigs

        from ..exceptions import ManifoldSPHWarning

        if getattr(self, "_spectrum", None) is not None:
            self._refuse_growth(self._spectrum)
            return
        L, _ = self._lossless_operator()
        n = L.shape[0]
        if n <= DENSE_SPECTRUM:
            lam = np.linalg.eigvals(L.toarray())
        else:
            try:
                lam = np.concatenate([eigs(L, k=8, which="LM", return_eigenvectors=False, tol=1e-8, maxiter=3000),
                                      eigs(L, k=8, which="LI", return_eigenvectors=False, tol=1e-8, maxiter=3000),
                                      eigs(L.tocsc(), k=8, sigma=0.0, return_eigenvectors=False, tol=1e-8,
                                           maxiter=3000)])
            except (ArpackNoConvergence, ArpackError, RuntimeError):
                raise ValueError(
                    f"the spectrum of the direct coupling could not be computed on {n} free E particles, so its "
                    f"stability is not guaranteed; use coupling='sbp' (energy-conserving)"
                ) from None
            warnings.warn(
                f"direct coupling on {n} free E particles: only the extreme eigenvalues were checked (partial "
                f"stability check); coupling='sbp' has a proven energy bound",
                ManifoldSPHWarning, stacklevel=4,
            )
        rho = float(np.abs(lam).max())
        self._spectrum = np.where(np.abs(lam.imag) <= SPECTRUM_TOL * rho, lam.real, lam)  # round-off
        self._refuse_growth(self._spectrum)

    def _refuse_growth(self, lam):
        g = float(leapfrog_growth(lam, self.dt).max())
        self.growth = g
        if g > 1.0 + 1e-12:
            k = int(np.argmax(leapfrog_growth(lam, self.dt)))
            raise ValueError(
                f"the direct coupling is unstable on this layout (h_ratio = {self.h / self.layout.dr:.3g}): its "
                f"E -> E operator has the eigenvalue {complex(lam[k]):.4g} (complex or positive), so a leap-frog "
                f"mode grows by {g:.6g} per step (10^{1e4 * math.log10(g):.3g} in 10^4 steps) whatever dt; use "
                f"coupling='sbp' (energy-conserving)"
            )

    def _update_coefficients(self):
        sxe, sye, sxh, syh = self._sigmas
        eps = EPS0 * self.eps_r
        self.ca_x, self.cb_x = self._coefficients(sxe, eps)
        self.ca_y, self.cb_y = self._coefficients(sye, eps)
        self.da_x, self.db_x = self._coefficients(sxh, MU0 * self.mu_r_x)
        self.da_y, self.db_y = self._coefficients(syh, MU0 * self.mu_r_y)
        fr = self.free
        self._cax, self._cbx, self._cay, self._cby = self.ca_x[fr], self.cb_x[fr], self.ca_y[fr], self.cb_y[fr]

    def set_dt(self, dt: float) -> None:
        """Change the time step (checked against the CFL rule and the stability limit).

        Call it before ``set_initial`` / ``run``; the fields are not rescaled.
        """
        dt = check_dt(dt, self.h, 1.0, self.c_max)
        if dt >= self.dt_stable:
            raise ValueError(f"dt = {dt:.4g} s exceeds the stability limit {self.dt_stable:.4g} s of this layout")
        self.dt = dt
        if self.coupling == "direct":
            self._check_direct_spectrum()
        self.courant = cfl_number(dt, self.h, self.c_max)
        self._update_coefficients()

    def _expand(self, D, cols=None):
        """Columns over the E particles ``cols`` (default: the free ones) -> columns over every E particle."""
        cols = self.free if cols is None else cols
        D = sp.csr_matrix(D)
        return sp.csr_matrix((D.data, np.asarray(cols)[D.indices], D.indptr), shape=(D.shape[0], self.n_e))

    def _coefficients(self, s, m):
        a = s * self.dt / (2.0 * m)
        return (1.0 - a) / (1.0 + a), (self.dt / m) / (1.0 + a)

    @property
    def n_particles(self) -> int:
        """Number of particles (E plus distinct H)."""
        return self.layout.n_particles

    def reset(self) -> None:
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

    @property
    def field(self) -> np.ndarray:
        """What ``run`` records: Ez (:attr:`e_field`)."""
        return self.ezx + self.ezy

    def probe_indices(self, xy: ArrayLike) -> np.ndarray:
        """Indices of the E particles nearest to the points ``xy`` (P, 2), for ``run(probes=...)``."""
        from .._validation import as_points

        q = as_points("xy", np.atleast_2d(np.asarray(xy, dtype=np.float64)), dim=2)
        d2 = ((self.layout.e[None, :, :] - q[:, None, :]) ** 2).sum(axis=2)
        return np.argmin(d2, axis=1)

    def set_initial(self, ez0: ArrayLike, hx0: ArrayLike | None = None, hy0: ArrayLike | None = None) -> None:
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

    def consistency_residual(self, *, margin: float | None = None) -> float:
        """Largest error of the four derivative matrices on the linear fields ``x`` and ``y`` (dimensionless).

        A consistent first-derivative row maps ``f = x`` to 1 and ``f = y`` to 0 (``Dx``), and
        conversely for ``Dy``; the E rows act on the H particles' values, the H rows on every E
        particle's (the PEC and driven ones included); next to mirror walls, on the linear fields that meet
        the mirror conditions (:meth:`_consistency_fields`). The "sbp", "mimetic" and "direct" couplings
        are exact to round-off on every layout; "adjoint" is not next to walls and on irregular
        layouts (O(1)). This is the certificate that the operators the run used are consistent.
        ``margin`` (m): only the rows of particles farther than this from every PEC and driven E
        particle (the interior residual; :data:`CONSISTENCY_MARGIN` supports is where no wall reaches
        a row of any coupling): "adjoint" is exact there on the lattice and O(1) on irregular layouts.

        >>> from manifold_sph.spem import yee_layout, jitter
        >>> lay = jitter(yee_layout((0, 0.1, 0, 0.1), 0.01), 0.2)
        >>> bool(TMzSolver(lay).consistency_residual() < 1e-8)
        True
        >>> bool(TMzSolver(lay, coupling="adjoint").consistency_residual() > 0.1)
        True
        """
        if margin is not None:
            margin = check_positive("margin", margin, allow_zero=True)
        key = (id(self.Dx_e), id(self.Dy_e), id(self.Dx_hy), id(self.Dy_hx), margin)
        cached = getattr(self, "_consistency", None) or {}
        if key in cached:
            return cached[key]
        lay = self.layout
        scale = lay.dr
        rows = {}
        if margin is not None:
            from scipy.spatial import cKDTree

            edge = ~np.isin(np.arange(self.n_e), self.free)  # PEC and driven E particles
            tree = cKDTree(lay.e[edge]) if edge.any() else None

            def far(points):
                return np.ones(len(points), dtype=bool) if tree is None else tree.query(points)[0] > margin

            rows = {"e": far(lay.e[self.free]), "hx": far(lay.hx), "hy": far(lay.hy)}
        worst = 0.0
        points = {"e": lay.e[self.free], "hx": lay.hx, "hy": lay.hy}
        for D, cols, axis, which in ((self.Dx_e, lay.hy, 0, "e"), (self.Dy_e, lay.hx, 1, "e"),
                                     (self.Dx_hy, lay.e, 0, "hy"), (self.Dy_hx, lay.e, 1, "hx")):
            keep = rows.get(which, np.ones(D.shape[0], dtype=bool))
            for f, target, mask in self._consistency_fields(points[which], cols, axis, cols is not lay.e and axis == 0):
                r = np.abs(D @ f - target)[keep & mask]
                if r.size:
                    worst = max(worst, float(r.max()) * scale)
        self._consistency = {**cached, key: worst}
        return worst

    def _consistency_fields(self, rows, cols, axis, odd):
        """Test fields (dimensionless, per column), the exact derivative (times dr) and the rows they test.

        Without mirror walls: ``x`` and ``y`` on every row. With them, the rows within reach of a plane
        are tested on the linear fields that meet its mirror conditions only: ``1`` and ``y`` (even
        columns) or ``x - m`` (odd columns, ``m`` the row's nearest plane); the other rows on ``x`` and ``y``.
        """
        scale = self.layout.dr
        out = []
        near, nearest = nearest_plane(rows, self.mirror, mirror_reach(self.h))
        for k in (0, 1):
            f = (cols[:, k] - cols[:, k].mean()) / scale
            out.append((f, 1.0 / scale if k == axis else 0.0, ~near))
        if near.any():
            if odd:
                for m in self.mirror:
                    out.append(((cols[:, 0] - m) / scale, 1.0 / scale if axis == 0 else 0.0, near & (nearest == m)))
            else:
                out.append((np.ones(len(cols)), 0.0, near))
                out.append(((cols[:, 1] - cols[:, 1].mean()) / scale, 1.0 / scale if axis == 1 else 0.0, near))
        return out

    def interior_consistency_residual(self) -> float:
        """:meth:`consistency_residual` over the rows farther than :data:`CONSISTENCY_MARGIN` kernel supports
        (``kappa h``) from every PEC and driven E particle: the certificate of a run's interior."""
        return self.consistency_residual(margin=CONSISTENCY_MARGIN * get_kernel(self.kernel).support * self.h)

    def energy(self) -> float:
        """The discrete energy that leap-frog conserves without losses and sources (J/m).

        ``sum V_E eps Ez^n^2 + sum V_H mu H^{n+1/2} H^{n-1/2}`` over the free E and every H
        particle (``H^{n-1/2}`` rebuilt from the last update; the volumes ``V`` are ``dr^2``, fitted with
        the "mimetic" coupling). Constant to round-off for the energy-conserving couplings ("sbp",
        "mimetic", "adjoint") without PML, conductivity and sources: the run's certificate of stability.
        """
        dr2 = self.layout.dr ** 2
        fr = self.free
        ez = self.ezx + self.ezy
        vx = getattr(self, "vol_hx", None)
        vy = getattr(self, "vol_hy", None)
        vx = np.ones(len(self.hx)) if vx is None else vx
        vy = np.ones(len(self.hy)) if vy is None else vy
        hx_prev = self.hx + self.db_x * (self.Dy_hx @ ez)
        hy_prev = self.hy - self.db_y * (self.Dx_hy @ ez)
        e_part = float((self.vol_e * EPS0 * self.eps_r[fr] * ez[fr]) @ ez[fr])
        h_part = float((vx * MU0 * self.mu_r_x * self.hx) @ hx_prev + (vy * MU0 * self.mu_r_y * self.hy) @ hy_prev)
        return dr2 * (e_part + h_part)

    def _pair(self, A, x, B, y):
        """``A @ x`` and ``B @ y``, on two threads when ``workers`` > 1 (scipy's sparse products release the GIL)."""
        if self._pool is None:
            return A @ x, B @ y
        fa = self._pool.submit(A.dot, x)
        b = B @ y
        return fa.result(), b

    def _fused_arrays(self):
        """The CSR arrays of the four operators for the compiled step (rebuilt if an operator was replaced)."""
        mats = (self.Dx_e, self.Dy_e, self.Dy_hx, self.Dx_hy)
        cached = getattr(self, "_fused", None)
        if cached is None or any(a is not b for a, b in zip(cached[0], mats)):
            csr = [sp.csr_matrix(m) for m in mats]  # entries as scipy's product reads them
            arrays = tuple((m.indptr, m.indices, np.ascontiguousarray(m.data, dtype=np.float64)) for m in csr)
            self._fused = cached = (mats, arrays, np.ascontiguousarray(self.free, dtype=np.int64))
        return cached[1], cached[2]

    def _drive_sources(self) -> list:
        """Apply the sources at ``self.t`` to the split Ez (hard: set, soft: added); returns them."""
        for s in self.sources:
            v = s.waveform(self.t)
            if s.kind == "hard":
                self.ezx[s.indices] = v
                self.ezy[s.indices] = 0.0
            else:
                self.ezx[s.indices] += v
        return self.sources

    def _step_plan(self):
        """The stencil runs and CSR remainder of the E and H half steps (:mod:`.stencil`), packed for
        :func:`.compiled.tmz_e_half` / :func:`.compiled.tmz_h_half`; found for the current operators and
        coefficients, rebuilt when one of them is replaced (``set_dt``). The H rows are those of the
        stacked ``[Dy_hx; Dx_hy]`` acting on ``[hx, hy]``."""
        cached = getattr(self, "_plan", None)
        if cached is not None:  # (chained identity tests: this runs on every step)
            k = cached[0]
            if (k[0] is self.Dx_e and k[1] is self.Dy_e and k[2] is self.Dy_hx and k[3] is self.Dx_hy
                    and k[4] is self._cax and k[5] is self._cbx and k[6] is self._cay and k[7] is self._cby
                    and k[8] is self.da_x and k[9] is self.db_x and k[10] is self.da_y and k[11] is self.db_y):
                return cached[1]
        from types import SimpleNamespace  # (below the cached return: an import costs microseconds per step)

        from .stencil import find_runs, pack_e, pack_h

        key = (self.Dx_e, self.Dy_e, self.Dy_hx, self.Dx_hy, self._cax, self._cbx, self._cay, self._cby,
               self.da_x, self.db_x, self.da_y, self.db_y)
        n_hx = len(self.layout.hx)
        coef_e = np.column_stack([self._cax, self._cbx, self._cay, self._cby])
        e = find_runs([self.Dx_e, self.Dy_e], self.free, coef_e)
        S = self._stacked_h_operator()
        coef_h = np.column_stack([np.concatenate([self.da_x, self.da_y]), np.concatenate([-self.db_x, self.db_y])])
        h = find_runs([S], np.arange(S.shape[0]), coef_h)
        plan = SimpleNamespace(e=e, h=h, n_hx=n_hx, e_args=pack_e(e, self.Dx_e, self.Dy_e, self.free, coef_e,
                                                                       self.n_e, n_hx),
                               h_args=pack_h(h, S, coef_h), ez=np.empty(self.n_e), buf=None, refs=None, snapped=None)
        self._plan = (key, plan)
        return plan

    def _stacked_h_operator(self):
        """``[Dy_hx; Dx_hy]`` (CSR, each row's entries in their stored order): the H rows of the stencil step."""
        A, B = sp.csr_matrix(self.Dy_hx), sp.csr_matrix(self.Dx_hy)
        return sp.csr_matrix((np.concatenate([A.data, B.data]), np.concatenate([A.indices, B.indices]),
                              np.concatenate([A.indptr, B.indptr[1:] + A.nnz])),
                             shape=(A.shape[0] + B.shape[0], self.n_e))

    def _step_operators(self):
        """``(Dx_e, Dy_e, Dy_hx, Dx_hy)`` as the step applies them: with :attr:`stencil`, each run row carries
        its pattern's weights (:meth:`.stencil.StencilRuns.snapped`), the numbers of the compiled kernels."""
        if not self.stencil:
            return self.Dx_e, self.Dy_e, self.Dy_hx, self.Dx_hy
        plan = self._step_plan()
        if plan.snapped is None:
            S = plan.h.snapped(0, self._stacked_h_operator())
            plan.snapped = (plan.e.snapped(0, self.Dx_e), plan.e.snapped(1, self.Dy_e), S[:plan.n_hx], S[plan.n_hx:])
        return plan.snapped

    def _stacked_h(self, pl):
        """``(h, out)``: the stacked ``[hx, hy]`` the H half step reads and the array it writes; ``self.hx``,
        ``self.hy`` become views of ``out``. ``out`` is ``h`` itself (an update in place) when the solver
        holds the only references to ``h`` and its views (CPython reference counts); otherwise a new
        array, so that an ``hx`` or ``hy`` kept from an earlier step keeps its values, as with the numpy
        step (fresh arrays of a million unknowns cost about 5 ns per unknown in page faults, measured)."""
        buf = pl.buf
        mine = buf is not None and self.hx is buf[1] and self.hy is buf[2]
        if mine and _refcount is not None and (_refcount(buf[0]), _refcount(buf[1]), _refcount(buf[2])) == pl.refs:
            return buf[0], buf[0]
        h = buf[0] if mine else np.concatenate([self.hx, self.hy])
        new = np.empty(len(h))
        pl.buf = buf = (new, new[:pl.n_hx], new[pl.n_hx:])
        del new
        self.hx, self.hy = buf[1], buf[2]
        if _refcount is not None:  # the counts when only the solver holds them (the same frame as the test above)
            pl.refs = (_refcount(buf[0]), _refcount(buf[1]), _refcount(buf[2]))
        return h, buf[0]

    def _step_stencil(self):
        """The compiled step with the stencil runs (:meth:`_step_plan`), one kernel call per half step: the
        numbers of the numpy step on :meth:`_step_operators`."""
        pl = self._step_plan()
        ea, ha = pl.e_args, pl.h_args
        h, out = self._stacked_h(pl)
        ez = pl.ez
        if self.workers > 1 and len(ez) >= THREADED_STEP:
            self._threaded_halves(pl, h, out)
            return
        compiled.tmz_e_half(0, len(ea[1]), 0, len(ea[8]), *ea, h, self.ezx, self.ezy, ez)
        self.t = (self.n + 1) * self.dt
        self.n += 1
        for s in self._drive_sources():
            ez[s.indices] = self.ezx[s.indices] + self.ezy[s.indices]
        compiled.tmz_h_half(0, len(ha[0]), 0, len(ha[7]), *ha, ez, h, out)

    def _threaded_halves(self, pl, h, out):
        """:meth:`_step_stencil` with each half step's runs and CSR rows cut into ``workers`` chunks of about
        equal rows, on threads (the kernels release the GIL; every row is computed as in one call)."""
        from .. import threads

        ea, ha = pl.e_args, pl.h_args
        w = self.workers
        if getattr(pl, "chunks", None) is None or len(pl.chunks[0]) != w:
            pl.chunks = (_chunks(ea[1][:, 1], len(ea[8]), w), _chunks(ha[0][:, 1], len(ha[7]), w))
        ez = pl.ez
        empty = np.zeros(0, dtype=np.int64)

        def e_job(c):
            q0, q1, r0, r1 = pl.chunks[0][c]
            compiled.tmz_e_half(q0, q1, r0, r1, ea[0] if c == 0 else empty, *ea[1:], h, self.ezx, self.ezy, ez)

        def h_job(c):
            compiled.tmz_h_half(*pl.chunks[1][c], *ha, ez, h, out)

        threads.run_chunks(e_job, w, workers=w)
        self.t = (self.n + 1) * self.dt
        self.n += 1
        for s in self._drive_sources():
            ez[s.indices] = self.ezx[s.indices] + self.ezy[s.indices]
        threads.run_chunks(h_job, w, workers=w)

    def step(self) -> None:
        """One leap-frog step: Ez to t + dt, then H to t + 3 dt / 2."""
        if _jit.ENABLED and self.stencil:
            self._step_stencil()
            return
        if _jit.ENABLED:  # the same numbers as the numpy step below, in one pass per half step
            (x, y, hxm, hym), fr = self._fused_arrays()
            ez = self.ezx + self.ezy  # fixed particles: their (held) values
            compiled.tmz_e_update(fr, *x, *y, self.hy, self.hx, self._cax, self._cbx, self._cay, self._cby,
                              self.ezx, self.ezy, ez)
            self.t = (self.n + 1) * self.dt
            self.n += 1
            for s in self._drive_sources():
                ez[s.indices] = self.ezx[s.indices] + self.ezy[s.indices]
            hx, hy = np.empty_like(self.hx), np.empty_like(self.hy)  # new arrays, as the numpy step's
            compiled.tmz_h_update(*hxm, ez, self.hx, self.da_x, self.db_x, -1.0, hx)
            compiled.tmz_h_update(*hym, ez, self.hy, self.da_y, self.db_y, 1.0, hy)
            self.hx, self.hy = hx, hy
            return
        fr = self.free
        Dx_e, Dy_e, Dy_hx, Dx_hy = self._step_operators()
        dhy, dhx = self._pair(Dx_e, self.hy, Dy_e, self.hx)
        self.ezx[fr] = self._cax * self.ezx[fr] + self._cbx * dhy
        self.ezy[fr] = self._cay * self.ezy[fr] - self._cby * dhx
        self.t = (self.n + 1) * self.dt
        self.n += 1
        self._drive_sources()
        ez = self.ezx + self.ezy
        dex, dey = self._pair(Dy_hx, ez, Dx_hy, ez)
        self.hx = self.da_x * self.hx - self.db_x * dex
        self.hy = self.da_y * self.hy + self.db_y * dey
