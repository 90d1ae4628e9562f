"""Reading and writing point clouds; conversions; clear errors on malformed files."""

import numpy as np
import pytest

from manifold_sph.reference import shapes
from manifold_sph.scans import convert
from manifold_sph.scans.io import ReadError, read, read_mesh, write

FORMATS = ["ply", "pcd", "xyz", "txt", "csv", "obj", "npy", "npz", "vtk", "vtp"]


@pytest.fixture(scope="module")
def cloud():
    return shapes.sphere(200)


@pytest.mark.parametrize("ext", FORMATS)
@pytest.mark.parametrize("binary", [True, False])
def test_round_trip(tmp_path, cloud, ext, binary):
    path = tmp_path / f"c.{ext}"
    write(path, cloud, binary=binary)
    back = read(path)
    atol = 1e-10 if (ext == "vtk" and not binary) else 1e-15  # VTK's legacy ascii writer keeps ~11 digits
    np.testing.assert_allclose(back.points, cloud.points, rtol=0, atol=atol)
    np.testing.assert_allclose(back.normals, cloud.normals, rtol=0, atol=atol)


@pytest.mark.parametrize("ext", ["ply", "pcd", "csv", "npz", "vtp"])
def test_fields_round_trip(tmp_path, cloud, ext):
    u = cloud.points[:, 2] ** 2
    path = tmp_path / f"c.{ext}"
    write(path, cloud, fields={"u": u})
    back, fields = read(path, return_fields=True)
    np.testing.assert_allclose(fields["u"], u, atol=1e-15)


def test_points_without_normals(tmp_path, cloud):
    path = tmp_path / "p.xyz"
    write(path, cloud.points)
    back = read(path)
    assert back.normals is None
    np.testing.assert_array_equal(back.points, cloud.points)


def test_write_refuses_to_overwrite(tmp_path, cloud):
    path = tmp_path / "c.ply"
    write(path, cloud)
    with pytest.raises(FileExistsError, match="overwrite=True"):
        write(path, cloud)
    write(path, cloud.points, overwrite=True)
    assert read(path).normals is None


def _ply_header(fmt, n_vertex, extra=""):
    return (
        f"ply\nformat {fmt} 1.0\ncomment test\nelement vertex {n_vertex}\n"
        "property float x\nproperty float y\nproperty float z\n" + extra + "end_header\n"
    ).encode()


# an octahedron: outward vertex normals are the vertices themselves
OCT_V = np.array([[1.0, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]])
OCT_F = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])


@pytest.mark.parametrize("fmt", ["binary_little_endian", "binary_big_endian", "ascii"])
def test_ply_faces_give_mesh_normals(tmp_path, fmt):
    extra = "element face 8\nproperty list uchar int vertex_indices\n"
    head = _ply_header(fmt, 6, extra)
    if fmt == "ascii":
        body = "".join(f"{a} {b} {c}\n" for a, b, c in OCT_V) + "".join(f"3 {a} {b} {c}\n" for a, b, c in OCT_F)
        data = head + body.encode()
    else:
        e = "<" if fmt.endswith("little_endian") else ">"
        face = np.zeros(8, dtype=[("n", "u1"), ("v", e + "i4", (3,))])
        face["n"], face["v"] = 3, OCT_F
        data = head + OCT_V.astype(e + "f4").tobytes() + face.tobytes()
    path = tmp_path / "oct.ply"
    path.write_bytes(data)
    # 6 vertices are too few for a PointCloud (10): check the mesh reader and normals directly
    v, f = read_mesh(path)
    np.testing.assert_array_equal(v, OCT_V)
    np.testing.assert_array_equal(f, OCT_F)
    np.testing.assert_allclose(convert.mesh_vertex_normals(v, f), OCT_V / 1.0, atol=1e-12)


