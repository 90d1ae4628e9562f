"""Fast paths of the build (issue 22): each gives the result of the path it replaced, to a stated tolerance."""

import warnings

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from manifold_sph import Surface, _jit, area, threads
from manifold_sph.reference import shapes

pytestmark = pytest.mark.skipif(not _jit.ENABLED, reason="the compiled kernels are off")


def _kernel_system(cloud_points, normals=None):
    s = Surface(cloud_points, cloud_points.copy() if normals is None else normals, area="shepard")
    A = area.kernel_matrix(s.neighborhood, s.pair_offsets(), s.kernel)
    return A, 1.0 / np.asarray(A.sum(axis=1)).ravel()


def _count_steps(monkeypatch):
    steps = []
    real = _jit.bicgstab_step
    monkeypatch.setattr(_jit, "bicgstab_step", lambda *a: steps.append(1) or real(*a))
    return steps


@pytest.mark.parametrize("min_rows", [10**9, 500])  # one block; four blocks
def test_ssor_area_solve_equals_the_direct_solution(monkeypatch, min_rows):
    monkeypatch.setattr(area, "SSOR_MIN_ROWS", min_rows)
    A, d = _kernel_system(shapes.sphere(3000).points)
    exact = spla.spsolve(sp.csc_matrix(A), np.ones(A.shape[0]))
    x, info = area.bicgstab_ssor(A.copy(), np.ones(A.shape[0]), d, rtol=1e-15, maxiter=area.SSOR_MAXITER,
                                 stall_window=area.SSOR_STALL_WINDOW)
    assert info == 0
    assert np.abs(A @ x - 1.0).max() < 1e-13
    assert np.abs(x - exact).max() < 1e-11 * np.abs(exact).max()


def test_ssor_needs_a_quarter_of_the_jacobi_iterations(monkeypatch):
    """Regression (time): about 14 iterations against 50 with the Shepard preconditioner (Fibonacci, 4000)."""
    from manifold_sph import _sparse

    steps = _count_steps(monkeypatch)
    A, d = _kernel_system(shapes.sphere(4000).points)
    with threads.limit(1):  # one call of the step kernel per iteration
        area.bicgstab_ssor(A, np.ones(A.shape[0]), d, rtol=1e-15, maxiter=60)
        n_ssor = len(steps)
        steps.clear()
        _sparse.bicgstab_csr(A, np.ones(A.shape[0]), d, d, rtol=1e-15, maxiter=150)
        n_jacobi = len(steps)
    assert n_ssor <= 20 and 3 * n_ssor < n_jacobi, (n_ssor, n_jacobi)


def test_ssor_result_does_not_depend_on_the_thread_count(monkeypatch):
    monkeypatch.setattr(area, "SSOR_MIN_ROWS", 1000)  # four blocks
    A, d = _kernel_system(shapes.sphere(6000).points)
    with threads.limit(1):
        x1, _ = area.bicgstab_ssor(A.copy(), np.ones(A.shape[0]), d, rtol=1e-15, maxiter=60)
    with threads.limit(3):
        x3, _ = area.bicgstab_ssor(A.copy(), np.ones(A.shape[0]), d, rtol=1e-15, maxiter=60)
    np.testing.assert_array_equal(x1, x3)


def test_ssor_sweep_order_is_a_permutation_of_the_unknowns(monkeypatch):
    steps = _count_steps(monkeypatch)
    c = shapes.sphere(6000)
    shuffle = np.random.default_rng(0).permutation(6000)
    p = c.points[shuffle]
    A, d = _kernel_system(p, c.normals[shuffle])
    with threads.limit(1):
        x0, info0 = area.bicgstab_ssor(A, np.ones(6000), d, rtol=1e-15, maxiter=60)
        n_given = len(steps)
        steps.clear()
        x1, info1 = area.bicgstab_ssor(A, np.ones(6000), d, rtol=1e-15, maxiter=60, order=np.argsort(p[:, 2]))
        n_sorted = len(steps)
    assert info0 == info1 == 0
    assert np.abs(x0 - x1).max() < 1e-11 * np.abs(x0).max()
    assert n_sorted < n_given  # the spiral's own order: 14 against 28 shuffled (measured)
    assert area._sweep_key(Surface(c)._xy) is None  # already sorted along z: kept
    key = area._sweep_key(Surface(p, c.normals[shuffle])._xy)
    assert key is not None and key.shape == (6000,)


