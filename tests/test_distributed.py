"""TiledSurface: tiled builds equal the single-process Surface (docs/distributed.md)."""

import numpy as np
import pytest

pytest.importorskip("dask")
pytest.importorskip("distributed")

from manifold_sph import Surface, pde  # noqa: E402
from manifold_sph.distributed import TileBuildError, TiledSurface  # noqa: E402
from manifold_sph.exceptions import ManifoldSPHWarning
from manifold_sph.reference import shapes

RTOL = 1e-12


def rel(a, b):
    return float(np.abs(np.asarray(a) - np.asarray(b)).max() / max(np.abs(np.asarray(b)).max(), 1e-300))


@pytest.fixture(scope="module")
def cloud():
    return shapes.sphere(2000)


def fields(x):
    f = np.cos(x[:, 0] * x[:, 2] - np.sin(x[:, 1]))
    F = np.c_[x[:, 1] * f, -x[:, 0], x[:, 2] ** 2]
    return f, F


def check_equal(ts, s, x):
    f, F = fields(x)
    assert rel(ts.gather(ts.laplacian(f)), s.laplacian(f)) < RTOL
    assert rel(ts.gather(ts.gradient(f)), s.gradient(f)) < RTOL
    assert rel(ts.gather(ts.divergence(F)), s.divergence(F)) < RTOL
    assert rel(ts.gather(ts.normals), s.normals) < RTOL
    assert rel(ts.gather(ts.mean_curvature()), s.mean_curvature()) < RTOL
    assert rel(ts.gather(ts.dV), s.dV) < RTOL


@pytest.fixture(scope="module")
def given(cloud):
    ts = TiledSurface(cloud.points, cloud.normals, tile_points=500, scheduler="synchronous")
    yield ts
    ts.close()


def test_given_normals_equal_single_process(given, cloud):
    s = Surface(cloud.points, cloud.normals, area="shepard")
    assert len(given.chunks) == 4 and sum(given.chunks) == 2000
    check_equal(given, s, cloud.points)
    assert abs(given.laplacian_matrix() - s.laplacian_matrix()).max() <= RTOL * abs(s.laplacian_matrix()).max()
    Dx, Dy = given.derivative_matrices()
    assert abs(Dx - s.derivative_matrices()[0]).max() <= RTOL * abs(Dx).max()


def test_estimated_normals_equal_and_oriented_across_tiles(cloud):
    x = cloud.points
    with TiledSurface(x, tile_points=500, scheduler="synchronous") as ts:
        s = Surface(x, area="shepard")
        check_equal(ts, s, x)
        n = ts.gather(ts.normals)
        assert np.all(np.einsum("ij,ij->i", n, x) > 0.99)  # outward in every tile
        assert np.all(ts.gather(ts.mean_curvature()) > 0.9)


def test_estimated_normals_stitched_when_tiles_disagree(cloud):
    """Flip one tile's estimated normals before stitching: the overlaps bring it back."""
    x = cloud.points
    with TiledSurface(x, tile_points=500, scheduler="synchronous") as ts:
        assert set(np.unique(ts.tile_sign)) <= {-1.0, 1.0}
        signs = ts.tile_sign.copy()
        n = ts.gather(ts.normals)
    assert np.all(np.einsum("ij,ij->i", n, x) > 0)
    assert signs.size == 4


def test_thin_and_empty_tiles(cloud):
    """A regular grid: 3 x 3 x 3 cells leave the sphere's centre cell empty (dropped), 12 slabs are thinner than the support."""
    x = cloud.points
    s = Surface(x, cloud.normals, area="shepard")
    with TiledSurface(x, cloud.normals, grid=(3, 3, 3), scheduler="synchronous") as ts:
        assert 0 not in ts.chunks and len(ts.chunks) <= 26
        check_equal(ts, s, x)
    with TiledSurface(x, cloud.normals, grid=(12, 1, 1), scheduler="synchronous") as ts:
        width = 2.0 / 12
        assert width < 3 * float(np.median(s.h))  # thinner than the kernel support
        f, _ = fields(x)
        assert rel(ts.gather(ts.laplacian(f)), s.laplacian(f)) < RTOL


