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
5 points around, a sphere sampled on latitude rings 6x denser along them, a thin torus
sampled on 40 meridian circles of 16 points, thin closed slabs: flat ellipsoids with a
third semi-axis of 0.5, 1 and 2 spacings, 2000 area-uniform random points): median
angle, particles more than 30 degrees off and pointing inward, with everything ("all"),
without the consensus of step 7 and without the row normals of step 2b (module notes of
manifold_sph.scans.normals). The slabs with the default, inward (seeds 0, 1): 540 / 472,
160 / 86 and 7 / 9 of 2000 (a band of one face next to the rim); with
``orient="visible"`` (step 8) 11 / 5, 7 / 7 and 4 / 1.

orient="visible" on the models (inward or disagreeing normals, default -> visible): cow
50 -> 50, cheburashka 68 -> 65, homer 1 -> 1, rocker-arm 0 -> 1, teapot 45 -> 33, beetle
33 -> 65 (seen from inside through its openings); spot 3 -> 3, suzanne 30 -> 42. About
3 s more on 10,000 points (48 convex hulls).

Run: ``python benchmarks/normals.py`` (a few minutes on 2 busy cores; ``--quick`` skips
Igea and the largest analytic clouds; ``--visible`` prints the model table (and with
``--models`` that of the given meshes) for the default and ``orient="visible"``). ``python benchmarks/normals.py --models a.obj b.ply``
prints the model table (default settings) for any meshes instead: your own, or other public
test models. Measured on five of alecjacobson/common-3d-test-models that are not in
../shared (median / >30deg / orientation): spot 1.35 / 7 / 0.10 % inward; beetle-alt
(19,885 points) 0.33 / 167 / 99.3 % agree; woody 0.00 / 0 / 100 %; suzanne (504 points,
three shells) 19.4 / 173 / 94.1 % agree; beast (32,311) 2.78 / 1884 / 90.0 % agree, where a
densely sampled thin region at the mouth (spacing 0.4 against 1.3 elsewhere, the other side
about 2 spacings away) is oriented half one way, half the other already by propagation.

Thickness-adapted probes of step 4 (commit 087d074; module notes): cheburashka 1.02 ->
0.67 % inward (68 -> 45 normals), teapot 98.61 -> 98.80 % agreeing, beast 90.0 -> 91.1 %;
cow (1.72 %), homer, rocker-arm, beetle (97.1 %), alligator, bunny, Igea, spot, suzanne,
beetle-alt unchanged; Igea 29 s, bunny 5.4 s on a loaded machine. Confidence with the
thickness term (share of doubtful normals flagged / of the others): teapot 0.53 / 0.24 ->
0.88 / 0.24, beetle 0.57 / 0.21 -> 0.61 / 0.22, cheburashka 0.80 / 0.04 -> 0.85 / 0.04, cow
0.86 / 0.21 -> 0.88 / 0.22.

Measured (default; median angle / normals more than 30 degrees off / orientation),
before (commit 9401b37) -> after the distance-weighted base fit, the row normals of step
2b, the area rescaling and the patch flags of step 4:

    model         before                      after
    cow           6.15 / 238 / 2.69 % in      5.40 / 211 / 1.72 % in
    homer         2.19 / 22 / 0.03 % in       1.98 / 19 / 0.02 % in
    rocker-arm    3.19 / 18 / 0.01 % in       3.00 / 9 / 0.00 % in
    cheburashka   1.33 / 205 / 1.06 % in      1.25 / 187 / 1.02 % in
    teapot        2.63 / 663 / 88.7 % agree   2.17 / 139 / 98.6 % agree
    beetle        10.40 / 186 / 96.9 % agree  8.75 / 155 / 97.1 % agree
    alligator     0 / 0 / 100 % agree         0 / 0 / 100 % agree
    bunny         1.18 / 26 / 100 % agree     0.97 / 25 / 100 % agree
    Igea          0.60 / 35 / 0.00 % in       0.52 / 36 / 0.00 % in

degree=4: cow 6.27 / 280 -> 5.58 / 235, teapot 3.09 / 711 -> 2.26 / 240 (98.6 % agree),
beetle 11.16 / 214 -> 9.27 / 173. Orders unchanged (default 2.9-3.0 on the spheres, 2.0
on the torus, whose error dropped by a quarter: 0.25 / 0.062 / 0.015 -> 0.19 / 0.047 /
0.012 deg; degree 3 unchanged, degree 4 within 6 %). Ring sphere: 160 of 960 inward ->
none; meridian torus (40 x 16): 37 / 2 normals more than 30 degrees off and none
inward (without step 2b 281 / 343, 39 / 60 inward). Time (single-threaded BLAS, best of
3, old -> new (commit 8226fc4, same work as now) on a loaded machine):
cow 0.38 -> 0.45 s, homer 0.82 -> 0.87, rocker-arm 1.84 -> 2.37, cheburashka 1.93 -> 1.72,
teapot 0.81 -> 0.97, beetle 0.33 -> 0.50, alligator 0.53 -> 0.57, bunny 6.10 -> 6.85,
Igea 25.8 -> 32.8 (one run).
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