def test_ssor_stops_when_it_stalls(monkeypatch):
    """Uniformly random points: the iteration stalls near 1e-4 (as with Jacobi) and stops after about
    ``SSOR_STALL_WINDOW`` iterations; the Surface then falls back exactly as before (LU when small)."""
    steps = _count_steps(monkeypatch)
    p = shapes.sphere(4000, sampling="random", seed=0).points
    A, d = _kernel_system(p)
    with threads.limit(1):
        _, info = area.bicgstab_ssor(A, np.ones(4000), d, rtol=1e-15, maxiter=area.SSOR_MAXITER,
                                     stall_window=area.SSOR_STALL_WINDOW)
    assert info > 0
    assert len(steps) <= area.SSOR_STALL_WINDOW + 10, len(steps)


def test_ssor_refuses_a_non_positive_diagonal():
    A = sp.csr_matrix(np.array([[0.0, 1.0], [1.0, 2.0]]))
    x, info = area.bicgstab_ssor(A, np.ones(2), np.ones(2), rtol=1e-15, maxiter=10)
    assert info == -12 and np.array_equal(x, np.ones(2))


@pytest.mark.parametrize("make", [lambda: shapes.sphere(3000), lambda: shapes.torus(3000)])
def test_numerical_area_elements_equal_the_jacobi_solve(monkeypatch, make):
    """The block-SSOR solve against the Shepard-preconditioned one it replaced: area elements and
    Laplacian to 1e-11 (measured 2e-13 to 2e-12 on spheres, tori, sausages and squares up to 60000)."""
    cloud = make()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        new = Surface(cloud)
        monkeypatch.setattr(area, "bicgstab_ssor", lambda A, b, x0, **k: (np.array(x0), -12))
        old = Surface(cloud)
    assert not new.area.fell_back and not old.area.fell_back
    assert np.abs(new.dV - old.dV).max() < 1e-11 * np.abs(old.dV).max()
    Ln, Lo = new.laplacian_matrix(), old.laplacian_matrix()
    assert abs(Ln - Lo).max() < 1e-10 * abs(Lo).max()


# ------------------------------------------------------------------ grid neighbour search
def _both_searches(monkeypatch, points, normals=None, **kw):
    from manifold_sph import neighbors

    monkeypatch.setattr(neighbors, "GRID_MIN_POINTS", 10**12)
    kd = neighbors.find_neighbors(points, normals, **kw)
    monkeypatch.setattr(neighbors, "GRID_MIN_POINTS", 0)
    calls = []
    real = neighbors._grid_search
    monkeypatch.setattr(neighbors, "_grid_search", lambda *a: calls.append(1) or real(*a))
    grid = neighbors.find_neighbors(points, normals, **kw)
    return kd, grid, calls


@pytest.mark.parametrize("sampling", ["fibonacci", "random"])
def test_grid_search_equals_the_kd_tree_search(monkeypatch, sampling):
    from manifold_sph.neighbors import smoothing_length_for_count

    c = shapes.sphere(20000, sampling=sampling, seed=1)
    h = smoothing_length_for_count(c.points, 27, 3.0)
    kd, grid, calls = _both_searches(monkeypatch, c.points, c.normals, h=h, support=3.0)
    assert calls
    np.testing.assert_array_equal(kd.indptr, grid.indptr)
    np.testing.assert_array_equal(kd.indices, grid.indices)  # the same order: by distance (no ties here)
    assert kd.indptr.dtype == grid.indptr.dtype and kd.indices.dtype == grid.indices.dtype
    # a per-particle h within GRID_MAX_RADIUS_RATIO
    hv = h * np.random.default_rng(0).uniform(0.8, 1.15, 20000)
    kd, grid, _ = _both_searches(monkeypatch, c.points, c.normals, h=hv, support=3.0)
    np.testing.assert_array_equal(kd.indptr, grid.indptr)
    np.testing.assert_array_equal(kd.indices, grid.indices)