def test_narrow_halo_is_widened(cloud):
    x = cloud.points
    s = Surface(x, cloud.normals, area="shepard", h="adaptive", scheme="cspm")
    with TiledSurface(x, cloud.normals, tile_points=500, halo=0.05, scheduler="synchronous", h="adaptive", scheme="cspm") as ts:
        assert max(r["attempts"] for r in ts.report) > 1
        f, _ = fields(x)
        assert rel(ts.gather(ts.laplacian(f)), s.laplacian(f)) < RTOL
        assert rel(ts.gather(ts.h), s.h) < RTOL


def test_heat_explicit_and_outputs(given, cloud, tmp_path):
    x = cloud.points
    s = Surface(x, cloud.normals, area="shepard")
    u0 = np.exp(-10 * ((x - [0, 0, 1]) ** 2).sum(axis=1))
    ref = pde.heat(s, u0, dt=1e-4, steps=5, method="explicit", laplacian="strong").u
    assert rel(given.gather(given.heat(u0, 1e-4, 5)), ref) < RTOL
    with pytest.raises(ValueError, match="explicit heat limit"):
        given.heat(u0, 1.0, 1)
    v0 = x[:, 2]
    ref = pde.wave(s, u0, dt=1e-3, steps=6, c=0.5, v0=v0, laplacian="strong").u
    assert rel(given.gather(given.wave(u0, 1e-3, 6, c=0.5, v0=v0)), ref) < RTOL
    with pytest.raises(ValueError, match="wave limit"):
        given.wave(u0, 1.0, 2)
    lap = given.laplacian(lambda p: p[:, 0] * p[:, 1])  # a callable field, evaluated tile by tile
    given.to_npy(lap, tmp_path / "lap.npy")
    assert rel(np.load(tmp_path / "lap.npy"), s.laplacian(x[:, 0] * x[:, 1])) < RTOL
    given.to_zarr(given.normals, str(tmp_path / "n.zarr"))
    import zarr

    z = zarr.open(str(tmp_path / "n.zarr"), mode="r")[:]
    assert z.shape == (2000, 3) and rel(z, s.normals[given.order]) < RTOL


def test_npy_source_and_cache_reuse(cloud, tmp_path):
    np.save(tmp_path / "p.npy", cloud.points)
    np.save(tmp_path / "n.npy", cloud.normals)
    cache = tmp_path / "cache"
    with pytest.raises(TileBuildError) as err:
        TiledSurface(str(tmp_path / "p.npy"), str(tmp_path / "n.npy"), tile_points=500, scheduler="synchronous",
                     cache_dir=cache, _fail_tiles={2})
    msg = str(err.value)
    assert "1 of 4 tile(s) failed" in msg and "tile 2 (bounding box" in msg and str(cache) in msg
    assert [f[0] for f in err.value.failures] == [2]
    ts = TiledSurface(str(tmp_path / "p.npy"), str(tmp_path / "n.npy"), tile_points=500, scheduler="synchronous", cache_dir=cache)
    reused = [bool(r.get("reused")) for r in ts.report]
    assert reused.count(True) == 3 and not reused[2]
    s = Surface(cloud.points, cloud.normals, area="shepard")
    f, _ = fields(cloud.points)
    assert rel(ts.gather(ts.laplacian(f)), s.laplacian(f)) < RTOL
    ts.close()
    assert cache.exists()  # a cache directory given by the user is kept


def test_las_source(cloud, tmp_path):
    laspy = pytest.importorskip("laspy")
    header = laspy.LasHeader(point_format=0, version="1.2")
    header.scales = np.array([1e-7, 1e-7, 1e-7])
    header.offsets = np.zeros(3)
    las = laspy.LasData(header)
    las.x, las.y, las.z = cloud.points.T
    las.write(str(tmp_path / "s.las"))
    back = laspy.read(str(tmp_path / "s.las"))
    pts = np.c_[back.x, back.y, back.z]
    s = Surface(pts, cloud.normals, area="shepard")
    with TiledSurface(str(tmp_path / "s.las"), cloud.normals, tile_points=1000, scheduler="synchronous") as ts:
        f, _ = fields(pts)
        assert rel(ts.gather(ts.points), pts) == 0
        assert rel(ts.gather(ts.laplacian(f)), s.laplacian(f)) < RTOL


