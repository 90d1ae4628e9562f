"""Lattice analysis of the SPEM operators: null modes and numerical dispersion.

On a uniform lattice every interior row of a cross-derivative matrix has the
same coefficients, so a plane wave ``exp(i k.x)`` is an eigenfunction and the
leap-frog dispersion relation follows from the symbols of the four matrices:

    sin^2(w dt / 2) = -(c dt / 2)^2 (s_x^EH s_x^HE + s_y^EH s_y^HE),
    s^AB(k) = sum_j D_ij exp(i k.(x_j - x_i))   (row i interior in set A).

The Yee FDTD reference is the same formula with two-point central
differences (``s = 2 i sin(k dr/2)/dr``).

Examples
--------
>>> r = null_mode_response("staggered")
>>> r["dx_row_alternating"] < 1e-12, r["dx_checkerboard"] < 1e-12
(True, True)
>>> null_mode_response("yee")["dx_checkerboard"] > 0.5
True
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import check_in, check_positive
from .constants import C0
from .layouts import make_layout
from .operators import DEFAULT_COUPLING, DEFAULT_H_RATIO, cross_gradient

if TYPE_CHECKING:
    from ..kernels import Kernel

__all__ = ["lattice_symbols", "null_mode_response", "phase_velocity", "yee_fdtd_phase_velocity", "measured_phase_velocity",
           "ppw_for_phase_error"]

_CELLS = 12


@functools.lru_cache(maxsize=32)
def _operators(layout, h_ratio, kernel, form, dr=1.0):
    lay = make_layout(layout, (0.0, _CELLS * dr, 0.0, _CELLS * dr), dr)
    h = h_ratio * dr
    kw = dict(kernel=kernel, form=form)
    ei = lay.e[~lay.e_fixed]  # interior E rows only
    ops = {
        "Dx_e": cross_gradient(ei, lay.hy, h, **kw)[0],
        "Dy_e": cross_gradient(ei, lay.hx, h, **kw)[1],
        "Dy_hx": cross_gradient(lay.hx, lay.e, h, **kw)[1],
        "Dx_hy": cross_gradient(lay.hy, lay.e, h, **kw)[0],
    }
    ops["e_rows"] = ei
    return lay, ops


def _centre(points, dr):
    c = points.mean(axis=0)
    return int(np.argmin(((points - c) ** 2).sum(axis=1)))


def lattice_symbols(wavevectors: ArrayLike, layout: str = "yee", *, h_ratio: float = DEFAULT_H_RATIO,
                    kernel: str | Kernel | type[Kernel] = "cubic", form: str = "fpm",
                    dr: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Symbols ``(s_x^EH, s_y^EH, s_y^HxE, s_x^HyE)`` at ``wavevectors`` (K, 2), from interior rows."""
    lay, ops = _operators(layout, h_ratio, kernel, form, dr)
    k = np.atleast_2d(np.asarray(wavevectors, dtype=np.float64))
    rows = {"Dx_e": (ops["e_rows"], lay.hy), "Dy_e": (ops["e_rows"], lay.hx), "Dy_hx": (lay.hx, lay.e), "Dx_hy": (lay.hy, lay.e)}
    out = []
    for name in ("Dx_e", "Dy_e", "Dy_hx", "Dx_hy"):
        P, Q = rows[name]
        i = _centre(P, dr)
        row = ops[name].getrow(i)
        x = Q[row.indices] - P[i]
        out.append((row.data[None, :] * np.exp(1j * k @ x.T)).sum(axis=1))
    return tuple(out)


def null_mode_response(layout: str = "yee", *, h_ratio: float = DEFAULT_H_RATIO, kernel: str | Kernel | type[Kernel] = "cubic",
                       form: str = "fpm") -> dict:
    """Interior response of the E-row x-derivative to grid-scale H patterns.

    ``dx_row_alternating``: ``H = (-1)^row (x - x_i)/dr`` (exact derivative
    ``+-1/dr``), response relative to ``1/dr``; ``dx_checkerboard``:
    ``H = (-1)^(row+col)``, response relative to ``2/dr`` (the two-point
    difference's). A value 0 means the pattern is invisible to the E update
    (a null mode): the staggered layout of [2] has both, the Yee-style
    layout neither.
    """
    check_in("layout", layout, ("yee", "staggered"))
    dr = 1.0
    lay, ops = _operators(layout, h_ratio, kernel, form, dr)
    H = lay.hy
    col = np.floor(H[:, 0] / dr).astype(int)
    row = np.floor(H[:, 1] / dr).astype(int)
    i = _centre(ops["e_rows"], dr)
    D = ops["Dx_e"].getrow(i)
    xi = ops["e_rows"][i, 0]
    ramp = (-1.0) ** row * (H[:, 0] - xi) / dr
    return {"dx_row_alternating": float(abs(D @ ramp)[0]) * dr,
            "dx_checkerboard": float(abs(D @ (-1.0) ** (row + col))[0]) / (2.0 / dr)}


