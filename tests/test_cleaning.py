"""Cleaning: duplicates, outliers, voxel downsampling, each reporting what it removed."""

from pathlib import Path

import numpy as np
import pytest

from manifold_sph import PointCloud
from manifold_sph.reference import shapes
from manifold_sph.scans.cleaning import clean, merge_duplicates, remove_outliers, voxel_downsample


@pytest.fixture(scope="module")
def sphere():
    return shapes.sphere(1000)


def test_merge_exact_duplicates(sphere):
    p, n = sphere.points, sphere.normals
    dup = np.vstack([p, p[[3, 7, 7]]])
    r = merge_duplicates(dup, np.vstack([n, -n[[3, 7, 7]]]))
    np.testing.assert_array_equal(r.points, p)  # input order kept
    np.testing.assert_allclose(np.abs(np.einsum("ij,ij->i", r.normals, n)), 1.0)
    assert r.removed.tolist() == [1000, 1001, 1002]
    assert r.groups[1000] == 3 and r.groups[1002] == 7
    assert r.report == "merge_duplicates: merged 3 of 1003 points into 2 groups (tolerance 0)"
    PointCloud(r.points, r.normals)  # now acceptable


def test_merge_with_tolerance_averages(sphere):
    p = sphere.points
    q = np.vstack([p, p[:10] + 1e-7])
    r = merge_duplicates(q, tolerance=1e-5)
    assert len(r.points) == 1000 and r.n_removed == 10
    np.testing.assert_allclose(r.points[:10], p[:10] + 5e-8, atol=1e-15)


def test_remove_outliers(sphere):
    rng = np.random.default_rng(0)
    far = rng.uniform(2, 3, size=(8, 3)) * rng.choice([-1, 1], size=(8, 3))
    r = remove_outliers(np.vstack([sphere.points, far]), k=10)
    assert r.removed.tolist() == list(range(1000, 1008))
    assert "removed 8 of 1008 points" in r.report
    # a clean, even cloud loses almost nothing
    assert remove_outliers(sphere).n_removed <= 5


def test_voxel_downsample(sphere):
    size = 0.15
    for mode in ("nearest", "centroid"):
        r = voxel_downsample(sphere, voxel_size=size, mode=mode)
        cells = np.floor((r.points - sphere.points.min(axis=0)) / size)
        if mode == "nearest":
            assert len(np.unique(cells, axis=0)) == len(r.points)  # one point per voxel
            assert set(map(tuple, r.points)) <= set(map(tuple, sphere.points))
        assert 100 < len(r.points) < 1000
        assert r.normals.shape == r.points.shape
        assert (r.groups >= 0).all() and r.groups.max() == len(r.points) - 1
        assert "voxel_downsample: kept" in r.report


def test_clean_chain(sphere):
    p = sphere.points
    r = clean(np.vstack([p, p[:4], [[9.0, 9.0, 9.0]]]), voxel_size=0.05)
    lines = r.report.splitlines()
    assert [ln.split(":")[0] for ln in lines] == ["merge_duplicates", "remove_outliers", "voxel_downsample"]
    assert r.groups[-1] == -1  # the outlier
    assert r.groups[1000] == r.groups[0]  # the duplicate went where its original went
    assert r.keep_mask.sum() == len(r.points)
    cloud = r.to_cloud()
    assert len(cloud) == len(r.points)


@pytest.mark.parametrize(
    "fn, kwargs, exc, match",
    [
        (merge_duplicates, {"tolerance": -1.0}, ValueError, "tolerance must be a finite non-negative number"),
        (remove_outliers, {"k": 0}, ValueError, "k must be at least 1"),
        (remove_outliers, {"k": 50}, ValueError, "k must be smaller than the number of points 20"),
        (remove_outliers, {"std_ratio": 0}, ValueError, "std_ratio must be a finite positive number"),
        (voxel_downsample, {"voxel_size": 0}, ValueError, "voxel_size must be a finite positive number"),
        (voxel_downsample, {"voxel_size": 0.1, "mode": "mean"}, ValueError, "mode must be one of"),
    ],
)
def test_bad_input(fn, kwargs, exc, match):
    p = np.random.default_rng(0).random((20, 3))
    with pytest.raises(exc, match=match):
        fn(p, **kwargs)