def test_failing_tile_reported(cloud):
    pts = cloud.points.copy()
    pts[7] = pts[8]  # a duplicate point: the tile holding it (and its neighbours' halos) cannot build
    with pytest.raises(TileBuildError, match=r"tile \d+ \(bounding box .*points must be distinct"):
        TiledSurface(pts, cloud.normals, tile_points=500, scheduler="synchronous")


def test_local_cluster_two_processes(cloud):
    x = cloud.points
    s = Surface(x, cloud.normals, area="shepard", scheme="cspm")
    with TiledSurface(x, cloud.normals, tile_points=500, scheme="cspm", n_workers=2) as ts:
        assert len(ts.client.scheduler_info()["workers"]) == 2
        f, F = fields(x)
        lap, grad = ts.compute(ts.laplacian(f)), ts.compute(ts.gradient(f))
        assert rel(lap[np.argsort(ts.order)], s.laplacian(f)) < RTOL
        assert rel(grad[np.argsort(ts.order)], s.gradient(f)) < RTOL


@pytest.mark.parametrize(
    "kwargs, exc, match",
    [
        ({"area": "numerical"}, ValueError, "area='shepard'"),
        ({"area": "voronoi"}, ValueError, "area must be one of"),
        ({"area": "geometric"}, ValueError, "total_area"),
        ({"tile_points": 0}, ValueError, "tile_points"),
        ({"tile_points": 2.5}, TypeError, "tile_points"),
        ({"scheduler": "mpi"}, ValueError, "scheduler"),
        ({"grid": (2, 0, 1)}, ValueError, "grid"),
        ({"halo": -1.0}, ValueError, "halo"),
        ({"h": "wide"}, ValueError, "h must be"),
        ({"neighbors": 2.0}, TypeError, "neighbors"),
        ({"colour": 1}, TypeError, "colour"),
        ({"client": "tcp://x"}, TypeError, "client"),
        ({"progress": "yes"}, TypeError, "progress"),
        ({"normal_options": {"radius": 1}}, TypeError, "normal_options"),
        ({"scheme": "fem"}, ValueError, "scheme"),
    ],
)
def test_bad_arguments(cloud, kwargs, exc, match):
    kwargs = {"scheduler": "synchronous"} | kwargs
    with pytest.raises(exc, match=match):
        TiledSurface(cloud.points, cloud.normals, **kwargs)


def test_bad_sources(cloud, tmp_path):
    with pytest.raises(ValueError, match="source"):
        TiledSurface(np.zeros((5, 2)), scheduler="synchronous")
    with pytest.raises(ValueError, match="normals"):
        TiledSurface(cloud.points, cloud.normals[:10], scheduler="synchronous")
    with pytest.raises(FileNotFoundError, match="source"):
        TiledSurface(str(tmp_path / "missing.npy"), scheduler="synchronous")


def test_progress_bar(given, cloud, capsys):
    with TiledSurface(cloud.points, cloud.normals, tile_points=1000, scheduler="synchronous", progress=True):
        pass
    assert "Completed" in capsys.readouterr().out


def test_bad_fields(given):
    with pytest.raises(ValueError, match="field"):
        given.laplacian(np.zeros(7))
    with pytest.raises(ValueError, match="field"):
        given.divergence(np.zeros((2000, 2)))
    with pytest.raises(ValueError, match="method"):
        given.mean_curvature("cotan")


def test_widened_rows_spliced_equal_a_full_search():
    """A tile's rim (or a scan's strays) widens a few supports: only those rows are searched again."""
    from manifold_sph.neighbors import find_neighbors

    c = shapes.sphere(40000, sampling="random", seed=1)
    keep = np.abs(c.points[:, 0]) < 0.5  # a slab: particles on its two rims have half neighbourhoods
    stray = np.array([[0.3, 0.0, 1.1], [0.0, 0.4, -1.08]])
    p = np.vstack([c.points[keep], stray])
    q = np.vstack([c.normals[keep], stray / np.linalg.norm(stray, axis=1)[:, None]])
    with pytest.warns(RuntimeWarning, match="wider supports"):
        s = Surface(p, q, area="shepard", h=0.017)
    assert s.widened.size >= 2
    nb = s.neighborhood
    full = find_neighbors(p, s.normals, h=nb.h, support=nb.support, normal_threshold=0.0)
    assert np.array_equal(full.indptr, nb.indptr) and np.array_equal(full.indices, nb.indices)
    assert full.n_filtered == nb.n_filtered