def phase_velocity(ppw: float, angle: float = 0.0, layout: str = "yee", *, h_ratio: float = DEFAULT_H_RATIO,
                   kernel: str | Kernel | type[Kernel] = "cubic", form: str = "fpm", courant: float = 0.9) -> float:
    """Numerical phase velocity over c for ``ppw`` particles per wavelength at ``angle`` (rad) from x.

    ``courant`` is the SPEM CFL number ``S = sqrt(2) c dt / h``.
    """
    ppw = check_positive("ppw", ppw)
    dr = 1.0
    k = 2 * np.pi / (ppw * dr)
    kv = np.array([[k * math.cos(angle), k * math.sin(angle)]])
    sxe, sye, syh, sxh = lattice_symbols(kv, layout, h_ratio=h_ratio, kernel=kernel, form=form, dr=dr)
    dt = courant * h_ratio * dr / (math.sqrt(2) * C0)
    rhs = -((C0 * dt / 2) ** 2) * (sxe * sxh + sye * syh)[0].real
    if not 0 <= rhs <= 1:
        return float("nan")
    w = 2 * math.asin(math.sqrt(rhs)) / dt
    return float(w / (C0 * k))


def yee_fdtd_phase_velocity(ppw: float, angle: float = 0.0, courant: float = 1 / math.sqrt(2)) -> float:
    """Yee FDTD phase velocity over c (2D, square cells, ``courant = c dt / dr``)."""
    k = 2 * np.pi / ppw
    s = courant**2 * (math.sin(k * math.cos(angle) / 2) ** 2 + math.sin(k * math.sin(angle) / 2) ** 2)
    return 2 * math.asin(math.sqrt(s)) / (courant * k)


def ppw_for_phase_error(tol: float = 0.01, layout: str = "yee", *,
                        angles: Sequence[float] = (0.0, math.pi / 8, math.pi / 4),
                        fdtd: bool = False, **kw: Any) -> float:
    """Smallest particles per wavelength with ``|v_phase / c - 1| <= tol`` at every angle (bisection)."""
    tol = check_positive("tol", tol)

    def worst(ppw):
        if fdtd:
            v = [yee_fdtd_phase_velocity(ppw, a) for a in angles]
        else:
            v = [phase_velocity(ppw, a, layout, **kw) for a in angles]
        v = np.asarray(v)
        return np.inf if np.isnan(v).any() else float(np.abs(v - 1).max())

    lo, hi = 2.5, 400.0
    if worst(hi) > tol:
        return float("inf")
    for _ in range(30):
        mid = math.sqrt(lo * hi)
        lo, hi = (lo, mid) if worst(mid) <= tol else (mid, hi)
    return hi


def measured_phase_velocity(layout: str = "yee", m: int = 4, *, cells: int = 40, h_ratio: float | None = None,
                            kernel: str | Kernel | type[Kernel] = "cubic", form: str = "fpm", coupling: str = DEFAULT_COUPLING,
                            courant: float = 0.9, steps: int = 300,
                            seed: int | np.random.Generator | None = 0) -> tuple[float, float]:
    """Phase velocity over c of the TM_mm mode of a PEC square, measured by running the solver.

    The square has ``cells`` spacings per side; Ez starts as
    ``sin(m pi x / a) sin(m pi y / a)`` (particles per wavelength
    ``sqrt(2) cells / m``). The projection ``a_n`` of Ez on the mode obeys
    ``a_{n+1} + a_{n-1} = 2 cos(w dt) a_n`` for a single discrete mode; ``w``
    is fitted by least squares. Works for every layout (irregular ones
    included), unlike the lattice-symbol :func:`phase_velocity`.

    Returns
    -------
    (v_phase / c, particles per wavelength)
    """
    from .layouts import make_layout as _make
    from .tmz import TMzSolver

    a = 1.0
    dr = a / cells
    lay = _make(layout, (0.0, a, 0.0, a), dr, seed=seed)
    s = TMzSolver(lay, h_ratio=h_ratio, kernel=kernel, form=form, coupling=coupling, courant=courant)
    e = lay.e
    mode = np.sin(m * np.pi * e[:, 0] / a) * np.sin(m * np.pi * e[:, 1] / a)
    s.set_initial(mode)
    series = [mode @ s.e_field]
    for _ in range(steps):
        s.step()
        series.append(mode @ s.e_field)
    x = np.asarray(series)
    cos_wdt = (x[1:-1] @ (x[2:] + x[:-2])) / (2 * x[1:-1] @ x[1:-1])
    w = math.acos(float(np.clip(cos_wdt, -1, 1))) / s.dt
    k = math.sqrt(2) * m * np.pi / a
    return float(w / (C0 * k)), float(2 * np.pi / k / dr)