def test_bad_points_and_normals():
    with pytest.raises(ValueError, match="points must be finite"):
        merge_duplicates(np.full((5, 3), np.nan))
    with pytest.raises(ValueError, match=r"normals must have shape \(20, 3\)"):
        remove_outliers(np.random.default_rng(0).random((20, 3)), np.ones((4, 3)))


# ------------------------------------------------------------- density-adaptive outliers
DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def _inject(p, frac=0.01, seed=0):
    rng = np.random.default_rng(seed)
    m = max(1, round(frac * len(p)))
    return np.vstack([p, rng.uniform(p.min(axis=0), p.max(axis=0), size=(m, 3))]), m


def test_variable_density_sphere_keeps_its_points():
    c = shapes.sphere(4000, sampling="variable", density_ratio=8)
    assert remove_outliers(c).n_removed == 0  # measured 0 (the statistical rule: tens of points)
    assert clean(c.points).n_removed == 0
    q, m = _inject(c.points * 1.0)
    r = remove_outliers(q)
    caught = (~r.keep_mask[-m:]).mean()
    assert r.keep_mask[:-m].mean() >= 0.999
    assert caught >= 0.4, caught  # measured 0.45 (many land within a few spacings of the sphere)
    # outliers well away from the surface (> 3 spacings) and not clumped: all caught
    far = np.random.default_rng(1).normal(size=(20, 3))
    far = far / np.linalg.norm(far, axis=1)[:, None] * np.linspace(1.3, 2.0, 20)[:, None]
    r = remove_outliers(np.vstack([c.points, far]))
    assert (~r.keep_mask[-20:]).all() and r.keep_mask[:-20].all()


def test_local_and_statistical_methods_and_errors(sphere):
    p = np.vstack([sphere.points, [[4.0, 0, 0]]])
    assert remove_outliers(p, method="statistical").removed.tolist() == [1000]
    assert "removed 1 of 1001 points (local, 16 neighbours)" in remove_outliers(p).report
    assert clean(p, outlier_method="statistical").n_removed == 1
    with pytest.raises(ValueError, match="method must be one of \\['local', 'statistical'\\], got 'lof'"):
        remove_outliers(p, method="lof")
    with pytest.raises(ValueError, match="ratio must be greater than 1, got 0.5"):
        remove_outliers(p, ratio=0.5)
    with pytest.raises(ValueError, match="max_offset must be a finite positive number"):
        remove_outliers(p, max_offset=0)
    with pytest.raises(ValueError, match="k must be at least 3 for method='local', got 2"):
        remove_outliers(p, k=2)


# measured (seed 0): % of a noise-free model removed, share of 1 % injected uniform outliers caught,
# share caught of those farther from the vertices than one neighbourhood radius (``python
# tests/test_cleaning.py`` prints them, and the catch rate by distance to the mesh in local spacings).
# Issue 16's targets: <= 0.1 % removed, met; >= 95 % caught, met on homer, the teapot and the scans:
# the misses lie within about 0.3 local spacings of the surface (undetectable against a sample), or
# have several stray points among their nearest neighbours, and the alligator is planar, so its
# outliers lie in its own plane. Seed 0 is a kind draw for the coarse models: seeds 1-3 give cow
# 62, 52, 83 %, homer 95, 93, 90, rocker-arm 88, 88, 81, cheburashka 94, 88, 85, teapot 84, 91, 84,
# beetle 64, 73, 55, bunny 98, 98, 100 (75-81 before sparse clumps were recognised), Igea 99.
# Statistical rule: cow 1.41 %, homer 0.15 %, rocker-arm 1.05 %, cheburashka 2.26 %, teapot 0 %
# removed; the beetle lost 0.7 % with ratio=3.
MODEL_LIMITS = {  # (max % removed, min caught, min caught beyond one radius)
    "cow": (0.1, 0.8, 0.95),  # 0.069 %, 0.83 (before the leave-one-out fit: 0.66; before issue 16: 0.48), 1.0
    "homer": (0.0, 0.95, 0.95),  # 0 %, 0.97 (0.80, 0.70), 1.0
    "rocker-arm": (0.03, 0.82, 0.95),  # 0.020 %, 0.85 (0.67, 0.58), 1.0
    "cheburashka": (0.05, 0.9, 0.95),  # 0.030 %, 0.94 (0.82, 0.75), 1.0
    "teapot": (0.04, 0.93, 0.95),  # 0.031 %, 0.97 (0.75, 0.69), 1.0
    "beetle": (0.0, 0.6, 0.95),  # 0 % (0.70 %), 0.64 (0.64, 0.27), 1.0
    "alligator": (0.0, 0.2, 0.8),  # 0 %, 0.22 (0.19, 0.19), 0.875
}