# ------------------------------------------------------------------ stable rows and the global solves
@pytest.fixture(scope="module")
def stable(cloud):
    ts = TiledSurface(cloud.points, cloud.normals, tile_points=500, scheduler="synchronous",
                      keep=("stable", "derivatives"))
    yield ts
    ts.close()


@pytest.fixture(scope="module")
def single(cloud):
    return Surface(cloud.points, cloud.normals, area="shepard")


def test_stable_rows_bit_equal(stable, single):
    K, M = stable.stiffness_matrix(), stable.mass_matrix()
    assert (K != single.stiffness_matrix()).nnz == 0
    assert np.array_equal(M.diagonal(), single.mass_matrix().diagonal())
    with pytest.raises(ValueError, match="laplacian"):
        stable.laplacian(np.ones(2000))


def test_stable_rows_bit_equal_on_random_points():
    c = shapes.sphere(2500, sampling="random", seed=2)
    s = Surface(c.points, c.normals, area="shepard")
    with TiledSurface(c.points, c.normals, tile_points=700, scheduler="synchronous", keep=("stable",)) as ts:
        assert (ts.stiffness_matrix() != s.stiffness_matrix()).nnz == 0
        assert np.array_equal(ts.mass_matrix().diagonal(), s.mass_matrix().diagonal())
        assert rel(ts.gather(ts.dV), s.dV) == 0


def test_local_engine_equals_single_process(stable, single, cloud):
    x = cloud.points
    u0 = np.exp(-10 * ((x - [0, 0, 1]) ** 2).sum(axis=1))
    ref = pde.heat(single, u0, dt=1e-3, steps=3, method="implicit", laplacian="stable").u
    u = stable.gather(stable.heat(u0, 1e-3, 3, method="implicit", engine="local"))
    assert rel(u, ref) < 1e-10
    assert stable.last_solve["engine"] == "local" and stable.last_solve["ranks"] == 1
    # Poisson: K u = M (f - mean f), zero mean; the l = 1 harmonic z: -Lap z = 2 z
    K, m = single.stiffness_matrix(), single.mass_matrix().diagonal()
    u = stable.gather(stable.poisson(x[:, 2], engine="local"))
    assert abs(np.dot(m, u)) < 1e-12
    assert rel(K @ u, m * (x[:, 2] - np.dot(m, x[:, 2]) / m.sum())) < 1e-9
    assert rel(u, x[:, 2] / 2) < 2e-2
    d = stable.gather(stable.geodesic_distance(7, engine="local"))
    exact = np.arccos(np.clip(x @ x[7], -1, 1))
    assert d[7] == 0 and np.linalg.norm(d - exact) / np.linalg.norm(exact) < 1e-2
    lam, V = stable.eigs(4, engine="local")
    np.testing.assert_allclose(lam, single.eigs(4).values, rtol=1e-9, atol=1e-12)
    assert V.shape == (2000, 4)


def test_driver_results_are_gathered_on_the_driver(cloud):
    """A global solve's result is already on the driver: gathering it does not send it through the cluster
    (whose client warns about graphs above 10 MB, 1.3M points of float64), and equals the synchronous one."""
    x = cloud.points
    with TiledSurface(x, cloud.normals, tile_points=700, n_workers=1, keep=("stable",)) as ts:
        sent = []
        compute = ts.client.compute
        ts.client.compute = lambda *a, **k: sent.append(a) or compute(*a, **k)
        u = ts.gather(ts.poisson(x[:, 2], engine="local"))
        assert not sent
        lap = ts.compute(ts.field(x[:, 2]) * 2.0)  # anything else still runs on the cluster
        assert len(sent) == 1 and np.array_equal(lap, 2.0 * x[ts.order, 2])
    with TiledSurface(x, cloud.normals, tile_points=700, scheduler="synchronous", keep=("stable",)) as sync:
        assert np.array_equal(u, sync.gather(sync.poisson(x[:, 2], engine="local")))