def test_grid_search_normal_filter_duplicates_and_refusals(monkeypatch):
    from manifold_sph import neighbors

    rng = np.random.default_rng(2)
    sheet = np.column_stack([rng.uniform(0, 1, 3000), rng.uniform(0, 1, 3000), np.zeros(3000)])
    p = np.vstack([sheet, sheet[:1000] + [0.0, 0.0, 0.004], sheet[:5]])  # a second sheet facing down; 5 exact twins
    nrm = np.zeros_like(p)
    nrm[:, 2] = 1.0
    nrm[3000:4000, 2] = -1.0
    kd, grid, calls = _both_searches(monkeypatch, p, nrm, h=0.01, support=3.0, normal_threshold=0.2)
    assert calls and grid.n_filtered == kd.n_filtered > 0
    np.testing.assert_array_equal(kd.indptr, grid.indptr)
    for i in range(p.shape[0]):  # the same sets; each row starts with the particle itself, then by distance
        assert set(kd.neighbors_of(i)) == set(grid.neighbors_of(i))
        row = grid.neighbors_of(i)
        assert row[0] == i
        d = np.linalg.norm(p[row] - p[i], axis=1)
        assert np.all(np.diff(d[1:]) >= 0)
    # where the grid does not apply, the KD-tree runs
    r = np.full(p.shape[0], 0.03)
    assert neighbors._grid_search(p, nrm, r * np.linspace(1, 2, p.shape[0]), 0.0, -1, np.int32) is None  # h varies 2x
    blob = rng.standard_normal((6000, 3))  # a volume: columns of thousands of points
    monkeypatch.setattr(neighbors, "GRID_MAX_COLUMN", 100)
    assert neighbors._grid_search(blob, None, np.full(6000, 1.0), 0.0, -1, np.int32) is None


def test_merged_near_duplicate_system_equals_the_sparse_product(monkeypatch):
    """The merged system (representatives' rows, columns moved to their group) is built by relabelling
    the columns instead of ``A[rep] @ P``: the same matrix once repeated entries are summed, and the
    same area elements (the solve converges on the Fibonacci sphere with one near-twin)."""
    from scipy.sparse.csgraph import connected_components

    c = shapes.sphere(3000)
    p = c.points
    t = np.cross(p[0], [0.0, 0.0, 1.0])
    q = p[0] + 1e-6 * t / np.linalg.norm(t)
    P = np.vstack([p, q / np.linalg.norm(q)])
    seen = []
    real = area._solve_partition_of_unity
    monkeypatch.setattr(area, "_solve_partition_of_unity", lambda B, **k: seen.append(B) or real(B, **k))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s = Surface(P, P.copy())
    assert s.area.n_merged == 1 and not s.area.fell_back
    A = area.kernel_matrix(s.neighborhood, s._xy, s.kernel)
    close = area.near_duplicate_pairs(s.neighborhood, s._xy)
    rows = np.searchsorted(s.neighborhood.indptr, close, side="right") - 1
    n = P.shape[0]
    ncl, label = connected_components(sp.coo_matrix((np.ones(close.size), (rows, s.neighborhood.indices[close])), shape=(n, n)))
    rep = np.full(ncl, n)
    np.minimum.at(rep, label, np.arange(n))
    ref = (A[rep] @ sp.csr_matrix((np.ones(n), (np.arange(n), label)), shape=(n, ncl))).tocsr()
    merged = seen[0]
    assert isinstance(merged, area._Merged)  # read through the maps, not copied
    B = merged.csr()
    x = np.random.default_rng(0).normal(size=ncl)
    np.testing.assert_array_equal(merged @ x, B @ x)  # the copy's products and row sums, bit for bit
    np.testing.assert_array_equal(merged.row_sums(), np.asarray(B.sum(axis=1)).ravel())
    d = 1.0 / merged.row_sums()
    x1, info1 = area.bicgstab_ssor(merged, np.ones(ncl), d, rtol=1e-15, maxiter=60)
    x2, info2 = area.bicgstab_ssor(B.copy(), np.ones(ncl), d, rtol=1e-15, maxiter=60)
    assert info1 == info2 == 0
    np.testing.assert_array_equal(x1, x2)  # the solve through the maps is the solve of the copy
    B.sum_duplicates()
    assert abs(B - ref).max() <= 1e-15 * abs(ref).max()
    dVc = spla.spsolve(sp.csc_matrix(ref), np.ones(ncl))
    size = np.bincount(label)
    assert np.abs(s.dV - (dVc / size)[label]).max() < 1e-11 * np.abs(s.dV).max()