@pytest.mark.parametrize("name", sorted(MODEL_LIMITS))
def test_models_lose_almost_nothing(name):
    path = DATA / "models" / f"{name}.obj"
    if not path.is_file():
        pytest.skip(f"{path} not found (the models live outside the repository)")
    import warnings

    from manifold_sph import ManifoldSPHWarning
    from manifold_sph.scans.io import read

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ManifoldSPHWarning)  # the meshes repeat seam vertices: merged, said
        p = read(path, duplicates="merge").points
    max_removed, min_caught, min_far = MODEL_LIMITS[name]
    r = clean(p)
    assert 100 * r.n_removed / len(p) <= max_removed + 1e-9, r.report  # target <= 0.1 %
    q, m = _inject(p)
    r = clean(q)
    caught = ~r.keep_mask[-m:]
    assert 100 * (~r.keep_mask[:-m]).mean() <= 0.1
    assert caught.mean() >= min_caught  # the 95 % target is met on homer only (see remove_outliers)
    assert caught[_beyond_one_radius(p, q[-m:])].mean() >= min_far


def _beyond_one_radius(p, q):
    """Outliers farther from the vertices than the nearest one's mean distance to its 16 neighbours."""
    from scipy.spatial import cKDTree

    tree = cKDTree(p)
    d, j = tree.query(q)
    return d > tree.query(p[j], 17)[0][:, 1:].mean(axis=1)


NOISY_FLOORS = {0.2: (0.95, 0.95), 0.5: (0.75, 0.95), 1.0: (0.5, 0.7)}  # noise-free: see the tests below


@pytest.mark.parametrize("noise", sorted(NOISY_FLOORS))
def test_noisy_sphere_keeps_its_samples_and_loses_far_outliers(noise):
    """Gaussian noise of up to one spacing is not mistaken for outliers (measured: none removed up to
    0.5, 3 of 8000 at 1.0; without the noise guard of the joint tests 17 and 183); of 80 uniform
    outliers in the bounding box, those more than 1 and 3 spacings off the sphere are caught
    (measured 1.0 / 1.0 noise-free, 1.0 / 1.0 at 0.1 spacing of noise, 0.97 / 1.0 at 0.2,
    0.93 / 1.0 at 0.3, 0.81 / 1.0 at 0.5, 0.55 / 0.76 at 1.0: an outlier within a few noise
    levels of the surface looks like a sample)."""
    c = shapes.sphere(8000, sampling="poisson", seed=1)
    h = np.sqrt(4 * np.pi / 8000)
    p = c.points + np.random.default_rng(0).normal(scale=noise * h, size=c.points.shape)
    q = np.random.default_rng(1).uniform(-1, 1, (80, 3))
    r = clean(np.vstack([p, q]))
    assert r.keep_mask[:-80].mean() >= 0.999
    d = np.abs(np.linalg.norm(q, axis=1) - 1) / h
    caught = ~r.keep_mask[-80:]
    near_floor, far_floor = NOISY_FLOORS[noise]
    assert caught[d > 1].mean() >= near_floor and caught[d > 3].mean() >= far_floor


def _separated(p, spacing, m, seed):
    """``m`` samples at least 6 local spacings apart, in a seeded random order."""
    chosen = []
    for i in np.random.default_rng(seed).permutation(len(p)):
        if all(np.linalg.norm(p[i] - p[j]) > 6 * spacing[i] for j in chosen):
            chosen.append(i)
            if len(chosen) == m:
                break
    return np.array(chosen)


