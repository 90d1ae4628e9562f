"""Curvature and geodesic distance: ours against libigl and potpourri3d, one table, same run.

1. Curvature on the torus R = 0.8, r = 0.2 (exact H, K from the implicit function):
   ours on Poisson-disk points (msph and msph4, exact normals, and msph4 from bare
   points with estimated normals) against libigl's ``principal_curvature`` (quadric
   fit) on a parametric triangle mesh of about the same number of vertices.
   Relative L2 errors of H and K, seconds.
2. Geodesic distance on the unit sphere from one source, Fibonacci and uniformly
   random points: ours (``Surface.geodesic_distance``, msph and msph4) against
   potpourri3d's ``PointCloudHeatSolver`` on the same points. Relative L2 error against
   ``arccos(x . x_s)``; set-up seconds (ours: the Surface build plus the solver's
   factorisations) and the first query.
3. The models of ../shared/data/models that are one closed shell: vertices as bare
   points, distance from vertex 0 against libigl's exact polyhedral geodesic (MMP) on the
   model's own mesh, ours and potpourri3d's point-cloud heat method, mean relative error.

libigl and potpourri3d come with the bench extra (``pip install ".[bench]"``); rows
for a missing peer are skipped. Run: ``python benchmarks/geometry.py [--quick]``.
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np

from manifold_sph import Surface
from manifold_sph.reference import shapes
from manifold_sph.scans.io import read_mesh

MODELS = Path(__file__).resolve().parents[2] / "shared" / "data" / "models"


def rel(a, b):
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def quiet(fn, *a, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*a, **kw)


def torus_mesh(nu, nv, R=0.8, r=0.2):
    u, v = np.meshgrid(np.arange(nu) * 2 * np.pi / nu, np.arange(nv) * 2 * np.pi / nv, indexing="ij")
    V = np.stack([(R + r * np.cos(v)) * np.cos(u), (R + r * np.cos(v)) * np.sin(u), r * np.sin(v)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a, b, c, d = i * nv + j, ((i + 1) % nu) * nv + j, ((i + 1) % nu) * nv + (j + 1) % nv, i * nv + (j + 1) % nv
    F = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return V, F


def curvature_rows(sizes):
    try:
        import igl
    except ImportError:
        igl = None
    print(f"{'torus N':>8s} {'method':34s} {'H rel L2':>9s} {'K rel L2':>9s} {'seconds':>8s}")
    for n in sizes:
        c = shapes.torus(n)
        P = c.points
        H, K = 0.5 * c.geometry.mean_curvature(P), c.geometry.gaussian_curvature(P)
        for label, make in (
            ("ours msph, exact normals", lambda: Surface(c, scheme="msph")),
            ("ours msph4, exact normals", lambda: Surface(c, scheme="msph4")),
            ("ours msph4, bare points", lambda: quiet(Surface, P, scheme="msph4")),
        ):
            t = time.perf_counter()
            s = make()
            h, k = s.mean_curvature(), s.gaussian_curvature()
            print(f"{n:8d} {label:34s} {rel(h, H):9.2e} {rel(k, K):9.2e} {time.perf_counter() - t:8.2f}", flush=True)
        if igl is not None:
            nu = int(round(np.sqrt(4 * n)))  # nu : nv = 4 : 1 (R / r)
            V, F = torus_mesh(nu, max(n // nu, 8))
            t = time.perf_counter()
            _, _, k1, k2, _ = igl.principal_curvature(V, F.astype(np.int64))
            tt = time.perf_counter() - t
            ref = shapes.torus(100)  # for its shape: the exact curvatures at the mesh vertices
            Hm, Km = 0.5 * ref.geometry.mean_curvature(V), ref.geometry.gaussian_curvature(V)
            hh, kk = 0.5 * (k1 + k2), k1 * k2
            if np.dot(hh, Hm) < 0:  # libigl's sign follows its normals
                hh = -hh
            print(f"{len(V):8d} {'libigl principal_curvature (mesh)':34s} {rel(hh, Hm):9.2e} {rel(kk, Km):9.2e} {tt:8.2f}", flush=True)


def random_sphere(n, seed=0):
    x = np.random.default_rng(seed).standard_normal((n, 3))
    return x / np.linalg.norm(x, axis=1)[:, None]


def geodesic_rows(sizes):
    try:
        import potpourri3d as pp3d
    except ImportError:
        pp3d = None
    print(f"\n{'sphere':10s} {'N':>7s} {'method':22s} {'rel L2':>9s} {'set-up s':>9s} {'query s':>8s}")
    for sampling in ("fibonacci", "random"):
        for n in sizes:
            P = shapes.sphere(n).points if sampling == "fibonacci" else random_sphere(n)
            exact = np.arccos(np.clip(P @ P[0], -1, 1))
            for scheme in ("msph", "msph4"):
                t = time.perf_counter()
                s = quiet(Surface, P, P.copy(), scheme=scheme)
                from manifold_sph.geometry import GeodesicSolver

                solver = quiet(GeodesicSolver, s)
                tb = time.perf_counter() - t
                t = time.perf_counter()
                d = solver(0)
                label = "ours " + scheme
                print(f"{sampling:10s} {n:7d} {label:22s} {rel(d, exact):9.2e} {tb:9.2f} "
                      f"{time.perf_counter() - t:8.2f}", flush=True)
            if pp3d is not None:
                t = time.perf_counter()
                solver = pp3d.PointCloudHeatSolver(P)
                tb = time.perf_counter() - t
                t = time.perf_counter()
                d = solver.compute_distance(0)
                print(f"{sampling:10s} {n:7d} {'potpourri3d':22s} {rel(d, exact):9.2e} {tb:9.2f} {time.perf_counter() - t:8.2f}", flush=True)


def model_rows():
    if not MODELS.is_dir():
        print(f"(models folder {MODELS} absent: skipped)")
        return
    try:
        import igl
        import potpourri3d as pp3d
    except ImportError:
        print("(libigl or potpourri3d missing: model rows skipped)")
        return
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from normals import mesh_reference  # benchmarks/normals.py

    print(f"\n{'model':12s} {'points':>7s} {'ours (bare points)':>19s} {'ours (mesh normals)':>20s} {'potpourri3d':>12s}   "
          "(mean relative error against libigl's exact polyhedral geodesic from vertex 0)")
    for name in ("cow", "homer", "rocker-arm", "cheburashka"):
        path = MODELS / f"{name}.obj"
        if not path.exists():
            continue
        P, ref_n, closed, shells = mesh_reference(path)
        V, F = read_mesh(str(path))
        U, inv = np.unique(V, axis=0, return_inverse=True)
        F = inv.ravel()[F]
        F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
        if len(U) != len(P):
            continue
        exact = igl.exact_geodesic(U, F.astype(np.int64), np.array([0]), np.array([], dtype=np.int64),
                                   np.arange(len(U)), np.array([], dtype=np.int64))
        mask = exact > 0

        def err(d):
            return float(np.mean(np.abs(d[mask] - exact[mask]) / exact[mask]))

        d_bare = quiet(Surface, P).geodesic_distance(0)
        d_mesh = quiet(Surface, P, ref_n).geodesic_distance(0)
        d_pp = pp3d.PointCloudHeatSolver(P).compute_distance(0)
        print(f"{name:12s} {len(P):7d} {err(d_bare):19.2e} {err(d_mesh):20.2e} {err(d_pp):12.2e}", flush=True)


if __name__ == "__main__":
    quick = "--quick" in sys.argv
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        curvature_rows([10000] if quick else [10000, 40000])
    geodesic_rows([10000] if quick else [10000, 40000])
    model_rows()
