"""The operator set shared by :class:`~manifold_sph.Surface` and :class:`~manifold_sph.Domain2D`.

After the geometry is set up (neighbourhood, tangent frames, pair offsets, area
elements), one assembly gives the tangent-plane matrices ``dx``, ``dy`` and
``lap``. Gradient and divergence matrices follow from them and the frames:

- gradient matrix, shape (D N, N): row ``D i + k`` gives component ``k`` of the
  gradient at particle ``i`` (``G @ f`` reshaped to (N, D) is the gradient);
- divergence matrix, shape (N, D N): acts on the field flattened row-major,
  ``F.reshape(-1)`` = ``[F_0x, F_0y, F_0z, F_1x, ...]``.

``D`` is 3 on surfaces and 2 in the plane.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING, TypeVar

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike

from ._sparse import RowBlocks
from ._validation import as_field, as_positive_field, check_bool, check_in, check_positive
from .area import AreaElements, area_elements, check_area_method
from .assembly import DEFECT_TOL, Assembled, ColumnAreas, assemble
from .diagnostics import BuildReport, collecting, note
from .frames import offsets_array, tangent_frames
from .kernels import get_kernel
from .neighbors import Neighborhood, adaptive_smoothing_length, smoothing_length_for_count
from .schemes import get_scheme
from .spectrum import Eigenpairs, stable_eigenpairs
from .voronoi import BOUNDARY, DEGENERATE, INCOMPLETE, NEAR_DUPLICATE, roughness, stiffness_matrix, voronoi_cells

__all__ = ["OperatorSet", "LAPLACIAN_FORMS", "GROSS_DISAGREEMENT"]

#: The Laplacians an operator set offers: ``"auto"`` picks one of the other two for the cloud.
LAPLACIAN_FORMS = ("auto", "strong", "stable")

#: A point where the two Laplacians differ, on the probe functions, by more than this many times the
#: root-mean-square size of the stable one's values (and 5 times the median difference) holds a gross
#: error of the scheme's Laplacian (:attr:`OperatorSet.laplacian_form`).
GROSS_DISAGREEMENT = 1.0

_T = TypeVar("_T")


class OperatorSet:
    """Gradient, divergence and Laplacian on a set of particles (base class).

    Subclasses call :meth:`_setup` with their geometry.
    """

    _dim: int = 3

    if TYPE_CHECKING:  # the subclasses' read-only property, declared for type checkers only

        @property
        def points(self) -> np.ndarray: ...

    # ------------------------------------------------------------------ setup
    def _resolve(self, kernel, scheme, neighbors, max_condition):
        self.kernel = get_kernel(kernel)
        self.scheme = get_scheme(scheme)
        if neighbors is None:
            neighbors = self.scheme.default_neighbors
        if isinstance(neighbors, bool) or not isinstance(neighbors, (int, np.integer)):
            raise TypeError(f"neighbors must be an integer mean neighbour count, got {neighbors!r}")
        if neighbors < self.scheme.min_neighbors:
            raise ValueError(
                f"neighbors must be at least {self.scheme.min_neighbors} for scheme {self.scheme.name!r}, got {neighbors}"
            )
        self.neighbors = int(neighbors)
        self.max_condition = check_positive("max_condition", max_condition)

    def _smoothing_length(self, h, points, tree=None):
        n = points.shape[0]
        if self.neighbors >= n:
            raise ValueError(f"neighbors must be smaller than the number of points {n}, got {self.neighbors}")
        support = self.kernel.support
        if h is None:
            h, self._knn = smoothing_length_for_count(points, self.neighbors, support, tree=tree, return_knn=True)
            return h  # the k-NN query is reused by the neighbour search (None for large clouds)
        if isinstance(h, str):
            if h != "adaptive":
                raise ValueError(f"h must be None, 'adaptive', a positive number or an array of shape ({n},), got {h!r}")
            return adaptive_smoothing_length(points, self.neighbors, support, tree=tree)
        if np.ndim(h) == 0:
            return check_positive("h", h)
        return as_positive_field("h", h, n)  # names the actual problem: shape, NaN or non-positive values

    @staticmethod
    def _check_isolated(nb: Neighborhood, hint: str) -> None:
        lonely = np.flatnonzero(nb.counts < 2)
        if lonely.size:
            raise ValueError(
                f"{lonely.size} particle(s) have no neighbour inside the kernel support "
                f"(isolated points, first indices {lonely[:8].tolist()}); {hint}"
            )

    def _setup(self, nb, xy, frames, area, total_area, columns=None, column_normals=None):
        """Area elements and assembly. ``frames`` (N, 2, D) maps tangent-plane components to ambient ones
        (an array or a :class:`~manifold_sph.frames.FramePair`, read as ``frames[rows, k]`` only);
        ``column_normals`` (N, D), when given, are the normals the divergence projects each column's vector on.

        Area elements are computed here when the scheme's weights use them, and
        on first access otherwise.
        """
        if getattr(self, "_build_report", None) is None:
            self._build_report = BuildReport(f"{type(self).__name__} of {nb.n_rows:,} points")
        with self._collect():
            self._setup_operators(nb, xy, frames, area, total_area, columns, column_normals)

    def _setup_operators(self, nb, xy, frames, area, total_area, columns, column_normals):
        self.neighborhood = nb
        self._xy = xy
        self._frames = frames
        self._columns = nb.indices if columns is None else columns
        self._column_normals = column_normals
        check_area_method(area, total_area)
        self._area_args = (area, total_area, columns)
        self._area = None
        if self.scheme.uses_area:
            # Negative elements (bounded or irregular clouds) are reported in area.n_negative, not
            # warned about: time stepping is guarded by pde.choose_laplacian's spectral check.
            dV = ColumnAreas(self.area.dV, self._columns)  # looked up per chunk, no (P,) copy
        else:  # the weights do not use area elements: compute them only when asked
            dV = ColumnAreas(np.ones(nb.n_rows), self._columns)
        # the Laplacian's weights now; the derivatives' by a second pass when first asked for (16 bytes a
        # pair that Laplacian-only work, the heat, wave and Poisson solvers, never holds)
        self._ops: Assembled = assemble(
            nb, xy, dV, self.kernel, self.scheme, columns=columns, n_cols=nb.n_rows, max_condition=self.max_condition,
            gradient=False,
        )
        if not np.all(np.isfinite(self._ops.pair_lap)):  # pragma: no cover - guarded by the fallbacks
            raise FloatingPointError("operator lap has non-finite weights; please report this cloud")
        if self._ops.fallback:
            parts = " and ".join(f"{idx.size} to {name!r}" for name, idx in self._ops.fallback.items())
            idx = np.sort(np.concatenate(list(self._ops.fallback.values())))
            note(
                "fallback", f"{idx.size} point(s) of the {self.scheme.name!r} scheme fell back to a simpler one ({parts})",
                detail=f"Their local fits had too few or collinear neighbours, or a condition number above "
                f"max_condition={self.max_condition:g}; the simpler scheme is less accurate there.",
                count=idx.size, indices=idx,
            )
        self._note_inconsistent(nb.n_rows)
        self._cache = {}

    def _note_inconsistent(self, n: int) -> None:
        """A warning when rows of the scheme asked for fail the quadratic-consistency test
        (:func:`manifold_sph.assembly.quadratic_defect`); rows that fell back are reported as such."""
        defect = np.where(self._ops.used_code == 0, self._ops.defect, 0.0)
        bad = np.flatnonzero(defect > DEFECT_TOL)
        if bad.size:
            note(
                "inconsistent", f"{bad.size} of {n} point(s) of the {self.scheme.name!r} scheme get the Laplacian of a "
                f"quadratic wrong by more than {DEFECT_TOL:g} (relative; largest {defect.max():.3g})",
                detail="This scheme is not consistent on irregular or random points (or neighbours across a thin gap, "
                "without the normal filter); scheme='msph' is exact on quadratics. OperatorSet.quadratic_defect has "
                "the per-point values.",
                count=bad.size, indices=bad,
            )

    # ------------------------------------------------------------ properties
    @property
    def area(self) -> AreaElements:
        """Area elements (``.dV``, ``.n_negative``, ``.method``), computed once."""
        if self._area is None:
            method, total_area, columns = self._area_args
            with self._collect():
                self._area = area_elements(method, self.neighborhood, self._xy, self.kernel, total_area=total_area,
                                           columns=columns)
        return self._area

    # ------------------------------------------------------------ diagnostics
    @contextmanager
    def _collect(self) -> Iterator[BuildReport]:
        """Collect what the enclosed work adapts into :meth:`report`; one warning at the end, if any."""
        if getattr(self, "_build_report", None) is None:
            self._build_report = BuildReport(f"{type(self).__name__} of {self.n_points:,} points")
        with collecting(self._build_report) as report:
            yield report

    def report(self) -> BuildReport:
        """What the build adapted to this cloud, in detail (the build's one warning summarises it).

        Entries (:class:`~manifold_sph.diagnostics.Adaptation`) say what was done, why, what
        the user can do, and which points it concerns: normals estimated or flipped, sparse
        points given wider supports, fallbacks to simpler schemes, near-duplicate points
        merged, repaired cells of the stable Laplacian, and which Laplacian
        :meth:`laplacian` uses. ``print(s.report())`` shows them; ``to_dict()`` gives them
        as JSON-ready data.

        Examples
        --------
        >>> from manifold_sph import Surface
        >>> from manifold_sph.reference import shapes
        >>> print(Surface(shapes.sphere(500)).report())
        Surface of 500 points: built as given, nothing adapted.
        """
        if getattr(self, "_build_report", None) is None:
            self._build_report = BuildReport(f"{type(self).__name__} of {self.n_points:,} points")
        return self._build_report

    @property
    def dim(self) -> int:
        """Dimension of the ambient space: 3 for a :class:`Surface`, 2 for a :class:`Domain2D`."""
        return self._dim

    def cached(self, key: Hashable, compute: Callable[[], _T]) -> _T:
        """The value stored on this operator set under ``key``, computed by ``compute()`` on first use.

        For quantities derived from the operators (curvatures, spectra, solver
        factorisations) that later calls reuse; the store lives as long as the set.

        Examples
        --------
        >>> from manifold_sph import Surface
        >>> from manifold_sph.reference import shapes
        >>> s = Surface(shapes.sphere(500))
        >>> calls = []
        >>> first = s.cached("two", lambda: calls.append(1) or 2)
        >>> second = s.cached("two", lambda: calls.append(1) or 2)
        >>> first, second, len(calls)
        (2, 2, 1)
        """
        if key not in self._cache:
            if not callable(compute):
                raise TypeError(f"compute must be a callable returning the value, got {type(compute).__name__}")
            self._cache[key] = compute()
        return self._cache[key]

    def pair_offsets(self) -> np.ndarray:
        """(P, 2) offsets ``x_j - x_i`` of every neighbour pair in the row particle's frame (CSR order of
        :attr:`neighborhood`). Surfaces project them anew on each call instead of storing them
        (16 bytes a pair), so keep the result if you need it twice."""
        return offsets_array(self._xy)

    @property
    def pair_columns(self) -> np.ndarray:
        """(P,) matrix column of every pair: :attr:`neighborhood` ``.indices``, or the owners of mirrored ghosts."""
        return self._columns

    @property
    def n_points(self) -> int:
        return self.neighborhood.n_rows

    @property
    def h(self) -> np.ndarray:
        """(N,) smoothing length of each particle."""
        return self.neighborhood.h

    @property
    def dV(self) -> np.ndarray:
        """(N,) area elements."""
        return self.area.dV

    @property
    def fallback(self) -> dict:
        """``{scheme name: indices}`` of particles computed with a fallback scheme."""
        return self._ops.fallback

    @property
    def quadratic_defect(self) -> np.ndarray:
        """(N,) largest error of each particle's Laplacian weights on ``x^2/2, xy, y^2/2`` in its tangent
        plane (exact: 1, 0, 1); see :func:`manifold_sph.assembly.quadratic_defect`."""
        return self._ops.defect

    @property
    def condition(self) -> np.ndarray:
        """(N,) largest condition number of each particle's local systems (first scheme tried)."""
        return self._ops.condition

    @property
    def scheme_used(self) -> np.ndarray:
        """(N,) name of the scheme that produced each particle's operators."""
        return self._ops.scheme_used

    # ------------------------------------------------------------- matrices
    def derivative_matrices(self) -> tuple[sp.csr_matrix, sp.csr_matrix]:
        """Tangent-plane derivative matrices ``(Dx, Dy)``, each (N, N), in the particles' own frames."""
        return self._ops.dx, self._ops.dy

    def laplacian_matrix(self, *, form: str = "auto") -> sp.csr_matrix:
        """Laplace-Beltrami matrix ``L ~ Lap_S``, shape (N, N): ``L @ f == laplacian(f, form=form)``.

        Parameters
        ----------
        form : {"auto", "strong", "stable"}
            ``"strong"``: the scheme's own matrix (high order on clean clouds; not symmetric).
            ``"stable"``: ``-M^-1 K`` (:meth:`stable_laplacian_matrix`). ``"auto"``: the one
            :attr:`laplacian_form` names for this cloud.

        Returns
        -------
        scipy.sparse.csr_matrix, shape (N, N)
            The matrix the operators use, not a copy: do not change it in place (scipy's
            ``abs(L)`` and some other operations sort its unsorted column indices in place,
            which changes the order of later row sums at round-off; use ``L.copy()``).
        """
        form = self._form(form)
        return self._ops.lap if form == "strong" else self.stable_laplacian_matrix()

    def _form(self, form: str) -> str:
        check_in("form", form, LAPLACIAN_FORMS)
        return self.laplacian_form if form == "auto" else form

    @property
    def laplacian_form(self) -> str:
        """``"strong"`` or ``"stable"``: the Laplacian that :meth:`laplacian` uses on this cloud.

        The scheme's (strong-form) Laplacian is high order where its local fits are well posed,
        and grossly wrong at points where they are not (noisy or irregular sampling: values of
        ``Lap_S x`` 60 times too large on a model's vertices). The stable Laplacian has no gross
        errors, but on irregular clouds every value carries an O(1) error (relative error of
        ``Lap_S(xyz)`` on uniformly random sphere points about 0.12-0.19 at any ``N``, against
        0.003-0.007 for the strong form from 16,000 points on).

        Both are applied to smooth probe functions (the centred coordinates and their
        products). Where they differ by more than :data:`GROSS_DISAGREEMENT` times the stable
        values' root-mean-square size (and 5 times the median difference), the larger of the
        two values is the wrong one; every other difference is taken as the stable form's
        error. The strong form is chosen when the energy of its gross errors is at most that
        of the stable form's errors: when it is the more accurate of the two in the mean square. Decided on
        first use (it builds the stable Laplacian) and recorded in :meth:`report`; docs/pde.md
        has the measurements.
        """
        if "form" not in self._cache:
            with self._collect():
                self._cache["form"] = self._choose_form()
        return self._cache["form"][0]

    def _choose_form(self) -> tuple[str, float]:
        try:
            st = self._stable()
        except ValueError as exc:  # no particle has a cell: only the scheme's Laplacian exists
            note("laplacian", "the Laplacian is the scheme's own (the stable one could not be built)",
                 detail=str(exc), severity="info")
            return "strong", np.nan
        ok = (st["flags"] & BOUNDARY) == 0
        ok[st["degenerate"]] = False
        x = np.asarray(self.points, dtype=np.float64)
        y = x - x.mean(axis=0)
        y /= max(float(np.sqrt((y**2).sum(axis=1).max())), 1e-300)
        d = y.shape[1]
        probes = np.column_stack([y] + [y[:, a] * y[:, b] for a in range(d) for b in range(a, d)])
        A = (self._ops.lap @ probes)[ok]
        B = (self.stable_laplacian_matrix() @ probes)[ok]
        top = float(np.abs(B).max()) if B.size else 0.0
        if top > 0 and np.isfinite(top):  # Laplacians scale as 1/s^2: their squares leave float64 at 1e+-100
            A, B = A / top, B / top
        rms = float(np.sqrt((B**2).sum(axis=1).mean())) if B.size else 0.0
        if not rms > 0:
            return "strong", np.nan  # no closed cell to compare on
        d = np.linalg.norm(A - B, axis=1) / rms
        gross = d > max(GROSS_DISAGREEMENT, 5.0 * float(np.median(d)))
        # at a gross difference the wrong value is the larger one (the truth is of the typical size)
        gross &= np.linalg.norm(A, axis=1) > np.linalg.norm(B, axis=1)
        ratio = float(np.sum(d[gross] ** 2) / max(np.sum(d[~gross] ** 2), 1e-300))
        if ratio <= 1.0:
            note("laplacian", f"the Laplacian is the {self.scheme.name!r} scheme's own (strong form)", severity="info",
                 detail=f"On smooth functions it has gross errors at {int(gross.sum())} point(s), carrying "
                 f"{ratio:.2g} times the energy of the stable Laplacian's errors: it is the more accurate one.")
            return "strong", ratio
        note("laplacian", "the Laplacian is the stable one (the scheme's own is not accurate on this cloud)",
             severity="info",
             detail=f"On smooth functions the {self.scheme.name!r} scheme's Laplacian is grossly wrong at "
             f"{int(gross.sum())} point(s) (ill-conditioned local fits: irregular or noisy sampling), carrying "
             f"{ratio:.3g} times the energy of the stable Laplacian's errors. Pass form='strong' to use it anyway.")
        return "stable", ratio

    def _pair_coefficients(self):
        """Per pair, the ambient vector ``dx_ij e1_i + dy_ij e2_i`` (P, D)."""
        rows = self.neighborhood.rows
        e = self._frames
        return rows, self._ops.pair_dx[:, None] * e[rows, 0] + self._ops.pair_dy[:, None] * e[rows, 1]

    def gradient_matrix(self) -> sp.csr_matrix:
        """Gradient matrix G, shape (D N, N), D = 3 on surfaces, 2 in the plane.

        ``(G @ f).reshape(N, D) == gradient(f)``.
        """
        if "grad" not in self._cache:
            D, n = self._dim, self.n_points
            rows, c = self._pair_coefficients()
            r = (D * rows[:, None] + np.arange(D)).ravel()
            cols = np.repeat(self._columns, D)
            self._cache["grad"] = sp.coo_matrix((c.ravel(), (r, cols)), shape=(D * n, n)).tocsr()
        return self._cache["grad"]

    def divergence_matrix(self) -> sp.csr_matrix:
        """Divergence matrix, shape (N, D N), acting on ``F.reshape(-1)`` (row-major (N, D) field).

        On a surface it takes the tangential part of ``F`` at each neighbour first.
        """
        if "div" not in self._cache:
            D, n = self._dim, self.n_points
            rows, c = self._pair_coefficients()
            if self._column_normals is not None:
                nj = self._column_normals[self._columns]
                c = c - np.einsum("pd,pd->p", c, nj)[:, None] * nj  # (I - n_j n_j^T) c
            r = np.repeat(rows, D)
            cols = (D * self._columns[:, None] + np.arange(D)).ravel()
            self._cache["div"] = sp.coo_matrix((c.ravel(), (r, cols)), shape=(n, D * n)).tocsr()
        return self._cache["div"]

    # ------------------------------------------------------------ operators
    def _blocks(self, name: str) -> RowBlocks:
        """The matrix ``dx``, ``dy`` or ``lap`` split for threaded products (built once)."""
        key = ("blocks", name)
        if key not in self._cache:
            self._cache[key] = RowBlocks(getattr(self._ops, name))
        return self._cache[key]

    def _tangential(self, F: np.ndarray) -> np.ndarray:
        return F

    def gradient(self, f: ArrayLike) -> np.ndarray:
        """Tangential gradient of a scalar field.

        Parameters
        ----------
        f : array_like, shape (N,)

        Returns
        -------
        ndarray, shape (N, D)
        """
        f = as_field("f", f, self.n_points)
        e = self._frames
        return (self._blocks("dx") @ f)[:, None] * e[:, 0] + (self._blocks("dy") @ f)[:, None] * e[:, 1]

    def divergence(self, F: ArrayLike) -> np.ndarray:
        """Divergence of (the tangential part of) a vector field.

        Parameters
        ----------
        F : array_like, shape (N, D)

        Returns
        -------
        ndarray, shape (N,)
        """
        F = self._tangential(as_field("F", F, self.n_points, self._dim))
        e = self._frames
        dx, dy = self._blocks("dx"), self._blocks("dy")
        return np.einsum("nk,nk->n", e[:, 0], dx @ F) + np.einsum("nk,nk->n", e[:, 1], dy @ F)

    # ------------------------------------------------------- stable Laplacian
    #: Nearest neighbours searched again for the cells that the neighbourhood does not close.
    _WIDER_K = 64

    def _wider_candidates(self, rows: np.ndarray):
        """``(indptr, xy, columns, radius[, height])`` of a wider search for ``rows``, or None (subclasses)."""
        return None

    def _pair_heights(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray | None:
        """Offsets ``n_i . (x_j - x_i)`` of pairs along the row particle's normal, or None (flat domains)."""
        return None

    #: Nearest points whose principal plane gives the second tangent plane of a cell left open (:meth:`_refit_open`).
    _REFIT_K = 12
    #: A refitted cell is kept only if neighbours holding this share of its flux weight have the
    #: particle in their own cells too (a plane across two sheets of a thin part fails this).
    _REFIT_SHARE = 0.8

    def _refit_open(self, rows: np.ndarray, tol: np.ndarray):
        """Cells of ``rows`` (cells left open by the hull) again, in the principal plane of each one's nearest points.

        A cell clipped by its neighbourhood's hull on a closed surface means the neighbours on one
        side were lifted out of reach: its normal is badly tilted (the rims of thin ears, thin tubes).
        The normal of the least-squares plane of the ``_REFIT_K`` nearest points (oriented like the
        given one) gives a second cell, with the ``_WIDER_K`` nearest neighbours that pass the normal
        filter against it. On an open surface's boundary no plane closes the cell, and those rows
        keep theirs. The caller also requires ``_REFIT_SHARE`` of the new cell's weight on
        neighbours that see the particle back.

        Parameters
        ----------
        rows : ndarray of int, shape (R,)
            Particles whose cells are open.
        tol : ndarray, shape (R,)
            Their tolerated heights (:func:`manifold_sph.voronoi.roughness`).

        Returns
        -------
        tuple or None
            ``(closed, indptr, cols, cells)``: ``closed`` (bool, shape (R,)) marks the rows whose new
            cell closed (neither open nor degenerate); ``indptr`` (R + 1,) and ``cols`` the new pairs
            in CSR layout; ``cells`` their :class:`~manifold_sph.voronoi.VoronoiCells`. None for
            planar domains and clouds of fewer than 4 points.
        """
        pts, nrm = getattr(self, "points", None), getattr(self, "normals", None)
        tree = getattr(self, "_tree", None)
        if tree is None or pts is None or nrm is None or np.shape(pts)[1] != 3 or pts.shape[0] < 4:
            return None
        n = pts.shape[0]
        k = min(self._REFIT_K, n)
        _, near = tree.query(pts[rows], k=k)
        q = pts[near] - pts[near].mean(axis=1, keepdims=True)
        _, vec = np.linalg.eigh(np.einsum("rkd,rke->rde", q, q))
        m = vec[:, :, 0]
        m *= np.where(np.einsum("rd,rd->r", m, nrm[rows]) < 0, -1.0, 1.0)[:, None]
        kk = min(self._WIDER_K, n)
        dist, idx = tree.query(pts[rows], k=kk)
        keep = np.einsum("rkd,rd->rk", nrm[idx], m) > getattr(self, "normal_threshold", 0.0)
        keep[:, 0] = True  # the particle itself (distance 0) comes first
        counts = keep.sum(axis=1)
        owner = np.repeat(np.arange(rows.size), counts)
        cols = idx[keep]
        d = pts[cols] - pts[rows][owner]
        u, v = tangent_frames(m)
        xy = np.stack([np.einsum("pd,pd->p", d, u[owner]), np.einsum("pd,pd->p", d, v[owner])], axis=1)
        z = np.einsum("pd,pd->p", d, m[owner])
        indptr = np.concatenate([[0], np.cumsum(counts)])
        radius = dist[:, -1] if kk < n else np.full(rows.size, np.inf)
        cells = voronoi_cells(indptr, xy, radius, height=z, height_tol=tol)
        closed = ((cells.flags & (BOUNDARY | DEGENERATE)) == 0) & (cells.area > 0)
        return closed, indptr, cols, cells

    def _stable(self) -> dict:
        """Voronoi stiffness and mass, built once (see :mod:`manifold_sph.voronoi`)."""
        if "stable" not in self._cache:
            with self._collect():
                self._cache["stable"] = self._build_stable()
        return self._cache["stable"]

    def _build_stable(self) -> dict:
        nb = self.neighborhood
        n = nb.n_rows
        rows, cols = nb.rows, np.asarray(self._columns)
        z = self._pair_heights(rows, cols)
        xy = self.pair_offsets()
        tol = None if z is None else roughness(nb.indptr, xy, z, nb.support * nb.h)
        cells = voronoi_cells(nb.indptr, xy, nb.support * nb.h, height=z, height_tol=tol)
        weights = cells.weights
        area, flags = cells.area.copy(), cells.flags.copy()
        redo = np.flatnonzero(flags & (INCOMPLETE | DEGENERATE))
        n_widened = 0
        if redo.size:
            wider = self._wider_candidates(redo)
            if wider is not None:
                indptr2, xy2, cols2, radius2 = wider[:4]
                more = voronoi_cells(indptr2, xy2, radius2, height=wider[4] if len(wider) > 4 else None,
                                     height_tol=None if tol is None else tol[redo])
                mark = np.zeros(n, dtype=bool)
                mark[redo] = True
                keep = ~mark[rows]
                rows = np.concatenate([rows[keep], np.repeat(redo, np.diff(indptr2))])
                cols = np.concatenate([cols[keep], cols2])
                weights = np.concatenate([weights[keep], more.weights])
                area[redo], flags[redo] = more.area, more.flags
                n_widened = int(redo.size)
        n_refitted = 0
        open_ = np.flatnonzero(flags & BOUNDARY)
        if open_.size and tol is not None:  # tol: the heights' roughness, None exactly when z is
            refit = self._refit_open(open_, tol[open_])
            if refit is not None and refit[0].any():
                closed, indptr3, cols3, more = refit
                # the new cell's neighbours must see the particle back in their own cells (weighted share)
                W = sp.csr_matrix((weights, (rows, cols)), shape=(n, n))
                owner = np.repeat(np.arange(open_.size), np.diff(indptr3))
                back = np.asarray(W[cols3, open_[owner]]).ravel() > 0
                wn = more.weights
                share = np.bincount(owner, wn * back, open_.size) / np.maximum(np.bincount(owner, wn, open_.size), 1e-300)
                closed = closed & (share >= self._REFIT_SHARE)
                good = open_[closed]
                mark = np.zeros(n, dtype=bool)
                mark[good] = True
                take = np.repeat(closed, np.diff(indptr3))
                keep = ~mark[rows]
                rows = np.concatenate([rows[keep], np.repeat(open_, np.diff(indptr3))[take]])
                cols = np.concatenate([cols[keep], cols3[take]])
                weights = np.concatenate([weights[keep], more.weights[take]])
                area[good], flags[good] = more.area[closed], more.flags[closed]
                n_refitted = int(good.size)
        area_was_zero = area <= 0
        degenerate = np.flatnonzero(area_was_zero)
        if degenerate.size:  # no cell: a mass from the neighbours' cells, and no flux of its own
            good = ~area_was_zero
            if not good.any():
                raise ValueError(
                    "stable Laplacian: no particle has a proper Voronoi cell (all neighbourhoods are "
                    "collinear or too small); increase neighbors"
                )
            sums = np.bincount(rows, weights=np.where(good[cols], area[cols], 0.0), minlength=n)
            cnt = np.bincount(rows, weights=good[cols].astype(float), minlength=n)
            fill = np.where(cnt[degenerate] > 0, sums[degenerate] / np.maximum(cnt[degenerate], 1), np.median(area[good]))
            area[degenerate] = fill
            weights = np.where(area_was_zero[rows], 0.0, weights)
        K = stiffness_matrix(rows, cols, weights, n)
        report = {
            "boundary": int(np.count_nonzero(flags & BOUNDARY)),
            "widened": n_widened,
            "refitted": n_refitted,
            "unclosed": int(np.count_nonzero(flags & INCOMPLETE)),
            "degenerate": int(degenerate.size),
            "near_duplicate": int(np.count_nonzero(flags & NEAR_DUPLICATE)),
        }
        if degenerate.size:
            note(
                "no_cell", f"{degenerate.size} point(s) have no cell in the stable Laplacian and were given their "
                "neighbours' mean area",
                detail="Their neighbours are collinear or too few for a Voronoi cell in the tangent plane; they "
                "exchange no heat of their own (they follow their neighbours' fluxes).",
                count=degenerate.size, indices=degenerate,
            )
        if report["near_duplicate"]:
            dup = np.flatnonzero(flags & NEAR_DUPLICATE)
            note(
                "near_duplicate_cells", f"{dup.size} point(s) nearly coincide with a neighbour (closer than 1e-3 of "
                "their cell's size) in the stable Laplacian", severity="info",
                detail="Their coupling uses that distance as a floor: strong but finite.", count=dup.size, indices=dup,
            )
        return {"K": K, "M": sp.diags(area).tocsr(), "area": area, "report": report, "flags": flags,
                "degenerate": degenerate}

    @property
    def stable_report(self) -> dict:
        """Counts from the stable Laplacian's Voronoi cells.

        ``boundary``: cells clipped by the neighbourhood's hull (open boundary);
        ``widened``: cells recomputed with a wider neighbour search; ``refitted``: cells left
        open by the hull that closed in the principal plane of the particle's 12 nearest points,
        with 80 % of their weight on neighbours whose cells hold the particle too (a badly tilted
        normal on a closed surface); ``unclosed``:
        cells that even the wider search may not have closed (kept clipped to the
        hull); ``degenerate``: particles without a cell; ``near_duplicate``:
        particles with a neighbour closer than 1e-3 of their cell's size.
        """
        return dict(self._stable()["report"])

    def stiffness_matrix(self) -> sp.csr_matrix:
        """Symmetric positive semi-definite stiffness K, shape (N, N), with ``K @ 1 == 0``.

        Two-point fluxes through tangent-plane Voronoi cells (:mod:`manifold_sph.voronoi`):
        ``-K`` is a weighted graph Laplacian, and ``L = -M^-1 K`` (:meth:`stable_laplacian_matrix`)
        a Laplace-Beltrami operator whose eigenvalues are real and ``<= 0`` on any cloud.

        Examples
        --------
        >>> import numpy as np
        >>> from manifold_sph import Surface
        >>> from manifold_sph.reference import shapes
        >>> s = Surface(shapes.sphere(1000))
        >>> K = s.stiffness_matrix()
        >>> bool(abs(K - K.T).max() == 0), bool(np.abs(K @ np.ones(1000)).max() < 1e-10)
        (True, True)
        """
        return self._stable()["K"]

    def mass_matrix(self) -> sp.csr_matrix:
        """Diagonal mass M, shape (N, N): the Voronoi cell areas (positive; their sum is the area)."""
        return self._stable()["M"]

    def stable_laplacian_matrix(self) -> sp.csr_matrix:
        """``L = -M^-1 K ~ Lap_S``, shape (N, N), real eigenvalues ``<= 0`` on any cloud (``laplacian_matrix(form="stable")``)."""
        if "stable_L" not in self._cache:
            st = self._stable()
            self._cache["stable_L"] = (-sp.diags(1.0 / st["area"]) @ st["K"]).tocsr()
        return self._cache["stable_L"]

    def eigs(self, k: int = 50, *, sigma: float | None = None, refine: bool = False, component: str | int = "largest",
             method: str = "auto") -> Eigenpairs:
        """The ``k`` smallest eigenpairs of ``K v = lambda M v`` (the stable Laplacian's spectrum), or those nearest ``sigma``.

        The contract, the methods and their memory: :mod:`manifold_sph.spectrum`.

        Parameters
        ----------
        k : int
            Number of eigenpairs, ``1 <= k <= n - 2`` (``n`` the particles of the chosen piece).
        sigma : float, optional
            Return the ``k`` eigenvalues nearest ``sigma`` (any cloud size) instead of the smallest.
        refine : bool
            Rayleigh-Ritz with the scheme's own (strong-form) Laplacian in the span of
            the first ``k + max(8, k // 4)`` stable eigenvectors: the eigenvalues of the
            small matrix ``V^T M (-L) V``, real parts, ascending. It carries the
            scheme's accuracy where that operator is accurate, and only there:
            measured on the unit sphere with ``scheme="msph4"``, median error of
            eigenvalues 1..48 on Fibonacci points 3.7e-6 (N = 8000) and 2.7e-7
            (32000) against 2.0e-3 and 4.9e-4 unrefined; on uniformly random points
            no gain (3.5e-3 at N = 8000) or a loss (1.9e-3 against 9.4e-4 at 32000).
            The vectors are then the Ritz vectors (for a complex pair of Ritz values,
            the real and imaginary parts of one vector), M-orthonormalised.
        component : "largest", "all" or int
            Solve on the largest connected piece of the cloud (default; the other
            particles are listed in ``.excluded``, with one warning), on the piece that
            holds particle ``component``, or on the whole cloud (one zero eigenvalue per piece).
        method : {"auto", "dense", "shift-invert", "lobpcg"}
            See :mod:`manifold_sph.spectrum`.

        Returns
        -------
        Eigenpairs
            ``.values`` (k,) ascending, ``.vectors`` (N, k) M-orthonormal
            (``vectors.T @ M @ vectors == I``), zero on ``.excluded``; unpacks as
            ``values, vectors``.

        Examples
        --------
        >>> import numpy as np
        >>> from manifold_sph import Surface
        >>> from manifold_sph.reference import shapes
        >>> lam, V = Surface(shapes.sphere(2000)).eigs(4)     # 0, then l(l+1) = 2 three times
        >>> np.round(lam, 1).tolist()
        [0.0, 2.0, 2.0, 2.0]
        """
        refine = check_bool("refine", refine)
        st = self._stable()
        return stable_eigenpairs(st["K"], st["area"], k, sigma=sigma, component=component, method=method,
                                 laplacian=self.laplacian_matrix(form="strong") if refine else None)

    def laplacian(self, f: ArrayLike, *, form: str = "auto") -> np.ndarray:
        """Laplace-Beltrami operator (Laplacian in the plane) of a scalar field.

        Parameters
        ----------
        f : array_like, shape (N,)
        form : {"auto", "strong", "stable"}
            Which Laplacian (:meth:`laplacian_matrix`); ``"auto"``: :attr:`laplacian_form`.

        Returns
        -------
        ndarray, shape (N,)
        """
        f = as_field("f", f, self.n_points)
        form = self._form(form)
        if form == "strong":
            return self._blocks("lap") @ f
        key = ("blocks", "stable")
        if key not in self._cache:
            self._cache[key] = RowBlocks(self.stable_laplacian_matrix())
        return self._cache[key] @ f

