"""Neighbourhoods: radius search, normal filter, smoothing lengths, CSR layout."""

import numpy as np
import pytest

from manifold_sph.neighbors import adaptive_smoothing_length, find_neighbors, smoothing_length_for_count


def brute_force(points, radius, normals=None, threshold=0.0):
    d = np.linalg.norm(points[:, None] - points[None], axis=2)
    keep = d < radius[:, None]
    if normals is not None:
        keep &= normals @ normals.T > threshold
    return keep


@pytest.fixture
def cloud():
    rng = np.random.default_rng(3)
    p = rng.normal(size=(400, 3))
    return p / np.linalg.norm(p, axis=1, keepdims=True)


def test_matches_brute_force_with_normal_filter(cloud):
    h = 0.12
    nb = find_neighbors(cloud, cloud, h=h, support=3.0, normal_threshold=0.9)
    keep = brute_force(cloud, np.full(len(cloud), 3 * h), cloud, 0.9)
    for i in range(len(cloud)):
        assert set(nb.neighbors_of(i).tolist()) == set(np.flatnonzero(keep[i]).tolist())
    assert nb.n_filtered == int(brute_force(cloud, np.full(len(cloud), 3 * h)).sum() - keep.sum())


def test_self_first_and_sorted(cloud):
    nb = find_neighbors(cloud, h=0.1, support=3.0)
    assert np.all(nb.indices[nb.indptr[:-1]] == np.arange(len(cloud)))
    rows = nb.rows
    d = np.linalg.norm(cloud[nb.indices] - cloud[rows], axis=1)
    same_row = rows[1:] == rows[:-1]
    assert np.all(d[1:][same_row] >= d[:-1][same_row])


def test_mean_count_reaches_target():
    p = np.random.default_rng(0).uniform(size=(3000, 2))
    for target in (12, 27, 40):
        h = smoothing_length_for_count(p, target, support=3.0)
        assert find_neighbors(p, h=h, support=3.0).counts.mean() == pytest.approx(target, abs=1e-9)


def test_adaptive_h_gives_exact_counts():
    rng = np.random.default_rng(1)
    p = np.concatenate([rng.uniform(size=(500, 2)), rng.uniform(size=(2000, 2)) * 0.5 + [1.5, 0]])  # density ratio 16
    h = adaptive_smoothing_length(p, k=20, support=2.0)
    nb = find_neighbors(p, h=h, support=2.0)
    assert np.all(nb.counts == 20)
    assert h[:500].mean() > 3 * h[500:].mean()


def test_candidates_with_ghosts():
    p = np.array([[0.0, 0.0], [0.5, 0.0], [2.0, 0.0]] + [[5.0 + i, 5.0] for i in range(8)])
    ghosts = np.array([[-0.2, 0.0]])
    nb = find_neighbors(p, h=0.25, support=3.0, candidates=np.concatenate([p, ghosts]))
    assert sorted(nb.neighbors_of(0).tolist()) == [0, 1, 11]


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(h=-1.0), "h must be a finite positive number"),
        (dict(h=np.ones(3)), r"h must be a scalar or have shape \(400,\)"),
        (dict(h=0.1, normal_threshold=1.5), r"normal_threshold must lie in \[-1, 1\)"),
    ],
)
def test_bad_input(cloud, kwargs, match):
    with pytest.raises(ValueError, match=match):
        find_neighbors(cloud, cloud, **kwargs)


def test_bad_targets(cloud):
    with pytest.raises(ValueError, match=r"target \(mean neighbour count\) must be in \[2, 400\)"):
        smoothing_length_for_count(cloud, 500)
    with pytest.raises(ValueError, match="k must be smaller than the number of points 400"):
        adaptive_smoothing_length(cloud, 400)


@pytest.mark.parametrize("jit", [True, False])
def test_query_in_row_blocks_equals_one_query(monkeypatch, jit):
    """Regression (memory): the k-NN query runs in row blocks so its (rows, k) arrays stay small;
    the neighbourhood must be the same as from one query of the whole cloud."""
    import manifold_sph.neighbors as nbm
    from manifold_sph import _jit

    rng = np.random.default_rng(5)
    p = rng.standard_normal((3000, 3))
    n = p / np.linalg.norm(p, axis=1)[:, None]
    p = n + 0.01 * rng.standard_normal((3000, 3))
    n = n + 0.6 * rng.standard_normal((3000, 3))  # noisy normals: some pairs are filtered
    n /= np.linalg.norm(n, axis=1)[:, None]
    monkeypatch.setattr(_jit, "ENABLED", jit)
    h = 0.04 * (1 + rng.random(3000))
    whole = find_neighbors(p, n, h=h, normal_threshold=0.3)
    monkeypatch.setattr(nbm, "_QUERY_ROWS", 701)  # blocks that do not divide N
    blocks = find_neighbors(p, n, h=h, normal_threshold=0.3)
    np.testing.assert_array_equal(whole.indptr, blocks.indptr)
    np.testing.assert_array_equal(whole.indices, blocks.indices)
    assert whole.n_filtered == blocks.n_filtered > 0
    assert blocks.indices.dtype == blocks.indptr.dtype == np.int32


def test_pair_offsets_are_projected_identically():
    """Surfaces project pair offsets per chunk instead of storing them: the chunks, a few pairs and
    the whole array must equal the one-pass projection bit for bit (operators stay invariant)."""
    from manifold_sph import Surface
    from manifold_sph.frames import PairOffsets, project_neighborhood
    from manifold_sph.reference import shapes

    s = Surface(shapes.sphere(3000))
    nb = s.neighborhood
    ref = project_neighborhood(s.points, s.u, s.v, nb.indptr, nb.indices)
    xy = PairOffsets(s.points, s.u, s.v, nb.indptr, nb.indices)
    np.testing.assert_array_equal(s.pair_offsets(), ref)
    np.testing.assert_array_equal(xy.rows(1000, 2345), ref[nb.indptr[1000] : nb.indptr[2345]])
    pos = np.array([[5, 17], [40000, nb.indices.size - 1]])
    np.testing.assert_array_equal(xy.at(pos), ref[pos])
    assert xy.shape == ref.shape
