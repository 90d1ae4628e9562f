"""The fast paths agree with the plain definitions they replace.

Threaded row blocks against scipy's product, the chunked projection against the
per-pair projection, the fused quintic radial terms against the generic ones,
the k-NN-sized neighbour search against a brute-force radius search.
"""

import numpy as np
import pytest
import scipy.sparse as sp

from manifold_sph import shapes
from manifold_sph._sparse import RowBlocks
from manifold_sph.frames import project_neighborhood, project_pairs, tangent_frames
from manifold_sph.kernels import Kernel, QuinticSpline
from manifold_sph.neighbors import find_neighbors


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