def test_global_solves_need_the_stable_rows(given):
    with pytest.raises(ValueError, match="keep=.*'stable'"):
        given.poisson(np.ones(2000), engine="local")
    with pytest.raises(ValueError, match="engine"):
        given.poisson(np.ones(2000), engine="petsc")


mpi_engine = pytest.mark.skipif(
    __import__("manifold_sph.distributed.solve", fromlist=["x"]).engine_available() is not None,
    reason="the MPI engine (mpi4py, petsc4py, slepc4py, mpirun) is not installed",
)


def global_solve(ts, problem, x, engine, ranks):
    """One global solve of the MPI tests, in tile order (eigs: the values)."""
    if problem == "heat":
        u0 = np.exp(-10 * ((x - [0, 0, 1]) ** 2).sum(axis=1))
        return ts.gather(ts.heat(u0, 1e-3, 2, method="implicit", engine=engine, ranks=ranks))
    if problem == "poisson":
        return ts.gather(ts.poisson(x[:, 2], engine=engine, ranks=ranks))
    if problem == "geodesic":
        return ts.gather(ts.geodesic_distance([3, 1500], engine=engine, ranks=ranks))
    return ts.eigs(6, engine=engine, ranks=ranks)[0]


@mpi_engine
@pytest.mark.parametrize("problem", ["heat", "poisson", "geodesic"])
def test_mpi_engine_two_ranks_equals_local(stable, cloud, problem):
    # CG + GAMG to a relative residual of 1e-12 (geodesic heat step: MUMPS Cholesky); measured 5e-13 to 1e-11
    loc = global_solve(stable, problem, cloud.points, "local", 1)
    got = global_solve(stable, problem, cloud.points, "mpi", 2)
    assert stable.last_solve["engine"] == "mpi" and stable.last_solve["ranks"] == 2
    assert stable.last_solve["peak_gb_per_rank"] > 0
    assert rel(got, loc) < 1e-8


@mpi_engine
@pytest.mark.parametrize("direct", [True, False])
def test_mpi_engine_eigenpairs_two_ranks(stable, monkeypatch, direct):
    """Shift-invert on one MUMPS factor (up to EIGS_DIRECT_MAX_N particles) or by multigrid CG (above)."""
    import manifold_sph.distributed.solve as S

    if not direct:
        monkeypatch.setattr(S, "EIGS_DIRECT_MAX_N", 10)
    lam, _ = stable.eigs(6, engine="local")
    lam2, V = stable.eigs(6, engine="mpi", ranks=2)
    assert stable.last_solve["engine"] == "mpi" and stable.last_solve["ranks"] == 2
    assert ("mumps" in stable.last_solve["method"]) == direct, stable.last_solve["method"]
    np.testing.assert_allclose(lam2, lam, rtol=1e-8, atol=1e-10)  # lambda_0 = 0: atol
    V = np.asarray(V)
    K, m = stable.stiffness_matrix("tile"), stable.mass_matrix("tile").diagonal()
    assert np.abs(V.T @ (m[:, None] * V) - np.eye(6)).max() < 1e-8  # M-orthonormal
    res = np.linalg.norm(K @ V - m[:, None] * V * lam2, axis=0) / np.linalg.norm(m[:, None] * V, axis=0)
    assert res.max() < 1e-8 * max(lam2.max(), 1.0)


@mpi_engine
def test_mpi_engine_geodesic_far_from_the_sources():
    # at 20,000 points the heat step's solution spans ~1e-27 across the sphere: a CG heat step to a relative
    # residual of 1e-12 loses the far field (PETSC_OPTIONS="-ksp_type cg -pc_type gamg" gives 0.40 here)
    c = shapes.sphere(20000)
    with TiledSurface(c.points, c.normals, tile_points=5000, scheduler="synchronous",
                      keep=("stable", "derivatives")) as ts:
        loc = ts.gather(ts.geodesic_distance(11, engine="local"))
        got = ts.gather(ts.geodesic_distance(11, engine="mpi", ranks=2))
        x = ts.gather(ts.points)
    assert rel(got, loc) < 1e-8
    exact = np.arccos(np.clip(x @ x[np.argmin(loc)], -1, 1))
    assert rel(got, exact) < 1e-2


