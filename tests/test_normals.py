"""Normal estimation: PCA accuracy, consistent and outward orientation, confidence, bad input."""

from pathlib import Path

import numpy as np
import pytest

from manifold_sph.normals import estimate_normals, orient_normals, pca_normals, tuning
from manifold_sph.reference import shapes


def dots(a, b):
    return np.einsum("ij,ij->i", a, b)


@pytest.mark.parametrize(
    "make, min_dot",
    [
        (lambda: shapes.sphere(2000), 0.999),
        (lambda: shapes.torus(3000), 0.98),
        (lambda: shapes.double_torus(3000), 0.93),
        (lambda: shapes.sphere(3000, sampling="variable", density_ratio=4), 0.995),
    ],
    ids=["sphere", "torus", "double_torus", "variable_sphere"],
)
def test_estimated_normals_are_accurate_and_outward(make, min_dot):
    cloud = make()  # built when the test runs, not at collection in every worker
    n = estimate_normals(cloud.points)
    assert n.shape == cloud.points.shape
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
    d = dots(n, cloud.normals)
    assert d.min() > min_dot  # every normal outward and close to the exact one


def test_pca_normal_error_decreases_with_resolution():
    errs = []
    for n in (1000, 4000):
        c = shapes.sphere(n)
        est, _ = pca_normals(c.points, k=12)
        errs.append(np.degrees(np.arccos(np.clip(np.abs(dots(est, c.normals)), 0, 1))).max())
    assert errs[1] < 0.6 * errs[0]  # O(h): halving the spacing roughly halves the error


def test_orientation_recovers_random_flips_on_two_components():
    a = shapes.sphere(800)
    b = shapes.torus(1500, center=(4.0, 0.0, 0.0))
    p = np.vstack([a.points, b.points])
    exact = np.vstack([a.normals, b.normals])
    signs = np.where(np.random.default_rng(1).random(len(p)) < 0.5, -1.0, 1.0)[:, None]
    n, labels = orient_normals(p, signs * exact)
    np.testing.assert_allclose(n, exact, atol=1e-12)
    assert labels.max() + 1 == 2
    assert np.array_equal(np.unique(labels[:800]), [labels[0]])


def test_consistent_is_consistent_and_none_is_raw():
    c = shapes.torus(2000)
    n = estimate_normals(c.points, orient="consistent")
    d = dots(n, c.normals)
    assert (d > 0).all() or (d < 0).all()
    raw = estimate_normals(c.points, orient="none", method="pca")
    pca, _ = pca_normals(c.points, k=16)
    np.testing.assert_allclose(raw, pca)


def test_viewpoint_orientation():
    c = shapes.sphere(500)
    n = estimate_normals(c.points, orient=[0.0, 0.0, 0.0])  # towards the centre: inward
    assert dots(n, c.normals).max() < -0.99


def test_flat_patch_is_oriented_deterministically():
    rng = np.random.default_rng(0)
    p = np.c_[rng.uniform(size=(300, 2)), np.zeros(300)]
    n = estimate_normals(p)
    np.testing.assert_allclose(n, np.tile([0.0, 0.0, 1.0], (300, 1)), atol=1e-12)


def test_confidence_separates_flat_from_isotropic():
    rng = np.random.default_rng(0)
    flat = np.c_[rng.uniform(size=(400, 2)), 1e-4 * rng.standard_normal(400)]
    blob = rng.standard_normal((400, 3))
    _, cf = estimate_normals(flat, return_confidence=True)
    _, cb = estimate_normals(blob, return_confidence=True)
    assert cf.min() > 0.99
    assert np.median(cb) < 0.6
    assert ((0 <= cb) & (cb <= 1)).all()


@pytest.mark.parametrize("noise", [0.1, 0.3])
def test_noisy_sphere_normals_stay_outward(noise):
    c = shapes.sphere(3000, sampling="poisson")
    spacing = np.sqrt(4 * np.pi / 3000)
    p = c.points + noise * spacing * np.random.default_rng(2).standard_normal(c.points.shape)
    radial = p / np.linalg.norm(p, axis=1)[:, None]
    for k, slope, measured in ((None, 30, (2.5, 8.3)), (24, 12, (1.1, 3.5))):
        n = estimate_normals(p, k=k)
        assert dots(n, radial).min() > 0.5  # all outward
        # mean error (degrees); the default (k = 16, distance-weighted) fits the noise, a larger
        # explicit k (uniform weights) averages it
        assert np.degrees(np.arccos(np.clip(dots(n, radial), -1, 1))).mean() < slope * noise + 0.5, measured


def test_noisy_torus_normals_stay_outward():
    # noise of 0.3 nearest-neighbour spacings: the probes of the winding number sit inside the
    # noisy layer and measure too small a jump; areas enlarged by it flipped 150 of 4000 normals
    # (measured), so the rescaling of step 4 only ever reduces areas (measured: none inward)
    from scipy.spatial import cKDTree

    c = shapes.torus(4000)
    spacing = np.median(cKDTree(c.points).query(c.points, 2)[0][:, 1])
    p = c.points + 0.3 * spacing * np.random.default_rng(3).standard_normal(c.points.shape)
    assert (dots(estimate_normals(p), c.normals) < 0).sum() == 0


def test_normals_do_not_depend_on_point_order_or_threads():
    """The same normals (and orientation) whatever the order of the points and the thread count:
    nothing in the estimate may depend on the array order (seed choice of the orientation, ties in
    the neighbour search) or on how rows are split between threads."""
    from manifold_sph import threads

    p = shapes.torus(1000).points
    ref = estimate_normals(p)
    with threads.limit(1):
        np.testing.assert_array_equal(estimate_normals(p), ref)
    perm = np.random.default_rng(0).permutation(len(p))
    np.testing.assert_allclose(estimate_normals(p[perm]), ref[perm], rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    "args, kwargs, exc, match",
    [
        ((np.zeros((5, 2)),), {}, ValueError, r"points must have shape \(N, 3\)"),
        ((np.full((20, 3), np.nan),), {}, ValueError, "points must be finite"),
        ((np.random.default_rng(0).random((20, 3)),), {"k": 2}, ValueError, "k must be at least 3"),
        ((np.random.default_rng(0).random((20, 3)),), {"k": 21}, ValueError, "k must be at most the number of points 20"),
        ((np.random.default_rng(0).random((20, 3)),), {"k": 5.5}, TypeError, "k must be an integer"),
        ((np.random.default_rng(0).random((20, 3)),), {"orient": "inward"}, ValueError, "orient must be one of"),
        ((np.random.default_rng(0).random((20, 3)),), {"orient": [1.0, 2.0]}, ValueError, r"viewpoint of shape \(3,\)"),
        ((np.zeros((2, 3)),), {}, ValueError, "at least 3 points"),
    ],
)
def test_bad_input(args, kwargs, exc, match):
    with pytest.raises(exc, match=match):
        estimate_normals(*args, **kwargs)


def test_orient_normals_shape_mismatch():
    p = np.random.default_rng(0).random((20, 3))
    with pytest.raises(ValueError, match=r"normals must have shape \(20, 3\)"):
        orient_normals(p, p[:10])


# ----------------------------------------------------------------------------- convergence orders
def _order(make, ns, **kw):
    err = []
    for n in ns:
        c = make(n)
        est = estimate_normals(c.points, **kw)
        err.append(np.degrees(np.arccos(np.clip(dots(est, c.normals), -1, 1))).mean())
    return np.polyfit(np.log([n**-0.5 for n in ns]), np.log(err), 1)[0], err