def test_ply_triangle_strips(tmp_path):
    # a strip over a 2 x 6 grid in the plane z = 0, wound counter-clockwise
    x = np.repeat(np.arange(6.0), 2)
    y = np.tile([0.0, 1.0], 6)
    v = np.c_[x, y, np.zeros(12)]
    strip = np.array([1, 0, 3, 2, 5, 4, 7, 6, 9, 8, 11, 10], dtype="<i4")
    head = _ply_header("binary_little_endian", 12, "element tristrips 1\nproperty list int int vertex_indices\n")
    path = tmp_path / "strip.ply"
    path.write_bytes(head + v.astype("<f4").tobytes() + np.int32(12).tobytes() + strip.tobytes())
    cloud = read(path, normals="mesh")
    np.testing.assert_allclose(cloud.normals, np.tile([0.0, 0, 1], (12, 1)), atol=1e-12)
    assert len(read_mesh(path)[1]) == 10


def test_obj_faces_and_negative_indices(tmp_path):
    c = shapes.sphere(12)  # an icosahedron-like cloud; build its hull faces
    from scipy.spatial import ConvexHull

    hull = ConvexHull(c.points)
    faces = hull.simplices.copy()
    # make every face outward
    centres = c.points[faces].mean(axis=1)
    nrm = np.cross(c.points[faces[:, 1]] - c.points[faces[:, 0]], c.points[faces[:, 2]] - c.points[faces[:, 0]])
    flip = np.einsum("ij,ij->i", nrm, centres) < 0
    faces[flip] = faces[flip][:, ::-1]
    lines = [f"v {a} {b} {c_}" for a, b, c_ in c.points]
    lines += [f"f {a + 1}/{a + 1} {b + 1} {c_ - 12}" for a, b, c_ in faces]  # mixed positive/negative
    path = tmp_path / "m.obj"
    path.write_text("\n".join(lines) + "\n")
    cloud = read(path, normals="mesh")
    assert np.einsum("ij,ij->i", cloud.normals, c.normals).min() > 0.9
    assert read(path, normals="file").normals is None  # the file stores none
    with pytest.warns(RuntimeWarning, match="normals from its 20 faces, which are not kept"):
        auto = read(path)  # the default: a mesh without stored normals gives its faces' (said once)
    np.testing.assert_array_equal(auto.normals, cloud.normals)


def test_pcd_ascii_written_by_hand(tmp_path):
    p = np.random.default_rng(0).random((12, 3))
    head = "VERSION .7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH 12\nHEIGHT 1\nPOINTS 12\nDATA ascii\n"
    path = tmp_path / "h.pcd"
    path.write_text(head + "".join(f"{a:.17g} {b:.17g} {c:.17g} 7\n" for a, b, c in p))
    cloud, fields = read(path, return_fields=True)
    np.testing.assert_array_equal(cloud.points, p)
    np.testing.assert_array_equal(fields["intensity"], 7.0)


def test_text_header_names_columns(tmp_path):
    p = np.random.default_rng(0).random((12, 3))
    path = tmp_path / "h.csv"
    path.write_text("z,x,y,temp\n" + "".join(f"{c:.17g},{a:.17g},{b:.17g},1.5\n" for a, b, c in p))
    cloud, fields = read(path, return_fields=True)
    np.testing.assert_array_equal(cloud.points, p)
    assert list(fields) == ["temp"]


def test_duplicates_error_and_merge(tmp_path, cloud):
    path = tmp_path / "d.npy"
    np.save(path, np.vstack([cloud.points, cloud.points[:3]]))
    with pytest.raises(ReadError, match=r"d\.npy.*3 exact duplicate point\(s\); pass duplicates='merge'"):
        read(path, duplicates="error")
    with pytest.warns(RuntimeWarning, match="merged 3 exact duplicate") as said:  # a ManifoldSPHWarning, the default
        back, fields = read(path, return_fields=True)
    assert len(said) == 1
    assert len(back) == 200 and fields["index"].tolist() == list(range(200))


def test_zero_normals_mean_no_normals(tmp_path, cloud):
    path = tmp_path / "z.npz"
    np.savez(path, points=cloud.points, normals=np.zeros_like(cloud.points))
    assert read(path).normals is None