@mpi_engine
def test_mpi_engine_iterations_independent_of_ranks(stable, cloud):
    # the same Krylov iterations on 1 and 2 ranks, to within 10 % (GAMG's aggregates follow the partition:
    # measured equal here, Poisson 25 against 24 at 100,000 points)
    for problem in ("heat", "poisson", "geodesic", "eigs"):
        a = global_solve(stable, problem, cloud.points, "mpi", 1)
        its1 = stable.last_solve["iterations"]
        b = global_solve(stable, problem, cloud.points, "mpi", 2)
        its2 = stable.last_solve["iterations"]
        assert len(its1) == len(its2) and all(abs(i - j) <= max(1, 0.1 * i) for i, j in zip(its1, its2)), (problem, its1, its2)
        assert rel(b, a) < 1e-8


@mpi_engine
def test_mpi_engine_banded_geodesic(monkeypatch):
    """Above GEODESIC_DIRECT_MAX_N both engines solve the geodesic's heat step in AMG-CG bands (no factor): they
    agree with each other and with the exact distance as the direct solve does."""
    import manifold_sph.distributed.solve as S

    c = shapes.sphere(20000)
    with TiledSurface(c.points, c.normals, tile_points=5000, scheduler="synchronous",
                      keep=("stable", "derivatives")) as ts:
        x = ts.gather(ts.points)
        direct = ts.gather(ts.geodesic_distance(11, engine="local"))
        monkeypatch.setattr(S, "GEODESIC_DIRECT_MAX_N", 1000)
        loc = ts.gather(ts.geodesic_distance(11, engine="local"))
        assert ts.last_solve["method"].startswith("jacobi-cg windows") and len(ts.last_solve["iterations"]) >= 4
        got = ts.gather(ts.geodesic_distance(11, engine="mpi", ranks=2))
        assert len(ts.last_solve["iterations"]) >= 4  # bands, then the Poisson solve
    exact = np.arccos(np.clip(x @ x[np.argmin(direct)], -1, 1))
    e_direct = np.linalg.norm(direct - exact) / np.linalg.norm(exact)
    for d in (loc, got):
        assert np.linalg.norm(d - exact) / np.linalg.norm(exact) < 1.1 * e_direct
    assert rel(got, loc) < 1e-4


def _two_spheres():
    a, b = shapes.sphere(1500), shapes.sphere(1500)
    return np.r_[a.points, b.points + [5.0, 0.0, 0.0]], np.r_[a.normals, b.normals]


@pytest.mark.parametrize("bands", [False, True])
def test_geodesic_on_a_cloud_of_two_pieces(monkeypatch, bands):
    """The piece without a source gets inf and a warning (as GeodesicSolver); the other piece its distances."""
    import manifold_sph.distributed.solve as S

    if bands:
        monkeypatch.setattr(S, "GEODESIC_DIRECT_MAX_N", 10)
    P, N = _two_spheres()
    with TiledSurface(P, N, tile_points=1000, scheduler="synchronous", keep=("stable", "derivatives")) as ts:
        with pytest.warns(ManifoldSPHWarning, match="1500 particle"):
            d = ts.gather(ts.geodesic_distance(0, engine="local"))
        assert ts.last_solve["unreached"] == 1500
    assert np.all(np.isinf(d[1500:]))
    exact = np.arccos(np.clip(P[:1500] @ P[0], -1, 1))
    assert np.linalg.norm(d[:1500] - exact) / np.linalg.norm(exact) < 1e-2


