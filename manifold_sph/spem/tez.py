"""TEz polarisation (Hz, Ex, Ey) on particles: the leap-frog solver and its split-field PML form.

The fields of TEz waves in the plane:

    mu dHz/dt = dEx/dy - dEy/dx,   eps dEx/dt = dHz/dy,   eps dEy/dt = -dHz/dx,

leap-frog with Hz at integer and E at half steps, on the layouts of
:mod:`.layouts` (:class:`.TEzLayout`: Hz at the cell centres, Ex at
``(i + 1/2, j) dr``, Ey at ``(i, j + 1/2) dr`` on the lattice); on a PEC wall the
tangential E particles are held at zero and Hz needs no boundary particle (its
condition, ``dHz/dn = 0``, is natural).

Couplings, as in :class:`.TMzSolver`:

``"sbp"`` (default)
    The Hz rows ``D`` (CSPM derivatives of the free E particles; the wall
    particles carry zero) are corrected by :func:`.operators.sbp_pair` so
    that the E rows ``-V_E^-1 D^T V_Hz`` are exact for linear fields: a
    skew-adjoint pair, so leap-frog conserves the discrete energy.
``"adjoint"``
    The E rows are ``-D^T`` without the correction (energy-conserving, not
    consistent next to walls).
``"direct"``
    Each set by its own CSPM derivatives; the spectrum of the Hz -> Hz
    operator is computed and a growing layout refused (ValueError).

Curved PEC walls (:func:`.tez_disk_layout`, closure walls of :func:`.wall_closure_layout`)
    Wall particles on the conductor carry only the tangential component of
    E, held at zero. The Hz rows are one curl operator ``C`` over every free Ex
    and Ey particle plus *closure* columns at the wall particles (they
    multiply zero fields, or the driven tangential field of a scatterer). In the
    flux weights ``Q = V_Hz C`` and the particle volumes ``V_Hz``, ``V_E`` the
    conditions below are linear; the smallest change of the CSPM weights and of
    the Voronoi volumes (in a band next to the wall; the lattice interior meets
    them already) that meets them exactly is one sparse normal-equations solve
    (:func:`curl_sbp`): ``C`` exact for linear (Ex, Ey) (the wall particles'
    tangential components included), ``G = -V_E^-1 C^T V_Hz`` exact for linear Hz
    at every free E particle, and the closure columns equal to the wall's
    arc-length quadrature (``sum_i Q_iw phi_i = -s_w phi(x_w)`` for linear
    ``phi``: the discrete form of ``int phi curl E = -int E . curl phi -
    oint phi E_t``). The pair is skew-adjoint in the volume inner products,
    so leap-frog conserves ``sum V mu Hz^2 + sum V eps E^{n+1/2} E^{n-1/2}``.
    Without the quadrature condition the frequency does not converge
    (the closure then places the wall O(dr) off).

:class:`TEzPMLSolver` adds the split-field PML (``Hz = Hzx + Hzy``, Berenger:
``mu dHzx/dt + sigma*_x Hzx = -dEy/dx``, ``mu dHzy/dt + sigma*_y Hzy = dEx/dy``,
``eps dEx/dt + sigma_y Ex = dHz/dy``, ``eps dEy/dt + sigma_x Ey = -dHz/dx`` with the
semi-implicit coefficients of :class:`.TMzSolver`), per-particle permittivities and
driven closure walls; where the conductivities are zero it is the lossless pair of
:class:`TEzSolver`, the same operators bit for bit. Measurements: docs/spem.md.

Examples
--------
>>> from manifold_sph.spem import tez_layout
>>> s = TEzSolver(tez_layout((0.0, 0.1, 0.0, 0.06), 0.01))
>>> s.set_initial(np.cos(np.pi * s.layout.hz[:, 0] / 0.1))
>>> s.run(20).probes.shape
(20, 0)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike

from .._validation import check_in, check_positive
from .constants import EPS0, MU0
from .layouts import TEzLayout
from .operators import COUPLINGS, DEFAULT_COUPLING, DEFAULT_H_RATIO, SBP_LAYERS, cross_gradient, sbp_pair
from .pml import PML
from .stability import STABILITY_MARGIN, leapfrog_growth, spectral_radius_bound
from .stepping import Leapfrog

__all__ = ["TEZ_COUPLINGS", "CircularInterface", "DISK_H_RATIO", "FOURTH_ORDER_WEIGHTS", "TEZ_PML_H_RATIO_MAX", "TEzSolver",
           "TEzPMLSolver", "curl_sbp", "fourth_order_rows", "per_e_particle"]


#: Couplings of :class:`TEzSolver` (those of :class:`.TMzSolver` but "mimetic").
TEZ_COUPLINGS = tuple(c for c in COUPLINGS if c != "mimetic")


#: Default ``h / dr`` of the circular TEz cavity. Measured (TE11 + TE21, 10 / 20 / 40 spacings per radius):
#: 0.7 gave a stable step of 0.68 / 0.57 / 0.29 of the CFL step (stiff particles next to the wall), 0.8
#: 0.89 / 0.89 / 0.84 with errors within 30 %; at 0.8 the frequency error is the lattice's own dispersion.
DISK_H_RATIO = 0.8

#: Largest ``h / dr`` at which the TEz split-field PML is validated. Measured (``run_tez_pml``, 40 cells,
#: 10-cell layer, order 3, R = 1e-6; normal / 45 deg): -58.3 / -55.5 dB at h/dr 0.8, -27.0 / -24.0 at 1.0,
#: -35.3 / -33.9 at 1.1, -19.8 / -17.6 at 1.3; ``tez-scatter-pec`` at 4 spacings per radius: error 8.3e-2 at
#: 0.8, 1.0 at 1.3.
TEZ_PML_H_RATIO_MAX = 0.8


#: Weight of the relative volume changes against the flux-weight changes in the wall correction.
DISK_VOLUME_WEIGHT = 0.01


#: The wall correction changes flux weights and volumes within ``max(DISK_BAND * dr, 2 kappa h)`` of the wall.
DISK_BAND = 3.0


#: Closure (wall) columns get every Hz particle within ``max(DISK_CLOSURE_REACH * dr, kappa h)`` of the wall particle.
DISK_CLOSURE_REACH = 2.0


@dataclass(frozen=True)
class CircularInterface:
    """A circle between two permittivities, for the jump-corrected curl pair (:func:`curl_sbp`, :class:`TEzSolver`).

    Across ``|x - center| = radius`` (``eps_in`` inside, ``eps_out`` outside,
    relative) ``Hz``, the tangential ``E`` and the normal ``eps E`` are
    continuous, and so is ``(1 / eps) dHz/dn`` (Hz's normal derivative jumps).
    A curl row or a gradient column whose pairs cross the circle is made exact
    not for linear fields (which break these conditions) but for fields that
    are linear in the polar coordinates ``u = radius (theta - theta_0)``,
    ``v = r - radius`` on each side and meet the conditions exactly
    (:meth:`conditions`): five divergence-free E fields (``rho = 1 / eps`` of
    the side, ``(E_r, E_t)``): ``(rho a / r, 0)``, ``(rho u a / r, rho v)``,
    ``(0, 1)``, ``(-a v / r, u)``, ``(0, v)`` (``a`` the radius; the span does
    not depend on the anchor ``theta_0``, and ``curl E`` is continuous), and
    three Hz fields, ``1``, ``u``, ``eps v``. The E particles carry the sharp
    permittivity of their side (:meth:`permittivity`). The volumes of the
    particles within ``reach`` spacings of the circle move with the weight
    ``volume_weight`` in the fit (the walls' 0.01: measured on the ka = 2,
    eps_r 4 cylinder at 4 / 8 / 16 spacings per radius, 0.01 gave 1.7e-1 /
    6.4e-2 / 7.4e-3, 1 9.1e-2 / 3.0e-2 / 5.7e-3, 30 4.0e-2 / 8.6e-3 / 1.9e-3,
    100 3.0e-2 / 5.7e-3 / 1.9e-3, 1000 refused).

    Examples
    --------
    >>> CircularInterface(0.1, 4.0).side(np.array([[0.05, 0.0], [0.2, 0.0]])).tolist()
    [True, False]
    """

    radius: float
    eps_in: float
    eps_out: float = 1.0
    center: tuple[float, float] = (0.0, 0.0)
    volume_weight: float = 30.0
    reach: float = 4.0

    def __post_init__(self) -> None:
        check_positive("radius", self.radius)
        check_positive("eps_in", self.eps_in)
        check_positive("eps_out", self.eps_out)
        c = np.asarray(self.center, dtype=np.float64)
        if c.shape != (2,) or not np.isfinite(c).all():
            raise ValueError(f"center must be two finite numbers, got {self.center!r}")

    def side(self, points: np.ndarray) -> np.ndarray:
        """True inside the circle (the ``eps_in`` side)."""
        p = np.asarray(points, dtype=np.float64) - np.asarray(self.center)
        return np.hypot(p[:, 0], p[:, 1]) < self.radius

    def permittivity(self, points: np.ndarray) -> np.ndarray:
        """The sharp relative permittivity of each point's side."""
        return np.where(self.side(points), self.eps_in, self.eps_out)

    def near(self, points: np.ndarray, scale: float) -> np.ndarray:
        """True within ``reach * scale`` of the circle."""
        p = np.asarray(points, dtype=np.float64) - np.asarray(self.center)
        return np.abs(np.hypot(p[:, 0], p[:, 1]) - self.radius) < self.reach * scale

    def conditions(self, hz: np.ndarray, cols: np.ndarray, dirs: np.ndarray, i: np.ndarray, j: np.ndarray,
                   n_free: int, scale: float, r_val: list, v_row: list, c_val: list,
                   v_col: list) -> tuple[list, list, list, list]:
        """The exactness conditions of :func:`curl_sbp` with the rows and columns that cross the circle replaced.

        For the pairs (row ``i``, column ``j``) of ``curl_sbp``: ``r_val`` (pair
        values of the six row fields), ``v_row`` (the rows' ``dEx/dy - dEy/dx``
        of each field), ``c_val`` (pair values of the three column fields) and
        ``v_col`` (``d x grad g`` per free column), in units of ``scale``;
        returns the four lists, the crossing rows' sixth slot empty.
        """
        c = np.asarray(self.center, dtype=np.float64)
        R = self.radius / scale
        ph, pc = (hz - c) / scale, (cols - c) / scale
        rh, rc = np.maximum(np.hypot(ph[:, 0], ph[:, 1]), 1e-12), np.maximum(np.hypot(pc[:, 0], pc[:, 1]), 1e-12)
        th_h, th_c = np.arctan2(ph[:, 1], ph[:, 0]), np.arctan2(pc[:, 1], pc[:, 0])
        in_h, in_c = rh < R, rc < R
        eps_h = np.where(in_h, self.eps_in, self.eps_out)
        eps_c = np.where(in_c, self.eps_in, self.eps_out)
        cross = in_h[i] != in_c[j]
        nr = len(hz)
        row_cut = np.bincount(i, cross, minlength=nr) > 0
        col_cut = np.bincount(j, cross, minlength=len(cols))[:n_free] > 0
        r_val = [a.copy() for a in r_val]
        v_row = [a.copy() for a in v_row]
        c_val = [a.copy() for a in c_val]
        v_col = [a.copy() for a in v_col]
        # rows: the five E fields at the column points, polar frame anchored at the row's angle (the sixth slot empty)
        s = np.flatnonzero(row_cut[i])
        ii, kk = i[s], j[s]
        u = R * np.angle(np.exp(1j * (th_c[kk] - th_h[ii])))
        v = rc[kk] - R
        er = pc[kk] / rc[kk, None]
        d = dirs[kk]
        dn = d[:, 0] * er[:, 0] + d[:, 1] * er[:, 1]
        dt = -d[:, 0] * er[:, 1] + d[:, 1] * er[:, 0]
        rho = 1.0 / eps_c[kk]
        for m, val in enumerate((rho * R / rc[kk] * dn, rho * (u * R / rc[kk] * dn + v * dt), dt,
                                 u * dt - R * v / rc[kk] * dn,
                                 v * dt, 0.0 * v)):
            r_val[m][s] = val
        rows = np.flatnonzero(row_cut)
        r0, rho0 = rh[rows], 1.0 / eps_h[rows]
        for m, curl in enumerate((0.0 * r0, rho0 * (2.0 * r0 + R) * (r0 - R) / r0**2, 1.0 / r0, 0.0 * r0,
                                  (2.0 * r0 - R) / r0,
                                  0.0 * r0)):
            v_row[m][rows] = curl  # the rows compute dEx/dy - dEy/dx = -(curl E)_z
        # columns: Hz = 1, u, eps v at the Hz particles, polar frame anchored at the column's angle
        s = np.flatnonzero(np.r_[col_cut, np.zeros(len(cols) - n_free, bool)][j])
        ii, kk = i[s], j[s]
        c_val[1][s] = R * np.angle(np.exp(1j * (th_h[ii] - th_c[kk])))
        c_val[2][s] = eps_h[ii] * (rh[ii] - R)
        cc = np.flatnonzero(col_cut)
        er = pc[cc] / rc[cc, None]
        et = np.column_stack([-er[:, 1], er[:, 0]])
        d = dirs[cc]
        cross2 = lambda a: d[:, 0] * a[:, 1] - d[:, 1] * a[:, 0]  # noqa: E731
        v_col[1][cc] = cross2(et * (R / rc[cc])[:, None])
        v_col[2][cc] = cross2(er * eps_c[cc, None])
        return r_val, v_row, c_val, v_col


#: The fourth-order staggered difference: weights of the partners at 1/2 and 3/2 spacings.
FOURTH_ORDER_WEIGHTS = (27.0 / 24.0, -1.0 / 24.0)


def fourth_order_rows(curl0: sp.csr_matrix, hz: np.ndarray, e: np.ndarray, dirs: np.ndarray, dr: float) -> sp.csr_matrix:
    """The Hz rows of ``curl0`` that sit inside a perfect lattice set to the fourth-order staggered curl.

    A row qualifies when its free E columns (the first ``len(e)``, direction
    ``dirs``: Ex ``(1, 0)``, Ey ``(0, 1)``) hold the partners at ``(0, +-1/2)``,
    ``(0, +-3/2)`` spacings (Ex) and ``(+-1/2, 0)``, ``(+-3/2, 0)`` (Ey) and no
    wall column with a weight; its weights become
    ``dEx/dy - dEy/dx ~ sum_s sign w_s (E(+s) - E(-s)) / dr`` with
    :data:`FOURTH_ORDER_WEIGHTS` (exact for cubic fields along each axis, so
    linear fields stay exact and the lattice's dispersion error falls from
    ``(k dr)^2 / 24`` to ``O((k dr)^4)``). Other rows are unchanged.
    """
    C = sp.csr_matrix(curl0, copy=True)
    C.sort_indices()
    nr = C.shape[0]
    ne = len(e)
    i = np.repeat(np.arange(nr), np.diff(C.indptr))
    k = C.indices
    free = k < ne
    o = np.zeros((len(k), 2))
    o[free] = (e[k[free]] - hz[i[free]]) / dr
    comp = np.full(len(k), -1)
    comp[free] = np.argmax(np.abs(dirs[k[free]]), axis=1)
    along = np.where(comp == 0, o[:, 1], o[:, 0])
    across = np.where(comp == 0, o[:, 0], o[:, 1])
    on_axis = free & (np.abs(across) < 1e-6)
    w = np.zeros(len(k))
    hits = np.zeros(nr)
    for dist, weight in zip((0.5, 1.5), FOURTH_ORDER_WEIGHTS):
        m = on_axis & (np.abs(np.abs(along) - dist) < 1e-6)
        w[m] = np.sign(along[m]) * weight * np.where(comp[m] == 0, 1.0, -1.0) / dr
        hits += np.bincount(i[m], minlength=nr)
    walled = np.bincount(i[~free], np.abs(C.data[~free]) > 1e-200, minlength=nr) > 0
    ok = (hits == 8) & ~walled
    sel = ok[i]
    C.data[sel] = w[sel]
    return C


def curl_sbp(hz: np.ndarray, cols: np.ndarray, dirs: np.ndarray, curl0: sp.csr_matrix, n_free: int,
              wall_length: np.ndarray, vol_hz: np.ndarray, vol_e: np.ndarray, width: float, scale: float,
              volume_weight: float = DISK_VOLUME_WEIGHT, interface: CircularInterface | None = None
              ) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray, float]:
    """Flux weights and volumes of the energy-conserving TEz curl pair next to curved walls (module docstring).

    ``curl0`` (Hz rows) approximates ``dEx/dy - dEy/dx`` from the E columns: the
    first ``n_free`` are free Ex / Ey particles, the rest wall (closure)
    columns; column ``k`` carries the component ``dirs[k] . E`` at ``cols[k]``.
    Unknowns: ``Q = V_Hz C`` on the pattern of ``curl0``, ``V_Hz``, ``V_E`` (units
    ``dr^2``); only those of particles within ``width`` of a wall particle or
    of a particle farther than ``2 width`` from the wall that misses its
    conditions (everywhere on irregular layouts, nowhere inside a lattice)
    change; when that band cannot meet the conditions (to 1e-6) the whole
    operator does. Conditions: every Hz row exact for the six linear (Ex, Ey);
    every free column's adjoint ``-V_E^-1 C^T V_Hz`` exact for linear Hz;
    every closure column ``sum_i Q_iw {1, x_i - x_w, y_i - y_w} = {-s_w, 0, 0}``.
    Minimum of ``|dQ|^2 + sum (dV / V0)^2 / volume_weight`` by one sparse
    normal-equations solve. With ``interface`` (:class:`CircularInterface`) the rows and
    free columns whose pairs cross its circle take its jump-field conditions
    instead of the linear ones, the volumes next to it its ``volume_weight``,
    and a band that misses the conditions raises ValueError (no whole-operator
    solve).

    Returns
    -------
    C : csr (n_hz, n_cols)
        ``Q / V_Hz`` (closure columns included).
    vol_hz, vol_e : arrays
        The volumes (units of ``dr^2``).
    residual : float
        Largest violated condition (dimensionless).
    """
    from scipy.sparse.linalg import spsolve

    curl0 = sp.csr_matrix(curl0)
    curl0.sort_indices()
    nr, nc = curl0.shape
    i = np.repeat(np.arange(nr), np.diff(curl0.indptr))
    k = curl0.indices
    P = len(k)
    x = (cols[k] - hz[i]) / scale
    d = dirs[k]
    y = -x
    # row conditions (NR per Hz particle): E = (1, 0), (0, 1), (x, 0), (y, 0), (0, x), (0, y) [and a 7th next to an
    # interface]; curl = dEx/dy - dEy/dx; entries on the pairs (r_val) and on the row's volume (v_row: -curl E)
    r_val = [d[:, 0], d[:, 1], d[:, 0] * x[:, 0], d[:, 0] * x[:, 1], d[:, 1] * x[:, 0], d[:, 1] * x[:, 1]]
    zr = np.zeros(nr)
    v_row = [zr, zr, zr, -np.ones(nr), np.ones(nr), zr]
    # column conditions (3 per column): sum_i Q_ik g_i + V_k (d_k x grad g) = 0 for g = 1, x_i - x_k, y_i - y_k
    c_val = [np.ones(P), y[:, 0], y[:, 1]]
    v_col = [np.zeros(n_free), -dirs[:n_free, 1], dirs[:n_free, 0]]
    if interface is not None:
        r_val, v_row, c_val, v_col = interface.conditions(hz, cols, dirs, i, k, n_free, scale, r_val, v_row,
                                                          c_val, v_col)
    NR = len(r_val)
    ar = np.arange(nr)
    ae = np.arange(n_free)
    r_idx = [NR * i + m for m in range(NR)]
    c_idx = [NR * nr + 3 * k + m for m in range(3)]
    rows = np.concatenate(r_idx + c_idx + [NR * ar + m for m in range(NR)] + [NR * nr + 3 * ae + m for m in range(3)])
    unk = np.concatenate([np.tile(np.arange(P), NR + 3), np.tile(P + ar, NR), np.tile(P + nr + ae, 3)])
    vals = np.concatenate(r_val + c_val + v_row + v_col)
    n_con = NR * nr + 3 * nc
    A = sp.csr_matrix((vals, (rows, unk)), shape=(n_con, P + nr + n_free))
    target = np.zeros(n_con)
    target[NR * nr + 3 * n_free :: 3] = -np.asarray(wall_length) / scale
    u0 = np.r_[curl0.data * scale * vol_hz[i], vol_hz, vol_e]
    vw = np.full(nr + n_free, volume_weight)
    if interface is not None:  # the volumes next to the interface move more freely than those at the walls
        vw[interface.near(np.vstack([hz, cols[:n_free]]), scale)] = interface.volume_weight
    weight = np.r_[np.ones(P), vw * np.r_[vol_hz, vol_e] ** 2]
    r = target - A @ u0
    from scipy.spatial import cKDTree

    bad = np.r_[np.abs(r[: NR * nr]).reshape(nr, NR).max(axis=1), np.abs(r[NR * nr : NR * nr + 3 * n_free])
                .reshape(n_free, 3).max(axis=1)] > 1e-9
    # seeds: the wall, and the particles missing their conditions farther from it than 2 widths (irregular
    # layouts; on a lattice every such particle is next to the wall, and a band grown around them spread the
    # correction and measured a less accurate field: 5.3e-3 against 7.8e-3 at 20 spacings per radius)
    wall_tree = cKDTree(cols[n_free:])
    far = np.r_[wall_tree.query(hz)[0], wall_tree.query(cols[:n_free])[0]] > 2.0 * width
    seeds = np.vstack([cols[n_free:], hz[(bad & far)[:nr]], cols[:n_free][(bad & far)[nr:]]])
    tree = cKDTree(seeds)
    near_hz = tree.query(hz, distance_upper_bound=width)[0] < width
    near_c = tree.query(cols, distance_upper_bound=width)[0] < width
    on = np.r_[near_hz[i] | near_c[k], near_hz, near_c[:n_free]]
    for attempt in range(2):
        con = np.asarray(abs(A[:, on]).sum(axis=1)).ravel() > 0
        As = A[con][:, on]
        ws = weight[on]
        M = (As @ sp.diags(ws) @ As.T).tocsc()
        M = M + sp.identity(M.shape[0], format="csc") * (1e-12 * M.diagonal().max())
        u = u0.copy()
        u[on] += ws * (As.T @ spsolve(M, r[con]))
        residual = float(np.abs(target - A @ u).max())
        if interface is not None and residual >= 1e-6:  # one step of iterative refinement (the weighted volumes)
            u[on] += ws * (As.T @ spsolve(M, (target - A @ u)[con]))
            residual = float(np.abs(target - A @ u).max())
        if residual < 1e-6 or on.all():
            break
        if interface is not None and on.sum() < 0.5 * len(on):
            # the interface band misses its conditions: the whole operator's solve would be far larger
            raise ValueError(f"the interface correction cannot meet its conditions in its band (largest residual "
                             f"{residual:.3g}); use the cell average")
        on = np.ones(len(u0), bool)  # the band could not meet them (small or irregular layouts): the whole operator
    vh, ve = u[P : P + nr], u[P + nr :]
    with np.errstate(divide="ignore", invalid="ignore"):
        C = sp.csr_matrix((u[:P] / scale / vh[i], curl0.indices.copy(), curl0.indptr.copy()), shape=curl0.shape)
    return C, vh, ve, residual