@pytest.mark.parametrize("sampling", ["poisson", "variable", "random"])
def test_single_outliers_a_fraction_of_a_spacing_off_the_surface(sampling):
    """Exact answers: 40 stray points, each alone, a given number of local spacings (mean distance
    to the 3 nearest samples) off a noise-free torus along the normal, alternately out and in.
    From 0.3 spacings on every one is caught by the leave-one-out fit on the Poisson and
    variable-density tori (measured: 34/34 and 35/35 from 0.3 to 2 spacings; 10 and 22 at 0.2,
    none at 0.1: the threshold is 0.2 spacings), on the random sphere (clumpy) 31/40 at 0.3,
    38/40 at 0.5, all from 1; and no sample is removed. (4 spacings inwards, the stray points
    of the 2000-point torus gather near the axis of its tube and shield each other: 26/34.)"""
    from scipy.spatial import cKDTree

    c = shapes.sphere(2000, sampling="random", seed=1) if sampling == "random" else shapes.torus(2000, sampling=sampling, seed=3)
    p, nrm = c.points, c.normals
    spacing = cKDTree(p).query(p, 4)[0][:, 1:].mean(axis=1)
    idx = _separated(p, spacing, 40, 0)
    sign = np.where(np.arange(len(idx)) % 2, 1.0, -1.0)
    assert remove_outliers(p).n_removed == 0
    random = sampling == "random"
    for d, floor in ((0.3, 0.75 if random else 1.0), (0.5, 0.95 if random else 1.0), (2.0, 1.0)):
        q = p[idx] + (d * spacing[idx] * sign)[:, None] * nrm[idx]
        r = remove_outliers(np.vstack([p, q]))
        assert r.keep_mask[: len(p)].all(), d
        assert (~r.keep_mask[len(p) :]).mean() >= floor, (d, (~r.keep_mask[len(p) :]).mean())
    q = p[idx] + (0.1 * spacing[idx] * sign)[:, None] * nrm[idx]  # below the threshold: kept
    assert remove_outliers(np.vstack([p, q])).keep_mask.all()
    with pytest.raises(ValueError, match="fit_offset must be a finite positive number"):
        remove_outliers(p, fit_offset=-0.1)
    assert remove_outliers(np.vstack([p, p[idx] + (spacing[idx])[:, None] * nrm[idx]]), fit_offset=None).n_removed < 40


def test_pairs_of_stray_points():
    """Exact answers: 30 pairs of stray points, 0.8 spacings apart, 2 and 3 spacings off a noise-free
    torus. Each lifts the other's reference height; a point more than 1.5 spacings off its fit
    leaves out one neighbour that its own fit rejects, so all 60 are caught (measured; without that
    rule 0 at 2 spacings, 60 at 3 by the other tests). At 1 spacing the pairs stay (measured: 0):
    two samples of a coarse fin look the same (the beetle has them)."""
    from scipy.spatial import cKDTree

    from manifold_sph.frames import tangent_frames

    c = shapes.torus(2000, seed=3)
    p, nrm = c.points, c.normals
    spacing = cKDTree(p).query(p, 4)[0][:, 1:].mean(axis=1)
    idx = _separated(p, spacing, 30, 0)
    u, _ = tangent_frames(nrm[idx])
    for d, caught in ((2.0, 60), (3.0, 60), (1.0, 0)):
        a = p[idx] + (d * spacing[idx])[:, None] * nrm[idx]
        r = remove_outliers(np.vstack([p, a, a + (0.8 * spacing[idx])[:, None] * u]))
        assert r.keep_mask[: len(p)].all() and (~r.keep_mask[len(p) :]).sum() == caught, d


def test_sparse_clumps_around_a_surface_and_a_separate_coarse_object():
    """200 stray points uniform in [-1.5, 1.5]^3 around a dense sphere (20,000 points), with a
    separate sphere of 100 points (radius 0.5, 5 times coarser) nearby: the stray points link into
    sparse pieces of the neighbour graph, interleaved with the dense sphere, and are caught
    (measured 0.99 of all, all of those more than 3 spacings off; 0.94 without the sparse-clump
    rule); the coarse sphere lies apart and is kept whole, and no sample is lost."""
    p = shapes.sphere(20000).points
    small = shapes.sphere(100, radius=0.5, center=(0, 0, 2.2)).points
    q = np.random.default_rng(3).uniform(-1.5, 1.5, (200, 3))
    q = q[np.linalg.norm(q - [0, 0, 2.2], axis=1) > 0.7]
    r = remove_outliers(np.vstack([p, small, q]))
    far = np.abs(np.linalg.norm(q, axis=1) - 1) > 3 * np.sqrt(4 * np.pi / 20000)
    caught = ~r.keep_mask[20100:]
    assert r.keep_mask[:20100].all()
    assert caught.mean() >= 0.97 and caught[far].all(), (caught.mean(), caught[far].mean())


