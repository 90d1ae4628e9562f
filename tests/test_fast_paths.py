"""The fast paths agree with the plain definitions they replace.

Threaded row blocks against scipy's product, the chunked projection against the
per-pair projection, the fused quintic radial terms against the generic ones,
the k-NN-sized neighbour search against a brute-force radius search.
"""

import numpy as np
import pytest
import scipy.sparse as sp

from manifold_sph._sparse import RowBlocks
from manifold_sph.frames import project_neighborhood, project_pairs, tangent_frames
from manifold_sph.kernels import Kernel, QuinticSpline
from manifold_sph.neighbors import find_neighbors
from manifold_sph.reference import shapes


@pytest.mark.parametrize("n_blocks", [1, 2, 3, 7])
def test_row_blocks_equal_scipy(n_blocks):
    A = sp.random(997, 800, density=0.02, random_state=1, format="csr")
    x = np.random.default_rng(0).standard_normal(800)
    X = np.random.default_rng(1).standard_normal((800, 3))
    B = RowBlocks(A, n_blocks=n_blocks)
    assert len(B.blocks) == n_blocks
    assert B.bounds[0] == 0 and B.bounds[-1] == 997
    np.testing.assert_allclose(B @ x, A @ x, rtol=0, atol=1e-13)
    np.testing.assert_allclose(B @ X, A @ X, rtol=0, atol=1e-13)
    np.testing.assert_allclose(B.matvec(x), A @ x, rtol=0, atol=1e-13)


def test_row_blocks_balance_by_entries():
    # the first 10 rows hold most entries: the cut must fall there, not at row N/2
    rows = np.concatenate([np.repeat(np.arange(10), 100), np.arange(10, 1000)])
    cols = np.concatenate([np.tile(np.arange(100), 10), np.arange(10, 1000)])
    A = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(1000, 1000))
    B = RowBlocks(A, n_blocks=2)
    assert B.bounds[1] <= 10
    x = np.arange(1000.0)
    np.testing.assert_array_equal(B @ x, A @ x)


def test_row_blocks_small_matrix_one_block():
    A = sp.eye(50, format="csr")
    assert len(RowBlocks(A).blocks) == 1


def test_project_neighborhood_equals_project_pairs():
    pc = shapes.sphere(3000)
    p, n = pc.points, pc.normals
    u, v = tangent_frames(n)
    nb = find_neighbors(p, n, h=0.08)
    rows = np.repeat(np.arange(p.shape[0]), np.diff(nb.indptr))
    ref = project_pairs(p, u, v, rows, nb.indices)
    for workers in (1, -1):
        got = project_neighborhood(p, u, v, nb.indptr, nb.indices, workers=workers)
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-15)


def test_project_neighborhood_with_candidates():
    rng = np.random.default_rng(3)
    p = rng.standard_normal((40, 3))
    cand = np.vstack([p, rng.standard_normal((15, 3))])
    u, v = tangent_frames(rng.standard_normal((40, 3)))
    indptr = np.concatenate([[0], np.cumsum(rng.integers(0, 9, 40))])
    indices = rng.integers(0, 55, indptr[-1])
    rows = np.repeat(np.arange(40), np.diff(indptr))
    np.testing.assert_allclose(
        project_neighborhood(p, u, v, indptr, indices, candidates=cand),
        project_pairs(p, u, v, rows, indices, candidates=cand),
        rtol=0,
        atol=1e-14,
    )


def test_quintic_fused_radial_terms_match_generic():
    k = QuinticSpline()
    R = np.concatenate([[0.0, 1e-8, 1e-3], np.linspace(0.01, 3.5, 2001), [1.0, 2.0, 3.0]])
    w, q, t = k.radial_terms(R)
    w0, q0, t0 = Kernel.radial_terms(k, R)
    np.testing.assert_allclose(w, w0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(w, k.profile(R), rtol=0, atol=1e-12)
    np.testing.assert_allclose(q, q0, rtol=0, atol=1e-10)
    # the generic (w'' - w'/R)/R^2 cancels catastrophically near 0; compare away from it
    far = R > 0.05
    np.testing.assert_allclose(t[far], t0[far], rtol=1e-9, atol=1e-9)
    # near 0 the fused value is the exact polynomial 240 - 150 R
    near = (R > 0) & (R < 1)
    np.testing.assert_allclose(t[near], 240.0 - 150.0 * R[near], rtol=1e-14)
    assert t[0] == 0.0 and q[-1] == 0.0 and t[-1] == 0.0 and w[-1] == 0.0


def test_neighbor_search_equals_brute_force():
    pc = shapes.sphere(1500)
    p, n = pc.points, pc.normals
    h = 0.09
    nb = find_neighbors(p, n, h=h, support=3.0)
    d = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=-1)
    keep = (d < 3.0 * h) & (n @ n.T > 0.0)
    for i in range(0, 1500, 37):
        got = np.sort(nb.indices[nb.indptr[i] : nb.indptr[i + 1]])
        np.testing.assert_array_equal(got, np.flatnonzero(keep[i]))