@pytest.mark.parametrize(
    "kw, minimum",
    [({}, 1.8), ({"degree": 3}, 2.7), ({"degree": 4}, 3.5), ({"method": "pca"}, 0.8)],
    ids=["default", "degree3", "degree4", "pca"],
)
def test_normal_error_order_on_poisson_torus(kw, minimum):
    # measured (benchmarks/normals.py, N = 2000, 8000): 2.0, 3.1, 4.6, 1.0
    slope, err = _order(lambda n: shapes.torus(n), (2000, 8000), **kw)
    assert slope >= minimum, (slope, err)


@pytest.mark.parametrize("sampling", ["fibonacci", "poisson"])
def test_normal_error_order_on_sphere(sampling):
    # measured: default 3.3 (fibonacci) / 3.0 (poisson), degree 3: 3.0, degree 4: 6
    for kw, minimum in (({}, 1.8), ({"degree": 3}, 2.7), ({"degree": 4}, 3.5)):
        slope, err = _order(lambda n: shapes.sphere(n, sampling=sampling), (1000, 4000), **kw)
        assert slope >= minimum, (kw, slope, err)


# ----------------------------------------------------------------------------- sharp edges
def _cube(m=16, jitter=0.2, seed=0):
    """Jittered grid samples of the faces of [-1, 1]^3 with the face normals."""
    rng = np.random.default_rng(seed)
    g = (np.arange(m) + 0.5) / m * 2 - 1
    u, v = [a.ravel() for a in np.meshgrid(g, g)]
    pts, nrm = [], []
    for ax in range(3):
        o = [a for a in range(3) if a != ax]
        for sgn in (-1.0, 1.0):
            p = np.zeros((m * m, 3))
            p[:, o[0]] = u + jitter * (2 / m) * (rng.random(m * m) - 0.5)
            p[:, o[1]] = v + jitter * (2 / m) * (rng.random(m * m) - 0.5)
            p[:, ax] = sgn
            pts.append(p)
            nrm.append(np.tile(np.eye(3)[ax] * sgn, (m * m, 1)))
    return np.vstack(pts), np.vstack(nrm)


def test_cube_normals_are_not_averaged_across_edges():
    p, exact = _cube()
    edge = np.sort(np.abs(p), axis=1)[:, 1] > 1 - 2 / 16 * 1.01  # the row next to an edge

    def angles(**kw):
        return np.degrees(np.arccos(np.clip(dots(estimate_normals(p, **kw), exact), -1, 1)))

    pca, default, d3 = angles(method="pca"), angles(), angles(degree=3)
    for ang in (pca, default, d3):
        assert ang.max() < 90  # all outward
    assert pca[~edge].max() > 10 and np.median(pca[edge]) > 30  # measured 17 and 33 degrees
    assert default[~edge].max() < 1e-6 and d3[~edge].max() < 1e-6  # flat faces exact
    assert np.median(default[edge]) < 27  # measured 25 degrees: the default k = 12 still straddles
    assert np.mean(d3[edge] < 5) > 0.95  # measured 0.99: degree 3 (k = 20) keeps to one face


# ----------------------------------------------------------------------------- thin and anisotropic parts
def _thin_torus(seed=0):
    """A torus tube (R = 1, r = 0.05) sampled 5 points around, and its exact normals."""
    c = shapes.thin_torus(seed=seed)
    return c.points, c.normals


def _ring_sphere(seed=0):
    """The unit sphere on 12 latitude rings of 80 points (6x denser along than across), and its normals."""
    c = shapes.ring_sphere(seed=seed)
    return c.points, c.normals


def _without_consensus(monkeypatch):
    from manifold_sph.normals import estimate

    monkeypatch.setattr(estimate, "consensus_normals", lambda pts, neighbors, normals, fixed=None: (normals, None))


def _unsigned_angles(n, exact):
    return np.degrees(np.arccos(np.clip(np.abs(dots(n, exact)), 0, 1)))


def _unweighted_base(monkeypatch):
    """The base jet fit before the distance weights: uniform weights on the 12 nearest."""
    monkeypatch.setattr(tuning, "JET_WEIGHT", 0.0)
    monkeypatch.setitem(tuning.DEFAULT_JET_K, 2, 12)


@pytest.mark.parametrize("seed", [0, 1])
def test_thin_tube_directions_by_consensus(seed, monkeypatch):
    # a tube 5 points around: the nearest reach across it and along it, the fits there
    # disagree with the 8- and 20-point ones; the consensus (module notes, step 7) picks the
    # candidate the neighbours' reflected normals agree with. Measured (seeds 0, 1): median
    # 7.2 / 7.3 deg, none > 30 deg; without the consensus 8.3 / 8.3 deg and 0 / 3 > 30 deg (the
    # distance-weighted base fit of step 2 keeps to the near side); with the former uniform
    # 12-point base fit 6.8 / 7.7 deg and none, and without the consensus 10.8 / 11.3 deg and
    # 55 / 44 particles > 30 deg
    p, exact = _thin_torus(seed=seed)
    n = estimate_normals(p)
    ang = _unsigned_angles(n, exact)
    assert (ang > 30).sum() <= 2 and np.median(ang) < 8.5, ((ang > 30).sum(), np.median(ang))
    assert dots(n, exact).min() > 0  # all outward
    _without_consensus(monkeypatch)
    alone = _unsigned_angles(estimate_normals(p), exact)
    assert (alone > 30).sum() <= 6, (alone > 30).sum()
    _unweighted_base(monkeypatch)
    old = _unsigned_angles(estimate_normals(p), exact)
    assert (old > 30).sum() > 30 and np.median(old) > 10  # the test can tell


def test_ring_sampled_sphere_directions_by_consensus(monkeypatch):
    # rows of points along latitude rings (the teapot's sampling): measured median 0.01 deg
    # and no normal > 30 deg off, with or without the consensus (the distance-weighted base
    # fit keeps to the ring's own row); with the former uniform 12-point fit 0.30 deg and 8 (37
    # without the consensus)
    p, exact = _ring_sphere()
    ang = _unsigned_angles(estimate_normals(p), exact)
    assert (ang > 30).sum() <= 2 and np.median(ang) < 0.05, ((ang > 30).sum(), np.median(ang))
    _without_consensus(monkeypatch)
    _unweighted_base(monkeypatch)
    old = _unsigned_angles(estimate_normals(p), exact)
    assert (old > 30).sum() >= 30 and np.median(old) > 0.2


def _meridian_torus(meridians=40, per=16, R=1.0, r=0.08, seed=0):
    """A thin torus sampled on planar meridian circles (a rolled lip, the rows of a surface of
    revolution): ``per`` points around each (jittered along it), meridians at jittered angles."""
    rng = np.random.default_rng(seed)
    phi = np.repeat((np.arange(meridians) + 0.3 * rng.random(meridians)) * 2 * np.pi / meridians, per)
    th = ((np.arange(per)[None, :] + 0.3 * rng.random((meridians, per))) * 2 * np.pi / per).ravel()
    n = np.c_[np.cos(th) * np.cos(phi), np.cos(th) * np.sin(phi), np.sin(th)]
    return np.c_[R * np.cos(phi), R * np.sin(phi), np.zeros_like(phi)] + r * n, n


