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


# ----------------------------------------------------------------------------- as_cloud: anything point-like in
import warnings  # noqa: E402

from manifold_sph import as_cloud, read, write  # noqa: E402
from manifold_sph.reference import shapes  # noqa: E402


def _icosphere(flip=False):
    import trimesh.creation

    m = trimesh.creation.icosphere(subdivisions=2)  # 162 vertices, 320 faces, wound outward
    v, f = np.asarray(m.vertices), np.asarray(m.faces)
    return v, (f[:, ::-1] if flip else f)


def _obj_text(v, f):
    return ("".join(f"v {a!r} {b!r} {c!r}\n" for a, b, c in np.asarray(v).tolist())
            + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in np.asarray(f).tolist()))


def _outward(cloud):
    return float(np.einsum("ij,ij->i", cloud.normals, cloud.points / np.linalg.norm(cloud.points, axis=1)[:, None]).min())


def test_as_cloud_arrays_and_clouds():
    c = shapes.sphere(100)
    assert as_cloud(c) is c
    s_like = type("Holder", (), {"cloud": c})()  # anything holding a cloud (a Surface)
    assert as_cloud(s_like) is c
    a = as_cloud(c.points)
    assert a.normals is None and np.array_equal(a.points, c.points)
    b = as_cloud(c.points.tolist(), normals=c.normals)
    np.testing.assert_allclose(b.normals, c.normals)
    flipped = as_cloud(c, normals=-c.normals)
    np.testing.assert_allclose(flipped.normals, -c.normals) and flipped.geometry is c.geometry


def test_as_cloud_duplicates_in_arrays_refused_unless_merged():
    c = shapes.sphere(100)
    p = np.vstack([c.points, c.points[:4]])
    with pytest.raises(ValueError, match=r"4 point\(s\) duplicate others.*as_cloud\(points, duplicates='merge'\)"):
        as_cloud(p)
    with pytest.warns(RuntimeWarning, match=r"merged 4 exact duplicate point\(s\) \(100 kept") as said:
        m = as_cloud(p, duplicates="merge")
    assert len(said) == 1 and np.array_equal(m.points, c.points)
    with pytest.raises(ValueError, match="duplicates must be one of"):
        as_cloud(p, duplicates="drop")


@pytest.mark.parametrize("bad, match", [
    (object(), "points must be an \\(N, 3\\) array, a PointCloud, a file path.*got builtins.object"),
    (b"cow.obj", "got bytes"),
    (42, "points must be an \\(N, 3\\) array"),
])
def test_as_cloud_refuses_what_is_not_point_like(bad, match):
    with pytest.raises(TypeError, match=match):
        as_cloud(bad)


def test_as_cloud_paths(tmp_path):
    c = shapes.sphere(60)
    write(tmp_path / "s.ply", c)
    for path in (tmp_path / "s.ply", str(tmp_path / "s.ply")):
        back = as_cloud(path)
        np.testing.assert_array_equal(back.points, c.points)
        np.testing.assert_allclose(back.normals, c.normals)
    with pytest.raises(FileNotFoundError, match="no such file"):
        as_cloud(tmp_path / "missing.ply")
    # a mesh file without normals: the faces give them (outward), the faces are dropped, said once
    v, f = _icosphere(flip=True)  # wound inward: the signed volume turns them out
    (tmp_path / "m.obj").write_text(_obj_text(v, f))
    with pytest.warns(RuntimeWarning, match=r"'m.obj': normals from its 320 faces, which are not kept") as said:
        m = as_cloud(tmp_path / "m.obj")
    assert len(said) == 1 and _outward(m) > 0.95


def test_mesh_faces_give_no_normals_when_untrustworthy(tmp_path):
    v, f = _icosphere()
    f2 = f.copy()
    f2[:40] = f2[:40, ::-1]  # some faces wound the other way
    (tmp_path / "w.obj").write_text(_obj_text(v, f2))
    with pytest.warns(RuntimeWarning, match="give no normals: the faces are not wound consistently"):
        assert as_cloud(tmp_path / "w.obj").normals is None
    extra = np.vstack([v, [[3.0, 3.0, 3.0]]])  # a vertex in no face
    (tmp_path / "u.obj").write_text(_obj_text(extra, f))
    with pytest.warns(RuntimeWarning, match=r"1 of its 163 points are in no face"):
        u = as_cloud(tmp_path / "u.obj")
    assert u.normals is None and len(u) == 163


def test_duplicated_seam_vertices_merge_before_the_face_normals(tmp_path):
    """A mesh whose seam vertices are repeated (the teapot): merged first, so the seam normals
    average both sides, in one warning saying both things."""
    v, f = _icosphere()
    seam = np.arange(0, 162, 9)
    v2 = np.vstack([v, v[seam]])
    f2 = f.copy()
    copy_of = {int(s): 162 + k for k, s in enumerate(seam)}
    half = f2[:, 0] >= 0
    half[::2] = False
    for k in np.flatnonzero(half):  # every other face uses the copies
        f2[k] = [copy_of.get(int(i), int(i)) for i in f2[k]]
    (tmp_path / "t.obj").write_text(_obj_text(v2, f2))
    with pytest.warns(RuntimeWarning, match=r"merged 18 exact duplicate.*; normals from its 320 faces") as said:
        t = as_cloud(tmp_path / "t.obj")
    assert len(said) == 1 and len(t) == 162 and _outward(t) > 0.98
    with pytest.raises(ValueError, match="18 exact duplicate point"):
        as_cloud(tmp_path / "t.obj", duplicates="error")