@mpi_engine
def test_mpi_engine_geodesic_on_a_cloud_of_two_pieces():
    P, N = _two_spheres()
    with TiledSurface(P, N, tile_points=1000, scheduler="synchronous", keep=("stable", "derivatives")) as ts:
        with pytest.warns(ManifoldSPHWarning):
            loc = ts.gather(ts.geodesic_distance(0, engine="local"))
        with pytest.warns(ManifoldSPHWarning, match="1500 particle"):
            got = ts.gather(ts.geodesic_distance(0, engine="mpi", ranks=2))
        assert ts.last_solve["unreached"] == 1500
    assert np.all(np.isinf(got[1500:])) and rel(got[:1500], loc[:1500]) < 1e-8


def test_local_poisson_on_a_cloud_of_two_pieces():
    """Zero mean on every piece, one value held a piece: -Lap u = z on two unit spheres gives u = z / 2 on each
    (the whole cloud's single constant null space made the factorisation fail)."""
    P, N = _two_spheres()
    with TiledSurface(P, N, tile_points=1000, scheduler="synchronous", keep=("stable",)) as ts:
        u = ts.gather(ts.poisson(P[:, 2], engine="local"))
        assert ts.last_solve["pieces"] == 2
    for sl in (slice(0, 1500), slice(1500, 3000)):
        assert abs(u[sl].mean()) < 1e-2 * np.abs(u[sl]).max()
        assert rel(u[sl], P[sl, 2] / 2) < 2e-2


def test_piece_labels_equal_the_components_of_the_whole_matrix():
    """Read tile by tile, the pieces are the connected components of the assembled K (three pieces cut across
    six tiles, one of them a single isolated particle's own piece)."""
    from scipy.sparse.csgraph import connected_components

    from manifold_sph.distributed.solve import piece_labels

    a, b, c = shapes.sphere(1500), shapes.sphere(900), shapes.sphere(600)
    P = np.r_[a.points, b.points * 0.7 + [3.0, 0.0, 0.0], c.points * 0.5 + [0.0, 3.0, 0.0]]
    N = np.r_[a.normals, b.normals, c.normals]
    with TiledSurface(P, N, tile_points=500, scheduler="synchronous", keep=("stable",)) as ts:
        assert len(ts.chunks) >= 6
        pieces, labels = piece_labels(ts)
        ref_count, ref = connected_components(ts.stiffness_matrix("tile"), directed=False)
    assert pieces == ref_count == 3
    # the same partition: each label of one maps to exactly one label of the other
    pairs = np.unique(np.c_[labels, ref], axis=0)
    assert len(pairs) == 3 and len(np.unique(pairs[:, 0])) == 3 and len(np.unique(pairs[:, 1])) == 3


@mpi_engine
def test_mpi_engine_poisson_on_a_cloud_of_two_pieces():
    """As the local engine: zero mean and u = z / 2 on each of two unit spheres, equal to it to 1e-8 (with the one
    constant null space of a connected cloud, CG did not converge here)."""
    P, N = _two_spheres()
    with TiledSurface(P, N, tile_points=1000, scheduler="synchronous", keep=("stable",)) as ts:
        loc = ts.gather(ts.poisson(P[:, 2], engine="local"))
        got = ts.gather(ts.poisson(P[:, 2], engine="mpi", ranks=2))
        assert ts.last_solve["engine"] == "mpi" and ts.last_solve["pieces"] == 2
    assert rel(got, loc) < 1e-8
    for sl in (slice(0, 1500), slice(1500, 3000)):
        assert abs(got[sl].mean()) < 1e-2 * np.abs(got[sl]).max()
        assert rel(got[sl], P[sl, 2] / 2) < 2e-2


@mpi_engine
def test_mpi_engine_geodesic_rhs_in_blocks_of_rows(monkeypatch):
    """The geodesic's right-hand side formed one row at a time (blocks of one row: every block but the first starts
    inside a tile) equals the local engine's to 1e-8 (a diagonal test relative to the block, not the tile, dropped the
    entries of the rows next to each tile's first particle)."""
    import manifold_sph.distributed.solve as S

    real = S.job_description
    monkeypatch.setattr(S, "job_description", lambda ts: real(ts) | {"block_rows": 1})
    c = shapes.sphere(3000)
    with TiledSurface(c.points, c.normals, tile_points=1000, scheduler="synchronous",
                      keep=("stable", "derivatives")) as ts:
        loc = ts.gather(ts.geodesic_distance(5, engine="local"))
        got = ts.gather(ts.geodesic_distance(5, engine="mpi", ranks=2))
    assert rel(got, loc) < 1e-8


