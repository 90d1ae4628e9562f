"""Tangent frames (the construction of [1], docs/method.md section 2.2) and the projection to local coordinates."""

import numpy as np
import pytest

from manifold_sph.frames import check_frames, project_pairs, tangent_frames


def random_normals(n, seed=0):
    p = np.random.default_rng(seed).normal(size=(n, 3))
    return p / np.linalg.norm(p, axis=1, keepdims=True)


def test_orthonormal_right_handed_including_poles_of_the_construction():
    n = np.concatenate([random_normals(2000), [[0, 1, 0], [0, -1, 0], [1e-9, 1, 0], [0, 0, 1]]])
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    u, v = tangent_frames(n)
    check_frames(n, u, v, tol=1e-12)
    assert np.allclose(np.cross(u, v), n, atol=1e-12)


def test_seed_construction_u_in_plane_y_const():
    n = random_normals(500, 1)
    u, _ = tangent_frames(n)
    generic = np.hypot(n[:, 0], n[:, 2]) >= 0.1
    assert np.allclose(u[generic, 1], 0.0, atol=1e-15)  # u lies in the plane y = y_i
    assert np.allclose(u[~generic, 0], 0.0, atol=1e-15)  # near e_y: the plane x = x_i


def test_check_frames_rejects_bad_frame():
    n = np.array([[0.0, 0.0, 1.0]])
    with pytest.raises(ValueError, match="u.n"):
        check_frames(n, np.array([[0.0, 0.6, 0.8]]), np.array([[1.0, 0.0, 0.0]]))


def test_projection_drops_the_normal_offset():
    n = random_normals(50, 2)
    u, v = tangent_frames(n)
    rng = np.random.default_rng(3)
    p = rng.normal(size=(50, 3))
    a, b, c = rng.normal(size=(3, 50))
    rows = np.arange(50)
    cols = rng.permutation(50)
    q = np.empty_like(p)
    q[cols] = p + a[:, None] * u + b[:, None] * v + c[:, None] * n
    xy = project_pairs(p, u, v, rows, cols, candidates=q)
    assert np.allclose(xy, np.stack([a, b], 1), atol=1e-12)


def test_frame_pair_reads_the_stacked_frames_and_checks_shapes():
    from manifold_sph.frames import FramePair, tangent_frames

    n = np.random.default_rng(0).normal(size=(5, 3))
    u, v = tangent_frames(n / np.linalg.norm(n, axis=1)[:, None])
    stacked, e = np.stack([u, v], axis=1), FramePair(u, v)
    assert e.shape == stacked.shape
    for rows in (slice(None), [4, 0, 4]):
        for k in (0, 1):
            np.testing.assert_array_equal(e[rows, k], stacked[rows, k])
    with pytest.raises(ValueError, match=r"u and v must be \(N, D\) arrays of one shape, got \(5, 3\) and \(4, 3\)"):
        FramePair(u, v[:4])