def test_open3d_objects():
    o3d = pytest.importorskip("open3d")
    c = shapes.sphere(80)
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(c.points.copy()))
    assert as_cloud(pc).normals is None
    pc.normals = o3d.utility.Vector3dVector(c.normals.copy())
    np.testing.assert_allclose(as_cloud(pc).normals, c.normals)
    t = o3d.t.geometry.PointCloud(o3d.core.Tensor(c.points.copy()))
    t.point.normals = o3d.core.Tensor(c.normals.copy())
    np.testing.assert_allclose(as_cloud(t).normals, c.normals)
    v, f = _icosphere()
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(v), o3d.utility.Vector3iVector(f))
    with pytest.warns(RuntimeWarning, match="the open3d.TriangleMesh: normals from its 320 faces"):
        m = as_cloud(mesh)
    assert _outward(m) > 0.95
    tm = o3d.t.geometry.TriangleMesh.from_legacy(mesh)
    with pytest.warns(RuntimeWarning, match="normals from its 320 faces"):
        assert _outward(as_cloud(tm)) > 0.95


def test_pyvista_and_vtk_objects():
    pv = pytest.importorskip("pyvista")
    c = shapes.sphere(80)
    poly = pv.PolyData(c.points.copy())
    poly.point_data["Normals"] = c.normals
    poly.point_data["u"] = np.arange(80.0)
    back = as_cloud(poly)
    np.testing.assert_allclose(back.normals, c.normals)
    v, f = _icosphere()
    surf = pv.PolyData(v, np.c_[np.full(len(f), 3), f].ravel())
    with pytest.warns(RuntimeWarning, match="the pyvista.PolyData: normals from its 320 faces"):
        assert _outward(as_cloud(surf)) > 0.95
    import vtk  # a bare VTK object is wrapped by pyvista

    raw = vtk.vtkPolyData()
    raw.DeepCopy(surf)
    with pytest.warns(RuntimeWarning, match="normals from its 320 faces"):
        assert len(as_cloud(raw)) == 162


def test_trimesh_objects():
    trimesh = pytest.importorskip("trimesh")
    v, f = _icosphere()
    mesh = trimesh.Trimesh(v, f, process=False)
    with pytest.warns(RuntimeWarning, match="the trimesh.Trimesh: normals from its 320 faces") as said:
        m = as_cloud(mesh)
    assert len(said) == 1 and _outward(m) > 0.95
    pc = trimesh.PointCloud(v)
    assert as_cloud(pc).normals is None
    scene = trimesh.Scene([mesh])
    with pytest.warns(RuntimeWarning, match="normals from its 320 faces"):
        assert len(as_cloud(scene)) == 162


def test_every_entry_point_takes_point_like_input(tmp_path):
    """Surface, Domain2D, write and the conversions take a path, a cloud and another library's object."""
    import trimesh

    from manifold_sph import Domain2D, Surface

    v, f = _icosphere()
    mesh = trimesh.Trimesh(v, f, process=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # faces dropped, supports widened: said elsewhere
        s = Surface(mesh)
        assert s.n_points == 162 and not s.normals_estimated and _outward(s.cloud) > 0.95
        write(tmp_path / "m.ply", mesh)
        assert len(read(tmp_path / "m.ply")) == 162
        assert Surface(tmp_path / "m.ply").n_points == 162
    from manifold_sph import estimate_normals

    n = estimate_normals(tmp_path / "m.ply")
    assert n.shape == (162, 3) and float(np.einsum("ij,ij->i", n, v / np.linalg.norm(v, axis=1)[:, None]).min()) > 0.9
    grid = np.stack(np.meshgrid(np.linspace(0, 1, 12), np.linspace(0, 1, 12)), -1).reshape(-1, 2)
    flat = np.c_[grid, np.full(len(grid), 0.5)]  # the plane z = 0.5
    write(tmp_path / "flat.xyz", flat)
    d = Domain2D(tmp_path / "flat.xyz")
    np.testing.assert_array_equal(d.points, grid)
    with pytest.raises(ValueError, match="points must be planar for a Domain2D"):
        Domain2D(shapes.sphere(50))


def test_views_to_pyvista_and_open3d():
    c = shapes.sphere(40)
    mesh = c.to_pyvista({"z": c.points[:, 2], "grad": c.normals})
    assert mesh.n_points == 40 and mesh.point_data["grad"].shape == (40, 3)
    np.testing.assert_allclose(mesh.point_data["Normals"], c.normals)
    assert "field" in c.to_pyvista(c.points[:, 0]).point_data
    with pytest.raises(ValueError, match=r"field 'z' must have shape \(40,\) or \(40, k\), got shape \(3,\)"):
        c.to_pyvista({"z": [1, 2, 3]})
    o = c.to_open3d()
    np.testing.assert_allclose(np.asarray(o.normals), c.normals)
    back = as_cloud(o)
    np.testing.assert_array_equal(back.points, c.points)


def test_notebook_display_is_a_png_or_nothing():
    from conftest import gl_probe

    c = shapes.sphere(200)
    png = c._repr_png_()
    if gl_probe()[0]:
        assert png[:8] == b"\x89PNG\r\n\x1a\n"
        pic = c.show(c.points[:, 2])
        assert pic.shape == (480, 640, 3) and pic._repr_png_()[:4] == b"\x89PNG"
    else:
        assert png is None