DASK_MPI_SCRIPT = '''
"""mpirun -n 4 python SCRIPT OUT: a Dask cluster from dask_mpi (scheduler, this client, two workers), the tiles
built on it, then the global solves on the workers' own MPI ranks (engine "auto" and "dask-mpi") and locally."""
import json, sys
import numpy as np
from dask_mpi import initialize

initialize(nthreads=1, dashboard=False, memory_limit=0)
from dask.distributed import Client
from manifold_sph.distributed import TiledSurface
from manifold_sph.reference import shapes

client = Client()
client.wait_for_workers(2)
cloud = shapes.sphere(2000)
x = cloud.points
u0 = np.exp(-10 * ((x - [0, 0, 1]) ** 2).sum(axis=1))
out = {}
with TiledSurface(x, cloud.normals, tile_points=600, client=client, keep=("stable", "derivatives")) as ts:
    for engine in ("auto", "dask-mpi", "local"):
        heat = ts.gather(ts.heat(u0, 1e-3, 2, method="implicit", engine=engine))
        info = dict(ts.last_solve)
        poisson = ts.gather(ts.poisson(x[:, 2], engine=engine))
        geodesic = ts.gather(ts.geodesic_distance([3, 1500], engine=engine))
        lam = ts.eigs(6, engine=engine)[0]
        out[engine] = {"heat": heat.tolist(), "poisson": poisson.tolist(), "geodesic": geodesic.tolist(),
                       "eigs": np.asarray(lam).tolist(), "engine": info["engine"], "ranks": info["ranks"]}
    try:
        ts.poisson(x[:, 2], engine="dask-mpi", ranks=3)
    except ValueError as e:
        out["too_many_ranks"] = str(e)
client.close()
with open(sys.argv[1], "w") as f:
    json.dump(out, f)
'''

dask_mpi = pytest.mark.skipif(__import__("importlib.util").util.find_spec("dask_mpi") is None,
                              reason="dask-mpi (the mpi extra) is not installed")


@mpi_engine
@dask_mpi
def test_dask_mpi_engine_on_the_workers_ranks(tmp_path):
    """Under mpirun, a cluster from dask_mpi.initialize: the global solves run on its two workers' ranks
    (chosen by "auto") and equal the local engine (CG + multigrid to 1e-12; MUMPS; SLEPc)."""
    import json
    import os
    import shutil
    import subprocess
    import sys

    script, out = tmp_path / "run.py", tmp_path / "out.json"
    script.write_text(DASK_MPI_SCRIPT)
    launcher = shutil.which("mpirun") or shutil.which("mpiexec")
    env = dict(os.environ, OMPI_MCA_rmaps_base_oversubscribe="1", OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    cmd = [launcher, "-n", "4", "--oversubscribe", sys.executable, str(script), str(out)]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=600, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    res = json.loads(out.read_text())
    for engine in ("auto", "dask-mpi"):
        assert res[engine]["engine"] == "dask-mpi" and res[engine]["ranks"] == 2
        for name in ("heat", "poisson", "geodesic"):
            assert rel(np.array(res[engine][name]), np.array(res["local"][name])) < 1e-8, (engine, name)
        np.testing.assert_allclose(res[engine]["eigs"], res["local"]["eigs"], rtol=1e-8, atol=1e-10)
    assert res["local"]["engine"] == "local"
    assert "ranks" in res["too_many_ranks"] and "2 worker" in res["too_many_ranks"]


def test_dask_mpi_engine_refused_without_mpi_workers(stable):
    """A LocalCluster's workers are not MPI ranks: engine="dask-mpi" says so; "auto" does not pick it."""
    from manifold_sph.distributed.solve import dask_mpi_workers

    assert dask_mpi_workers(stable.client) is None
    with pytest.raises(ValueError, match="dask_mpi.initialize"):
        stable.poisson(np.ones(2000), engine="dask-mpi")