# ----------------------------------------------------------------------------- threads
def test_one_thread_and_all_threads_build_the_same_operators():
    from manifold_sph import Surface, threads

    cloud = shapes.sphere(6000)
    f = cloud.points[:, 0] * cloud.points[:, 1] + np.cos(cloud.points[:, 2])
    with threads.limit(1):
        assert threads.get_num_threads() == 1
        s1 = Surface(cloud, scheme="cspm")
        L1 = s1.laplacian_matrix()
        y1 = s1.laplacian(f)
    with threads.limit(2):
        s2 = Surface(cloud, scheme="cspm")
        L2 = s2.laplacian_matrix()
        y2 = s2.laplacian(f)
    # chunks are independent: the same arithmetic in either case
    assert (L1 != L2).nnz == 0
    np.testing.assert_array_equal(s1.area.dV, s2.area.dV)
    np.testing.assert_allclose(y1, y2, rtol=0, atol=1e-12 * np.abs(y1).max())


def test_row_blocks_follow_the_thread_setting():
    from manifold_sph import threads

    A = sp.random(3000, 3000, density=0.03, random_state=2, format="csr")
    x = np.random.default_rng(5).standard_normal(3000)
    B = RowBlocks(A, n_blocks=2)
    with threads.limit(1):
        np.testing.assert_allclose(B @ x, A @ x, rtol=0, atol=1e-12)


def test_thread_setting_is_validated_and_restored():
    from manifold_sph import get_num_threads, set_num_threads, threads

    before = get_num_threads()
    with pytest.raises(ValueError, match="n must be at least 1, got 0"):
        set_num_threads(0)
    with pytest.raises(TypeError, match="n must be an integer, got float 2.5"):
        set_num_threads(2.5)
    with pytest.raises(TypeError, match="n must be an integer, got bool True"):
        set_num_threads(True)
    with pytest.raises(ValueError, match="workers must be at least 1, got -3"):
        threads.resolve_workers(-3)
    set_num_threads(np.int64(1))
    try:
        assert get_num_threads() == 1
    finally:
        set_num_threads(None)
    assert get_num_threads() == before
    with pytest.raises(RuntimeError):
        with threads.limit(1):
            raise RuntimeError("inside")
    assert get_num_threads() == before
    with pytest.raises(ValueError, match="n must be at least 1, got 0"):
        with threads.limit(0):
            pass
    assert get_num_threads() == before
    with pytest.raises(TypeError, match="workers must be an integer, got str"):
        threads.run_chunks(lambda c: None, 3, workers="2")
    with pytest.raises(ValueError, match="workers must be at least 1, got 0"):
        threads.run_chunks(lambda c: None, 3, workers=0)


def test_thread_environment_variable(monkeypatch):
    import importlib

    from manifold_sph import threads

    monkeypatch.setenv(threads.ENV_VAR, "1")
    assert threads._from_env() == 1
    from manifold_sph import ManifoldSPHWarning

    for bad in ("two", "0", "-3", "1.5"):  # a warning and the default: importing must never fail
        monkeypatch.setenv(threads.ENV_VAR, bad)
        with pytest.warns(ManifoldSPHWarning, match=f"MANIFOLD_SPH_NUM_THREADS must be a positive integer.*{bad!r}"):
            assert threads._from_env() is None
    monkeypatch.delenv(threads.ENV_VAR)
    assert threads._from_env() is None
    importlib.reload(threads)  # the module state is back to the default
    assert threads.get_num_threads() >= 1


def test_run_chunks_reraises():
    from manifold_sph.threads import run_chunks

    def job(c):
        if c == 2:
            raise ValueError("chunk 2")

    with pytest.raises(ValueError, match="chunk 2"):
        run_chunks(job, 5, workers=2)