@pytest.mark.parametrize("seed", [0, 1])
def test_meridian_rows_are_not_taken_for_the_surface(seed, monkeypatch):
    # 40 meridian circles of 16 points (spacing 0.03 along, 0.16 between): the nearest lie on
    # the particle's own circle and the fit returns the plane of the circle. Step 2b (module
    # notes) sees points steeply above and below that plane (the neighbouring circles) and
    # takes the normal across the rows. Measured (seeds 0, 1): 37 / 2 normals > 30 deg off,
    # none inward; without step 2b 281 / 343 and 39 / 60 inward
    p, exact = _meridian_torus(seed=seed)
    d = dots(estimate_normals(p), exact)
    ang = np.degrees(np.arccos(np.clip(np.abs(d), 0, 1)))
    assert (ang > 30).sum() <= 60 and (d < 0).sum() == 0, ((ang > 30).sum(), (d < 0).sum())
    monkeypatch.setattr(tuning, "ROW_STEEP", 0)  # step 2b off
    d = dots(estimate_normals(p), exact)
    assert (np.degrees(np.arccos(np.clip(np.abs(d), 0, 1))) > 30).sum() >= 200 and (d < 0).sum() >= 30


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_ring_sampled_sphere_with_polar_holes_points_outward(monkeypatch, seed):
    # the two tight rings around the polar holes: their 8 nearest lie on the ring, so the area
    # estimate pi r_8^2 / 7.5 is too small there and too large on the wide rings; the winding
    # numbers inside overshoot 1 and flipping the small polar rings lowered the objective (160
    # of 960 inward). Rescaled by the measured jump w_in - w_out (module notes, step 4): none
    p, exact = _ring_sphere(seed=seed)
    assert np.sum(dots(estimate_normals(p), exact) < 0) == 0
    monkeypatch.setattr(tuning, "CALIBRATE", False)
    assert np.sum(dots(estimate_normals(p), exact) < 0) >= 80  # the test can tell


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_ring_sampled_band_is_oriented_as_one_surface(monkeypatch, seed):
    # latitude rings 6x denser along than across: the k-NN graph falls apart into bands of
    # rings, each oriented alone (80-160 of 800 normals inward); bridged to their nearest other
    # band, the whole band (the sphere without its polar caps) points outward (measured 0)
    p, exact = _ring_sphere(seed=seed)
    p, exact = p[80:-80], exact[80:-80]
    assert np.sum(dots(estimate_normals(p), exact) < 0) == 0
    from manifold_sph.normals import graph, orientation

    knn_only = graph.orientation_graph

    def unbridged(pts, nrm, neighbors):
        a, b, s, length, comps = knn_only(pts, nrm, neighbors)
        ko = min(tuning.ORIENT_K, neighbors.shape[1])
        return (*graph.graph_edges(pts, nrm, neighbors[:, :ko]), comps)

    monkeypatch.setattr(orientation, "orientation_graph", unbridged)
    monkeypatch.setattr(tuning, "CALIBRATE", False)  # the area rescaling of step 4 alone also repairs it
    assert np.sum(dots(estimate_normals(p), exact) < 0) >= 80  # the test can tell


def _flat_ellipsoid(n=2000, thickness=1.0, seed=0):
    """A thin closed slab (:func:`manifold_sph.reference.shapes.flat_ellipsoid`): points, exact normals."""
    c = shapes.flat_ellipsoid(n, thickness, seed)
    return c.points, c.normals


@pytest.mark.parametrize("seed", [0, 1])
def test_visible_orientation_repairs_a_thin_closed_slab(seed):
    # a slab two spacings thick: the directions are right (median 0.03 deg) but propagation
    # carries the sign around the rim wrongly, leaving a band of one face next to the rim
    # inward (measured 160 / 86 of 2000, seeds 0, 1), and the winding number cannot resolve a
    # slab this thin. Visibility from outside (module notes, step 8) measured 7 / 7
    p, exact = _flat_ellipsoid(seed=seed)
    inward = np.mean(dots(estimate_normals(p), exact) < 0)
    assert inward > 0.02, inward  # the test can tell
    n, conf = estimate_normals(p, orient="visible", return_confidence=True)
    assert np.mean(dots(n, exact) < 0) <= 0.005
    assert ((0 <= conf) & (conf <= 1)).all()


@pytest.mark.parametrize("seed", [0, 1])
def test_probes_stay_inside_a_thin_closed_slab(seed, monkeypatch):
    # exact directions, random signs: the winding-number probes one spacing off the surface
    # cross a slab two spacings thick; at most half the height of the point straight across
    # (module notes, step 4) they stay inside. Measured (seeds 0, 1): 15 / 25 of 2000 inward,
    # with the usual offset 61 / 83
    p, exact = _flat_ellipsoid(seed=seed)
    signs = np.where(np.random.default_rng(0).random(len(p)) < 0.5, -1.0, 1.0)[:, None]
    n, _ = orient_normals(p, signs * exact)
    assert np.mean(dots(n, exact) < 0) <= 0.015
    monkeypatch.setattr(tuning, "THICK_PROBE", 0.0)
    n, _ = orient_normals(p, signs * exact)
    assert np.mean(dots(n, exact) < 0) >= 0.025  # the test can tell


