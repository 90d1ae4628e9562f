"""PointCloud validation: shapes, finiteness, normals, duplicates, size."""

import numpy as np
import pytest

from manifold_sph import PointCloud


def pts(n=20, seed=0):
    return np.random.default_rng(seed).normal(size=(n, 3))


def test_normals_are_unit_and_arrays_read_only():
    p = pts()
    c = PointCloud(p, normals=3 * p)
    assert np.allclose(np.linalg.norm(c.normals, axis=1), 1.0, atol=1e-15)
    assert np.allclose(c.normals, p / np.linalg.norm(p, axis=1, keepdims=True))
    with pytest.raises(ValueError):
        c.points[0, 0] = 1.0
    assert c.points.dtype == np.float64 and len(c) == 20 and c.normals is not None


def test_points_are_copied():
    p = pts()
    c = PointCloud(p)
    p[0] = 99.0
    assert c.points[0, 0] != 99.0


@pytest.mark.parametrize(
    "points, normals, match",
    [
        (pts()[:, :2], None, r"points must have shape \(N, 3\), got shape \(20, 2\)"),
        (np.where(np.arange(20)[:, None] == 4, np.inf, pts()), None, r"points must be finite, .*index \(4, 0\)"),
        (pts(9), None, "points must hold at least 10 points, got 9"),
        (np.concatenate([pts(), pts()[:3]]), None, r"3 point\(s\) duplicate others"),
        (pts(), pts(19), r"normals must have shape \(20, 3\) to match points"),
        (pts(), np.where(np.arange(20)[:, None] == 2, 0.0, pts()), r"normals must be non-zero, but 1 normal\(s\)"),
        (pts(), np.full((20, 3), np.nan), "normals must be finite"),
    ],
)
def test_bad_input(points, normals, match):
    with pytest.raises(ValueError, match=match):
        PointCloud(points, normals)


def test_non_numeric_is_a_type_error():
    with pytest.raises(TypeError, match="points must be a numeric array"):
        PointCloud([["a", "b", "c"]] * 12)


def test_a_cloud_keeps_the_geometry_it_samples():
    from manifold_sph.reference import shapes

    c = shapes.sphere(50)
    assert c.geometry is not None and c.geometry.name == "sphere"
    assert PointCloud(c.points, geometry=c.geometry).geometry is c.geometry
    assert "geometry=sphere" in repr(c)


def test_uniformly_short_normals_are_not_zero():
    """Regression: normals of length 1e-13 everywhere were rejected as zero (the threshold was
    absolute below 1); it is relative to the longest normal."""
    p = np.random.default_rng(1).normal(size=(20, 3))
    c = PointCloud(p, normals=1e-13 * p)
    np.testing.assert_allclose(np.linalg.norm(c.normals, axis=1), 1.0)
    n = p.copy()
    n[3] *= 1e-14  # 1e-14 of the others: a zero in all but name
    with pytest.raises(ValueError, match=r"1 normal\(s\) have zero length or are shorter than 1e-12 times the longest"):
        PointCloud(p, normals=n)


def test_negative_h_array_is_named_as_negative_not_as_a_shape():
    from manifold_sph import Surface
    from manifold_sph.reference import shapes

    c = shapes.sphere(200)
    h = np.full(200, 0.2)
    h[7] = -0.1
    with pytest.raises(ValueError, match=r"h must be positive, but 1 of its 200 value\(s\) are <= 0 \(first at index 7"):
        Surface(c, h=h)
    with pytest.raises(ValueError, match=r"h must have shape \(200,\), got shape \(3,\)"):
        Surface(c, h=np.ones(3))
