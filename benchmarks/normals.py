"""Normals from bare points against mesh normals, and convergence orders on analytic shapes.

Every model of ../shared/data/models plus the bunny and Igea of ../shared/data/scans
(missing files are skipped): the VERTICES are the point cloud (faces dropped, exact
duplicate positions merged), the faces give the reference (area-weighted vertex
normals, outward). Columns, for the default and for ``degree=4``: points, share of
normals within 10 degrees of the mesh's, median angle (unsigned), particles more than
30 degrees off, and for closed meshes the share pointing inward, for open or
multi-shell ones the share agreeing in sign with the mesh; the sign agreement among
the particles within 30 degrees; time of :func:`manifold_sph.estimate_normals`.

Then the normal error (mean angle) against resolution on the Fibonacci sphere, a
Poisson-disk sphere and a Poisson-disk torus, with the fitted order, for the default
(jet, degree 2), degree 3 and 4 and ``method="pca"``.

Last, thin and anisotropically sampled synthetic clouds with exact normals (a torus tube
5 points around, a sphere sampled on latitude rings 6x denser along them): median angle,
particles more than 30 degrees off and pointing inward, with the consensus of step 7
(module notes of manifold_sph.scans.normals) and without it.

Run: ``python benchmarks/normals.py`` (about a minute on 2 cores; ``--quick`` skips
Igea and the largest analytic clouds).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from manifold_sph.reference import shapes
from manifold_sph.scans.io import read_mesh
from manifold_sph.scans.normals import estimate_normals

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
MODELS = [DATA / "models" / f for f in ("cow.obj", "homer.obj", "rocker-arm.obj", "cheburashka.obj", "teapot.obj", "beetle.obj", "alligator.obj")]
SCANS = [DATA / "scans" / "stanford-bunny.obj", DATA / "scans" / "igea.ply"]


def mesh_reference(path):
    """Distinct vertex positions (those used by faces), area-weighted unit normals, closed?, shells."""
    V, F = read_mesh(str(path))
    U, inv = np.unique(V, axis=0, return_inverse=True)
    F = inv.ravel()[F]
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    c = np.cross(U[F[:, 1]] - U[F[:, 0]], U[F[:, 2]] - U[F[:, 0]])  # twice the area times the normal
    N = np.zeros_like(U)
    for a in range(3):
        np.add.at(N, F[:, a], c)
    length = np.linalg.norm(N, axis=1)
    used = np.zeros(len(U), bool)
    used[F.ravel()] = True
    keep = used & (length > 0)
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    closed = bool(np.all(counts == 2))
    A = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(len(U), len(U)))
    shells = csgraph.connected_components(A, directed=False)[0] - int((~used).sum())
    return U[keep], N[keep] / length[keep, None], closed, shells


def model_table(paths, variants=(("default", {}), ("degree=4", {"degree": 4}))):
    """One row per model and variant of :func:`estimate_normals`; ``>30deg`` counts the
    particles whose direction is more than 30 degrees off (their sign is moot: thin or
    coarsely sampled parts), ``sign ok`` the orientation among the others."""
    print(f"{'model':14s} {'normals':>9s} {'points':>7s} {'shells':>6s} {'<10deg':>7s} {'median':>7s} {'>30deg':>7s} "
          f"{'orientation':>22s} {'sign ok':>8s} {'time':>7s}")
    for path in paths:
        if not path.exists():
            print(f"{path.stem:14s} (missing, skipped)")
            continue
        P, ref, closed, shells = mesh_reference(path)
        for label, kw in variants:
            t = time.perf_counter()
            n = estimate_normals(P, **kw)
            t = time.perf_counter() - t
            d = np.einsum("ij,ij->i", n, ref)
            ang = np.degrees(np.arccos(np.clip(np.abs(d), 0.0, 1.0)))
            orient = f"{100 * np.mean(d < 0):6.2f} % inward" if closed and shells == 1 else f"{100 * np.mean(d > 0):6.2f} % agree (open)"
            sure = ang <= 30
            print(f"{path.stem:14s} {label:>9s} {len(P):7d} {shells:6d} {100 * np.mean(ang < 10):6.1f}% {np.median(ang):6.2f}d "
                  f"{int((~sure).sum()):7d} {orient:>22s} {100 * np.mean(d[sure] > 0):7.2f}% {t:6.2f}s", flush=True)


def orders(quick=False):
    cases = [
        ("sphere fibonacci", lambda n: shapes.sphere(n), (1000, 4000, 16000)),
        ("sphere poisson", lambda n: shapes.sphere(n, sampling="poisson"), (1000, 4000, 16000)),
        ("torus poisson", lambda n: shapes.torus(n), (2000, 8000, 32000)),
    ]
    variants = [("jet d2 (default)", {}), ("jet d3", {"degree": 3}), ("jet d4", {"degree": 4}), ("pca", {"method": "pca"})]
    print(f"\n{'cloud':18s} {'normals':18s} {'mean angle error (deg) at N':>40s} {'order':>6s}")
    for name, make, ns in cases:
        ns = ns[:2] if quick else ns
        clouds = [make(n) for n in ns]
        h = np.array([n**-0.5 for n in ns])
        for label, kw in variants:
            err = []
            for c in clouds:
                n = estimate_normals(c.points, **kw)
                err.append(np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", n, c.normals), -1.0, 1.0))).mean())
            slope = np.polyfit(np.log(h), np.log(err), 1)[0]
            print(f"{name:18s} {label:18s} {' '.join(f'{e:.2e}' for e in err):>40s} {slope:6.2f}", flush=True)


def synthetic():
    from manifold_sph.scans import normals as mod

    clouds = [(f"thin torus seed {s}", shapes.thin_torus(seed=s)) for s in range(3)]
    clouds += [(f"ring sphere seed {s}", shapes.ring_sphere(seed=s)) for s in range(3)]
    cases = [(name, (c.points, c.normals)) for name, c in clouds]
    print(f"\n{'cloud':20s} {'points':>7s} {'step 7':>7s} {'median':>7s} {'>30deg':>7s} {'inward':>7s}")
    original = mod._consensus
    for name, (p, exact) in cases:
        for label, fn in (("on", original), ("off", lambda pts, nb, n, fixed=None: (n, None))):
            mod._consensus = fn
            try:
                d = np.einsum("ij,ij->i", estimate_normals(p), exact)
            finally:
                mod._consensus = original
            ang = np.degrees(np.arccos(np.clip(np.abs(d), 0.0, 1.0)))
            print(f"{name:20s} {len(p):7d} {label:>7s} {np.median(ang):6.2f}d {int((ang > 30).sum()):7d} {int((d < 0).sum()):7d}", flush=True)


if __name__ == "__main__":
    quick = "--quick" in sys.argv
    model_table(MODELS + SCANS[: 1 if quick else 2])
    orders(quick)
    synthetic()
