"""reference.sampling.sample_triangles: area-uniform random points on a triangle mesh."""

import numpy as np
import pytest

from manifold_sph.reference.sampling import sample_triangles

V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0, 0, 3]])


def test_points_on_their_faces_area_uniform_and_reproducible():
    F = np.array([[0, 1, 2], [1, 3, 2], [0, 1, 4]])  # areas 0.5, 0.5, 1.5
    p, f = sample_triangles(V, F, 20000, seed=3)
    q, g = sample_triangles(V, F, 20000, seed=3)
    assert np.array_equal(p, q) and np.array_equal(f, g)
    np.testing.assert_allclose(np.bincount(f, minlength=3) / 20000, [0.2, 0.2, 0.6], atol=0.015)
    a, b, c = (V[F[f, k]] for k in range(3))  # barycentric coordinates in [0, 1]: on the face
    n = np.cross(b - a, c - a)
    A2 = np.einsum("ij,ij->i", n, n)
    l1 = np.einsum("ij,ij->i", np.cross(b - p, c - p), n) / A2
    l2 = np.einsum("ij,ij->i", np.cross(c - p, a - p), n) / A2
    assert np.all(l1 >= -1e-12) and np.all(l2 >= -1e-12) and np.all(l1 + l2 <= 1 + 1e-12)
    np.testing.assert_allclose(np.einsum("ij,ij->i", p - a, n), 0.0, atol=1e-12)
    # uniform within the unit square's two faces: the mean is its centre
    sq = f < 2
    np.testing.assert_allclose(p[sq, :2].mean(axis=0), [0.5, 0.5], atol=0.01)


def test_bad_input():
    F = [[0, 1, 2]]
    with pytest.raises(ValueError, match="vertices"):
        sample_triangles(np.array([[0.0, 0, np.nan], [1, 0, 0], [0, 1, 0]]), F, 5)
    with pytest.raises(ValueError, match="vertices"):
        sample_triangles(np.zeros((3, 2)), F, 5)
    with pytest.raises(ValueError, match="faces"):
        sample_triangles(V, [[0, 1]], 5)
    with pytest.raises(ValueError, match="faces"):
        sample_triangles(V, [[0, 1, 9]], 5)
    with pytest.raises(ValueError, match="faces"):
        sample_triangles(V, [[0.0, 1.0, 2.0]], 5)
    with pytest.raises(ValueError, match="area"):
        sample_triangles(V, [[0, 0, 1]], 5)
    with pytest.raises(ValueError, match="n"):
        sample_triangles(V, F, 0)
    with pytest.raises(TypeError, match="seed"):
        sample_triangles(V, F, 5, seed="x")
