"""Open boundaries: detection, and what the operators and the heat equation do there."""

from pathlib import Path

import numpy as np
import pytest
from scipy.sparse import csgraph

from manifold_sph import Surface
from manifold_sph.pde import heat
from manifold_sph.reference import shapes
from manifold_sph.scans.boundary import angular_gaps, detect_boundary


@pytest.fixture(scope="module")
def open_scan():
    """A synthetic scan with holes: a sphere without its north cap, plus a separate open cylinder-free patch."""
    c = shapes.sphere(3000, sampling="poisson", seed=1)
    keep = c.points[:, 2] < 0.6
    spacing = np.sqrt(4 * np.pi / 3000)
    return c.points[keep], c.normals[keep], spacing


def test_closed_surfaces_have_no_boundary():
    for cloud in (shapes.sphere(2000, sampling="poisson"), shapes.torus(3000), shapes.sphere(3000, sampling="variable")):
        assert detect_boundary(cloud).n_boundary == 0


def test_rim_of_an_open_sphere(open_scan):
    p, n, spacing = open_scan
    rep = detect_boundary(p, n)
    z = p[:, 2]
    rim = z > 0.6 - 0.3 * spacing
    inner = z < 0.6 - 2.5 * spacing
    assert rep.mask[rim].all()  # every particle on the rim found
    assert not rep.mask[inner].any()  # and no interior particle
    assert rep.n_loops == 1
    assert "in 1 connected piece(s)" in rep.report
    # a Surface gives the same answer with its own neighbourhood
    s = Surface(p, n, scheme="standard", area="shepard")
    rs = detect_boundary(s)
    assert rs.mask[rim].all() and not rs.mask[inner].any()


def test_plate_edges_and_angular_gaps():
    g = np.linspace(0, 1, 15)
    x, y = np.meshgrid(g, g)
    plate = np.c_[x.ravel(), y.ravel(), np.zeros(225)]
    rep = detect_boundary(plate, np.tile([0.0, 0, 1], (225, 1)))
    edge = (x.ravel() == 0) | (x.ravel() == 1) | (y.ravel() == 0) | (y.ravel() == 1)
    np.testing.assert_array_equal(rep.mask, edge)
    corner = (x.ravel() == 0) & (y.ravel() == 0)
    np.testing.assert_allclose(np.degrees(rep.gap[corner]), 270.0)
    # lonely rows get a full turn
    assert angular_gaps(np.array([[0.0, 0.0], [1.0, 0.0]]), np.array([0, 1, 2])).tolist() == [2 * np.pi, 2 * np.pi]


def test_standard_shepard_laplacian_is_an_m_matrix(open_scan):
    p, n, _ = open_scan
    s = Surface(p, n, scheme="standard", area="shepard")
    L = s.laplacian_matrix(form="strong").tocoo()
    off = L.row != L.col
    assert L.data[off].min() >= 0  # non-negative off-diagonal weights
    assert np.abs(np.asarray(s.laplacian_matrix(form="strong").sum(axis=1))).max() < 1e-8 * np.abs(L.data).max()  # zero row sums
    assert (L.diagonal() < 0).all()


def test_heat_on_an_open_scan_respects_the_maximum_principle(open_scan):
    p, n, _ = open_scan
    # a second, disjoint piece: the same open sphere shifted away
    P = np.vstack([p, p + [5.0, 0, 0]])
    N = np.vstack([n, n])
    s = Surface(P, N, scheme="standard", area="shepard")
    u0 = np.zeros(len(P))
    u0[np.argmin(P[:, 2])] = 1.0  # a point source at the south pole of the first piece
    u0[len(p) + np.argmin(p[:, 2])] = -2.0  # and a cold one on the second
    for dt, steps in ((1e-4, 5), (0.05, 200)):
        u = heat(s, u0, dt=dt, steps=steps, method="implicit").u
        assert u.min() >= -2.0 - 1e-9 and u.max() <= 1.0 + 1e-9
    _, lab = csgraph.connected_components(s.laplacian_matrix(), directed=False)
    assert lab.max() + 1 == 2
    for c in range(2):  # the long run tends to a constant on every component (insulated boundary)
        assert np.ptp(u[lab == c]) < 1e-6
    assert u[lab == lab[0]].mean() > 0 > u[lab == lab[-1]].mean()