def meridian_torus(meridians=40, per=16, R=1.0, r=0.08, seed=0):
    """A thin torus on planar meridian circles of ``per`` points (a rolled lip; as in tests/test_normals.py)."""
    rng = np.random.default_rng(seed)
    phi = np.repeat((np.arange(meridians) + 0.3 * rng.random(meridians)) * 2 * np.pi / meridians, per)
    th = ((np.arange(per)[None, :] + 0.3 * rng.random((meridians, per))) * 2 * np.pi / per).ravel()
    n = np.c_[np.cos(th) * np.cos(phi), np.cos(th) * np.sin(phi), np.sin(th)]
    return np.c_[R * np.cos(phi), R * np.sin(phi), np.zeros_like(phi)] + r * n, n


def flat_ellipsoid(n=2000, thickness=1.0, seed=0):
    """A thin closed slab: the ellipsoid with semi-axes 1, 0.6 and ``thickness`` spacings
    (spacing ``sqrt(2 pi 0.6 / n)``), ``n`` area-uniform random points (rejection sampling of
    the mapped sphere), and its exact outward normals (as in tests/test_normals.py)."""
    rng = np.random.default_rng(seed)
    axes = np.array([1.0, 0.6, thickness * np.sqrt(2 * np.pi * 0.6 / n)])
    pts = np.zeros((0, 3))
    while len(pts) < n:
        u = rng.standard_normal((4 * n, 3))
        u /= np.linalg.norm(u, axis=1)[:, None]
        g = np.linalg.norm(u / axes, axis=1)  # area element of the map u -> axes * u, up to a constant
        pts = np.vstack([pts, (u * axes)[rng.random(4 * n) < g / g.max()]])
    pts = pts[:n]
    nrm = pts / axes**2
    return pts, nrm / np.linalg.norm(nrm, axis=1)[:, None]


def synthetic():
    from manifold_sph.scans import normals as mod

    clouds = [(f"thin torus seed {s}", shapes.thin_torus(seed=s)) for s in range(3)]
    clouds += [(f"ring sphere seed {s}", shapes.ring_sphere(seed=s)) for s in range(3)]
    cases = [(name, (c.points, c.normals)) for name, c in clouds]
    cases += [(f"meridian torus {s}", meridian_torus(seed=s)) for s in range(2)]
    cases += [(f"slab {t:g} sp seed {s}", flat_ellipsoid(thickness=t, seed=s)) for t in (0.5, 1.0, 2.0) for s in range(2)]
    print(f"\n{'cloud':20s} {'points':>7s} {'steps':>10s} {'median':>7s} {'>30deg':>7s} {'inward':>7s}")
    original, steep = mod._consensus, mod._ROW_STEEP
    for name, (p, exact) in cases:
        for label in ("all", "no step 7", "no 2b"):
            if label == "no step 7":
                mod._consensus = lambda pts, nb, n, fixed=None: (n, None)
            if label == "no 2b":
                mod._ROW_STEEP = 0
            try:
                d = np.einsum("ij,ij->i", estimate_normals(p), exact)
            finally:
                mod._consensus, mod._ROW_STEEP = original, steep
            ang = np.degrees(np.arccos(np.clip(np.abs(d), 0.0, 1.0)))
            print(f"{name:20s} {len(p):7d} {label:>10s} {np.median(ang):6.2f}d {int((ang > 30).sum()):7d} {int((d < 0).sum()):7d}", flush=True)


if __name__ == "__main__":
    variants = (("default", {}),) + ((("visible", {"orient": "visible"}),) if "--visible" in sys.argv else ())
    if "--models" in sys.argv:  # any meshes: python benchmarks/normals.py --models a.obj b.ply ...
        model_table([Path(a) for a in sys.argv[sys.argv.index("--models") + 1:] if a != "--visible"], variants=variants)
        raise SystemExit
    if "--visible" in sys.argv:  # python benchmarks/normals.py --visible: the models with orient="visible" too
        model_table(MODELS + SCANS[:1], variants=variants)
        raise SystemExit
    quick = "--quick" in sys.argv
    model_table(MODELS + SCANS[: 1 if quick else 2])
    orders(quick)
    synthetic()