class TEzSolver(Leapfrog):
    """Leap-frog SPEM for TEz waves (module docstring) in a PEC rectangle or a cavity with curved PEC walls.

    Parameters
    ----------
    layout : TEzLayout
        :func:`tez_layout` (rectangle) or :func:`tez_disk_layout` (curved walls: couplings "sbp" and
        "adjoint"; "direct" is refused).
    h_ratio : float
        ``h / dr`` (default 0.7, cubic kernel; :data:`DISK_H_RATIO` suits curved walls).
    eps_r, mu_r : float
        Relative permittivity (E particles) and permeability (Hz particles), finite and > 0.
    coupling : {"sbp", "adjoint", "direct"}
    courant : float
        Fraction of the smaller of the CFL step ``h / (sqrt(2) c_max)`` and
        the spectral limit ``2 / sqrt(rho)`` (default 0.9).
    kernel, form : str
        As :func:`.operators.cross_gradient`.
    sbp_layers : int or None
        As :class:`.TMzSolver`.
    interface : CircularInterface, optional
        A dielectric circle: the rows and columns whose pairs cross it are made exact for fields meeting its
        jump conditions (curved layouts, coupling "sbp"; give the E particles
        :meth:`CircularInterface.permittivity`).
    bulk_order : {2, 4}
        4: the Hz rows inside a perfect lattice (curved layouts, ``h_ratio`` >= 0.75 so the partners at 3/2
        spacings are neighbours) use the fourth-order staggered difference (:func:`fourth_order_rows`); the
        wall and interface corrections start from them.

    Examples
    --------
    >>> from manifold_sph.spem import tez_layout
    >>> s = TEzSolver(tez_layout((0.0, 0.1, 0.0, 0.1), 0.01))
    >>> s.set_initial(np.cos(np.pi * s.layout.hz[:, 0] / 0.1))
    >>> _ = s.run(50)
    >>> bool(abs(s.energy() / s.energy0 - 1) < 1e-12)  # "sbp": the discrete energy is conserved
    True
    """

    def __init__(self, layout: TEzLayout, *, h_ratio: float = DEFAULT_H_RATIO, eps_r: float = 1.0, mu_r: float = 1.0,
                 coupling: str = DEFAULT_COUPLING, courant: float = 0.9, kernel: str = "cubic", form: str = "fpm",
                 sbp_layers: int | None = SBP_LAYERS, interface: CircularInterface | None = None,
                 bulk_order: int = 2) -> None:
        if not isinstance(layout, TEzLayout):
            raise TypeError(f"layout must be a TEzLayout, got {type(layout).__name__}")
        if interface is not None:
            if not isinstance(interface, CircularInterface):
                raise TypeError(f"interface must be a CircularInterface or None, got {type(interface).__name__}")
            if not layout.curved or coupling != "sbp":
                raise ValueError("interface needs a layout with wall (closure) particles and coupling 'sbp' (the "
                                 f"corrected curl pair); got curved={layout.curved}, coupling={coupling!r}")
        self.interface = interface
        self.bulk_order = check_in("bulk_order", bulk_order, (2, 4))
        if bulk_order == 4 and not layout.curved:
            raise ValueError("bulk_order 4 needs a layout with wall (closure) particles (the corrected curl pair)")
        self.layout = layout
        self.h = check_positive("h_ratio", h_ratio) * layout.dr
        if coupling == "mimetic":  # not built for TEz (its wall particles are the vector set's): never run another
            raise ValueError("coupling 'mimetic' is available for TMz only (TMzSolver); TEzSolver offers "
                             f"{', '.join(repr(c) for c in TEZ_COUPLINGS)}")
        self.coupling = check_in("coupling", coupling, TEZ_COUPLINGS)
        courant = check_positive("courant", courant)
        if courant > 1:
            raise ValueError(f"courant must be at most 1, got {courant}")
        self.eps = EPS0 * check_positive("eps_r", eps_r)
        self.mu = MU0 * check_positive("mu_r", mu_r)
        self.c_max = 1.0 / math.sqrt(self.eps * self.mu)
        lay = layout
        self.fx = np.flatnonzero(~lay.ex_fixed)
        self.fy = np.flatnonzero(~lay.ey_fixed)
        self.vol_hz, self.vol_ex, self.vol_ey = np.ones(len(lay.hz)), np.ones(len(self.fx)), np.ones(len(self.fy))
        self.sbp_residual = 0.0
        kw = {"kernel": kernel, "form": form}
        from ..kernels import get_kernel

        self._support = get_kernel(kernel).support * self.h
        if lay.curved:
            self._assemble_curved(kw)
        else:
            self._assemble_straight(kw, sbp_layers)
        L = (self.Dx @ self.Gx + self.Dy @ self.Gy) / (self.eps * self.mu)  # Hz'' = L Hz
        self._check_spectrum(L.tocsr(), courant)
        self.reset()

    def interior_consistency_residual(self) -> float:
        """Largest error of the four derivative matrices on the linear fields ``x`` and ``y`` (dimensionless: the
        error times ``dr``) over the rows farther than :data:`~manifold_sph.spem.tmz.CONSISTENCY_MARGIN` kernel
        supports from every wall particle and held E particle and, with an ``interface``, from its circle (whose
        rows are fitted on the jump fields instead): the certificate of a run's interior, as
        :meth:`TMzSolver.interior_consistency_residual`: small for "sbp" and for "adjoint" on the lattice, O(1)
        for "adjoint" on irregular layouts (docs/spem.md, "Defaults per layout and what certifies a run", has the
        measured values).

        >>> from manifold_sph.spem import tez_disk_layout
        >>> disk = tez_disk_layout((0.0, 0.0), 0.1, 0.01, amplitude=0.2)
        >>> bool(TEzSolver(disk, h_ratio=0.8).interior_consistency_residual() < 1e-6)
        True
        >>> bool(TEzSolver(disk, h_ratio=0.8, coupling="adjoint").interior_consistency_residual() > 0.5)
        True
        """
        from scipy.spatial import cKDTree

        from .tmz import CONSISTENCY_MARGIN

        lay = self.layout
        edge = np.vstack([lay.ex[lay.ex_fixed], lay.ey[lay.ey_fixed]]
                         + ([lay.wall] if lay.wall is not None else []))
        margin = CONSISTENCY_MARGIN * self._support
        tree = cKDTree(edge) if len(edge) else None

        def far(p):
            keep = np.ones(len(p), dtype=bool) if tree is None else tree.query(p)[0] > margin
            if self.interface is not None:
                c = np.asarray(self.interface.center, dtype=np.float64)
                keep &= np.abs(np.hypot(*(p - c).T) - self.interface.radius) > margin
            return keep

        hz, ex, ey = lay.hz, lay.ex[self.fx], lay.ey[self.fy]
        worst = 0.0
        for D, rows, cols, axis in ((self.Dx, hz, ey, 0), (self.Dy, hz, ex, 1), (self.Gx, ey, hz, 0),
                                    (self.Gy, ex, hz, 1)):
            keep = far(rows)
            for k in (0, 1):
                f = (cols[:, k] - cols[:, k].mean()) / lay.dr
                r = np.abs(D @ f - (1.0 / lay.dr if k == axis else 0.0))[keep]
                if r.size:
                    worst = max(worst, float(r.max()) * lay.dr)
        return worst

    def _assemble_straight(self, kw, sbp_layers):
        """Rectangles: the Hz rows from the free E particles (wall E columns dropped), corrected by ``sbp_pair``."""
        lay = self.layout
        # Hz rows: d/dx of Ey and d/dy of Ex (the wall E particles carry zero: their columns are dropped)
        Dx = cross_gradient(lay.hz, lay.ey, self.h, row_name="Hz particles", col_name="Ey particles", **kw)[0]
        Dy = cross_gradient(lay.hz, lay.ex, self.h, row_name="Hz particles", col_name="Ex particles", **kw)[1]
        Dx, Dy = sp.csr_matrix(Dx)[:, self.fy], sp.csr_matrix(Dy)[:, self.fx]
        if self.coupling == "sbp":
            vol_h = np.ones(len(lay.hz))
            Dx, _ = sbp_pair(Dx, lay.hz, lay.ey[self.fy], 0, vol_h, np.ones(len(self.fy)), scale=lay.dr,
                             layers=sbp_layers)
            Dy, _ = sbp_pair(Dy, lay.hz, lay.ex[self.fx], 1, vol_h, np.ones(len(self.fx)), scale=lay.dr,
                             layers=sbp_layers)
        if self.coupling == "direct":
            Gx = cross_gradient(lay.ey[self.fy], lay.hz, self.h, row_name="Ey particles", col_name="Hz particles",
                                **kw)[0]
            Gy = cross_gradient(lay.ex[self.fx], lay.hz, self.h, row_name="Ex particles", col_name="Hz particles",
                                **kw)[1]
        else:
            Gx, Gy = -Dx.T, -Dy.T
        self.Dx, self.Dy, self.Gx, self.Gy = (sp.csr_matrix(M) for M in (Dx, Dy, Gx, Gy))

    def _assemble_curved(self, kw):
        """Curved PEC walls: one curl operator over the free E particles and the wall closure (module docstring)."""
        from scipy.spatial import cKDTree

        from ..kernels import get_kernel

        lay = self.layout
        if self.coupling == "direct":
            raise ValueError("coupling 'direct' is not available with curved PEC walls (its spectrum is not "
                             "controlled next to the wall); use coupling='sbp' (energy-conserving) or 'adjoint'")
        dr, wall, nrm = lay.dr, lay.wall, lay.wall_normal
        ex, ey = lay.ex[self.fx], lay.ey[self.fy]
        nx, ny = len(ex), len(ey)
        Dy = sp.csr_matrix(cross_gradient(lay.hz, np.vstack([ex, wall]), self.h, row_name="Hz particles",
                                          col_name="Ex and wall particles", **kw)[1])
        Dx = sp.csr_matrix(cross_gradient(lay.hz, np.vstack([ey, wall]), self.h, row_name="Hz particles",
                                          col_name="Ey and wall particles", **kw)[0])
        tau = np.column_stack([-nrm[:, 1], nrm[:, 0]])
        # the wall columns: only the tangential component (held at zero); the normal one is not represented
        Cw = Dy[:, nx:] @ sp.diags(tau[:, 0]) - Dx[:, ny:] @ sp.diags(tau[:, 1])
        support = get_kernel(kw["kernel"]).support * self.h
        reach = max(DISK_CLOSURE_REACH * dr, support)
        pairs = cKDTree(wall).sparse_distance_matrix(cKDTree(lay.hz), reach, output_type="ndarray")
        Cw = (Cw + sp.csr_matrix((np.full(len(pairs), 1e-300), (pairs["j"], pairs["i"])), shape=Cw.shape)).tocsr()
        curl0 = sp.hstack([Dy[:, :nx], -Dx[:, :ny], Cw]).tocsr()
        if self.bulk_order == 4:
            dirs4 = np.vstack([np.tile([1.0, 0.0], (nx, 1)), np.tile([0.0, 1.0], (ny, 1))])
            curl0 = fourth_order_rows(curl0, lay.hz, np.vstack([ex, ey]), dirs4, dr)
        vh0 = lay.volumes[0] if lay.volumes is not None else np.ones(len(lay.hz))
        ve0 = np.r_[lay.volumes[1][self.fx], lay.volumes[2][self.fy]] if lay.volumes is not None else np.ones(nx + ny)
        if self.coupling == "sbp":
            cols = np.vstack([ex, ey, wall])
            dirs = np.vstack([np.tile([1.0, 0.0], (nx, 1)), np.tile([0.0, 1.0], (ny, 1)), tau])
            width = max(DISK_BAND * dr, 2.0 * support)
            C, vh, ve, self.sbp_residual = curl_sbp(lay.hz, cols, dirs, curl0, nx + ny, lay.wall_length, vh0, ve0,
                                                     width, dr, interface=self.interface)
            if self.sbp_residual > 1e-6:
                raise ValueError(f"the wall correction cannot meet its conditions (largest residual "
                                 f"{self.sbp_residual:.3g}): the operators would be inconsistent; change h_ratio "
                                 f"or the layout")
            if not (np.all(vh > 0.05 * vh0) and np.all(ve > 0.05 * ve0)):
                raise ValueError(f"the wall correction left a particle volume at or below 5 % of its cell "
                                 f"(min Hz {float(np.min(vh / vh0)):.3g}, E {float(np.min(ve / ve0)):.3g} of the "
                                 f"cell): change h_ratio or the layout's wall_spacing / wall_margin")
        else:  # "adjoint": the uncorrected curl and its adjoint in the Voronoi volumes (energy-conserving)
            C, vh, ve = curl0, vh0, ve0
        self.curl = C[:, : nx + ny].tocsr()
        self.closure = C[:, nx + ny :].tocsr()  # multiplies the zero tangential E on the wall
        self.vol_hz, self.vol_ex, self.vol_ey = vh, ve[:nx], ve[nx:]
        G = (sp.diags(1.0 / ve) @ (-self.curl.T) @ sp.diags(vh)).tocsr()
        # as the rectangle's four matrices: mu dHz/dt = Dy Ex - Dx Ey, eps dEx/dt = Gy Hz, eps dEy/dt = -Gx Hz
        self.Dy, self.Dx = self.curl[:, :nx].tocsr(), (-self.curl[:, nx:]).tocsr()
        self.Gy, self.Gx = G[:nx].tocsr(), (-G[nx:]).tocsr()

    def _check_spectrum(self, L, courant):
        from scipy.sparse.linalg import eigs

        if self.coupling == "direct":
            lam = np.linalg.eigvals(L.toarray()) if L.shape[0] <= 900 else np.concatenate(
                [eigs(L, k=8, which="LM", return_eigenvectors=False), eigs(L, k=8, which="LI",
                                                                        return_eigenvectors=False)])
            rho = float(np.abs(lam).max())
        else:
            lam = None
            r = np.sqrt(self.vol_hz)
            S = (sp.diags(r) @ L @ sp.diags(1.0 / r)).tocsr()  # V^1/2 L V^-1/2 = -V^1/2 C V_E^-1 C^T V^1/2 / (eps mu)
            theta, bound = spectral_radius_bound(0.5 * (S + S.T))  # negative semi-definite
            rho = max(bound, theta * (1.0 + STABILITY_MARGIN)) / (1.0 + STABILITY_MARGIN)  # as TMzSolver's
        self.dt_stable = 2.0 / math.sqrt(rho * (1.0 + STABILITY_MARGIN))  # the margin: at least 0.5 %
        self.dt = courant * min(self.dt_stable, self.h / (math.sqrt(2.0) * self.c_max))
        if lam is not None:
            g = float(leapfrog_growth(lam, self.dt).max())
            if g > 1.0 + 1e-12:
                raise ValueError(f"the direct coupling is unstable on this layout: a leap-frog mode grows by {g:.6g} "
                                 f"per step; use coupling='sbp' (energy-conserving)")

    @property
    def n_particles(self) -> int:
        """Hz + Ex + Ey particles."""
        return self.layout.n_particles

    def reset(self) -> None:
        """Zero the fields, t = 0."""
        self.hz = np.zeros(len(self.layout.hz))
        self.ex = np.zeros(len(self.fx))
        self.ey = np.zeros(len(self.fy))
        self.t, self.n = 0.0, 0
        self.energy0 = 0.0

    def set_dt(self, dt: float) -> None:
        """Change the step (below the CFL and spectral limits); call before :meth:`set_initial`."""
        dt = check_positive("dt", dt)
        limit = min(self.dt_stable, self.h / (math.sqrt(2.0) * self.c_max))
        if dt >= limit:
            raise ValueError(f"dt = {dt:.4g} s exceeds the stability limit {limit:.4g} s")
        self.dt = dt

    def set_initial(self, hz0: ArrayLike) -> None:
        """Hz(0) = hz0 with E(0) = 0, E advanced half a step (second order for fields even in time)."""
        from .._validation import as_field

        self.reset()
        self.hz = as_field("hz0", hz0, len(self.layout.hz)).copy()
        self.ex = 0.5 * self.dt / self.eps * (self.Gy @ self.hz)
        self.ey = -0.5 * self.dt / self.eps * (self.Gx @ self.hz)
        self.energy0 = self.energy()

    def energy(self) -> float:
        """``mu Hz^n . V Hz^n + eps E^{n+1/2} . V E^{n-1/2}``, conserved by leap-frog when ``G = -V^-1 D^T V``.

        The volumes ``V`` are 1 on rectangles and fitted next to curved walls ("sbp", "adjoint").

        ``E^{n-1/2}`` is reconstructed from the last update.
        """
        ex_prev = self.ex - self.dt / self.eps * (self.Gy @ self.hz)
        ey_prev = self.ey + self.dt / self.eps * (self.Gx @ self.hz)
        return float(self.mu * (self.vol_hz * self.hz) @ self.hz
                     + self.eps * ((self.vol_ex * self.ex) @ ex_prev + (self.vol_ey * self.ey) @ ey_prev))

    def step(self) -> None:
        """Hz to t + dt, then E to t + 3 dt / 2."""
        self.hz += self.dt / self.mu * (self.Dy @ self.ex - self.Dx @ self.ey)
        self.n += 1
        self.t = self.n * self.dt
        self.ex += self.dt / self.eps * (self.Gy @ self.hz)
        self.ey -= self.dt / self.eps * (self.Gx @ self.hz)

    @property
    def field(self) -> np.ndarray:
        """What ``run`` records: Hz."""
        return self.hz