def test_dirichlet_rim_holds_values(open_scan):
    p, n, _ = open_scan
    s = Surface(p, n, scheme="standard", area="shepard")
    rim = detect_boundary(s).mask
    u = heat(s, np.zeros(len(p)), dt=0.05, steps=100, fixed=rim, fixed_values=1.0).u
    np.testing.assert_array_equal(u[rim], 1.0)
    assert u.max() <= 1 + 1e-9 and u.min() > 0.9  # heated from the rim towards the rim value (0.977 at t = 5)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(k=2), "k must be at least 3"),
        (dict(k=10_000), "k must be at most the number of points"),
        (dict(max_gap=0), "max_gap must be a finite positive number"),
        (dict(max_offset=-1), "max_offset must be a finite positive number"),
        (dict(normals=np.ones((3, 3))), r"normals must have shape \(500, 3\)"),
        (dict(normals=np.zeros((500, 3))), "normals must be non-zero"),
        (dict(max_gap=400), "max_gap must be at most 360 degrees"),
        (dict(seed_gap=100), r"seed_gap must be at least max_gap \(110\)"),
        (dict(normal_threshold=1.0), "normal_threshold must be below 1"),
        (dict(normal_threshold=-0.1), "normal_threshold must be a finite non-negative number"),
        (dict(max_elevation=0), "max_elevation must be a finite positive number"),
        (dict(max_elevation=91), "max_elevation must be at most 90 degrees"),
        (dict(min_piece=0), "min_piece must be"),
        (dict(oriented="yes"), "oriented must be True or False"),
        (dict(seed_size=0), "seed_size must be at least 1"),
        (dict(max_offset=float("nan")), "max_offset must be a finite positive number"),
        (dict(resolve=0), "resolve must be a finite positive number"),
    ],
)
def test_bad_input(kwargs, match):
    p = shapes.sphere(500).points
    kwargs = dict(kwargs)
    kwargs.setdefault("normals", shapes.sphere(500).normals)
    with pytest.raises((ValueError, TypeError), match=match):
        detect_boundary(p, **kwargs)


