"""The scan pipeline end to end: synthetic scans by default, the real ones when ../shared has them.

The real scans (Stanford bunny, Igea) live in /work/shared/data/scans, outside the
repository; their tests skip when the folder or the file is absent. The heavy
parts are marked slow.
"""

import os
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.sparse import csgraph

from manifold_sph import Surface
from manifold_sph.normals import estimate_normals
from manifold_sph.pde import heat
from manifold_sph.reference import functions, shapes
from manifold_sph.reference.accuracy import operator_errors
from manifold_sph.scans.boundary import detect_boundary
from manifold_sph.scans.cleaning import clean
from manifold_sph.scans.io import read

SCANS = Path(os.environ.get("MANIFOLD_SPH_SCANS", Path(__file__).resolve().parents[2] / "shared" / "data" / "scans"))
SCHEMES = ["standard", "cspm", "msph", "ncsph"]


def scan(name):
    path = SCANS / name
    if not path.is_file():
        pytest.skip(f"{path} not found (the real scans live outside the repository)")
    return path


# ----------------------------------------------------------------- synthetic scans
def noisy_sphere_errors(n, levels, seed=0):
    fn = functions.cos_xz_sin_y
    c = shapes.sphere(n, sampling="poisson", seed=seed)
    spacing = np.sqrt(4 * np.pi / n)
    out = {s: [] for s in SCHEMES}
    for level in levels:
        p = c.points + level * spacing * np.random.default_rng(seed + 1).standard_normal(c.points.shape)
        nrm = estimate_normals(p)
        xp = p / np.linalg.norm(p, axis=1)[:, None]
        lap = c.geometry.laplace_beltrami(xp, fn.gradient(xp), fn.hessian(xp))
        for s in SCHEMES:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                L = Surface(p, nrm, scheme=s, area="shepard").laplacian(fn.value(xp), form="strong")
            out[s].append(np.linalg.norm(L - lap) / np.linalg.norm(lap))
    return out


def test_noisy_sphere_error_grows_smoothly():
    levels = (0.0, 0.1, 0.2, 0.3)
    err = noisy_sphere_errors(2000, levels)
    for s in SCHEMES:
        e = np.array(err[s])
        assert np.all(np.isfinite(e)), s
        assert np.all(np.diff(e) > 0), (s, e)  # grows with the noise ...
        assert np.all(e[1:] / e[:-1] < 5), (s, e)  # ... smoothly, no blow-up
    for s in ("cspm", "msph", "ncsph"):  # measured (N = 2000): about 0.02, 0.04, 0.1, 0.2
        assert err[s][0] < 0.03 and err[s][-1] < 0.4, (s, err[s])


def test_variable_density_adaptive_h_matches_uniform_cloud():
    n = 3000
    uni = shapes.sphere(n, sampling="poisson")
    var = shapes.sphere(n, sampling="variable", density_ratio=4)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = {r["scheme"]: r for r in operator_errors(uni, "cos_xz_sin_y", schemes=SCHEMES[1:])}
        ada = {r["scheme"]: r for r in operator_errors(var, "cos_xz_sin_y", schemes=SCHEMES[1:], h="adaptive")}
    for s in SCHEMES[1:]:
        # adaptive h on the variable cloud stays within a factor 2 of the uniform cloud (measured 1.0-1.6)
        assert ada[s]["lap_l2"] < 2.0 * ref[s]["lap_l2"], (s, ada[s]["lap_l2"], ref[s]["lap_l2"])
        assert ada[s]["grad_l2"] < 2.0 * ref[s]["grad_l2"]


def test_synthetic_scan_pipeline(tmp_path):
    """Write a dirty open scan, read it back and run the whole pipeline."""
    c = shapes.torus(3000, seed=3)
    keep = c.points[:, 0] < 0.0  # cut the torus in half: two rims
    p = c.points[keep]
    rng = np.random.default_rng(0)
    dirty = np.vstack([p, p[:25], rng.uniform(-3, 3, size=(5, 3)) + [4.0, 0, 0]])
    path = tmp_path / "scan.xyz"
    np.savetxt(path, dirty)
    with pytest.warns(RuntimeWarning, match="merged 25 exact duplicate"):
        cloud, fields = read(path, duplicates="merge", return_fields=True)
    assert len(cloud) == len(p) + 5 and cloud.normals is None
    cleaned = clean(cloud)
    assert len(cleaned.points) == len(p)
    nrm = estimate_normals(cleaned.points)
    assert np.einsum("ij,ij->i", nrm, c.normals[keep]).min() > 0.9
    rep = detect_boundary(cleaned.points, nrm)
    assert rep.n_loops == 2  # two cut circles
    s = Surface(cleaned.points, nrm, scheme="standard", area="shepard")
    u0 = (cleaned.points[:, 0] < -0.7).astype(float)
    u = heat(s, u0, dt=0.01, steps=20).u
    assert u.min() >= -1e-9 and u.max() <= 1 + 1e-9


# ----------------------------------------------------------------- real scans
def test_bunny_normals_agree_with_mesh():
    path = scan("stanford-bunny.obj")
    cloud = read(path, normals="none")  # vertices only, as a scanner would deliver them
    assert len(cloud) == 35947 and cloud.normals is None
    ref, fields = read(path, normals="mesh", return_fields=True)
    nrm = estimate_normals(cloud.points)
    agree = np.einsum("ij,ij->i", nrm[fields["index"]], ref.normals) > 0
    assert agree.mean() >= 0.99  # measured: 100%


@pytest.mark.slow
def test_bunny_operators_and_heat():
    path = scan("stanford-bunny.obj")
    cloud = read(path, normals="none")
    pts = clean(cloud).points
    nrm = estimate_normals(pts)
    assert detect_boundary(pts, nrm).n_boundary > 0  # the bunny is open at the bottom
    f = np.sin(20 * pts[:, 0]) * pts[:, 1]
    for s in SCHEMES:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            S = Surface(pts, nrm, scheme=s, area="shepard", h="adaptive")
        for out in (S.laplacian(f), S.gradient(f), S.divergence(np.c_[f, f, f])):
            assert np.all(np.isfinite(out)), s
    S = Surface(pts, nrm, scheme="standard", area="shepard", h="adaptive")
    u0 = np.zeros(len(pts))
    u0[np.argmax(pts[:, 1])] = 1.0
    u = heat(S, u0, dt=0.01, steps=40).u
    assert u.min() >= -1e-9 and u.max() <= 1 + 1e-9
    _, lab = csgraph.connected_components(S.laplacian_matrix(), directed=False)
    for c in np.unique(lab):
        assert np.ptp(u[lab == c]) < 1e-8


@pytest.mark.slow
def test_igea_pipeline_end_to_end():
    """The whole scan pipeline on Igea (134,345 points) keeps the maximum principle. Its time is
    measured by benchmarks/scans.py (a timed assertion here failed on a loaded machine)."""
    path = scan("igea.ply")
    cloud = read(path, normals="none")
    assert len(cloud) == 134345
    pts = clean(cloud).points
    nrm = estimate_normals(pts)
    S = Surface(pts, nrm, scheme="standard", area="shepard", h="adaptive")
    u0 = np.zeros(len(pts))
    u0[np.argmax(pts[:, 1])] = 1.0
    u = heat(S, u0, dt=1e-4, steps=10).u
    assert u.min() >= -1e-9 and u.max() <= 1 + 1e-9