def test_ssor_split_offsets_int16_and_int32_give_the_same_solve(monkeypatch):
    """The split's columns are int16 offsets when the sweep order keeps the matrix that narrow, else int32:
    the same iteration either way (and with the order given or shuffled)."""
    monkeypatch.setattr(area, "SSOR_MIN_ROWS", 1000)  # four blocks
    c = shapes.sphere(5000)
    A, d = _kernel_system(c.points)
    shuffle = np.random.default_rng(1).permutation(5000)
    for order in (None, shuffle):
        x16, info16 = area.bicgstab_ssor(A, np.ones(5000), d, rtol=1e-15, maxiter=60, order=order)
        monkeypatch.setattr(area, "SSOR_NARROW_WIDTH", 0)
        x32, info32 = area.bicgstab_ssor(A, np.ones(5000), d, rtol=1e-15, maxiter=60, order=order)
        monkeypatch.setattr(area, "SSOR_NARROW_WIDTH", 32767)
        assert info16 == info32 == 0
        np.testing.assert_array_equal(x16, x32)


@pytest.mark.parametrize("sampling", ["fibonacci", "random"])
def test_released_kernel_matrix_gives_the_same_area_elements(monkeypatch, sampling):
    """Above LU_MAX_ROWS the solver frees the kernel matrix's entries once its split copy is built (the
    build's memory peak, issue 22). The elements, the fallback and the reported residual must be those
    of the unreleased solve: round-off (converged, Fibonacci) or identical (Shepard fallback, random)."""
    # seed=2: no near-duplicates (merged systems are never released)
    c = shapes.sphere(3000) if sampling == "fibonacci" else shapes.sphere(3000, sampling="random", seed=2)
    s = Surface(c.points, c.normals, area="shepard")
    nb, xy, kern = s.neighborhood, s.pair_offsets(), s.kernel
    A = area.kernel_matrix(nb, xy, kern)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        kept = area._numerical(A.copy(), nb, xy, None)  # 3000 rows <= LU_MAX_ROWS: nothing released
        monkeypatch.setattr(area, "LU_MAX_ROWS", 1000)
        B = A.copy()
        released = area._numerical(B, nb, xy, None)
    assert B.data.size == 0  # the entries were given up
    assert released.fell_back == (sampling == "random")
    if sampling == "random":  # stalls near 1e-4: the Shepard elements and their residual
        np.testing.assert_array_equal(released.dV, 1.0 / np.asarray(A.sum(axis=1)).ravel())
        assert released.residual == pytest.approx(np.abs(A @ released.dV - 1.0).max(), rel=1e-12)
    else:
        np.testing.assert_allclose(released.dV, kept.dV, rtol=0, atol=1e-12 * np.abs(kept.dV).max())
        assert np.abs(A @ released.dV - 1.0).max() < 1e-12
        assert released.residual == pytest.approx(np.abs(A @ released.dV - 1.0).max(), rel=1e-3, abs=1e-15)


@pytest.mark.parametrize("scheme", ["cspm", "msph", "ncsph", "msph4"])
def test_derivative_weights_on_demand_equal_the_one_pass_ones(scheme):
    """A Surface keeps the Laplacian's pair weights only; the derivatives' come from a second pass when
    first asked for (issue 22: 16 bytes a pair less). They must be the one-pass assembly's, bit for bit,
    fallbacks included (a uniformly random cloud has some)."""
    from manifold_sph import assembly

    c = shapes.sphere(4000, sampling="random", seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s = Surface(c.points, c.normals, scheme=scheme)
        assert s._ops._pair_dx is None  # not built yet
        one = assembly.assemble(s.neighborhood, s._xy, assembly.ColumnAreas(s.dV, s._columns) if s.scheme.uses_area
                                else assembly.ColumnAreas(np.ones(s.n_points), s._columns),
                                s.kernel, s.scheme, n_cols=s.n_points, max_condition=s.max_condition)
    np.testing.assert_array_equal(s._ops.pair_lap, one.pair_lap)
    np.testing.assert_array_equal(s._ops.pair_dx, one.pair_dx)
    np.testing.assert_array_equal(s._ops.pair_dy, one.pair_dy)
    f = c.points[:, 0] * c.points[:, 2]
    g = s.gradient(f).ravel()
    np.testing.assert_allclose(s.gradient_matrix() @ f, g, rtol=0, atol=1e-10 * np.abs(g).max())  # sum order