def test_no_nan_warning_when_a_row_has_no_direction():
    """A particle whose neighbours are all filtered out (opposite normals) used to give inf - inf = NaN."""
    import warnings

    xy = np.array([[0.0, 0.0], [0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gaps = angular_gaps(xy, np.array([0, 2, 5]))  # row 0: only zero offsets
    np.testing.assert_allclose(gaps, [2 * np.pi, np.pi])
    p = shapes.sphere(400).points
    n = p.copy()
    n[7] *= -1  # one flipped normal: every neighbour of particle 7 fails the normal filter
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rep = detect_boundary(p, n)
    assert np.all(np.isfinite(rep.gap)) and np.all(np.isfinite(rep.offset))


# ------------------------------------------------------------ known boundaries, synthetic
def _jittered_disk(m=56, seed=0):
    rng = np.random.default_rng(seed)
    g = (np.arange(m) + 0.5) / m * 2 - 1
    x, y = np.meshgrid(g, g)
    p = np.c_[x.ravel(), y.ravel()] + rng.uniform(-0.3, 0.3, (m * m, 2)) * (2 / m)
    p = p[np.hypot(p[:, 0], p[:, 1]) <= 1]
    return np.c_[p, np.zeros(len(p))], 2 / m


def test_disk_rim_in_one_piece():
    p, h = _jittered_disk()
    r = np.hypot(p[:, 0], p[:, 1])
    rep = detect_boundary(p, np.tile([0.0, 0, 1], (len(p), 1)))
    assert rep.mask[r > 1 - 0.5 * h].all()  # measured: all
    assert not rep.mask[r < 1 - 2 * h].any()  # measured: none
    assert rep.n_loops == 1


def test_uniformly_random_disk():
    q = np.random.default_rng(1).uniform(-1, 1, (6000, 2))
    q = q[np.hypot(q[:, 0], q[:, 1]) < 1]
    r = np.hypot(q[:, 0], q[:, 1])
    h = np.sqrt(np.pi / len(q))
    rep = detect_boundary(np.c_[q, np.zeros(len(q))], np.tile([0.0, 0, 1], (len(q), 1)))
    assert rep.mask[r > 1 - 0.3 * h].mean() >= 0.95  # measured 0.97 (clumps leave a few rim points covered)
    assert rep.mask[r < 1 - 3 * h].sum() <= 3  # measured 1 of 4672
    assert rep.n_loops == 1


@pytest.fixture(scope="module")
def hemisphere():
    c = shapes.sphere(4000, sampling="poisson", seed=2)
    up = c.points[:, 2] > 0
    return c.points[up], c.normals[up], np.sqrt(4 * np.pi / 4000)


@pytest.mark.parametrize("case", ["exact", "estimated", "noisy", "bad normals"])
def test_hemisphere_rim(hemisphere, case):
    """Exact normals, estimated ones, 10 % of a spacing of noise, and 5 % of the normals turned by
    90 degrees (a minority of bad normals: each is outvoted by its neighbours')."""
    p, n, h = hemisphere
    z = p[:, 2]
    if case == "estimated":
        n = None
    elif case == "noisy":
        p = p + np.random.default_rng(3).normal(scale=0.1 * h, size=p.shape)
        n = None
    elif case == "bad normals":
        rng = np.random.default_rng(0)
        bad = rng.random(len(p)) < 0.05
        t = np.cross(n[bad], rng.normal(size=(int(bad.sum()), 3)))
        n = n.copy()
        n[bad] = t / np.linalg.norm(t, axis=1, keepdims=True)
    rep = detect_boundary(p, n)
    assert rep.mask[z < 0.3 * h].all()  # measured: all, in every case
    assert not rep.mask[z > 2.5 * h].any()  # measured: none (bad normals without the vote: 89, in 40 pieces)
    assert rep.n_loops == 1


def test_flipped_normals_and_orientation_seams(hemisphere):
    """Orientation-free by default: 30 % of the normals flipped, or a seam where the orientation
    changes, add no boundary. ``oriented=True`` turns lone flipped normals back (10 %: none
    added; 30 %: 25 interior particles) but takes a seam for a rim (92 particles)."""
    p, n, h = hemisphere
    z = p[:, 2]
    inner = z > 2.5 * h
    flipped = n * np.where(np.random.default_rng(0).random(len(p)) < 0.3, -1.0, 1.0)[:, None]
    seam = n * np.where(p[:, 0] > 0, -1.0, 1.0)[:, None]
    for m in (flipped, seam):
        rep = detect_boundary(p, m)
        assert rep.mask[z < 0.3 * h].all() and not rep.mask[inner].any() and rep.n_loops == 1
    few = n * np.where(np.random.default_rng(0).random(len(p)) < 0.1, -1.0, 1.0)[:, None]
    rep = detect_boundary(p, few, oriented=True)
    assert rep.mask[z < 0.3 * h].all() and not rep.mask[inner].any()
    assert detect_boundary(p, seam, oriented=True).mask[inner].sum() > 50


def test_open_cylinder_has_two_rims():
    th = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    z = np.linspace(0, 2, 30)
    T, Z = np.meshgrid(th, z)
    T = T + (np.arange(30)[:, None] % 2) * np.pi / 60  # staggered rings
    p = np.c_[np.cos(T.ravel()), np.sin(T.ravel()), Z.ravel()]
    ends = (Z.ravel() == 0) | (Z.ravel() == 2)
    for n in (np.c_[p[:, :2], np.zeros(len(p))], None):
        rep = detect_boundary(p, n)
        np.testing.assert_array_equal(rep.mask, ends)
        assert rep.n_loops == 2
        assert set(rep.labels[ends & (Z.ravel() == 0)]) != set(rep.labels[ends & (Z.ravel() == 2)])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_uniformly_random_open_cylinder(seed):
    """Exact answers: 3000 uniformly random points on an open cylinder (radius 1, height 3). Both
    rims are found (measured: 98-100 % of the particles within 0.3 spacings of a rim) and nothing
    more than 2.5 spacings inside, except (seed 1) a void of the random sampling about 3 spacings
    across, which is a hole to any test on the points: one extra piece of 12 particles."""
    rng = np.random.default_rng(seed)
    th, z = rng.uniform(0, 2 * np.pi, 3000), rng.uniform(0, 3, 3000)
    p = np.c_[np.cos(th), np.sin(th), z]
    d = np.minimum(z, 3 - z) / np.sqrt(2 * np.pi * 3 / 3000)
    rep = detect_boundary(p, np.c_[p[:, :2], np.zeros(3000)])
    assert rep.mask[d < 0.3].mean() >= 0.95
    assert rep.mask[d > 2.5].sum() <= (13 if seed == 1 else 0)
    assert rep.n_loops == (3 if seed == 1 else 2)


def test_specks_are_dropped():
    """Lone candidates (pieces under min_piece, or without a particle whose gap exceeds seed_gap)
    are dropped; min_piece=1 and seed_gap=max_gap keep every candidate."""
    p = np.random.default_rng(4).uniform(-1, 1, (3000, 2))
    p = np.c_[p, np.zeros(len(p))]
    n = np.tile([0.0, 0, 1], (len(p), 1))
    inner = np.abs(p[:, :2]).max(axis=1) < 0.8
    strict = detect_boundary(p, n)
    loose = detect_boundary(p, n, min_piece=1, seed_gap=110.0)
    assert loose.mask[inner].sum() >= strict.mask[inner].sum()
    assert strict.mask[inner].sum() <= 2
    assert not (strict.mask & ~loose.mask).any()  # the cleanup only removes


def test_density_change_is_no_rim():
    """Exact answer: a rectangle sampled on a grid of spacing 0.1 for x < 0 and 0.01 for x > 0. The
    dense particles along x = 0 have their k nearest neighbours all on the dense side; the next
    coarse particle lies 0.055 away and the one beyond it 0.1: no hole, only sparser sampling.
    Measured: without ``resolve`` 88 of the 176 particles along the jump and 18 more inside are
    flagged; with it none, and 98.9 % of the outer rim is still found, in one piece."""
    A = np.array(np.meshgrid(np.arange(-1, 0, 0.1) + 0.05, np.arange(-0.5, 0.5, 0.1) + 0.05)).reshape(2, -1).T
    B = np.array(np.meshgrid(np.arange(0, 0.3, 0.01) + 0.005, np.arange(-0.5, 0.5, 0.01) + 0.005)).reshape(2, -1).T
    p = np.c_[np.r_[A, B], np.zeros(len(A) + len(B))]
    x, y = p[:, 0], p[:, 1]
    n = np.tile([0.0, 0, 1], (len(p), 1))
    jump = (np.abs(x) < 0.02) & (np.abs(y) < 0.44)
    rim = (x < -0.9) | (x > 0.29) | (np.abs(y) > 0.49) | ((x < 0) & (np.abs(y) > 0.4))
    rep = detect_boundary(p, n)
    assert not rep.mask[~rim].any() and rep.mask[rim].mean() >= 0.95 and rep.n_loops == 1
    old = detect_boundary(p, n, resolve=None)
    assert old.mask[jump].sum() >= 40  # the test can fail: without it the jump is taken for a rim
    assert not (rep.mask & ~old.mask).any()


MODELS = Path(__file__).resolve().parents[2] / "shared" / "data" / "models"


def _mesh_reference(name):
    """Welded vertices, area-weighted vertex normals, mesh-boundary vertices (edges in one face),
    and which of those are geometrically free and open (see :func:`_boundary_kinds`)."""
    path = MODELS / f"{name}.obj"
    if not path.is_file():
        pytest.skip(f"{path} not found (the models live outside the repository)")
    from manifold_sph.scans.convert import mesh_vertex_normals
    from manifold_sph.scans.io import read_mesh

    v, f = read_mesh(path)
    u, inv = np.unique(v, axis=0, return_inverse=True)
    f = inv.ravel()[f]
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
    used = np.zeros(len(u), bool)
    used[f.ravel()] = True
    f = (np.cumsum(used) - 1)[f]
    p = u[used]
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    ue, cnt = np.unique(e, axis=0, return_counts=True)
    ref = np.zeros(len(p), bool)
    ref[ue[cnt == 1].ravel()] = True
    free, open_ = _boundary_kinds(p, f, ue, ref)
    return p, mesh_vertex_normals(p, f), ref, free, open_


def _point_triangle_distance(q, a, b, c):
    """Distance from the point q to each triangle (a, b, c) (rows), vectorised (Ericson, Real-Time
    Collision Detection 5.1.5)."""
    ab, ac, ap = b - a, c - a, q - a
    bp, cp = q - b, q - c
    dot = lambda x, y: np.einsum("ij,ij->i", x, y)  # noqa: E731
    d1, d2, d3, d4, d5, d6 = dot(ab, ap), dot(ac, ap), dot(ab, bp), dot(ac, bp), dot(ab, cp), dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        den = va + vb + vc
        v, w = vb / den, vc / den
    inner = a + ab * v[:, None] + ac * w[:, None]
    conds = [
        (d1 <= 0) & (d2 <= 0),
        (d3 >= 0) & (d4 <= d3),
        (d6 >= 0) & (d5 <= d6),
        (vc <= 0) & (d1 >= 0) & (d3 <= 0),
        (vb <= 0) & (d2 >= 0) & (d6 <= 0),
        (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0),
    ]
    choices = [a, b, c, a + ab * t_ab[:, None], a + ac * t_ac[:, None], b + (c - b) * t_bc[:, None]]
    closest = inner.copy()
    for cond, choice in zip(reversed(conds), reversed(choices)):  # the first condition wins
        closest[cond] = choice[cond]
    return np.linalg.norm(q - closest, axis=1)


def _boundary_kinds(p, f, edges, ref, rings=3, inside=0.95, narrow=0.75):
    """Which mesh-boundary vertices the point cloud can show as boundary. The rest of the mesh, seen
    from a boundary vertex, is its faces more than ``rings`` edges away. *Free*: the generalised
    winding number of the rest is below ``inside`` there (the teapot's handle ends and spout base
    end inside its body: 1.07-1.13; its rims and spout tip 0.56-0.80; an open surface such as the
    beetle's or a plane's, below 0.4). *Open*: free, and the rest lies farther than ``narrow`` mean
    edge lengths (a narrow slit, a rim resting on another, closes at the cloud's resolution: the
    alligator's outline has notches 0.35-0.6 edges wide)."""
    import scipy.sparse as sp

    n = len(p)
    A = sp.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n)).tocsr()
    A = ((A + A.T + sp.identity(n, format="csr")) > 0).astype(np.int32)
    R = A
    for _ in range(rings - 1):
        R = ((R @ A) > 0).astype(np.int32)
    length = np.linalg.norm(p[edges[:, 0]] - p[edges[:, 1]], axis=1)
    mean_edge = np.bincount(edges.ravel(), np.repeat(length, 2), n) / np.maximum(np.bincount(edges.ravel(), minlength=n), 1)
    vs = np.flatnonzero(ref)
    free = np.zeros(n, bool)
    open_ = np.zeros(n, bool)
    tri = p[f]  # (faces, 3 corners, 3)
    for s0 in range(0, len(vs), 32):  # 32 boundary vertices against all faces at a time
        v = vs[s0 : s0 + 32]
        far = ~R[v].toarray().astype(bool)[:, f].any(axis=2)  # (32, faces): the rest of the mesh
        a, b, c = (tri[None, :, i, :] - p[v][:, None, :] for i in range(3))
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        dot = lambda x, y: np.einsum("vfi,vfi->vf", x, y)  # noqa: E731
        num = dot(a, np.cross(b, c))
        den = la * lb * lc + dot(a, b) * lc + dot(b, c) * la + dot(c, a) * lb
        winding = np.where(far, np.arctan2(num, den), 0.0).sum(axis=1) / (2 * np.pi)
        free[v] = np.abs(winding) < inside
    # distance to the rest of the mesh, over the faces whose centroid lies close enough to matter
    from scipy.spatial import cKDTree

    centroid = tri.mean(axis=1)
    reach = np.linalg.norm(tri - centroid[:, None, :], axis=2).max()
    lists = cKDTree(centroid).query_ball_point(p[vs], narrow * mean_edge[vs] + reach)
    row = np.repeat(np.arange(len(vs)), [len(x) for x in lists])
    face = np.concatenate([np.asarray(x, dtype=np.int64) for x in lists]) if len(row) else np.zeros(0, np.int64)
    far = ~(R[vs].toarray().astype(bool)[row[:, None], f[face]].any(axis=1))
    q = p[vs][row]
    dist = _point_triangle_distance(q, tri[face, 0], tri[face, 1], tri[face, 2])
    nearest = np.full(len(vs), np.inf)
    np.minimum.at(nearest, row[far], dist[far])
    open_[vs] = free[vs] & (nearest > narrow * mean_edge[vs])
    return free, open_


def _scores(p, rep, ref, free, open_):
    """Recall on the mesh boundary, on its free and on its open part, false-positive share, and the
    share of the false positives within 2 local spacings (mean distance to the 6 nearest) of a
    mesh-boundary vertex."""
    from scipy.spatial import cKDTree

    fp = rep.mask & ~ref
    spacing = cKDTree(p).query(p[fp], 7)[0][:, 1:].mean(axis=1)
    near = (cKDTree(p[ref]).query(p[fp])[0] <= 2 * spacing).mean() if fp.any() else 1.0
    return rep.mask[ref].mean(), rep.mask[free].mean(), rep.mask[open_].mean(), fp.sum() / max(rep.n_boundary, 1), near


# measured (recall on all mesh-boundary vertices / on the free ones / on the open ones (see
# _boundary_kinds), false-positive share of the flagged particles, pieces; ``python
# tests/test_boundary.py`` prints them). Teapot: 160 boundary vertices in 6 loops; the handle's two
# ends and the spout's base end inside the body (53 of their 60 vertices by winding number): 107
# free (the lid's rim, the body's rim, the spout's tip, 7 handle-end vertices), of which only 22 are
# open (the body's rim and the lid's lie 0.5 edge lengths apart, the spout's tip curls back).
# Mesh normals 0.787 / 0.776 / 0.818, 0.113 in 6 pieces (without the ``resolve`` test, which drops
# the ring of the spout's wall under its rolled lip: 0.787 / 0.776 / 0.818, 0.241); oriented=True
# 0.675 / 0.607 / 0.909, 0.206 in 5 (without ``resolve`` 0.894 / 0.935 / 0.909, 0.251: the body's
# and lid's rims were found through the anisotropy of the sampling, their empty side pointing along
# the rim or down the wall to a particle one ordinary step away); estimated normals 0.575 / 0.710 /
# 0.591, 0.179 in 4 (without ``resolve`` 0.403; before issue 16: 0.67 / 0.49 in 9 with mesh
# normals). Beetle (301 boundary vertices, all free, 272 open, 23 loops, many of 2-10 vertices, in
# 1148): 0.505 / 0.505 / 0.526, 0.415 in 3 pieces (without ``resolve`` 0.528 / 0.528 / 0.548,
# 0.482 in 3); estimated 0.505 / 0.505 / 0.522, 0.406 in 3 (without 0.538, 0.449). Alligator (planar,
# 433 boundary vertices, 373 open: 60 lie in notches of the outline narrower than 0.75 edges, which a
# cloud cannot show): 0.797 / 0.797 / 0.925, 0.025 in 1 piece (the same without ``resolve``). The
# targets (>= 0.9, <= 0.1) are NOT met on the teapot and the beetle: both meshes are
# strongly anisotropic (edge-length ratio per vertex: median 2.9 / 4.7, 99th percentile 17 / 43: a
# particle's nearest neighbours lie on one meridian); the beetle's false positives lie 1-3 mesh edges
# from its boundary (85 / 37 / 23 of 148 before ``resolve``: its boundary is a quarter of its
# vertices, with the next row a fraction of a spacing inside); its missed open boundary vertices have
# neighbours all round (median gap 98 degrees: its panels lie 1-2 spacings apart, and its loops of
# 2-10 vertices, 35 vertices in loops at most 3.5 spacings across, are smaller than a
# neighbourhood). A finer mesh of the same beetle (19,885 vertices; not in the repository) gives
# 0.94 recall with 4 % false positives. (Estimated normals come from manifold_sph.normals, which is
# being reworked: looser floors.)
BOUNDARY_FLOORS = {  # min recall (all, free, open), max false positives; with mesh / estimated normals
    "teapot": ((0.75, 0.75, 0.8, 0.14), (0.5, 0.6, 0.5, 0.22)),
    "beetle": ((0.47, 0.47, 0.49, 0.45), (0.47, 0.47, 0.49, 0.45)),
    "alligator": ((0.75, 0.75, 0.9, 0.05), (0.75, 0.75, 0.9, 0.05)),
}
FAR_FALSE_POSITIVES = {"teapot": 12, "beetle": 16, "alligator": 0}  # measured 10, 13, 0 (mesh normals)


@pytest.mark.parametrize("name", sorted(BOUNDARY_FLOORS))
def test_mesh_boundaries_of_open_models(name):
    import warnings

    p, n, ref, free, open_ = _mesh_reference(name)
    for normals, (lo, lo_free, lo_open, hi) in zip((n, None), BOUNDARY_FLOORS[name]):
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # no NaN RuntimeWarning (the beetle raised one)
            rep = detect_boundary(p, normals)
        assert np.all(np.isfinite(rep.gap)) and np.all(np.isfinite(rep.offset))
        recall, recall_free, recall_open, false_pos, near = _scores(p, rep, ref, free, open_)
        assert recall >= lo and recall_free >= lo_free and recall_open >= lo_open and false_pos <= hi, (
            recall, recall_free, recall_open, false_pos, rep.n_loops)
        assert rep.n_loops <= 10
        if normals is not None:  # false positives more than 2 local spacings from the mesh boundary
            assert round((1 - near) * (rep.mask & ~ref).sum()) <= FAR_FALSE_POSITIVES[name]
    if name == "teapot":  # consistently oriented mesh normals separate the lid from the rim
        assert free.sum() == 107 and open_.sum() == 22  # the handle's ends and the spout's base lie inside the body
        rep = detect_boundary(p, n, oriented=True)
        recall, _, recall_open, false_pos, _ = _scores(p, rep, ref, free, open_)
        assert recall_open >= 0.85 and false_pos <= 0.25  # measured 0.909, 0.206
        old = detect_boundary(p, n, oriented=True, resolve=None)  # 0.894 / 0.935 / 0.909, 0.251
        assert _scores(p, old, ref, free, open_)[0] > recall and not (rep.mask & ~old.mask).any()


# Closed models: every flagged particle is a false positive. Measured with the meshes' normals
# (``resolve=None`` in brackets): cow 155 (196), homer 10 (22), rocker-arm 141 (268), cheburashka
# 171 (173). What is left: voids of the vertex sampling about as wide as the neighbourhood (the
# rocker-arm's large flat triangles: the nearest particle across the gap lies 1.0-1.5 k-th
# neighbour distances away, in plane, 1.6-4 times the step beyond it, as across a hole of radius 3
# spacings, which is found), and thin parts and tight bends (the cow's legs and horns,
# cheburashka's ears: across the gap the surface rises 50-60 degrees out of the tangent plane).
CLOSED_FLAGGED = {"cow": 175, "homer": 15, "rocker-arm": 160, "cheburashka": 190}


@pytest.mark.parametrize("name", sorted(CLOSED_FLAGGED))
def test_closed_models_flag_few(name):
    p, n, ref, _, _ = _mesh_reference(name)
    assert not ref.any()
    rep = detect_boundary(p, n)
    old = detect_boundary(p, n, resolve=None)
    assert rep.n_boundary <= CLOSED_FLAGGED[name] and not (rep.mask & ~old.mask).any()


def _holed_sphere(sampling, n=6000, seed=1, radii=(1, 1.5, 2, 3, 4, 6)):
    """A sphere with six round holes of the given radii (in mean spacings sqrt(4 pi / n)), centred
    on the axes; returns the points, normals, each point's hole and distance to its rim (spacings)."""
    c = shapes.sphere(n, sampling=sampling, seed=seed)
    h = np.sqrt(4 * np.pi / n)
    centres = np.r_[np.eye(3), -np.eye(3)]
    d = (np.arccos(np.clip(c.points @ centres.T, -1, 1)) - np.asarray(radii) * h) / h
    keep = (d > 0).all(axis=1)
    return c.points[keep], c.normals[keep], d[keep].argmin(axis=1), d[keep].min(axis=1)


@pytest.mark.parametrize("sampling", ["poisson", "random", "variable"])
def test_small_holes(sampling):
    """Exact answers: holes of radius 1-6 spacings. The rim of a hole of radius 3 spacings or more
    is found whole (measured: poisson and random 9/9, 12/12 or 8/8, 17/17 or 15/15; variable 5/8
    at 3, all from 4), with no particle flagged more than 2 spacings from a rim (random: 9, in its
    own voids); holes of radius 1-1.5 (2 for poisson and random) are not: no particle of such a
    rim has a half-plane empty. Those of 3-4 spacings are kept by their size (``seed_size``), not
    by a seed: without it, only the largest (poisson) or the three largest (random) remain."""
    p, n, hole, d = _holed_sphere(sampling)
    rep = detect_boundary(p, n)
    rim = d < 0.5
    found = {r: rep.mask[rim & (hole == j)].mean() for j, r in enumerate((1, 1.5, 2, 3, 4, 6))}
    assert found[4] == 1.0 and found[6] == 1.0
    assert found[3] >= (0.6 if sampling == "variable" else 1.0)
    assert found[1] == 0.0 and found[1.5] == 0.0
    assert rep.mask[d > 2].sum() <= (10 if sampling == "random" else 0)
    strict = detect_boundary(p, n, seed_size=None)
    assert not (strict.mask & ~rep.mask).any()
    assert strict.n_loops < rep.n_loops if sampling != "random" else strict.n_loops == rep.n_loops


if __name__ == "__main__":  # the numbers behind BOUNDARY_FLOORS: python tests/test_boundary.py
    import sys
    from unittest import mock

    for name in ("teapot", "beetle", "alligator"):
        with mock.patch.object(pytest, "skip", side_effect=SystemExit):
            p, n, ref, free, open_ = _mesh_reference(name)
        for label, normals, kw in (("mesh normals", n, {}), ("mesh, oriented", n, {"oriented": True}), ("estimated", None, {})):
            rep = detect_boundary(p, normals, **kw)
            recall, recall_free, recall_open, fp, near = _scores(p, rep, ref, free, open_)
            print(f"{name:10s} {label:15s} recall {recall:.3f} (free {recall_free:.3f} of {int(free.sum())}, open "
                  f"{recall_open:.3f} of {int(open_.sum())})  false positives "
                  f"{fp:.3f} ({100 * near:.0f} % of them within 2 spacings of the mesh boundary)  pieces {rep.n_loops} "
                  f"({rep.n_boundary} flagged, {int(ref.sum())} mesh boundary vertices)")
            # against the open class alone: hits on the other mesh-boundary vertices count neither way
            judged = rep.mask & ~(ref & ~open_)
            print(f"{'':26s} open class only: recall {recall_open:.3f}, false positives "
                  f"{(rep.mask & ~ref).sum() / max(judged.sum(), 1):.3f} of {int(judged.sum())} judged")
    for sampling in ("poisson", "random", "variable"):
        p, n, hole, d = _holed_sphere(sampling)
        rep = detect_boundary(p, n)
        rim = d < 0.5
        print(f"sphere with holes of radius 1, 1.5, 2, 3, 4, 6 spacings, {sampling:8s}: rim found "
              + " ".join(f"{int(rep.mask[rim & (hole == j)].sum())}/{int((rim & (hole == j)).sum())}" for j in range(6))
              + f"; flagged > 2 spacings from a rim {int(rep.mask[d > 2].sum())}; pieces {rep.n_loops}")
    sys.exit(0)
