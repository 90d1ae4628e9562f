"""Laplace-Beltrami spectra on irregular clouds: ours against robust-laplacian and the cotan FEM.

One table, same run, same points:

1. Unit sphere, uniformly random (iid, seeded) and Fibonacci points, N = 2000, 8000,
   32000, 131072: relative errors of the eigenvalues 1..48 of ``-Lap`` against the
   exact ``l (l + 1)`` (median and max), build time and ``eigs(50)`` time, for
   - ``stable``: our Voronoi stiffness and mass (:meth:`Surface.eigs`), exact normals;
   - ``stable/pca``: the same with normals estimated from the points;
   - ``stable/noise 0.1h`` and ``0.3h`` (random points only): points moved by Gaussian
     noise of 0.1 and 0.3 mean spacings, normals estimated (``k=24``);
   - the strong-form schemes (cspm, msph, msph4; eigenvalues of the non-symmetric
     ``L``, real parts) up to N = 32000;
   - robust-laplacian's ``point_cloud_laplacian`` (bench extra) and its eigsh;
   - the cotan FEM on the convex hull of the same points (a Delaunay mesh of the
     sphere, which a point cloud does not have), lumped mass.
2. Closed models of ../shared/data/models (and any ``--model`` OBJ): the 20 smallest
   non-zero eigenvalues of the vertices as a cloud, median and max relative error
   against the limit of the cotan FEM of the model's own mesh under midpoint
   subdivision (Richardson extrapolation of two levels), for the cotan FEM of the mesh
   itself, ours (normals estimated, and the mesh's area-weighted normals) and
   robust-laplacian; ``vs mesh`` is the median against the unsubdivided cotan FEM;
   ``open/refit`` counts our cells still clipped by the neighbourhood's hull (all spurious on a
   closed model) and the open cells that closed when computed again in the principal plane of
   the particle's nearest points (``Surface.stable_report``).

Usage: ``python benchmarks/spectra.py [--quick] [--sizes 2000,8000] [--models-only]
[--model path.obj] [--json out.json]``.
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from manifold_sph import Surface, estimate_normals
from manifold_sph.reference import shapes

EXACT = np.concatenate([[l * (l + 1)] * (2 * l + 1) for l in range(1, 7)])  # 48 eigenvalues
MODELS = Path(__file__).resolve().parents[2] / "shared" / "data" / "models"


def random_sphere(n, seed=0):
    x = np.random.default_rng(seed).standard_normal((n, 3))
    return x / np.linalg.norm(x, axis=1)[:, None]


def cotan(verts, faces):
    """Cotan stiffness and barycentric lumped mass of a triangle mesh."""
    v = verts[faces]
    K = sp.csr_matrix((len(verts), len(verts)))
    rows, cols, vals = [], [], []
    for a in range(3):
        j, k = faces[:, (a + 1) % 3], faces[:, (a + 2) % 3]
        e1, e2 = v[:, (a + 1) % 3] - v[:, a], v[:, (a + 2) % 3] - v[:, a]
        cot = np.einsum("ij,ij->i", e1, e2) / np.linalg.norm(np.cross(e1, e2), axis=1)
        rows += [j, k]
        cols += [k, j]
        vals += [-0.5 * cot, -0.5 * cot]
    W = sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(len(verts),) * 2).tocsr()
    K = W - sp.diags(np.asarray(W.sum(axis=1)).ravel())
    area = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    m = np.bincount(faces.ravel(), weights=np.repeat(area / 3, 3), minlength=len(verts))
    return K.tocsr(), m


def sym_eigs(K, m, k):
    n = K.shape[0]
    sigma = -1e-2 / m.sum()
    v0 = np.random.default_rng(0).standard_normal(n)
    lam = spla.eigsh(K.tocsc(), k=k, M=sp.diags(m).tocsc(), sigma=sigma, which="LM", v0=v0, return_eigenvectors=False)
    return np.sort(lam)


def strong_eigs(L, k):
    n = L.shape[0]
    v0 = np.random.default_rng(0).standard_normal(n)
    lam = spla.eigs(L.tocsc(), k=k, sigma=1e-3, which="LM", v0=v0, return_eigenvectors=False)
    return np.sort(-lam.real)


def errors(lam, exact):
    e = np.abs(lam - exact) / exact
    return float(np.median(e)), float(e.max())


def quiet(fn, *a, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*a, **kw)


def sphere_rows(sizes, strong_max):
    rows = []
    try:
        import robust_laplacian
    except ImportError:
        robust_laplacian = None
    from scipy.spatial import ConvexHull

    for sampling in ("random", "fibonacci"):
        for n in sizes:
            P = random_sphere(n) if sampling == "random" else shapes.sphere(n).points
            cases = []

            def ours(normals, label, scheme="msph"):
                t = time.perf_counter()
                s = quiet(Surface, P, normals, scheme=scheme, area="shepard")
                s.stiffness_matrix()
                tb = time.perf_counter() - t
                t = time.perf_counter()
                lam, _ = s.eigs(49)
                return label, lam[1:], tb, time.perf_counter() - t

            cases.append(ours(P.copy(), "stable"))
            cases.append(ours(quiet(estimate_normals, P), "stable/pca"))
            if sampling == "random":  # noisy copies: points moved off the sphere, normals estimated
                spacing = np.sqrt(4 * np.pi / n)
                for sig in (0.1, 0.3):
                    Q = P + sig * spacing * np.random.default_rng(1).standard_normal(P.shape)
                    t = time.perf_counter()
                    s = quiet(Surface, Q, quiet(estimate_normals, Q, k=24), area="shepard")
                    s.stiffness_matrix()
                    tb = time.perf_counter() - t
                    t = time.perf_counter()
                    lam, _ = s.eigs(49)
                    cases.append((f"stable/noise {sig}h", lam[1:], tb, time.perf_counter() - t))
            if n <= strong_max:
                for scheme in ("cspm", "msph", "msph4"):
                    t = time.perf_counter()
                    s = quiet(Surface, P, P.copy(), scheme=scheme)
                    tb = time.perf_counter() - t
                    t = time.perf_counter()
                    try:
                        lam = strong_eigs(s.laplacian_matrix(form="strong"), 50)[1:49]
                    except Exception:  # noqa: BLE001 - ARPACK failure is a result too
                        lam = np.full(48, np.nan)
                    cases.append((f"strong {scheme}", lam, tb, time.perf_counter() - t))
            if robust_laplacian is not None:
                t = time.perf_counter()
                L, M = robust_laplacian.point_cloud_laplacian(P)
                tb = time.perf_counter() - t
                t = time.perf_counter()
                lam = sym_eigs(L, M.diagonal(), 49)[1:]
                cases.append(("robust-laplacian", lam, tb, time.perf_counter() - t))
            t = time.perf_counter()
            hull = ConvexHull(P)
            K, m = cotan(P, hull.simplices)
            tb = time.perf_counter() - t
            t = time.perf_counter()
            lam = sym_eigs(K, m, 49)[1:]
            cases.append(("cotan FEM on hull", lam, tb, time.perf_counter() - t))
            for label, lam, tb, te in cases:
                med, mx = errors(lam, EXACT)
                rows.append(dict(cloud=f"sphere {sampling}", n=n, method=label, median=med, max=mx, build_s=tb, eigs_s=te))
                print(f"{'sphere ' + sampling:18s} {n:7d} {label:20s} {med:10.2e} {mx:10.2e} {tb:8.2f} {te:8.2f}", flush=True)
    return rows


def mesh_arrays(path):
    """Distinct vertices used by faces, faces re-indexed (degenerate ones dropped), area-weighted normals."""
    import trimesh

    mesh = trimesh.load(path, process=False, force="mesh")
    V, F = np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces)
    U, inv = np.unique(V, axis=0, return_inverse=True)
    F = inv.ravel()[F]
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    used = np.unique(F)
    remap = np.full(len(U), -1)
    remap[used] = np.arange(used.size)
    U, F = U[used], remap[F]
    c = np.cross(U[F[:, 1]] - U[F[:, 0]], U[F[:, 2]] - U[F[:, 0]])
    N = np.zeros_like(U)
    for a in range(3):
        np.add.at(N, F[:, a], c)
    return U, F, N / np.linalg.norm(N, axis=1)[:, None]


def subdivision_limit(V, F, k=21):
    """Eigenvalues ``1..k-1`` of the cotan FEM of the mesh under midpoint subdivision, extrapolated
    (Richardson, two levels, O(h^2)): the limit of the polyhedron's own spectrum."""
    import trimesh

    levels = []
    for _ in range(2):
        V, F = trimesh.remesh.subdivide(V, F)
        K, m = cotan(V, F)
        levels.append(sym_eigs(K, m, k)[1:])
    return levels[1] + (levels[1] - levels[0]) / 3