def test_run_chunks_runs_every_chunk_once_and_nested_calls_serially():
    import threading

    from manifold_sph.threads import in_chunk, run_chunks

    seen = []
    lock = threading.Lock()
    inner = {}

    def job(c):
        assert in_chunk()
        sub = []
        run_chunks(lambda k: sub.append(k), 3, workers=2)  # nested: serial, in order, no deadlock
        inner[c] = sub
        with lock:
            seen.append(c)

    run_chunks(job, 40, workers=2)
    assert sorted(seen) == list(range(40))
    assert all(v == [0, 1, 2] for v in inner.values())
    assert not in_chunk()  # the caller's flag is restored


def test_thread_pool_is_renewed_in_a_forked_child():
    import multiprocessing as mp

    from manifold_sph.threads import run_chunks

    run_chunks(lambda c: None, 4, workers=2)  # the parent's pool exists
    ctx = mp.get_context("fork")
    with ctx.Pool(1) as pool:
        out = pool.apply_async(_square_chunks).get(timeout=60)  # a dead inherited pool would hang here
    assert out == [0, 1, 4, 9]


def _square_chunks():
    from manifold_sph.threads import run_chunks

    out = [None] * 4

    def job(c):
        out[c] = c * c

    run_chunks(job, 4, workers=2)
    return out


@pytest.mark.parametrize("scheme", ["cspm", "msph", "ncsph", "msph4"])
def test_chunk_size_does_not_change_the_operators(monkeypatch, scheme):
    import manifold_sph.assembly as assembly
    from manifold_sph import Surface

    cloud = shapes.torus(3000)  # irregular counts: chunks pad to different widths
    ref = Surface(cloud, scheme=scheme, area="shepard").laplacian_matrix()
    monkeypatch.setattr(assembly, "CHUNK_ROWS", 97)
    got = Surface(cloud, scheme=scheme, area="shepard").laplacian_matrix()
    diff = abs(ref - got).max()
    assert diff <= 1e-12 * abs(ref).max(), diff


def test_radius_knn_asks_again_for_dense_rows(monkeypatch):
    # a dense clump the strided probe misses: its rows come back full, are asked again,
    # and every neighbour inside the radius is found (the arrays widen only as needed)
    import manifold_sph.neighbors as nbm

    rng = np.random.default_rng(11)
    base = rng.random((20000, 3)) * [1.0, 1.0, 0.0]
    clump = base[7] + rng.normal(scale=0.002, size=(60, 3)) * [1.0, 1.0, 0.0]
    pts = np.vstack([base, clump])
    tree = nbm.build_tree(pts)
    radii = np.full(pts.shape[0], 0.02)
    calls = []
    knn = nbm._knn
    monkeypatch.setattr(nbm, "_knn", lambda *a: calls.append(a[2]) or knn(*a))
    groups = nbm._radius_knn(tree, pts, radii, -1)
    assert len(calls) >= 3  # probe, everyone, the full rows again
    _, dist, idx = groups[0]
    counts = (dist < radii[:, None]).sum(axis=1)
    for rows, d, _ in groups[1:]:  # the rows asked again replace the first group's
        counts[rows] = (d < radii[rows, None]).sum(axis=1)
        assert d.shape[1] <= (d < radii[rows, None]).sum(axis=1).max() + 1 or d.shape[1] == calls[-1]
    ref = tree.query_ball_point(pts, 0.02, return_length=True)
    np.testing.assert_array_equal(counts, ref)
    assert dist.shape[1] < ref.max()  # the first group is not widened to the clump's rows


def test_build_tree_rejects_bad_points():
    from manifold_sph.neighbors import build_tree

    with pytest.raises(ValueError, match="points must be finite"):
        build_tree(np.array([[0.0, 0.0, 0.0], [1.0, np.nan, 0.0]]))
    with pytest.raises(ValueError, match=r"points must have shape \(N, 1\) or \(N, 2\) or \(N, 3\), got shape \(4, 5\)"):
        build_tree(np.zeros((4, 5)))
    with pytest.raises(TypeError, match="points must be a numeric array"):
        build_tree("abc")
    assert build_tree(np.eye(3)).n == 3


def test_thread_pool_size_is_validated():
    from manifold_sph.threads import pool

    for bad in (0, -2, 1.5, "2"):
        with pytest.raises((ValueError, TypeError), match="size"):
            pool(bad)
    assert pool(1) is pool(1)  # one pool, kept between calls
