"""Real and synthetic scans: the figures of issue 6.

Run:  python benchmarks/scans.py [--scans DIR] [--only models,bunny,igea,noise,density] [--picture PATH]

``models`` (first): one table over every model of ../shared/data/models plus the bunny
and Igea, vertices as bare points: normals from the points against the mesh's
(median angle; share pointing inward on closed one-shell models, share agreeing
on the others), then for the default scheme (msph), cspm and msph4 with all other
defaults (normals estimated): build time, particles that fell back, supports
widened, default heat (``laplacian="auto"``) bounded by the initial range, and the
stable Laplacian's 20 smallest non-zero eigenvalues against the cotan FEM of the
model's own mesh (closed one-shell models; median relative distance, with
robust-laplacian's beside it when the bench extra is installed). The ``boundary``
column is :func:`detect_boundary` with the estimated normals against the mesh's
boundary vertices (those on an edge of one face), raw: recall / share of the
flagged particles that are not mesh-boundary vertices / pieces (the detector's own); on closed models
the number of flagged particles (all false). Some mesh-boundary vertices lie inside
another part or touch one and cannot show as a rim of the cloud:
``python tests/test_boundary.py`` splits the figures by kind.

Prints, for the Stanford bunny and Igea (../shared/data/scans, skipped when absent):
reading, cleaning, normal estimation (agreement with the mesh's vertex normals),
boundary detection, operators of every scheme (finite?), and implicit heat from a
point source with the standard (Taylor) scheme and Shepard (positive) area
elements (maximum principle, convergence to a constant per connected component),
with the over- and undershoot of the corrected schemes on the same run; then the
noisy sphere (Laplace-Beltrami error per scheme at 0, 0.1, 0.2, 0.3 mean
spacings of noise, normals estimated) and the variable-density sphere (uniform
versus adaptive h).
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.sparse import csgraph

from manifold_sph import Surface
from manifold_sph.normals import estimate_normals
from manifold_sph.pde import heat
from manifold_sph.reference import functions, shapes
from manifold_sph.reference.accuracy import operator_errors
from manifold_sph.scans.boundary import detect_boundary
from manifold_sph.scans.cleaning import clean
from manifold_sph.scans.io import read

SCHEMES = ["standard", "cspm", "msph", "ncsph"]
DEFAULT_SCANS = Path(__file__).resolve().parents[2] / "shared" / "data" / "scans"
MODEL_SCHEMES = ["msph", "cspm", "msph4"]


def models_table(scans: Path):
    """The table of every model and scan (see the module notes)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from normals import MODELS, mesh_reference  # benchmarks/normals.py
    from spectra import cotan, sym_eigs  # benchmarks/spectra.py

    from manifold_sph.scans.io import read_mesh

    try:
        import robust_laplacian
    except ImportError:
        robust_laplacian = None
    paths = MODELS + [scans / "stanford-bunny.obj", scans / "igea.ply"]
    head = " ".join(f"{s + ' s/fb/wid/heat':>22s}" for s in MODEL_SCHEMES)
    print(f"{'model':12s} {'points':>7s} {'median':>7s} {'orientation':>15s} {'boundary':>17s} {head} "
          f"{'eigs: stable':>13s} {'robust':>8s}")
    for path in paths:
        if not path.exists():
            print(f"{path.stem:12s} (missing, skipped)")
            continue
        P, ref, closed, shells = mesh_reference(path)
        nrm = estimate_normals(P)
        d = np.einsum("ij,ij->i", nrm, ref)
        ang = np.degrees(np.arccos(np.clip(np.abs(d), 0.0, 1.0)))
        orient = f"{100 * np.mean(d < 0):.2f} % inward" if closed and shells == 1 else f"{100 * np.mean(d > 0):.2f} % agree"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            found = detect_boundary(P, nrm)
            rim = found.mask
        on_mesh_rim = mesh_boundary_vertices(path, P)
        if closed:
            bnd = f"{int(rim.sum())} flagged"
        else:
            fp = int((rim & ~on_mesh_rim).sum()) / max(int(rim.sum()), 1)
            bnd = f"{rim[on_mesh_rim].mean():.2f}/{fp:.2f}/{found.n_loops}"
        cols, surf = [], None
        for scheme in MODEL_SCHEMES:
            t = time.perf_counter()
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    s = Surface(P, nrm, scheme=scheme)
                    tb = time.perf_counter() - t
                    z = P[:, 1] - P[:, 1].mean()
                    u = heat(s, z, dt=1e-3 * np.ptp(P) ** 2, steps=20).u
                bounded = bool(np.all(np.isfinite(u)) and np.abs(u).max() <= np.abs(z).max() * (1 + 1e-9))
                fb = sum(len(v) for v in s.fallback.values())
                cols.append(f"{tb:6.2f}/{fb:4d}/{len(s.widened):4d}/{'yes' if bounded else 'NO':>3s}")
                surf = s if scheme == "msph" else surf
            except Exception as exc:  # noqa: BLE001 - a failure is a result
                cols.append(f"{'FAILED ' + type(exc).__name__:>22s}")
        eig_ours = eig_rl = "-"
        if closed and shells == 1 and surf is not None and len(P) <= 40000:
            V, F = read_mesh(str(path))
            U, inv = np.unique(V, axis=0, return_inverse=True)
            Fm = inv.ravel()[F]
            Fm = Fm[(Fm[:, 0] != Fm[:, 1]) & (Fm[:, 1] != Fm[:, 2]) & (Fm[:, 0] != Fm[:, 2])]
            if len(U) == len(P):
                K, m = cotan(U, Fm)
                exact = sym_eigs(K, m, 21)[1:]
                lam, _ = surf.eigs(21)
                eig_ours = f"{np.median(np.abs(lam[1:] - exact) / exact):.2e}"
                if robust_laplacian is not None:
                    L, M = robust_laplacian.point_cloud_laplacian(P)  # P and U: the same sorted unique positions
                    lr = sym_eigs(L, M.diagonal(), 21)[1:]
                    eig_rl = f"{np.median(np.abs(lr - exact) / exact):.2e}"
        print(f"{path.stem:12s} {len(P):7d} {np.median(ang):6.2f}d {orient:>15s} {bnd:>17s} {' '.join(f'{c:>22s}' for c in cols)} "
              f"{eig_ours:>13s} {eig_rl:>8s}", flush=True)