def model_rows(extra=()):
    rows = []
    paths = [MODELS / f"{name}.obj" for name in ("cow", "homer", "rocker-arm", "cheburashka")] + [Path(p) for p in extra]
    if not MODELS.is_dir() and not extra:
        print(f"(models folder {MODELS} absent: skipped)")
        return rows
    try:
        import robust_laplacian
    except ImportError:
        robust_laplacian = None
    for path in paths:
        if not path.exists():
            continue
        name = path.stem
        V, F, N = mesh_arrays(path)
        K, m = cotan(V, F)
        coarse = sym_eigs(K, m, 21)[1:]
        limit = subdivision_limit(V, F)
        cand = [("cotan FEM (the mesh)", coarse, 0.0, "")]
        for label, normals in (("stable (est. normals)", None), ("stable (mesh normals)", N)):
            t = time.perf_counter()
            s = quiet(Surface, V, normals, scheme="msph", area="shepard")
            lam, _ = s.eigs(21)
            r = s.stable_report
            cand.append((label, lam[1:], time.perf_counter() - t, f"{r['boundary']}/{r['refitted']}"))
        if robust_laplacian is not None:
            t = time.perf_counter()
            L, M = robust_laplacian.point_cloud_laplacian(V)
            cand.append(("robust-laplacian", sym_eigs(L, M.diagonal(), 21)[1:], time.perf_counter() - t, ""))
        for label, lam, tt, cells in cand:
            med, mx = errors(lam, limit)
            med_c, _ = errors(lam, coarse)
            rows.append(dict(cloud=name, n=len(V), method=label, median=med, max=mx, median_vs_mesh=med_c, seconds=tt,
                             open_refitted=cells))
            print(f"{name:18s} {len(V):7d} {label:22s} {med:10.2e} {mx:10.2e} {med_c:10.2e} {tt:8.2f} {cells:>11s}", flush=True)
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="N = 2000 and 8000 only")
    ap.add_argument("--sizes", default=None, help="comma-separated sphere sizes")
    ap.add_argument("--strong-max", type=int, default=32000, help="largest N for the strong-form schemes")
    ap.add_argument("--json", default=None, help="also write the rows to this JSON file")
    ap.add_argument("--model", action="append", default=[], help="another closed mesh (OBJ) for the model table")
    ap.add_argument("--models-only", action="store_true", help="skip the sphere table")
    args = ap.parse_args(argv)
    sizes = [2000, 8000] if args.quick else [2000, 8000, 32000, 131072]
    if args.sizes:
        sizes = [int(v) for v in args.sizes.split(",")]
    print(f"{'cloud':18s} {'N':>7s} {'method':20s} {'median':>10s} {'max':>10s} {'build s':>8s} {'eigs s':>8s}")
    rows = [] if args.models_only else sphere_rows(sizes, args.strong_max)
    print(f"\n{'model':18s} {'N':>7s} {'method':22s} {'median':>10s} {'max':>10s} {'vs mesh':>10s} {'seconds':>8s}"
          f" {'open/refit':>11s}   (20 smallest eigenvalues against the subdivision limit of the mesh's cotan FEM;"
          " 'vs mesh': median against the mesh's own cotan FEM; 'open/refit': stable_report's cells still"
          " clipped by the hull / cells closed in the plane of the nearest points)")
    rows += model_rows(args.model)
    if args.json:
        path = Path(args.json)
        if path.exists():
            raise SystemExit(f"{path} exists: not overwritten")
        path.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