# ----------------------------------------------------------------------------- time domain
def per_e_particle(name: str, value: float | ArrayLike, n: int) -> np.ndarray:
    """A relative material value per E particle: a positive scalar or an (n,) array of positive finite values."""
    a = np.asarray(value, dtype=np.float64)
    if a.ndim == 0:
        return np.full(n, check_positive(name, float(a)))
    if a.shape != (n,):
        raise ValueError(f"{name} must be a scalar or have shape ({n},), got shape {a.shape}")
    if not np.all(np.isfinite(a)) or not np.all(a > 0):
        raise ValueError(f"{name} must be finite and > 0 at every particle")
    return a


class TEzPMLSolver(Leapfrog):
    """Leap-frog TEz with split-field PML, per-particle permittivity and driven wall closures (module docstring).

    The operators are those of :class:`.TEzSolver` on a layout with closure
    walls (:func:`tez_scattering_layout`), built with the smallest
    permittivity: the energy-conserving pair with a larger permittivity
    anywhere has a smaller spectral radius (``V_E eps`` grows in the Loewner
    order), so the step of that solver stays stable.

    Parameters
    ----------
    layout : TEzLayout
        With wall (closure) particles.
    eps_ex, eps_ey : float or array
        Relative permittivity per free Ex / Ey particle (> 0).
    pml : PML, optional
        Absorbing layers (zero conductivity elsewhere).
    h_ratio, courant, coupling
        As :class:`.TEzSolver` (couplings "sbp" and "adjoint").
    pml_check : bool
        Refuse a PML with ``h_ratio`` above :data:`TEZ_PML_H_RATIO_MAX`, where the layer no longer absorbs
        (default True; False runs anyway).
    interface, bulk_order
        As :class:`.TEzSolver`.

    Notes
    -----
    Without PML and drive the discrete energy :meth:`energy` is conserved.
    The split-field layer is not proven stable on these operators (it is not
    on the Yee lattice either: Berenger's split is weakly well-posed); measured
    from a random Hz on the PEC cylinder at 3 spacings per radius, R0 = 1e-6:
    a 2-cell layer in a box reaching 8 spacings grew (the energy 7x every
    5000 steps), 3 to 6 cells decayed (sampled every 5000 steps up to 2 10^4). The
    scattering cases use 6 cells or more (half a wavelength at 4 spacings per
    radius, ka = 2).

    Examples
    --------
    >>> from manifold_sph.spem import tez_scattering_layout
    >>> lay = tez_scattering_layout("pec", 0.1, 0.05, 0.2)
    >>> s = TEzPMLSolver(lay)
    >>> s.set_initial(np.exp(-((lay.hz[:, 0] - 0.15) ** 2 + lay.hz[:, 1] ** 2) / 0.003))
    >>> _ = s.run(200)
    >>> bool(abs(s.energy() / s.energy0 - 1) < 1e-12)  # lossless, undriven: the discrete energy is conserved
    True
    """

    def __init__(self, layout: TEzLayout, *, eps_ex: float | ArrayLike = 1.0, eps_ey: float | ArrayLike = 1.0,
                 pml: PML | None = None, h_ratio: float = DISK_H_RATIO, courant: float = 0.9,
                 coupling: str = "sbp", pml_check: bool = True, interface: CircularInterface | None = None,
                 bulk_order: int = 2) -> None:
        if not isinstance(layout, TEzLayout):
            raise TypeError(f"layout must be a TEzLayout, got {type(layout).__name__}")
        if not layout.curved:
            raise ValueError("layout must have wall (closure) particles (tez_scattering_layout or "
                             "wall_closure_layout)")
        if pml is not None and not isinstance(pml, PML):
            raise TypeError(f"pml must be a PML or None, got {type(pml).__name__}")
        check_in("coupling", coupling, ("sbp", "adjoint"))
        if pml is not None and pml_check:
            self.check_pml_support(check_positive("h_ratio", h_ratio))
        er_x = per_e_particle("eps_ex", eps_ex, len(layout.ex))
        er_y = per_e_particle("eps_ey", eps_ey, len(layout.ey))
        self.base = TEzSolver(layout, h_ratio=h_ratio, eps_r=float(min(er_x.min(), er_y.min())), coupling=coupling,
                              courant=courant, interface=interface, bulk_order=bulk_order)
        b = self.base
        self.layout, self.pml = layout, pml
        self.Dx, self.Dy, self.Gx, self.Gy, self.closure = b.Dx, b.Dy, b.Gx, b.Gy, b.closure
        self.vol_hz, self.vol_ex, self.vol_ey = b.vol_hz, b.vol_ex, b.vol_ey
        self.eps_x, self.eps_y = EPS0 * er_x, EPS0 * er_y
        zh = np.zeros(len(layout.hz))
        sx_h, sy_h = pml.sigma(layout.hz) if pml else (zh, zh)
        self._sig = (sx_h * MU0 / EPS0, sy_h * MU0 / EPS0,
                     pml.sigma(layout.ex)[1] if pml else np.zeros(len(layout.ex)),
                     pml.sigma(layout.ey)[0] if pml else np.zeros(len(layout.ey)))
        self.dt = b.dt
        self._coefficients()
        self.reset()

    def interior_consistency_residual(self) -> float:
        """:meth:`TEzSolver.interior_consistency_residual` of the operators this solver steps with."""
        return self.base.interior_consistency_residual()

    @staticmethod
    def check_pml_support(h_ratio: float) -> None:
        """Refuse (ValueError) a support ``h / dr`` above :data:`TEZ_PML_H_RATIO_MAX`, where the split-field
        layer no longer absorbs."""
        if h_ratio > TEZ_PML_H_RATIO_MAX * (1 + 1e-9):
            raise ValueError(
                f"h_ratio = {h_ratio:.3g} is outside the range where the TEz split-field PML absorbs (h_ratio <= "
                f"{TEZ_PML_H_RATIO_MAX}: a 10-cell layer reflects -58 dB at 0.8, -27 dB at 1.0, -20 dB at 1.3); use "
                f"h_ratio <= {TEZ_PML_H_RATIO_MAX}, or pml_check=False to run anyway"
            )

    @property
    def dt_stable(self) -> float:
        """Largest stable step of the lossless pair (:class:`.TEzSolver`'s spectral limit)."""
        return self.base.dt_stable

    def _coefficients(self):
        def coef(s, m):
            a = s * self.dt / (2.0 * m)
            return (1.0 - a) / (1.0 + a), (self.dt / m) / (1.0 + a)

        shx, shy, sex, sey = self._sig
        self.dax, self.dbx = coef(shx, MU0)
        self.day, self.dby = coef(shy, MU0)
        self.cax, self.cbx = coef(sex, self.eps_x)
        self.cay, self.cby = coef(sey, self.eps_y)

    def set_dt(self, dt: float) -> None:
        """Change the step (below the stability limit); call before :meth:`set_initial`."""
        self.base.set_dt(dt)
        self.dt = self.base.dt
        self._coefficients()

    def reset(self) -> None:
        """Zero the fields, t = 0."""
        self.hzx = np.zeros(len(self.layout.hz))
        self.hzy = np.zeros(len(self.layout.hz))
        self.ex = np.zeros(len(self.layout.ex))
        self.ey = np.zeros(len(self.layout.ey))
        self.t, self.n = 0.0, 0
        self.energy0 = 0.0

    @property
    def hz(self) -> np.ndarray:
        """``Hz = Hzx + Hzy``."""
        return self.hzx + self.hzy

    def set_initial(self, hz0: ArrayLike) -> None:
        """Hz(0) = hz0 (split evenly), E(0) = 0 advanced half a step (lossless update)."""
        from .._validation import as_field

        self.reset()
        h = as_field("hz0", hz0, len(self.layout.hz))
        self.hzx, self.hzy = 0.5 * h, 0.5 * h
        self.ex = 0.5 * self.dt / self.eps_x * (self.Gy @ h)
        self.ey = -0.5 * self.dt / self.eps_y * (self.Gx @ h)
        self.energy0 = self.energy()

    def energy(self) -> float:
        """``mu Hz . V Hz + eps E^{n+1/2} . V E^{n-1/2}`` (conserved without PML and drive; ``E^{n-1/2}`` rebuilt)."""
        h = self.hz
        ex_prev = self.ex - self.dt / self.eps_x * (self.Gy @ h)
        ey_prev = self.ey + self.dt / self.eps_y * (self.Gx @ h)
        return float(MU0 * (self.vol_hz * h) @ h + (self.vol_ex * self.eps_x * self.ex) @ ex_prev
                     + (self.vol_ey * self.eps_y * self.ey) @ ey_prev)

    def step(self, wall_et: np.ndarray | None = None, dex: np.ndarray | None = None,
             dey: np.ndarray | None = None, dhz: np.ndarray | None = None) -> None:
        """Hz to t + dt, then E to t + 3 dt / 2.

        ``wall_et``: the tangential E (``E . tau``, ``tau = (-n_y, n_x)``) on the
        wall particles at t + dt / 2 (zero without); ``dex``, ``dey``: increments
        added to Ex, Ey after their update, ``dhz`` to Hz after its update (volume sources).
        """
        cy = self.Dy @ self.ex
        if wall_et is not None:
            cy = cy + self.closure @ wall_et
        self.hzx = self.dax * self.hzx - self.dbx * (self.Dx @ self.ey)
        self.hzy = self.day * self.hzy + self.dby * cy
        if dhz is not None:
            self.hzy += dhz
        self.n += 1
        self.t = self.n * self.dt
        h = self.hzx + self.hzy
        self.ex = self.cax * self.ex + self.cbx * (self.Gy @ h)
        self.ey = self.cay * self.ey - self.cby * (self.Gx @ h)
        if dex is not None:
            self.ex += dex
        if dey is not None:
            self.ey += dey

    @property
    def field(self) -> np.ndarray:
        """What ``run`` records: Hz (undriven steps)."""
        return self.hzx + self.hzy