def mesh_boundary_vertices(path: Path, P: np.ndarray) -> np.ndarray:
    """(len(P),) bool: the points that are vertices on an edge of only one face of the mesh at ``path``."""
    from scipy.spatial import cKDTree

    from manifold_sph.scans.io import read_mesh

    V, F = read_mesh(str(path))
    U, inv = np.unique(V, axis=0, return_inverse=True)
    F = inv.ravel()[F]
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    ue, cnt = np.unique(e, axis=0, return_counts=True)
    rim = np.unique(ue[cnt == 1].ravel())
    out = np.zeros(len(P), bool)
    if rim.size:
        d, j = cKDTree(P).query(U[rim])
        out[j[d == 0.0]] = True
    return out


def components(surface) -> np.ndarray:
    """Connected component of every particle in the surface's neighbour graph."""
    return csgraph.connected_components(surface.laplacian_matrix(form="strong"), directed=False)[1]


def heat_run(surface, source: int, dt: float, steps: int):
    u0 = np.zeros(surface.n_points)
    u0[source] = 1.0
    try:
        with np.errstate(all="ignore"):
            u = heat(surface, u0, dt, steps, method="implicit").u
    except FloatingPointError as exc:
        return None, str(exc)
    return u, ""


def scan_pipeline(path: Path, *, mesh_reference: bool, dt: float, steps: int, picture=None, all_schemes=True):
    t_all = time.perf_counter()
    t0 = time.perf_counter()
    cloud = read(path)
    print(f"\n== {path.name}: {len(cloud)} points, read in {time.perf_counter() - t0:.2f} s")
    t0 = time.perf_counter()
    cleaned = clean(cloud.points)
    print("   " + cleaned.report.replace("\n", "\n   ") + f"  [{time.perf_counter() - t0:.2f} s]")
    pts = cleaned.points
    t0 = time.perf_counter()
    nrm, conf = estimate_normals(pts, return_confidence=True)
    print(f"   normals estimated in {time.perf_counter() - t0:.2f} s; confidence < 0.5 at {(conf < 0.5).sum()} points")
    if mesh_reference:
        ref, fields = read(path, normals="mesh", return_fields=True)
        orig = np.flatnonzero(cleaned.keep_mask)  # kept input indices, in output order
        pos = {int(i): k for k, i in enumerate(orig)}
        both = [(pos[int(i)], k) for k, i in enumerate(fields["index"]) if int(i) in pos]
        a, b = np.array(both).T
        agree = np.einsum("ij,ij->i", nrm[a], ref.normals[b]) > 0
        print(f"   orientation agrees with the mesh vertex normals at {100 * agree.mean():.3f}% of {a.size} points")
    t0 = time.perf_counter()
    rep = detect_boundary(pts, nrm)
    print(f"   boundary: {rep.report}  [{time.perf_counter() - t0:.2f} s]")
    source = int(np.argmax(pts[:, 1]))  # the top of the scan
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        t0 = time.perf_counter()
        S = Surface(pts, nrm, scheme="standard", area="shepard", h="adaptive")
        tb = time.perf_counter() - t0
    L = S.laplacian_matrix(form="strong").tocoo()
    off = L.row != L.col
    print(
        f"   standard+shepard: built in {tb:.2f} s, min off-diagonal weight {L.data[off].min():.3e} (>= 0: M-matrix), "
        f"max |row sum| {np.abs(np.asarray(S.laplacian_matrix(form='strong').sum(axis=1))).max():.1e}"
    )
    t0 = time.perf_counter()
    u, err = heat_run(S, source, dt, steps)
    lab = components(S)
    spread = max(np.ptp(u[lab == c]) for c in np.unique(lab))
    print(
        f"   heat (implicit, dt={dt:g}, {steps} steps) in {time.perf_counter() - t0:.2f} s: "
        f"min {u.min():.3e}, max {u.max():.3e} (bounds [0, 1]); {lab.max() + 1} component(s), "
        f"largest spread within a component {spread:.2e}"
    )
    short = max(1, steps // 10)
    u_std, _ = heat_run(S, source, dt / 100, short)
    print(f"   short run (dt={dt / 100:g}, {short} steps): standard min {u_std.min():.2e} max {u_std.max():.3e}")
    print(f"   pipeline (read .. heat) total {time.perf_counter() - t_all:.1f} s")
    if picture is not None:
        try:
            from manifold_sph.viz.render import render_field

            render_field(pts, u_std, title=f"heat from a point source, {path.name}", filename=picture, overwrite=True, camera="iso")
            print(f"   picture written to {picture}")
        except Exception as exc:  # rendering needs an off-screen GL context
            print(f"   picture skipped: {type(exc).__name__}: {exc}")
    if not all_schemes:
        return
    for name in SCHEMES[1:]:
        with warnings.catch_warnings(record=True):
            warnings.simplefilter("always")
            t0 = time.perf_counter()
            Sc = Surface(pts, nrm, scheme=name, area="shepard", h="adaptive")
            tb = time.perf_counter() - t0
        f = np.sin(20 * pts[:, 0]) * pts[:, 1]
        finite = all(np.all(np.isfinite(x)) for x in (Sc.laplacian(f, form="strong"), Sc.gradient(f), Sc.divergence(np.c_[f, f, f])))
        fb = sum(v.size for v in Sc.fallback.values())
        res = []
        for ddt, nst in ((dt, steps), (dt / 100, short)):
            u, err = heat_run(Sc, source, ddt, nst)
            res.append(f"dt={ddt:g}: " + ("blew up: " + err if u is None else f"min {u.min():.2e}, max {u.max():.2e}"))
        print(f"   {name:<8} built {tb:5.2f} s, operators finite: {finite}, fallback {fb}; heat " + "; ".join(res))


def noisy_sphere(n=4000, levels=(0.0, 0.1, 0.2, 0.3), seed=0, area="shepard"):
    """Relative L2 error of Lap_S(cos(xz) sin y) on a sphere with position noise (in mean spacings)."""
    fn = functions.cos_xz_sin_y
    c = shapes.sphere(n, sampling="poisson", seed=seed)
    spacing = np.sqrt(4 * np.pi / n)
    rows = []
    for level in levels:
        rng = np.random.default_rng(seed + 1)
        p = c.points + level * spacing * rng.standard_normal(c.points.shape)
        nrm = estimate_normals(p)
        xp = p / np.linalg.norm(p, axis=1)[:, None]  # exact reference at the nearest sphere points
        f = fn.value(xp)
        lap = c.geometry.laplace_beltrami(xp, fn.gradient(xp), fn.hessian(xp))
        row = {"noise": level, "normal_err_deg": float(np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", nrm, xp), -1, 1))).mean())}
        for name in SCHEMES:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                S = Surface(p, nrm, scheme=name, area=area)
            L = S.laplacian(f, form="strong")
            row[name] = float(np.linalg.norm(L - lap) / np.linalg.norm(lap)) if np.all(np.isfinite(L)) else np.nan
        rows.append(row)
    return rows


def density_study(n=4000, ratio=4.0, seed=0):
    """Relative L2 Laplace-Beltrami errors: uniform (poisson) vs variable-density sphere, uniform vs adaptive h."""
    out = []
    for label, cloud in (
        ("uniform cloud", shapes.sphere(n, sampling="poisson", seed=seed)),
        (f"variable, ratio {ratio:g}", shapes.sphere(n, sampling="variable", density_ratio=ratio, seed=seed)),
    ):
        for h in (None, "adaptive"):
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    rows = operator_errors(cloud, "cos_xz_sin_y", schemes=SCHEMES, h=h)
                out.append((label, h or "uniform", {r["scheme"]: (r["lap_l2"], r["grad_l2"]) for r in rows}))
            except ValueError as exc:
                out.append((label, h or "uniform", str(exc).split(";")[0]))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scans", type=Path, default=DEFAULT_SCANS)
    ap.add_argument("--only", default="models,bunny,igea,noise,density")
    ap.add_argument("--picture", default=None, help="PNG of the Igea heat flow (needs off-screen rendering)")
    args = ap.parse_args(argv)
    only = set(args.only.split(","))
    if "models" in only:
        print("== every model and scan, vertices as bare points, all defaults (normals estimated)")
        print("   per scheme: build seconds / particles fallen back / supports widened / default heat bounded")
        models_table(args.scans)
    if "bunny" in only:
        p = args.scans / "stanford-bunny.obj"
        if p.is_file():
            scan_pipeline(p, mesh_reference=True, dt=1e-2, steps=40)
        else:
            print(f"skipping the bunny: {p} not found")
    if "igea" in only:
        p = args.scans / "igea.ply"
        if p.is_file():
            scan_pipeline(p, mesh_reference=True, dt=1e-2, steps=10, picture=args.picture, all_schemes=False)
        else:
            print(f"skipping Igea: {p} not found")
    if "noise" in only:
        print("\n== noisy sphere, N = 4000, normals estimated, area='shepard': relative L2 error of Lap_S")
        print(f"{'noise':>6} {'normal err':>10} " + " ".join(f"{s:>9}" for s in SCHEMES))
        for r in noisy_sphere():
            print(f"{r['noise']:>6.1f} {r['normal_err_deg']:>9.2f}° " + " ".join(f"{r[s]:>9.2e}" for s in SCHEMES))
    if "density" in only:
        print("\n== variable density sphere (source Fig. 56; density ratio 4 between hemispheres), N = 4000")
        print("   relative L2 error of Lap_S / grad_S of cos(xz) sin(y), area='numerical'")
        for label, h, res in density_study():
            if isinstance(res, str):
                print(f"   {label:<20} h={h:<9} fails: {res}")
            else:
                print(f"   {label:<20} h={h:<9} " + "  ".join(f"{s} {res[s][0]:.2e}/{res[s][1]:.2e}" for s in SCHEMES))


if __name__ == "__main__":
    main()