def test_visible_orientation_leaves_closed_surfaces_alone():
    # the same signs as "outward" on a torus and through orient_normals (random flips of exact
    # normals); on a uniformly random sphere with noise of 0.3 spacings no more inward than
    # "outward" (measured seeds 4-6: 2 / 4 / 4 -> 1 / 3 / 3 of 2000)
    c = shapes.torus(2000)
    np.testing.assert_array_equal(estimate_normals(c.points, orient="visible"), estimate_normals(c.points))
    rng = np.random.default_rng(4)
    u = rng.standard_normal((2000, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    p = u + 0.3 * np.sqrt(4 * np.pi / 2000) * rng.standard_normal(u.shape)
    inward = (dots(estimate_normals(p, orient="visible"), u) < 0).sum()
    assert inward <= (dots(estimate_normals(p), u) < 0).sum() and inward <= 2, inward
    signs = np.where(rng.random(2000) < 0.5, -1.0, 1.0)[:, None]
    n, _ = orient_normals(c.points, signs * c.normals, orient="visible")
    np.testing.assert_allclose(n, c.normals, atol=1e-12)


def test_sharper_refit_weights_where_the_residual_is_bias_not_noise(monkeypatch):
    # step 5 refits with sharper Gaussian weights where the degree-3 fit explains much of the
    # degree-2 residual (coarse, curved: bias) and keeps the base weights on noise. Measured mean
    # errors, sharpened / base weights: Poisson torus 1000 points 0.31 / 0.38 deg, random torus
    # 0.44 / 0.55, double torus 2000 points 0.89 / 1.16; random sphere of 2000 points with noise of
    # 0.1 / 0.3 spacings (as drawn here) 2.32 / 2.28 and 12.09 / 11.80 deg (+1.7 % and +2.4 %)
    def mean_err(points, exact):  # direction only (signs are another test's business)
        d = np.abs(dots(estimate_normals(points), exact))
        return np.degrees(np.arccos(np.clip(d, 0, 1))).mean()

    rng = np.random.default_rng(0)
    sph = shapes.sphere(2000, sampling="random", seed=0)
    h = np.sqrt(4 * np.pi / 2000)
    cases = [(shapes.torus(1000).points, shapes.torus(1000).normals), (shapes.double_torus(2000).points, shapes.double_torus(2000).normals)]
    noisy = [(sph.points + a * h * rng.standard_normal(sph.points.shape), sph.normals) for a in (0.1, 0.3)]
    sharp = [mean_err(p, n) for p, n in cases + noisy]
    monkeypatch.setattr(tuning, "SHARP_WEIGHT", tuning.JET_WEIGHT)
    base = [mean_err(p, n) for p, n in cases + noisy]
    assert all(a <= 0.85 * b for a, b in zip(sharp[:2], base[:2])), (sharp, base)
    assert all(a <= 1.06 * b for a, b in zip(sharp[2:], base[2:])), (sharp, base)


def test_consensus_leaves_well_sampled_surfaces_alone(monkeypatch):
    # every normal agrees with the 8- and 20-point fits: nothing is undetermined, nothing changes
    c = shapes.torus(3000)
    with_c = estimate_normals(c.points, degree=3)
    _without_consensus(monkeypatch)
    np.testing.assert_array_equal(estimate_normals(c.points, degree=3), with_c)


# ----------------------------------------------------------------------------- test models
MODELS = Path(__file__).resolve().parents[2] / "shared" / "data" / "models"


def _mesh_reference(name):
    from manifold_sph.scans.io import read_mesh

    path = MODELS / name
    if not path.exists():
        pytest.skip(f"{path} not present")
    V, F = read_mesh(str(path))
    U, inv = np.unique(V, axis=0, return_inverse=True)  # merge duplicate vertices (teapot)
    F = inv.ravel()[F]
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    c = np.cross(U[F[:, 1]] - U[F[:, 0]], U[F[:, 2]] - U[F[:, 0]])
    N = np.zeros_like(U)
    for a in range(3):
        np.add.at(N, F[:, a], c)
    length = np.linalg.norm(N, axis=1)
    keep = length > 0
    keep[np.setdiff1d(np.arange(len(U)), F.ravel())] = False
    return U[keep], N[keep] / length[keep, None]


@pytest.mark.parametrize(
    "name, max_wrong, max_median, max_off",
    [
        # closed: share pointing inward (%), median angle (deg), particles > 30 deg off; measured
        # 1.72, 0.02, 0, 1.02 %, 5.40, 1.98, 3.00, 1.25 deg and 211, 19, 9, 187 (weighted base fit,
        # steps 2b and 4 as now); before: 2.7, 0.03, 0.01, 1.1 %, 6.2, 2.2, 3.2, 1.3 deg and 238,
        # 22, 18, 205 (before the consensus of step 7: 3.0, 0.02, 0, 1.1 %, 6.4, 2.2, 3.2, 1.3 deg
        # and 341, 34, 20, 206; MST+PCA: 13.9, 2.4, 0, 11.0 % and 9.7, 4.4, 6.4, 3.1 deg)
        # with the sharper refit weights of step 5 (module notes): cow 1.76 %, 5.18 deg, 207; homer
        # 0.02 %, 1.74, 21; rocker-arm 0, 2.77, 12; cheburashka 0.67 %, 1.03, 184
        ("cow.obj", 1.8, 5.7, 230),
        ("homer.obj", 0.1, 2.1, 25),
        ("rocker-arm.obj", 0.05, 3.1, 12),
        ("cheburashka.obj", 0.8, 1.3, 195),  # 0.67 % with the thickness-adapted probes of step 4
        # open or several shells: share disagreeing in sign with the mesh; measured 1.4, 2.9, 0 %,
        # 2.17, 8.75, 0 deg and 139, 155, 0; before: 11.3, 3.1, 0 %, 2.6, 10.4, 0 deg and 663,
        # 186, 0 (before step 7: 13.1, 3.1, 0 %, 2.7, 11.6, 0 deg and 845, 235, 0; MST+PCA: 10.8,
        # 3.0, 0 % and 6.3, 13.1, 0 deg)
        ("teapot.obj", 2.5, 2.3, 150),
        # with the sharper refit weights of step 5: teapot 1.95 deg, 133, 1.2 %; beetle 8.82 deg,
        # 154, 3.05 % (35 of 1148 disagreeing, 33 before)
        ("beetle.obj", 3.1, 9.2, 165),
        ("alligator.obj", 0.0, 0.01, 0),
    ],
)
def test_models_orientation_and_angle(name, max_wrong, max_median, max_off):
    P, ref = _mesh_reference(name)
    n = estimate_normals(P)
    d = dots(n, ref)
    ang = np.degrees(np.arccos(np.clip(np.abs(d), 0, 1)))
    assert 100 * np.mean(d < 0) <= max_wrong
    assert np.median(ang) <= max_median
    assert (ang > 30).sum() <= max_off


@pytest.mark.parametrize("name, max_median", [("cow.obj", 6.0), ("teapot.obj", 2.6)])
def test_high_degree_normals_guarded_on_coarse_models(name, max_median):
    # degree 4 (k = 30) unguarded reaches across thin parts: median 9.0 deg on the cow and
    # 12.3 on the teapot (degree 3); guarded (module notes, step 6) measured 6.5 and 3.4,
    # with the consensus of step 7 6.3 and 3.1 (default degree 2: 6.2 and 2.6); with the
    # weighted base fit and steps 2b and 4 as now 5.71 and 2.26 (degree 2: 5.47 and 2.17)
    P, ref = _mesh_reference(name)
    d = dots(estimate_normals(P, degree=4), ref)
    assert np.median(np.degrees(np.arccos(np.clip(np.abs(d), 0, 1)))) <= max_median


def test_msph4_from_bare_points_as_accurate_as_with_exact_normals():
    # Surface estimates normals of the scheme's degree (4 for msph4): on a Poisson-disk torus
    # of 4000 points the Laplacian error is within 10 % of the exact-normal one (measured
    # 1.02e-3 against 9.8e-4; uniform 12-point degree-2 normals give 1.31e-3, at 32k: 2.6e-5,
    # 2.5e-4; the default distance-weighted 16-point degree-2 ones 1.08e-3)
    from manifold_sph import PointCloud, Surface

    c = shapes.torus(4000, sampling="poisson", seed=0)
    bare = Surface(c.points, scheme="msph4")
    assert bare.normals_estimated
    err = {}
    for label, nrm in (("exact", c.normals), ("bare", bare.cloud.normals), ("degree2", estimate_normals(c.points, k=12))):
        err[label] = _lap_error(PointCloud(c.points, nrm, geometry=c.geometry))
    assert err["bare"] <= 1.1 * err["exact"], err
    assert err["degree2"] > 1.2 * err["exact"], err  # the test can tell


def _lap_error(cloud):
    from manifold_sph.reference.accuracy import operator_errors

    return operator_errors(cloud, "xyz", ["msph4"])[0]["lap_l2"]


@pytest.mark.parametrize("name, min_flagged, max_false", [("cow.obj", 0.83, 0.23), ("teapot.obj", 0.80, 0.27)])
def test_confidence_flags_doubtful_particles_on_a_model(name, min_flagged, max_false):
    """Normals more than 30 degrees off or pointing inward get a confidence below 0.5."""
    P, ref = _mesh_reference(name)
    n, conf = estimate_normals(P, return_confidence=True)
    doubtful = dots(n, ref) < np.cos(np.radians(30))
    flagged, false = np.mean(conf[doubtful] < 0.5), np.mean(conf[~doubtful] < 0.5)
    # measured with the scale term: cow 0.89 and 0.21, teapot 0.61 and 0.21 (without it
    # 0.31 and 0.08 of the doubtful normals were flagged: thin parts looked confident). The
    # consensus of step 7 repairs flagged normals only and leaves them flagged: the same 28 and
    # 269 doubtful normals are missed as before it (then 0.92 / 0.18 and 0.69 / 0.15 of 351 and
    # 871 doubtful; then of 253 and 697). With the row normals of step 2b (module notes) the
    # teapot has 152 doubtful normals (its lip and meridian rows repaired), of which 0.53 are
    # flagged (72 missed), and 0.24 of the others; the cow 0.86 and 0.21 of 218 (31 missed).
    # With the thickness term (module notes: a point steeply across closer than the spacing)
    # the teapot 0.88 and 0.24 (its lip and rows), the cow 0.88 and 0.22
    assert flagged >= min_flagged and false <= max_false, (flagged, false)


def test_confidence_thickness_term_ignores_noise(monkeypatch):
    # a Poisson sphere with noise of 0.3 spacings (every normal within 30 degrees): the
    # thickness term counts only points across by more than 4 times the cloud's noise level
    # (module notes); measured 1.4 % below 0.5 (0.9 % without the term, 11.5 % without the guard)
    c = shapes.sphere(3000, sampling="poisson")
    p = c.points + 0.3 * np.sqrt(4 * np.pi / 3000) * np.random.default_rng(2).standard_normal(c.points.shape)
    _, conf = estimate_normals(p, return_confidence=True)  # the noisy path
    assert np.mean(conf < 0.5) < 0.03
    monkeypatch.setattr(tuning, "NOISE_CLEAN", np.inf)  # the clean path
    _, conf = estimate_normals(p, return_confidence=True)
    assert np.mean(conf < 0.5) < 0.03
    monkeypatch.setattr(tuning, "THIN_NOISE", 0.0)
    _, conf = estimate_normals(p, return_confidence=True)
    assert np.mean(conf < 0.5) > 0.08  # the test can tell


def test_confidence_is_high_on_a_smooth_closed_surface():
    c = shapes.torus(4000)
    _, conf = estimate_normals(c.points, return_confidence=True)
    assert conf.min() > 0.8 and np.median(conf) > 0.95  # measured 0.93 and 0.99


# ----------------------------------------------------------------------------- new arguments
@pytest.mark.parametrize(
    "kwargs, exc, match",
    [
        ({"method": "svd"}, ValueError, r"method must be one of \['jet', 'pca'\], got 'svd'"),
        ({"degree": 5}, ValueError, "degree must be an integer from 1 to 4, got 5"),
        ({"degree": 2.0}, TypeError, "degree must be an integer from 1 to 4, got float"),
        ({"method": "pca", "degree": 2}, ValueError, "degree applies only to method='jet'"),
        ({"degree": 4, "k": 12}, ValueError, "k must be at least 17 for a degree-4 jet fit, got 12"),
        ({"refine": "yes"}, TypeError, "refine must be a bool, got str"),
        ({"return_confidence": 1}, TypeError, "return_confidence must be a bool, got int"),
        ({"poles": "yes"}, TypeError, "poles must be a bool, got str"),
    ],
)
def test_bad_new_arguments(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        estimate_normals(np.random.default_rng(0).random((40, 3)), **kwargs)


def test_default_k_needs_enough_points():
    with pytest.raises(ValueError, match="at least 16 points for a degree-2 jet fit"):
        estimate_normals(np.random.default_rng(0).random((15, 3)))
    n = estimate_normals(np.random.default_rng(0).random((10, 3)), method="pca")  # k capped at N
    assert n.shape == (10, 3)


def test_winding_number_numpy_and_compiled_agree(monkeypatch):
    from manifold_sph import _jit
    from manifold_sph.normals import winding

    c = shapes.sphere(400)
    area = np.full(400, 4 * np.pi / 400)
    q = np.vstack([0.5 * c.points[:50], 1.5 * c.points[:50]])
    lab = (np.arange(400) % 3).astype(np.int64)
    fast = winding.winding_numbers(q, c.points, c.normals, area, 0.01 * np.ones(400), lab, 3, theta=0.3)
    monkeypatch.setattr(_jit, "ENABLED", False)
    slow = winding.winding_numbers(q, c.points, c.normals, area, 0.01 * np.ones(400), lab, 3)
    np.testing.assert_allclose(fast.sum(1)[:50], 1.0, atol=0.02)  # inside
    np.testing.assert_allclose(fast.sum(1)[50:], 0.0, atol=0.02)  # outside
    np.testing.assert_allclose(fast, slow, atol=0.02)


# ----------------------------------------------------------------------------- Voronoi poles
def _angles(a, b):
    a = a / np.linalg.norm(a, axis=1)[:, None]
    return np.degrees(np.arccos(np.clip(np.abs(dots(a, b)), 0.0, 1.0)))


@pytest.mark.parametrize("n, max_mean, max_max", [(2000, 2.5, 9.0), (8000, 1.1, 4.5)])
def test_voronoi_poles_give_the_normal_line_on_a_torus(n, max_mean, max_max):
    # the pole vector converges to the normal line (Amenta & Bern); Poisson torus, measured mean /
    # max angle 1.97 / 7.6 deg at 2000 points, 0.85 / 3.8 at 8000; the two poles on opposite sides
    from manifold_sph.normals.poles import voronoi_poles

    c = shapes.torus(n)
    pole, radius, second = voronoi_poles(c.points)
    a = _angles(pole, c.normals)
    assert a.mean() <= max_mean and a.max() <= max_max, (a.mean(), a.max())
    assert np.all(np.linalg.norm(second, axis=1) > 0)
    assert _angles(second, c.normals).max() <= max_max
    u1 = pole / np.linalg.norm(pole, axis=1)[:, None]
    u2 = second / np.linalg.norm(second, axis=1)[:, None]
    assert dots(u1, u2).max() < -0.98  # measured -0.989
    hull = np.isinf(radius)
    assert 0 < hull.sum() < n and np.all(radius[~hull] > 0)
    # on the hull the pole is at infinity, outward; elsewhere the radius is that of the pole's empty ball
    assert np.all(dots(u1[hull], c.normals[hull]) > 0.9)
    from scipy.spatial import cKDTree

    gap = cKDTree(c.points).query(c.points[~hull] + pole[~hull])[0]
    np.testing.assert_allclose(gap, radius[~hull], rtol=1e-6)


def test_voronoi_poles_with_duplicate_points():
    # an exact duplicate is a vertex of no tetrahedron: its pole is zero, and poles=True then
    # keeps its normal (same normals as the default on a torus with 50 duplicated points)
    from manifold_sph.normals.poles import voronoi_poles

    c = shapes.torus(2000)
    p = np.vstack([c.points, c.points[:50]])
    pole, radius, second = voronoi_poles(p)
    zero = np.linalg.norm(pole, axis=1) == 0
    assert zero.sum() == 50 and np.all(radius[zero] == 0)
    np.testing.assert_array_equal(estimate_normals(p, poles=True), estimate_normals(p))


def test_voronoi_poles_bad_input():
    from manifold_sph.normals.poles import voronoi_poles

    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="at least 5 points"):
        voronoi_poles(rng.random((4, 3)))
    with pytest.raises(ValueError, match="span a volume"):
        voronoi_poles(np.c_[rng.random((50, 2)), np.zeros(50)])
    with pytest.raises(ValueError, match="points must be finite"):
        voronoi_poles(np.full((10, 3), np.nan))
    with pytest.raises(ValueError, match=r"points must have shape \(N, 3\)"):
        voronoi_poles(rng.random((10, 2)))


@pytest.mark.parametrize("make", [lambda: shapes.sphere(1000), lambda: shapes.torus(3000)], ids=["sphere", "torus"])
def test_pole_signs_repair_isolated_flips_and_leave_right_signs(make):
    # step 9 alone: exact normals with 5 % flipped at random; the winding number at the two poles
    # of each particle (the far, medial ones) is that of the right majority: all repaired, and
    # none flipped where the signs are right
    from scipy.spatial import cKDTree

    from manifold_sph.normals import poles
    from manifold_sph.normals.poles import voronoi_poles

    c = make()
    vor = voronoi_poles(c.points)
    dist = cKDTree(c.points).query(c.points, 16)[0]
    s = np.where(np.random.default_rng(1).random(len(c.points)) < 0.05, -1.0, 1.0)
    n, flip = poles.pole_signs(c.points, s[:, None] * c.normals, dist, vor)
    assert flip.sum() == (s < 0).sum() > 20
    np.testing.assert_array_equal(n, c.normals)
    n, flip = poles.pole_signs(c.points, c.normals, dist, vor)
    assert not flip.any()


def test_poles_option_keeps_smooth_surfaces_and_planes():
    # poles=True changes only undetermined normals (step 7) and signs (step 9): none on a torus or
    # sphere; a planar cloud has no poles and is left to the default
    c = shapes.torus(3000)
    np.testing.assert_array_equal(estimate_normals(c.points, poles=True), estimate_normals(c.points))
    c = shapes.sphere(2000, sampling="poisson")
    np.testing.assert_array_equal(estimate_normals(c.points, poles=True), estimate_normals(c.points))
    p = np.c_[np.random.default_rng(0).random((200, 2)), np.zeros(200)]
    np.testing.assert_array_equal(estimate_normals(p, poles=True), estimate_normals(p))


@pytest.mark.parametrize("seed", [0, 1])
def test_poles_option_on_thin_closed_slabs(seed):
    # a slab 4 spacings thick (third semi-axis 2 spacings): inward measured 7 / 8 -> 3 / 5 (seeds
    # 0, 1); 2 spacings thick 160 / 86 -> 152 / 79 (the band next to the rim is not reached)
    p, exact = _flat_ellipsoid(thickness=2.0, seed=seed)
    before = (dots(estimate_normals(p), exact) < 0).sum()
    after = (dots(estimate_normals(p, poles=True), exact) < 0).sum()
    assert before >= 7 and after <= before - 3, (before, after)


@pytest.mark.parametrize(
    "name, before, after",
    [
        # wrong orientations (closed: inward; open: disagreeing with the mesh), default -> poles=True;
        # measured cow 51 -> 39 of 2903, teapot 50 -> 38 of 3241 (40 -> 29 before the thin-part cuts
        # of step 3 and the crossing sheets of step 4), beetle 35 -> 32 of 1148
        ("cow.obj", 48, 42),
        ("teapot.obj", 45, 42),
        ("beetle.obj", 34, 33),
    ],
)
def test_poles_option_orients_thin_parts_of_coarse_models(name, before, after):
    P, ref = _mesh_reference(name)
    closed = name != "teapot.obj" and name != "beetle.obj"
    wrong = (lambda n: (dots(n, ref) < 0).sum()) if closed else (lambda n: (dots(n, ref) <= 0).sum())
    assert wrong(estimate_normals(P)) >= before  # the test can tell
    assert wrong(estimate_normals(P, poles=True)) <= after


def _random_sample(name, seed, m=None):
    """Area-uniform random points of a model (as many as it has vertices, at least 2000; the
    sampling of ``benchmarks/normals.py --random``), their face normals, and closed?"""
    from manifold_sph.reference.sampling import sample_triangles
    from manifold_sph.scans.io import read_mesh

    path = MODELS / name
    if not path.exists():
        pytest.skip(f"{path} not present")
    V, F = read_mesh(str(path))
    U, inv = np.unique(V, axis=0, return_inverse=True)
    F = inv.ravel()[F]
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    c = np.cross(U[F[:, 1]] - U[F[:, 0]], U[F[:, 2]] - U[F[:, 0]])
    A = np.linalg.norm(c, axis=1)
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    closed = bool(np.all(np.unique(e, axis=0, return_counts=True)[1] == 2))
    m = max(2000, int(np.unique(F).size)) if m is None else m
    P, f = sample_triangles(U, F, m, seed)
    return P, c[f] / A[f, None], closed


def test_flipped_patch_in_a_narrow_gap_is_cut_and_flipped(monkeypatch):
    # homer, 6002 area-uniform random points (seed=1): propagation carries a wrong sign into a
    # patch at a narrow gap (right directions) over confident tree edges; its probes read both
    # inside (w_in + w_out about 2: the outer probe lies in the gap), which the D < 0 / S < 0.5
    # flags miss. Both-inside regions of at least 12 particles are cut as patches of their own
    # (module notes, step 4): measured 71 -> 8 normals inward
    P, ref, closed = _random_sample("homer.obj", 1)
    assert closed
    assert (dots(estimate_normals(P), ref) < 0).sum() <= 20
    monkeypatch.setattr(tuning, "FLAG_S_HIGH", None)
    assert (dots(estimate_normals(P), ref) < 0).sum() >= 50  # the test can tell


def test_part_inside_another_shell_keeps_its_propagated_sign(monkeypatch):
    # teapot, 3241 random points (seed=0): the body's wall inside the spout reads both inside
    # either way; such a patch is flipped only where the flip removes at least half of its
    # excess w_in + w_out - 1 (a flipped patch in a gap: nearly all). Disagreeing with the
    # mesh, measured: 70 (as without the both-inside patches), 96 without that condition
    P, ref, closed = _random_sample("teapot.obj", 0)
    assert not closed
    assert (dots(estimate_normals(P), ref) <= 0).sum() <= 78
    monkeypatch.setattr(tuning, "FLAG_S_EXPLAIN", np.inf)
    assert (dots(estimate_normals(P), ref) <= 0).sum() >= 86  # the test can tell


def test_best_signs_margin_keeps_an_entry():
    from manifold_sph.normals.winding import best_signs as _best_signs

    # two independent entries that both want to flip (g < 0); an infinite margin keeps the second
    H = np.zeros((2, 2))
    g = np.array([-1.0, -1.0])
    blocks = np.zeros((0, 2))
    assert np.array_equal(_best_signs(H, g, blocks), [-1.0, -1.0])
    assert np.array_equal(_best_signs(H, g, blocks, np.array([0.0, np.inf])), [-1.0, 1.0])


def _crossing_spheres(parts, sampling="random", seed=0):
    clouds = [shapes.sphere(n, radius=r, center=c, sampling=sampling, seed=seed + 10 * i) for i, (n, r, c) in enumerate(parts)]
    return np.vstack([c.points for c in clouds]), np.vstack([c.normals for c in clouds])


@pytest.mark.parametrize("sampling, seed", [("random", 0), ("poisson", 1)])
def test_closed_surfaces_passing_through_each_other_face_out(monkeypatch, sampling, seed):
    # two closed spheres passing through each other (the parts of an artist's model or an
    # assembly): the part of each inside the other read both inside in the whole field, and the
    # patch check flipped it (1037-1098 of 6560 wrong, measured). The closed sheets of step 4 are
    # judged by their own field: measured 7-10 (random), 0-1 (Poisson) wrong, seeds 0-2
    P, exact = _crossing_spheres([(4000, 1.0, (0, 0, 0)), (2560, 0.8, (1.2, 0, 0))], sampling, seed)
    assert (dots(estimate_normals(P), exact) < 0).sum() <= 0.005 * len(P)
    monkeypatch.setattr(tuning, "SHEETS", False)
    assert (dots(estimate_normals(P), exact) < 0).sum() >= 0.1 * len(P)  # the test can tell


@pytest.mark.parametrize("noise", [0.0, 0.3])
def test_sphere_wholly_inside_another_is_a_part_or_a_cavity(noise):
    # nested closed spheres: by default the inner one is a part of its own (normals out of it);
    # nested="cavity" reads it as the inner wall of a hollow ball (normals into the cavity).
    # Clean and noisy (0.3 spacings: the noisy path)
    P, exact = _crossing_spheres([(4000, 1.0, (0, 0, 0)), (1000, 0.5, (0.1, 0, 0))])
    P = P + noise * np.sqrt(4 * np.pi / 4000) * np.random.default_rng(0).normal(size=P.shape)
    d = dots(estimate_normals(P), exact)
    assert (d[:4000] < 0).sum() == 0 and (d[4000:] < 0).sum() == 0
    d = dots(estimate_normals(P, nested="cavity"), exact)
    assert (d[:4000] < 0).sum() == 0 and (d[4000:] < 0).sum() == 1000


def test_closed_sheets_leave_one_coarse_surface_alone():
    # one closed surface is one sheet: nothing to judge apart (a smooth sphere; the coarse models'
    # vertex clouds, whose pieces are cut apart by high curvature, are checked in the model tests)
    from scipy.spatial import cKDTree

    from manifold_sph.normals import shells

    P = shapes.sphere(3000, sampling="random", seed=0).points
    d, idx = cKDTree(P).query(P, 16)
    n = P / np.linalg.norm(P, axis=1)[:, None]
    h = np.sqrt(np.pi * d[:, 7] ** 2 / 7.5)
    assert shells.closed_sheets(P, n, idx, np.arange(len(P)), h, h**2, h) is None


def test_eyes_half_out_of_a_head_face_out(monkeypatch):
    # two closed eyes (400 random points each) half out of a head (12,000): the whole field read
    # both inside on their inner parts and flipped them (480-521 of 800 wrong, measured). An eye's
    # outer cap joins the head's sheet; its inner part, open, is still judged by its own field:
    # 0-11 wrong (seeds 0-2)
    parts = [(12000, 1.0, (0, 0, 0))] + [(400, 0.18, (x, 0.3, np.sqrt(1 - x * x - 0.09) - 0.08)) for x in (-0.35, 0.35)]
    P, exact = _crossing_spheres(parts, "random", 0)
    d = dots(estimate_normals(P), exact)
    assert (d[12000:] < 0).sum() <= 20 and (d[:12000] < 0).sum() <= 150
    monkeypatch.setattr(tuning, "SHEETS", False)
    monkeypatch.setattr(tuning, "PART_SHEETS", False)  # the sheets as parts (shells) alone: 201 wrong, measured
    assert (dots(estimate_normals(P), exact)[12000:] < 0).sum() >= 300  # the test can tell


@pytest.mark.parametrize("name, seed, before, after", [("alligator.obj", 0, 1089, 10), ("teapot.obj", 1, 652, 260)])
def test_noise_is_not_a_thin_part(monkeypatch, name, seed, before, after):
    # vertices with noise of 0.3 nearest-neighbour spacings: where the reflection rule and the
    # parallel rule disagree on a spanning-tree edge (noise tilts the edge out of the tangent
    # plane, or a real thin part), the edge now separates patches and the winding number decides;
    # propagation had carried a wrong sign into a third of the planar alligator (1089 -> 3
    # wrong, measured) and the teapot's lid (652 -> 198)
    from scipy.spatial import cKDTree

    P, ref = _mesh_reference(name)
    h = np.median(cKDTree(P).query(P, 2)[0][:, 1])
    Q = P + 0.3 * h * np.random.default_rng(seed).normal(size=P.shape)
    assert (dots(estimate_normals(Q), ref) < 0).sum() <= after  # the default: the noisy path (alligator 0, teapot 235)
    monkeypatch.setattr(tuning, "NOISE_CLEAN", np.inf)  # the clean path, where the cuts of step 3 act
    assert (dots(estimate_normals(Q), ref) < 0).sum() <= after
    monkeypatch.setattr(tuning, "CUT_THIN", 0.0)
    assert (dots(estimate_normals(Q), ref) < 0).sum() >= 0.8 * before  # the test can tell


# ----------------------------------------------------------------------------- k="auto", global orientation
def _noisy_sphere(n=4000, noise=0.3, seed=0):
    """Area-uniform random points of the unit sphere with Gaussian noise of ``noise`` spacings
    (per coordinate); the exact normals of the points before the noise."""
    c = shapes.sphere(n, sampling="random", seed=seed)
    h = np.sqrt(4 * np.pi / n)
    return c.points + noise * h * np.random.default_rng(seed + 100).normal(size=c.points.shape), c.normals, h


@pytest.mark.parametrize("noise", [0.0, 0.2, 0.5])
def test_noise_level_reads_the_noise_not_the_shape(noise):
    # Gaussian noise of s per coordinate puts s along the normal: the two-scale residual
    # decomposition reads it within 25 %, and about 0 on a clean, strongly curved cloud
    # (a torus of tube radius 0.25 on 3000 points: its quadric fits are biased, not noisy)
    from manifold_sph.normals.fitting import covariance, knn
    from manifold_sph.normals.scale import noise_level

    P, _, h = _noisy_sphere(4000, noise)
    dist, idx = knn(P, 32)
    sigma, spacing = noise_level(P, idx, dist, covariance(P, idx[:, :10])[1][:, :, 0])
    if noise:
        assert abs(np.median(sigma) / (noise * h) - 1.0) < 0.25
    else:
        assert np.median(sigma) < 0.02 * h
    T = shapes.torus(3000, R=1.0, r=0.25).points
    dist, idx = knn(T, 32)
    sigma, spacing = noise_level(T, idx, dist, covariance(T, idx[:, :10])[1][:, :, 0])
    assert np.median(sigma / spacing) < 0.05


def test_auto_scale_follows_the_noise():
    # the neighbourhood grows with the relative noise: 16 on a clean cloud, more on a noisy one,
    # and the noisy sphere's normals are more accurate than with the clean default (k=16)
    from manifold_sph.normals import tuning
    from manifold_sph.normals.scale import auto_k

    sp = np.ones(5)
    assert list(auto_k(np.array([0.0, 0.1, 0.3, 0.5, 1.0]), sp, 10000)) == [16, 16, 32, 64, 96]
    assert auto_k(np.array([1.0]), np.ones(1), 50)[0] <= 50
    P, exact, h = _noisy_sphere(4000, 0.5)
    err_auto = np.degrees(np.arccos(np.clip(dots(estimate_normals(P), exact), -1, 1)))
    err_16 = np.degrees(np.arccos(np.clip(np.abs(dots(estimate_normals(P, k=tuning.DEFAULT_JET_K[2]), exact)), 0, 1)))
    assert err_auto.max() < 90  # all outward (with k=16, some are not)
    assert np.sqrt(np.mean(err_auto**2)) < 0.6 * np.sqrt(np.mean(err_16**2))  # unsigned angles; measured 0.4


@pytest.mark.parametrize("noise", [0.3, 0.6])
def test_global_orientation_of_random_signs_on_noisy_clouds(noise):
    # exact directions with random signs on a noisy sphere and a noisy torus next to it (two
    # closed parts): the patches, their winding-number signs and the attached rest give every
    # normal its outward sign
    from manifold_sph.normals.fitting import knn
    from manifold_sph.normals.patches import global_orientation

    a = shapes.sphere(3000, sampling="random", seed=1)
    b = shapes.torus(4000, center=(3.5, 0.0, 0.0), sampling="random", seed=2)
    P = np.vstack([a.points, b.points])
    exact = np.vstack([a.normals, b.normals])
    h = np.sqrt(4 * np.pi / 3000)
    P = P + noise * h * np.random.default_rng(3).normal(size=P.shape)
    signs = np.where(np.random.default_rng(4).random(len(P)) < 0.5, -1.0, 1.0)[:, None]
    dist, idx = knn(P, 32)
    n, _ = global_orientation(P, signs * exact, idx, dist, np.full(len(P), noise * h))
    assert (dots(n, exact) < 0).sum() <= 0.002 * len(P)


def test_dipole_agreement_on_a_sheet_and_across_a_thin_part():
    from manifold_sph.normals.patches import dipole_agreement

    P = np.array([[0.0, 0, 0], [1, 0, 0], [0, 0, 0.5]])
    up = np.array([0.0, 0, 1])
    n = np.array([up, up, -up])  # a sheet (0, 1) and the other side of a thin plate (2, facing away)
    a, b = np.array([0, 0]), np.array([1, 2])
    assert np.all(dipole_agreement(P, n, a, b, np.zeros(3)) > 0)
    assert np.all(dipole_agreement(P, -n * np.array([[1], [-1], [-1]]), a, b, np.zeros(3)) < 0)
    # noise larger than the thickness: the edge across reads as lying in the plane (the sign of n . n)
    assert dipole_agreement(P, n, a[1:], b[1:], np.full(3, 1.0))[0] < 0


def test_integer_signs_recover_crossing_spheres():
    # two spheres through each other, cut into 8 patches, three flipped: the field counting whole
    # parts (1 inside one sphere, 2 inside both) is restored by flipping them back
    from manifold_sph.normals.fitting import knn
    from manifold_sph.normals.winding import integer_signs, winding_numbers

    a = shapes.sphere(3000, sampling="random", seed=0)
    b = shapes.sphere(2000, radius=0.7, center=(1.0, 0, 0), sampling="random", seed=1)
    P = np.vstack([a.points, b.points])
    exact = np.vstack([a.normals, b.normals])
    lab = (np.arange(len(P)) >= 3000) * 4 + (P[:, 1] > 0) * 2 + (P[:, 2] > 0)
    s0 = np.ones(8)
    s0[[1, 5, 6]] = -1.0
    n = exact * s0[lab][:, None]
    dist, _ = knn(P, 8)
    area = np.pi * dist[:, 7] ** 2 / 7.5
    h = np.sqrt(area)
    W = winding_numbers(np.vstack([P - h[:, None] * n, P + h[:, None] * n]), P, n, area, 0.2 * h, lab, 8)
    assert np.array_equal(integer_signs(W, lab, np.ones(8), area), s0)


def test_point_like_input_everywhere():
    from manifold_sph import PointCloud
    from manifold_sph.normals import jet_normals, voronoi_poles

    c = shapes.sphere(500)
    pc = PointCloud(c.points)
    np.testing.assert_array_equal(estimate_normals(pc), estimate_normals(c.points))
    np.testing.assert_array_equal(pca_normals(pc)[0], pca_normals(c.points)[0])
    np.testing.assert_array_equal(jet_normals(pc), jet_normals(c.points))
    np.testing.assert_array_equal(orient_normals(pc, c.normals)[0], orient_normals(c.points, c.normals)[0])
    np.testing.assert_array_equal(voronoi_poles(pc)[0], voronoi_poles(c.points)[0])


@pytest.mark.parametrize("kwargs, match", [({"k": "wide"}, "k must be a positive integer or 'auto'"),
                                           ({"nested": "hollow"}, "nested must be one of")])
def test_bad_auto_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        estimate_normals(shapes.sphere(200).points, **kwargs)


def test_unique_sorted_is_np_unique():
    from manifold_sph.normals.arrays import unique_sorted

    x = np.random.default_rng(0).integers(0, 1000, (300, 7))
    u, inv = np.unique(x, return_inverse=True)
    np.testing.assert_array_equal(unique_sorted(x), u)
    got_u, got_inv = unique_sorted(x, return_inverse=True)
    np.testing.assert_array_equal(got_u, u)
    np.testing.assert_array_equal(got_inv, inv.ravel())
    assert unique_sorted(np.zeros(0, dtype=np.int64)).size == 0


@pytest.mark.parametrize("degree", [1, 2, 3, 4])
def test_jet_fit_compiled_and_numpy_agree(degree):
    # the compiled kernel of the jet fits and its numpy twin: the same normals, residuals and
    # kurtosis to round-off, with weights, per-row degrees (0 keeps the frame) and row centres
    from manifold_sph.normals.fitting import covariance, jet_fit, jet_fit_numpy, knn

    c = shapes.torus(1500, sampling="random", seed=1)
    dist, idx = knn(c.points, 24)
    frame = covariance(c.points, idx[:, :10])[1][:, :, 0]
    w = np.random.default_rng(0).random(idx.shape)
    degs = np.where(np.arange(1500) % 7 == 0, 0, degree)
    out = []
    for fit in (jet_fit, jet_fit_numpy):
        r, k = np.zeros(1500), np.zeros(1500)
        out.append((fit(c.points, idx, frame, degs, weights=w, residual=r, kurtosis=k), r, k))
    np.testing.assert_allclose(out[0][0], out[1][0], atol=1e-9)
    np.testing.assert_allclose(out[0][1], out[1][1], atol=1e-9)
    np.testing.assert_allclose(out[0][2], out[1][2], rtol=1e-6)
    np.testing.assert_array_equal(out[0][0][degs == 0], frame[degs == 0])


@pytest.mark.slow
def test_multi_part_character_sheets_as_parts(monkeypatch):
    # the 24-part character of benchmarks/normals.py (seed 0, 32,598 points): its hat, a torus
    # resting on the head, was read inward with the head's field (883 of 2190 wrong); as a sheet of
    # its own, judged by its own field, 37. Measured: 97.94 % right signs, 95.34 % without
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from normals import multi_part  # benchmarks/normals.py

    P, ref, part, _ = multi_part("character", 0)
    assert np.mean(dots(estimate_normals(P), ref) > 0) >= 0.975
    monkeypatch.setattr(tuning, "PART_SHEETS", False)
    assert np.mean(dots(estimate_normals(P), ref) > 0) <= 0.96  # the test can tell