@pytest.mark.parametrize(
    "name, content, match",
    [
        ("bad.ply", b"not a ply at all", "not a PLY file"),
        ("trunc.ply", _ply_header("binary_little_endian", 100) + b"\x00" * 40, "truncated"),
        ("short.ply", _ply_header("ascii", 20) + b"0 0 0\n1 1 1\n", "truncated in element 'vertex'"),
        ("fmt.ply", b"ply\nformat weird 1.0\nelement vertex 1\nproperty float x\nend_header\n", "unknown PLY format"),
        ("noxyz.ply", b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float q\nend_header\n1\n", "no x, y, z columns"),
        ("words.xyz", b"1 2 3\n4 five 6\n", "malformed numeric data"),
        ("two.xyz", b"1 2\n3 4\n", "at least 3 columns"),
        ("empty.csv", b"# nothing\n", "no data rows"),
        ("nov.obj", b"f 1 2 3\n", "no vertex"),
        ("bad.pcd", b"VERSION .7\nFIELDS x y z\n", "no DATA line"),
        ("short.pcd", b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nPOINTS 20\nDATA binary\n" + b"\x00" * 12, "truncated"),
        ("nan.xyz", b"".join(b"%d 0 0\n" % i for i in range(11)) + b"nan 0 0\n", "NaN or inf"),
        ("junk.npy", b"\x93NUMPY garbage", "not a readable NPY"),
        ("bad.vtk", b"# vtk DataFile Version 2.0\ngarbage\n", r"bad\.vtk"),
    ],
)
def test_malformed_files_name_file_and_problem(tmp_path, name, content, match):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(ReadError, match=match) as info:
        read(path)
    assert name in str(info.value)


def test_missing_file_and_unknown_format(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.ply"):
        read(tmp_path / "nope.ply")
    p = tmp_path / "c.dat"
    p.write_text("1 2 3\n")
    with pytest.raises(ValueError, match="cannot tell the format"):
        read(p)
    with pytest.raises(ValueError, match="format must be one of"):
        read(p, format="dat")
    with pytest.raises(ValueError, match="normals='mesh' needs a mesh file"):
        read(p, format="xyz", normals="mesh")
    with pytest.raises(ValueError, match="normals must be one of"):
        read(p, format="xyz", normals="guess")


def test_write_bad_input(tmp_path, cloud):
    with pytest.raises(ValueError, match=r"field 'u' must have shape \(200,\)"):
        write(tmp_path / "a.ply", cloud, fields={"u": np.ones(3)})
    with pytest.raises(ValueError, match="OBJ files cannot hold per-point fields"):
        write(tmp_path / "a.obj", cloud, fields={"u": np.ones(200)})
    with pytest.raises(ValueError, match=r"cloud must be a PointCloud or an array of shape \(N, 3\)"):
        write(tmp_path / "b.ply", np.ones((5, 2)))


def test_conversions(cloud):
    pv_mesh = convert.to_pyvista(cloud, {"u": np.arange(200.0)})
    back, fields = convert.from_pyvista(pv_mesh, return_fields=True)
    np.testing.assert_array_equal(back.points, cloud.points)
    np.testing.assert_allclose(back.normals, cloud.normals)
    assert fields["u"][5] == 5.0

    tm = convert.to_trimesh(cloud)
    back = convert.from_trimesh(tm)
    np.testing.assert_array_equal(back.points, cloud.points)
    np.testing.assert_allclose(back.normals, cloud.normals)

    import trimesh.creation

    ico = trimesh.creation.icosphere(subdivisions=2)
    with pytest.warns(RuntimeWarning, match="normals from its 320 faces, which are not kept"):
        back = convert.from_trimesh(ico)
    assert np.einsum("ij,ij->i", back.normals, back.points).min() > 0.95

    o3 = convert.to_open3d(cloud)
    back = convert.from_open3d(o3)
    np.testing.assert_array_equal(back.points, cloud.points)
    np.testing.assert_allclose(back.normals, cloud.normals)

    with pytest.raises(TypeError, match="pyvista DataSet"):
        convert.from_pyvista(cloud)
    with pytest.raises(TypeError, match="trimesh"):
        convert.from_trimesh(cloud)
    with pytest.raises(TypeError, match="open3d"):
        convert.from_open3d(cloud)