def test_thin_plate_keeps_both_sheets():
    """Two sheets two spacings apart (a thin part): no sample is removed, and a stray point midway,
    one spacing from both, is not caught (documented limitation: its neighbours lie on both
    sheets, so no surface fits them)."""
    g = np.linspace(0, 1, 40)
    x, y = np.meshgrid(g, g)
    h = g[1]
    top = np.c_[x.ravel(), y.ravel(), np.full(x.size, 2 * h)]
    bottom = np.c_[x.ravel() + h / 2, y.ravel() + h / 2, np.zeros(x.size)]
    p = np.vstack([top, bottom])
    p[:, :2] += np.random.default_rng(1).uniform(-0.2, 0.2, (len(p), 2)) * h
    assert remove_outliers(p).n_removed == 0
    q = np.c_[np.random.default_rng(2).uniform(0.2, 0.8, (10, 2)), np.full(10, h)]
    r = remove_outliers(np.vstack([p, q]))
    assert r.keep_mask[: len(p)].all()


def test_far_outliers_of_a_dense_cloud_are_caught():
    """50,000 Fibonacci points and 1 % outliers uniform in the bounding box: far from the surface the
    outliers have only each other as neighbours (a volumetric clump), and are caught; points within
    two spacings of the sphere look like samples and may stay."""
    from manifold_sph.reference import shapes

    p = shapes.sphere(50000).points
    rng = np.random.default_rng(5)
    q = rng.uniform(-1.0, 1.0, (500, 3))
    r = clean(np.vstack([p, q]))
    spacing = np.sqrt(4 * np.pi / 50000)
    far = np.abs(np.linalg.norm(q, axis=1) - 1.0) > 2 * spacing
    caught = ~r.keep_mask[-500:]
    assert (~r.keep_mask[:-500]).mean() <= 1e-3
    # measured 0.987 (0.978 before the fit test; 0.80 when only clumps of <= k points counted)
    assert caught[far].mean() >= 0.95, caught[far].mean()


if __name__ == "__main__":  # the table behind MODEL_LIMITS: python tests/test_cleaning.py
    import sys

    from scipy.spatial import cKDTree

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from normals import MODELS, SCANS, mesh_reference  # benchmarks/normals.py

    try:  # exact distance to the mesh, when libigl is installed (else: to the nearest vertex)
        import igl

        from manifold_sph.scans.io import read_mesh
    except ImportError:
        igl = None
    bins = (0, 0.25, 0.5, 1, 2, np.inf)
    print("outliers caught by distance to the surface in local spacings (mean distance of the nearest vertex "
          "to its 3 nearest): " + ", ".join(f"[{a:g}, {b:g})" for a, b in zip(bins[:-1], bins[1:])))
    for path in MODELS + SCANS:
        if not path.is_file():
            continue
        p = mesh_reference(path)[0]
        r = clean(p)
        q, m = _inject(p)
        caught = ~clean(q).keep_mask[-m:]
        far = _beyond_one_radius(p, q[-m:])
        tree = cKDTree(p)
        d, j = tree.query(q[-m:])
        if igl is not None:
            V, F = read_mesh(str(path))
            d = np.sqrt(igl.point_mesh_squared_distance(q[-m:], V.astype(float), F.astype(np.int64))[0])
        d = d / tree.query(p[j], 4)[0][:, 1:].mean(axis=1)
        by = " ".join(f"{int(caught[(d >= a) & (d < b)].sum())}/{int(((d >= a) & (d < b)).sum())}" for a, b in zip(bins[:-1], bins[1:]))
        others = [(~clean(_inject(p, seed=seed)[0]).keep_mask[-m:]).mean() for seed in (1, 2, 3)]
        print(f"{path.stem:15s} {len(p):7d} points  removed {100 * r.n_removed / len(p):.3f} %  outliers caught "
              f"{100 * caught.mean():5.1f} % of {m} (seeds 1-3: {', '.join(f'{100 * c:.0f}' for c in others)} %), "
              f"{100 * caught[far].mean():5.1f} % of the {int(far.sum())} beyond one neighbourhood radius; by distance {by}")
