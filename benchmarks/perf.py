"""Speed, memory and accuracy of every build step, side by side with the peers (issue 8).

    python benchmarks/perf.py                                   # N = 10000, 100000
    python benchmarks/perf.py --sizes 10000,100000,1000000 --repeat 3 --json perf.json --peers
    python benchmarks/perf.py --ratios --sizes 10000,131072,1000000,4000000   # issue 22: ratios, RSS
    python benchmarks/perf.py --ratios --sampling random --sizes 131072,1000000
    python benchmarks/perf.py --stages --sizes 131072,1000000 --repeat 3    # where the build's seconds go

Unit sphere, Fibonacci points (``manifold_sph.reference.shapes.sphere``), exact normals,
f = cos(xz - sin y). Every speed figure stands next to the relative L2 error of
the Laplace-Beltrami operator it belongs to, against the exact reference
(``manifold_sph.reference.accuracy.exact_operators``); rows that are only a part of the
cspm build (KD-tree, neighbours, frames) carry the cspm error.

Steps, each timed separately (median of ``--repeat`` runs, ``time.perf_counter``):

- ``kdtree radius (bare)``: scipy ``cKDTree`` build + ``query_ball_point`` with
  ``return_length=True``, ``workers=-1``, at the cspm support radius: the lower
  bound no method avoids. Also with ``workers=1`` (the two-core speedup), and the
  k-NN ``query`` (k = 32, ``distance_upper_bound``) that the package itself uses;
- ``h (smoothing length)``: :func:`smoothing_length_for_count` on a prebuilt tree;
- ``neighbours``: :func:`find_neighbors` (k-NN search + radius + normal filter);
- ``frames+projection``: :func:`tangent_frames`, :func:`check_frames`, :func:`project_neighborhood`;
- ``area shepard`` / ``area numerical``: :func:`area_elements`;
- ``assembly <scheme>`` for cspm, msph, ncsph, msph4 (msph4 on its own 30-neighbour
  neighbourhood, the others on 27; area elements: numerical, msph4 does not use them);
- ``end-to-end <scheme>``: the whole :class:`Surface` construction (cspm with the
  default ``area="numerical"`` and with ``"shepard"``; msph4 with ``"shepard"``);
- ``matvec``: scipy's ``L @ f`` (one thread) and ``s.laplacian(f)`` (row blocks on threads) on the cspm Laplacian, and
  ``stream bytes``: reading the CSR arrays once (``np.sum(data)``, ``np.max(indices)``, ``np.max(indptr)``);
- ``heat``: :func:`manifold_sph.pde.heat`, implicit Euler, one step (the step-matrix
  build, the factorisation or the Jacobi set-up, and the solve): ``direct`` (sparse LU)
  up to 20,000 points, ``iterative`` (BiCGSTAB) always. Its error is that of the
  increment of u0 = z (a degree-1 harmonic, exact step z / (1 + 2 dt)).

Peak memory (``peak MB``): ``tracemalloc`` peak above the level before the step, in a
separate, untimed run of the step. numpy allocations are traced; the KD-tree's own
C++ arrays and the peers' (Kokkos, C++) allocations are not, so their rows say n/a.
The process's ``ru_maxrss`` is printed at the end.

A real scan (``--scan``, default the Igea scan of ``../shared/data/scans``, 134,345
points, skipped when absent): read, normals estimated, then the end-to-end builds and
the GMLS peers, timed as for the sphere. A scan has no exact reference, so its rows give
each Laplacian's relative difference from msph's (area shepard, h adaptive: the README's
advice for scans) instead of an error,
for f = cos(xz - sin y) in coordinates scaled to [-1, 1].

``end-to-end cspm, 1 thread`` repeats the default build under
``manifold_sph.threads.limit(1)``: the two-core speedup of the whole build.
``end-to-end cspm, numpy kernels`` repeats it with the compiled kernels of
``manifold_sph._jit`` turned off (``MANIFOLD_SPH_JIT=0``: the numpy schemes,
neighbour filter, projection and Krylov solve): what the compiled kernels gain.
Every other row runs the compiled kernels (the package's default), loaded from
numba's on-disk cache: a warm-up build at N = 2000 compiles them first if needed.

Spectrum: the largest relative error of the 15 smallest nonzero eigenvalues
(l (l + 1), l = 1..3) is printed for ours (cspm, msph4) up to N = 20,000 and for
robust-laplacian (``L x = lam M x``) up to N = 200,000. robust-laplacian is a
weak-form (cotan-like) Laplacian: its pointwise ``M^-1 L f`` is not expected to
converge on irregular points, its eigenvalues are.

``--peers`` (the ``bench`` extra, on the same points in the same run):
robust-laplacian ``point_cloud_laplacian`` (its (L, M) give the Laplacian
``-M^-1 L``: the sign is checked against the exact reference and both errors are
kept in the JSON) and pycompadre GMLS at polynomial order 2 and 4 (the call of
``benchmarks/msph4_vs_gmls.py``: manifold GMLS, QR, its default weighting, k-NN
neighbours; build = KD-tree + neighbour lists + ``generateAlphas``).

Threads: nothing is limited (numpy, scipy ``workers=-1``, Kokkos/OpenMP all use
every core). ``OMP_WAIT_POLICY`` defaults to ``PASSIVE`` here (set before the peers
load): with OpenMP's default spinning, pycompadre's idle Kokkos threads kept a core
busy and slowed every threaded step of ours measured after it in the same process. The load average before and after is printed,
because other jobs may share the machine.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import resource
import statistics
import sys
import time
import tracemalloc
import warnings

# pycompadre's Kokkos/OpenMP threads spin while idle by default and would steal the
# second core from our threaded steps run between its calls; let them sleep instead.
# Set before any OpenMP runtime loads; an explicit user setting wins.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np
from scipy.spatial import cKDTree

from manifold_sph import PointCloud, Surface, _jit, estimate_normals, read, threads
from manifold_sph.area import area_elements
from manifold_sph.assembly import assemble
from manifold_sph.frames import check_frames, project_neighborhood, tangent_frames
from manifold_sph.kernels import get_kernel
from manifold_sph.neighbors import GRID_MIN_POINTS, H_SAMPLE, find_neighbors, smoothing_length_for_count
from manifold_sph.pde import heat
from manifold_sph.reference import shapes
from manifold_sph.reference.accuracy import exact_operators
from manifold_sph.reference.errors import error_summary
from manifold_sph.reference.functions import cos_xz_sin_y
from manifold_sph.schemes import get_scheme

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from msph4_vs_gmls import gmls, median_build  # noqa: E402 - the GMLS call shared with that benchmark

SCHEMES = ("cspm", "msph", "ncsph", "msph4")
KERNEL = "quintic"
HEAT_DT = 0.01
DIRECT_MAX = 20000


# ----------------------------------------------------------------------------- helpers
def timed(fn, repeat, min_time=0.0):
    """Median wall time of ``fn()`` over ``repeat`` runs, and its last result.

    Runs shorter than ``min_time`` are looped and the loop time divided. The previous
    run's result is released (and garbage collected) before each run, untimed: otherwise
    every run allocates fresh memory while the last result still holds its own, and
    first-touch page faults (slow on this VM: 1.6 s for 650 MB of never-used memory,
    0.1 s when reused) are timed instead of the code."""
    times, out = [], None
    for _ in range(repeat):
        out = None
        gc.collect()
        loops, t = 0, 0.0
        t0 = time.perf_counter()
        while True:
            out = fn()
            loops += 1
            t = time.perf_counter() - t0
            if t >= min_time:
                break
        times.append(t / loops)
    return statistics.median(times), out


def traced_peak(fn, enabled=True):
    """Peak traced memory (MB) above the level before ``fn()`` (one untimed run)."""
    if not enabled:
        return None
    gc.collect()
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    tracemalloc.reset_peak()
    try:
        out = fn()
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    del out
    return (peak - base) / 2**20


def lap_err(approx, exact):
    return float(error_summary(approx, exact)["l2_rel"])


def quiet(fn):
    def run():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return fn()

    return run


#: Eigenvalues l (l + 1) of -Lap on the unit sphere, l = 1, 2, 3 (multiplicities 3, 5, 7).
SPHERE_EIGS = np.repeat([2.0, 6.0, 12.0], [3, 5, 7])
SPECTRUM_OURS_MAX = 20000  # our shift-invert LU (27 entries a row) takes 30-40 s at 1e5
SPECTRUM_PEER_MAX = 200000


def spectrum_err(L, M=None):
    """Largest relative error of the 15 smallest nonzero eigenvalues on the unit sphere.

    ``-L x = lam x`` for ours (non-symmetric: ARPACK ``eigs``), ``L x = lam M x`` for a
    weak-form peer (symmetric: ``eigsh``); shift-invert at -0.5, the zero mode dropped.
    """
    import scipy.sparse.linalg as spla

    if M is None:
        vals = spla.eigs(-L, k=16, sigma=-0.5, return_eigenvectors=False)
    else:
        vals = spla.eigsh(L, k=16, M=M, sigma=-0.5, return_eigenvectors=False)
    vals = np.sort(vals.real)[1:]
    return float(np.max(np.abs(vals - SPHERE_EIGS) / SPHERE_EIGS))


# ----------------------------------------------------------------------------- ours
def bench_size(n, repeat, mem, peers, pc):
    cloud = shapes.sphere(n)
    pts, nrm = cloud.points, cloud.normals
    f, _, lap_ex = exact_operators(cloud, cos_xz_sin_y)
    kernel = get_kernel(KERNEL)
    sup = kernel.support
    rows = []

    def add(step, t, err=None, peak=None, note="", **extra):
        rows.append({"n": n, "step": step, "time_s": t, "lap_l2": err, "peak_mb": peak, "note": note, **extra})
        e = "-" if err is None else f"{err:.3e}"
        p = "n/a" if peak is None else f"{peak:.0f}"
        print(f"{n:>8d} {step:<31} {t:>9.4f} {p:>8} {e:>10}  {note}", flush=True)

    # the geometry shared by the 27-neighbour schemes and by msph4 (30)
    geo = {}
    for k in sorted({get_scheme(s).default_neighbors for s in SCHEMES}):
        tree = cKDTree(pts)
        h = smoothing_length_for_count(pts, k, sup, tree=tree)
        nb = find_neighbors(pts, nrm, h=h, support=sup, tree=tree)
        u, v = tangent_frames(nrm)
        xy = project_neighborhood(pts, u, v, nb.indptr, nb.indices)
        areas = {m: area_elements(m, nb, xy, kernel) for m in ("shepard", "numerical")}
        geo[k] = (tree, h, nb, xy, areas)
    k27 = get_scheme("cspm").default_neighbors
    tree, h, nb, xy, areas = geo[k27]
    radius = sup * h

    # end-to-end first: its errors label the part rows
    t_e2e, s = timed(quiet(lambda: Surface(cloud, scheme="cspm")), repeat)
    L = s.laplacian_matrix(form="strong")
    e_cspm = lap_err(L @ f, lap_ex)
    p_e2e = traced_peak(quiet(lambda: Surface(cloud, scheme="cspm")), mem)
    e2e_note = f"area numerical, {nb.counts.mean():.1f} nb, {sum(v.size for v in s.fallback.values())} fallback"

    # bare KD-tree: the floor
    def bare(workers):
        return lambda: cKDTree(pts).query_ball_point(pts, radius, return_length=True, workers=workers)

    t_bare, cnt = timed(bare(-1), repeat)
    add("kdtree radius (bare)", t_bare, None, traced_peak(bare(-1), mem), f"build + ball query, workers=-1, mean count {cnt.mean():.1f}")
    t_bare1, _ = timed(bare(1), repeat)
    add("kdtree radius workers=1", t_bare1, None, None, f"2-core speedup x{t_bare1 / t_bare:.2f}")
    t_build, _ = timed(lambda: cKDTree(pts), repeat)
    add("  of which tree build", t_build, None, None, "single-threaded")
    t_knn, _ = timed(lambda: tree.query(pts, k=32, distance_upper_bound=radius, workers=-1), repeat)
    add("kdtree kNN k=32 (bare)", t_knn, None, traced_peak(lambda: tree.query(pts, k=32, distance_upper_bound=radius, workers=-1), mem),
        "prebuilt tree, workers=-1")

    # the steps of the cspm pipeline
    t_h, _ = timed(lambda: smoothing_length_for_count(pts, k27, sup, tree=tree), repeat)
    add("h (smoothing length)", t_h, e_cspm, traced_peak(lambda: smoothing_length_for_count(pts, k27, sup, tree=tree), mem),
        f"k-NN k={int(np.ceil(1.5 * k27)) + 4} on {min(n, H_SAMPLE)} strided points")
    nbf = lambda: find_neighbors(pts, nrm, h=h, support=sup, tree=tree)
    t_nb, _ = timed(nbf, repeat)
    add("neighbours", t_nb, e_cspm, traced_peak(nbf, mem), f"{nb.indices.size} pairs")

    def frames():
        u, v = tangent_frames(nrm)
        check_frames(nrm, u, v)
        return project_neighborhood(pts, u, v, nb.indptr, nb.indices)

    t_fr, _ = timed(frames, repeat)
    add("frames+projection", t_fr, e_cspm, traced_peak(frames, mem))

    area_t = {}
    for m in ("shepard", "numerical"):
        fn = lambda m=m: area_elements(m, nb, xy, kernel)
        area_t[m], _ = timed(fn, repeat)
        ops = assemble(nb, xy, areas[m].dV[nb.indices], kernel, get_scheme("cspm"), n_cols=n)
        add(f"area {m}", area_t[m], lap_err(ops.lap @ f, lap_ex), traced_peak(fn, mem),
            f"error: cspm with these dV, {areas[m].n_negative} negative")

    asm_t, asm_err = {}, {}
    for name in SCHEMES:
        k = get_scheme(name).default_neighbors
        _, _, nbk, xyk, ak = geo[k]
        dVp = ak["numerical"].dV[nbk.indices]
        fn = quiet(lambda nbk=nbk, xyk=xyk, dVp=dVp, name=name: assemble(nbk, xyk, dVp, kernel, get_scheme(name), n_cols=n))
        asm_t[name], ops = timed(fn, repeat)
        asm_err[name] = lap_err(ops.lap @ f, lap_ex)
        fb = sum(v.size for v in ops.fallback.values())
        add(f"assembly {name}", asm_t[name], asm_err[name], traced_peak(fn, mem), f"{nbk.counts.mean():.1f} nb, {fb} fallback")

    add("end-to-end cspm", t_e2e, e_cspm, p_e2e, e2e_note)
    with threads.limit(1):
        t_e2e1, _ = timed(quiet(lambda: Surface(cloud, scheme="cspm")), repeat)
    add("end-to-end cspm, 1 thread", t_e2e1, e_cspm, None, f"threads.limit(1); 2-core speedup x{t_e2e1 / t_e2e:.2f}")
    _jit.ENABLED = False
    try:
        t_np, s_np = timed(quiet(lambda: Surface(cloud, scheme="cspm")), repeat)
    finally:
        _jit.ENABLED = True
    e_np = lap_err(s_np.laplacian(f, form="strong"), lap_ex)
    del s_np
    add("end-to-end cspm, numpy kernels", t_np, e_np, None, f"MANIFOLD_SPH_JIT=0; compiled kernels x{t_np / t_e2e:.2f} faster")
    t_e2e_sh, s_sh = timed(quiet(lambda: Surface(cloud, scheme="cspm", area="shepard")), repeat)
    e_sh = lap_err(s_sh.laplacian(f, form="strong"), lap_ex)
    add("end-to-end cspm shepard", t_e2e_sh, e_sh, None, "area shepard")
    del s_sh
    t_m4, s4 = timed(quiet(lambda: Surface(cloud, scheme="msph4", area="shepard")), repeat)
    e_m4 = lap_err(s4.laplacian(f, form="strong"), lap_ex)
    fb4 = sum(v.size for v in s4.fallback.values())
    add("end-to-end msph4", t_m4, e_m4, traced_peak(quiet(lambda: Surface(cloud, scheme="msph4", area="shepard")), mem),
        f"area shepard (unused), {s4.neighborhood.counts.mean():.1f} nb, {fb4} fallback")
    spec = {}
    if n <= SPECTRUM_OURS_MAX:
        spec = {"cspm": spectrum_err(L), "msph4": spectrum_err(s4.laplacian_matrix(form="strong"))}
        print(f"{'':>8} spectrum (15 smallest nonzero eigenvalues of -L vs l(l+1), max relative error): "
              f"cspm {spec['cspm']:.2e}, msph4 {spec['msph4']:.2e}", flush=True)
    del s4

    # matvec against streaming the matrix bytes once
    nbytes = L.data.nbytes + L.indices.nbytes + L.indptr.nbytes
    t_sp, _ = timed(lambda: L @ f, max(repeat, 3), min_time=0.05)
    add("matvec scipy L @ f", t_sp, e_cspm, traced_peak(lambda: L @ f, mem), f"nnz {L.nnz}, {nbytes / 2**20:.1f} MB CSR, one thread")
    s.laplacian(f, form="strong")  # splits L into row blocks once
    t_mv, _ = timed(lambda: s.laplacian(f, form="strong"), max(repeat, 3), min_time=0.05)
    add("matvec s.laplacian(f)", t_mv, e_cspm, traced_peak(lambda: s.laplacian(f, form="strong"), mem),
        "row blocks on threads, input checks included")
    stream = lambda: (float(np.sum(L.data)), int(np.max(L.indices)), int(np.max(L.indptr)))
    t_st, _ = timed(stream, max(repeat, 3), min_time=0.05)
    add("stream matrix bytes", t_st, None, None, f"{nbytes / t_st / 1e9:.1f} GB/s; matvec/stream x{t_mv / t_st:.2f}")
    t_cp, _ = timed(lambda: (L.data.copy(), L.indices.copy()), max(repeat, 3), min_time=0.05)
    add("copy matrix bytes", t_cp, None, None, "read + write")

    # implicit heat, one step
    z = pts[:, 2].copy()
    exact_inc = z / (1 + 2 * HEAT_DT) - z
    heat_t = {}
    for solver in (("direct", "iterative") if n <= DIRECT_MAX else ("iterative",)):
        fn = lambda solver=solver: heat(s, z, dt=HEAT_DT, steps=1, method="implicit", solver=solver).u
        heat_t[solver], u1 = timed(fn, repeat)
        add(f"heat implicit 1 step {solver}", heat_t[solver], lap_err(u1 - z, exact_inc), traced_peak(fn, mem),
            "error of the increment (u0 = z)" + (", includes LU" if solver == "direct" else ", BiCGSTAB 1e-10"))

    res = {
        "e2e_cspm": t_e2e, "e2e_cspm_err": e_cspm, "e2e_cspm_1thread": t_e2e1,
        "bare_radius": t_bare, "bare_radius_w1": t_bare1, "bare_knn": t_knn,
        "e2e_msph4": t_m4, "e2e_msph4_err": e_m4, "matvec": t_mv, "matvec_scipy": t_sp, "stream": t_st, "peak_e2e_mb": p_e2e,
        "e2e_cspm_shepard": t_e2e_sh, "e2e_cspm_shepard_err": e_sh, "spectrum_err": spec,
        "assembly": asm_t, "assembly_err": asm_err, "heat": heat_t,
    }
    s = L = None  # free the matrices before the peers run
    gc.collect()
    if peers and n <= peers:
        res["peers"] = bench_peers(cloud, f, lap_ex, repeat, pc, add)
    return rows, res


# ----------------------------------------------------------------------------- peers
def bench_peers(cloud, f, lap_ex, repeat, pc, add):
    out = {}
    pts = np.ascontiguousarray(cloud.points)
    try:
        import robust_laplacian
    except ImportError as exc:  # pragma: no cover - environment
        print(f"robust-laplacian not installed ({exc}); skipped")
    else:
        t, (Lr, Mr) = timed(lambda: robust_laplacian.point_cloud_laplacian(pts), repeat)
        m = Mr.diagonal()
        e_neg = lap_err(-(Lr @ f) / m, lap_ex)
        e_pos = lap_err((Lr @ f) / m, lap_ex)
        sign = "-M^-1 L" if e_neg <= e_pos else "+M^-1 L"
        area = getattr(cloud.shape, "area", None)
        mass = float(m.sum() / area) if area else float("nan")  # 1 when its local triangulations cover the surface
        # a weak-form Laplacian: its eigenvalues (L x = lam M x) are the fairer accuracy figure
        sp_err = spectrum_err(Lr, Mr) if pts.shape[0] <= SPECTRUM_PEER_MAX and area else None
        sp_txt = "" if sp_err is None else f", spectrum error {sp_err:.2e}"
        add("peer robust_laplacian", t, min(e_neg, e_pos), None,
            f"n_neighbors=30, Laplacian {sign} (other sign {max(e_neg, e_pos):.2e}), sum M / area {mass:.3f}{sp_txt}; peak n/a (C++)")
        out["robust_laplacian"] = {"time_s": t, "lap_l2": min(e_neg, e_pos), "lap_l2_neg": e_neg, "lap_l2_pos": e_pos,
                                   "mass_over_area": mass, "spectrum_err": sp_err}
        del Lr, Mr
    if pc is not None:
        for order in (2, 4):
            row = median_build(lambda: gmls(pc, cloud, order), repeat)
            t = row["build"]
            add(f"peer gmls p{order}", t, row["lap"], None, f"pycompadre, {row['note']}, default weighting; peak n/a (Kokkos)")
            out[f"gmls_p{order}"] = {"time_s": t, "lap_l2": row["lap"]}
    return out


# ----------------------------------------------------------------------------- a real scan
DEFAULT_SCAN = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "shared", "data", "scans", "igea.ply")


def bench_scan(path, repeat, pc):
    """A scan as a user meets it: vertices only, normals estimated, then the builds.

    No exact reference exists for a scan: the error column stays empty and the
    note gives the relative difference of each Laplacian of f from msph's."""
    rows = []
    name = os.path.basename(path)

    def add(step, t, note=""):
        rows.append({"n": name, "step": step, "time_s": t, "note": note})
        print(f"{name:>8} {step:<31} {t:>9.4f} {'n/a':>8} {'-':>10}  {note}", flush=True)

    t_read, cloud = timed(lambda: read(path), repeat)
    pts = cloud.points
    add("read", t_read, f"{pts.shape[0]} points, normals in file: {cloud.normals is not None}")
    t_nrm, nrm = timed(lambda: estimate_normals(pts), repeat)
    add("estimate normals", t_nrm, "PCA + outward orientation (manifold_sph.estimate_normals)")
    cloud = PointCloud(pts, nrm)
    # f = cos(xz - sin y) in coordinates scaled to [-1, 1] (the head is 0.1 across)
    X = (pts - 0.5 * (pts.min(0) + pts.max(0))) / (0.5 * float(np.ptp(pts, axis=0).max()))
    f = np.cos(X[:, 0] * X[:, 2] - np.sin(X[:, 1]))
    out = {"n_points": int(pts.shape[0]), "read": t_read, "normals": t_nrm}
    laps = {}
    # the README's advice for scans (area "shepard", h "adaptive") and the defaults
    runs = (("msph", "shepard", "adaptive"), ("cspm", "shepard", "adaptive"), ("cspm", "numerical", None),
            ("msph4", "shepard", "adaptive"))
    for scheme, area, hh in runs:
        kw = {} if hh is None else {"h": hh}
        t, s = timed(quiet(lambda: Surface(cloud, scheme=scheme, area=area, **kw)), repeat)
        key = f"{scheme} {area}" + ("" if hh is None else f" h={hh}")
        laps[key] = s.laplacian(f, form="strong")
        fb = sum(v.size for v in s.fallback.values())
        ref = laps["msph shepard h=adaptive"]
        diff = np.linalg.norm(laps[key] - ref) / np.linalg.norm(ref)
        add(f"e2e {key}", t, f"{s.neighborhood.counts.mean():.1f} nb, {fb} fallback, "
            f"{s.area.n_negative} dV < 0; |L f - L_msph f| / |L_msph f| = {diff:.2e}")
        out[f"e2e_{key}"] = t
        del s
    if pc is not None:
        for order in (2, 4):
            t = median_build(lambda: gmls(pc, cloud, order), repeat)["build"]
            add(f"peer gmls p{order}", t, f"pycompadre, same points and estimated normals; cspm (shepard, adaptive) "
                f"x{t / out['e2e_cspm shepard h=adaptive']:.2f} faster, default cspm x{t / out['e2e_cspm numerical']:.2f}"
                if order == 2 else f"pycompadre; msph4 x{t / out['e2e_msph4 shepard h=adaptive']:.2f} faster")
            out[f"gmls_p{order}"] = t
    return rows, out


# ----------------------------------------------------------------------------- report
def targets(results):
    lines, out = [], {}

    def check(name, value, ok, text):
        out[name] = {"value": value, "met": bool(ok)}
        lines.append(f"  [{'met' if ok else 'NOT met'}] {name}: {text}")

    for n, r in results.items():
        if n == "scan":
            continue
        p = r.get("peers", {})
        if "gmls_p2" in p:
            ratio = p["gmls_p2"]["time_s"] / r["e2e_cspm"]
            check(f"N={n} cspm build >= 3x faster than GMLS p2", ratio, ratio >= 3,
                  f"x{ratio:.2f} (ours {r['e2e_cspm']:.3f} s, err {r['e2e_cspm_err']:.2e}; "
                  f"GMLS {p['gmls_p2']['time_s']:.3f} s, err {p['gmls_p2']['lap_l2']:.2e})")
            ratio = p["gmls_p2"]["time_s"] / r["e2e_cspm_shepard"]
            check(f"N={n} cspm build, area='shepard', >= 3x faster than GMLS p2", ratio, ratio >= 3,
                  f"x{ratio:.2f} (ours {r['e2e_cspm_shepard']:.3f} s, err {r['e2e_cspm_shepard_err']:.2e})")
        if "gmls_p4" in p:
            ratio = p["gmls_p4"]["time_s"] / r["e2e_msph4"]
            smaller = r["e2e_msph4_err"] < p["gmls_p4"]["lap_l2"]
            check(f"N={n} msph4 >= 5x faster than GMLS p4, smaller error", ratio, ratio >= 5 and smaller,
                  f"x{ratio:.2f} (ours {r['e2e_msph4']:.3f} s, err {r['e2e_msph4_err']:.2e}; GMLS {p['gmls_p4']['time_s']:.3f} s, "
                  f"err {p['gmls_p4']['lap_l2']:.2e}; error smaller: {smaller})")
        ratio = r["e2e_cspm"] / r["bare_radius"]
        check(f"N={n} end-to-end cspm <= 2.5x bare radius query", ratio, ratio <= 2.5,
              f"x{ratio:.2f} ({r['e2e_cspm']:.3f} s vs {r['bare_radius']:.3f} s)")
        ratio = r["e2e_cspm_shepard"] / r["bare_radius"]
        check(f"N={n} end-to-end cspm, area='shepard', <= 2.5x bare radius query", ratio, ratio <= 2.5,
              f"x{ratio:.2f} ({r['e2e_cspm_shepard']:.3f} s vs {r['bare_radius']:.3f} s)")
        ratio = r["matvec"] / r["stream"]
        check(f"N={n} matvec <= 2x streaming the bytes", ratio, ratio <= 2,
              f"x{ratio:.2f} (s.laplacian(f) {r['matvec'] * 1e3:.2f} ms vs {r['stream'] * 1e3:.2f} ms; scipy's one-thread L @ f "
              f"{r['matvec_scipy'] * 1e3:.2f} ms, x{r['matvec_scipy'] / r['stream']:.2f})")
        if n >= 1_000_000:
            check(f"N={n} end-to-end cspm <= 6 s", r["e2e_cspm"], r["e2e_cspm"] <= 6, f"{r['e2e_cspm']:.2f} s")
            pk = r["peak_e2e_mb"]
            if pk is not None:
                check(f"N={n} peak memory <= 2.5 GB", pk, pk <= 2560, f"{pk:.0f} MB traced (tracemalloc)")
    ns = sorted(k for k in results if k != "scan")
    if len(ns) >= 2:
        slope = float(np.polyfit(np.log(ns), np.log([results[n]["e2e_cspm"] for n in ns]), 1)[0])
        check(f"scaling exponent (end-to-end cspm, N={ns[0]}..{ns[-1]}) <= 1.1", slope, slope <= 1.1 and ns[-1] >= 1_000_000,
              f"{slope:.3f}" + ("" if ns[-1] >= 1_000_000 else " (the target is over 1e4..1e6; not measured to 1e6)"))
        for key in ("bare_radius", "matvec"):
            sl = float(np.polyfit(np.log(ns), np.log([results[n][key] for n in ns]), 1)[0])
            lines.append(f"  (for reference: {key} exponent {sl:.3f})")
            out[f"exponent_{key}"] = sl
    return lines, out


def warm_up():
    """Build every timed scheme once on a small cloud: numba's kernels are compiled (first run on
    a machine) or loaded from its cache here, not inside a timed step (the grid neighbour search's
    kernels with the first cloud, of its minimum size)."""
    quiet(lambda: Surface(shapes.sphere(GRID_MIN_POINTS)))()
    cloud = shapes.sphere(2000)
    for name in SCHEMES:
        quiet(lambda name=name: Surface(cloud, scheme=name))()
    quiet(lambda: heat(Surface(cloud), cloud.points[:, 2], dt=0.01, steps=1, method="implicit", solver="iterative"))()


RATIO_MODES = ("query", "default", "shepard")


def ratio_child(n: int, mode: str, repeat: int, sampling: str = "fibonacci") -> dict:
    """One measurement in a fresh process (so ``ru_maxrss`` is this step's peak): the bare KD-tree
    query of the issue (``cKDTree(p).query(p, k=40, distance_upper_bound=3 h, workers=-1)``, h the
    default build's), or ``Surface(p, n)`` with defaults, or with ``area="shepard"``."""
    from scipy.spatial import cKDTree

    from manifold_sph.neighbors import smoothing_length_for_count

    c = shapes.sphere(n) if sampling == "fibonacci" else shapes.sphere(n, sampling="random", seed=0)
    p, nn = c.points.copy(), c.normals.copy()
    del c
    warm = shapes.sphere(GRID_MIN_POINTS)  # numba's cache loaded, the grid search's kernels too
    quiet(lambda: Surface(warm))()
    h = float(smoothing_length_for_count(p, 27))  # msph's default count
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    times, cpus = [], []
    for _ in range(repeat):
        gc.collect()
        t0, c0 = time.perf_counter(), time.process_time()
        if mode == "query":
            cKDTree(p).query(p, k=40, distance_upper_bound=3 * h, workers=-1)
        elif mode == "default":
            quiet(lambda: Surface(p, nn))()
        else:
            quiet(lambda: Surface(p, nn, area="shepard"))()
        times.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return {"n": n, "mode": mode, "sampling": sampling, "seconds": float(np.median(times)),
            "cpu_seconds": float(np.median(cpus)), "rss_before_mb": rss0, "rss_peak_mb": rss1}


def ratio_table(sizes, repeat: int, sampling: str = "fibonacci") -> list[dict]:
    """Issue 22's table: default and Shepard builds as ratios of the bare KD-tree query, each in a fresh
    process with its peak resident memory, and the fitted scaling exponent of the default build."""
    import subprocess

    print(f"cores {os.cpu_count()}, load average at start {' '.join(f'{x:.2f}' for x in os.getloadavg())}; "
          f"{sampling} points on the unit sphere, exact normals; median of {repeat} runs, each row in a fresh process")
    print(f"{'N':>9} {'query s':>8} {'default s':>10} {'ratio':>6} {'shepard s':>10} {'ratio':>6} "
          f"{'peak RSS MB':>12} {'RSS before':>11} {'build MB per 1M':>16}   CPU s: query default shepard (ratios)")
    rows = []
    for n in sizes:
        r = {}
        for mode in RATIO_MODES:
            out = subprocess.run([sys.executable, __file__, "--ratio-child", f"{n},{mode},{repeat},{sampling}"], check=True,
                                 capture_output=True, text=True).stdout
            r[mode] = json.loads(out.strip().splitlines()[-1])
        q, d, sh = (r[m]["seconds"] for m in RATIO_MODES)
        peak, before = r["default"]["rss_peak_mb"], r["default"]["rss_before_mb"]
        qc, dc, sc = (r[m].get("cpu_seconds", float("nan")) for m in RATIO_MODES)
        print(f"{n:>9d} {q:>8.3f} {d:>10.3f} {d / q:>6.2f} {sh:>10.3f} {sh / q:>6.2f} {peak:>12.0f} {before:>11.0f} "
              f"{(peak - before) / n * 1e6:>16.0f}   {qc:.3f} {dc:.3f} ({dc / qc:.2f}) {sc:.3f} ({sc / qc:.2f})", flush=True)
        rows.append({"n": n, "query_s": q, "default_s": d, "shepard_s": sh, "default_ratio": d / q, "shepard_ratio": sh / q,
                     "query_cpu_s": qc, "default_cpu_s": dc, "shepard_cpu_s": sc,
                     "rss_peak_mb": peak, "rss_before_mb": before})
    if len(rows) >= 2:
        x = np.log([r["n"] for r in rows])
        for key in ("default_s", "query_s"):
            slope = np.polyfit(x, np.log([r[key] for r in rows]), 1)[0]
            print(f"scaling exponent of {key[:-2]} time, N = {rows[0]['n']} .. {rows[-1]['n']}: {slope:.3f}")
    print("targets (issue 22): default <= 2.0x and shepard <= 1.5x the query; build <= 1000 MB per 1M points; "
          f"exponent <= 1.05. Load average at end {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return rows


#: The build's stages as ``(label, module, function)``: each is timed (wall and process CPU) where the
#: pipeline calls it. Indented labels are parts of the one above.
STAGES = (
    ("KD-tree build", "surface", "build_tree"),
    ("h (smoothing length)", "operators", "smoothing_length_for_count"),
    ("neighbours", "surface", "find_neighbors"),
    ("  grid search", "neighbors", "_grid_search"),
    ("frames", "surface", "tangent_frames"),
    ("area elements", "operators", "area_elements"),
    ("  kernel matrix", "area", "kernel_matrix"),
    ("  near-duplicate pairs", "area", "near_duplicate_pairs"),
    ("  solve", "area", "_solve_partition_of_unity"),
    ("assembly (weights)", "operators", "assemble"),
)


def stage_table(sizes, repeat: int, sampling: str = "fibonacci") -> list[dict]:
    """Per-stage seconds of ``Surface(p, n)`` (default and ``area="shepard"``) as fractions of the bare
    KD-tree query of :func:`ratio_child`, wall and process CPU time (all threads), median of ``repeat``
    runs, in this process after a warm-up. CPU time is the steadier figure on a shared machine."""
    import functools
    import importlib

    from manifold_sph.neighbors import smoothing_length_for_count

    wall, cpu = {}, {}
    originals = []
    for label, mod_name, fn_name in STAGES:
        mod = importlib.import_module(f"manifold_sph.{mod_name}")
        fn = getattr(mod, fn_name, None)
        if fn is None:  # a stage this version of the package does not have
            continue
        originals.append((mod, fn_name, fn))

        @functools.wraps(fn)
        def timed_stage(*a, _fn=fn, _label=label, **k):
            t0, c0 = time.perf_counter(), time.process_time()
            try:
                return _fn(*a, **k)
            finally:
                wall[_label] = wall.get(_label, 0.0) + time.perf_counter() - t0
                cpu[_label] = cpu.get(_label, 0.0) + time.process_time() - c0

        setattr(mod, fn_name, timed_stage)
    rows = []
    try:
        quiet(lambda: Surface(shapes.sphere(GRID_MIN_POINTS)))()  # numba's cache loaded, the grid search's kernels too
        print(f"cores {os.cpu_count()}, load average at start {' '.join(f'{x:.2f}' for x in os.getloadavg())}; {sampling} "
              f"points, exact normals; median of {repeat} runs; each stage as a fraction of the bare query (wall | CPU)")
        for n in sizes:
            c = shapes.sphere(n) if sampling == "fibonacci" else shapes.sphere(n, sampling="random", seed=0)
            p, nn = c.points.copy(), c.normals.copy()
            del c
            h = float(smoothing_length_for_count(p, 27))
            for mode in ("default", "shepard"):
                runs = []
                for _ in range(repeat):
                    gc.collect()
                    t0, c0 = time.perf_counter(), time.process_time()
                    cKDTree(p).query(p, k=40, distance_upper_bound=3 * h, workers=-1)
                    q = (time.perf_counter() - t0, time.process_time() - c0)
                    gc.collect()
                    wall.clear()
                    cpu.clear()
                    t0, c0 = time.perf_counter(), time.process_time()
                    quiet(lambda: Surface(p, nn) if mode == "default" else Surface(p, nn, area="shepard"))()
                    b = (time.perf_counter() - t0, time.process_time() - c0)
                    runs.append((q, b, dict(wall), dict(cpu)))
                med = lambda f: float(np.median([f(r) for r in runs]))  # noqa: E731
                qw, qc = med(lambda r: r[0][0]), med(lambda r: r[0][1])
                bw, bc = med(lambda r: r[1][0]), med(lambda r: r[1][1])
                print(f"\nN = {n}, {mode}: query {qw:.3f} s (CPU {qc:.3f} s), build {bw:.3f} s (CPU {bc:.3f} s): "
                      f"ratio {med(lambda r: r[1][0] / r[0][0]):.2f} wall, {med(lambda r: r[1][1] / r[0][1]):.2f} CPU")
                row = {"n": n, "mode": mode, "sampling": sampling, "query_s": qw, "query_cpu_s": qc, "build_s": bw,
                       "build_cpu_s": bc, "stages": {}}
                for label, _, _ in STAGES:
                    if not any(label in r[2] for r in runs):
                        continue
                    sw = med(lambda r: r[2].get(label, 0.0) / r[0][0])
                    sc = med(lambda r: r[3].get(label, 0.0) / r[0][1])
                    print(f"  {label:<26} {sw:>6.2f} | {sc:>5.2f}")
                    row["stages"][label.strip()] = {"wall_q": sw, "cpu_q": sc}
                rest_w = med(lambda r: (r[1][0] - sum(v for k, v in r[2].items() if not k.startswith(" "))) / r[0][0])
                rest_c = med(lambda r: (r[1][1] - sum(v for k, v in r[3].items() if not k.startswith(" "))) / r[0][1])
                print(f"  {'rest (checks, set-up)':<26} {rest_w:>6.2f} | {rest_c:>5.2f}")
                rows.append(row)
    finally:
        for mod, fn_name, fn in originals:
            setattr(mod, fn_name, fn)
    return rows


def main(argv=None):
    if argv is None and len(sys.argv) == 3 and sys.argv[1] == "--ratio-child":
        n, mode, repeat, sampling = sys.argv[2].split(",")
        print(json.dumps(ratio_child(int(n), mode, int(repeat), sampling)))
        return
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="10000,100000", help="comma-separated cloud sizes (default 10000,100000)")
    ap.add_argument("--repeat", type=int, default=3, help="runs per timing; the median is reported")
    ap.add_argument("--json", help="write all rows and the target checks to this file")
    ap.add_argument("--peers", action="store_true", help="robust-laplacian and pycompadre GMLS p2 / p4 on the same points")
    ap.add_argument("--peers-max", type=int, default=200_000, help="run the peers only up to this N (default 200000)")
    ap.add_argument("--no-mem", action="store_true", help="skip the tracemalloc runs")
    ap.add_argument("--scan", default=str(DEFAULT_SCAN),
                    help="a scan to time as users would (read, estimate normals, build); 'none' skips it "
                         "(default: the Igea scan of ../shared, skipped when absent)")
    ap.add_argument("--ratios", action="store_true",
                    help="only issue 22's table: builds as ratios of the bare KD-tree query, peak RSS per million "
                         "points, scaling exponent (each row in a fresh process)")
    ap.add_argument("--sampling", choices=("fibonacci", "random"), default="fibonacci",
                    help="--ratios and --stages on Fibonacci (near-uniform) or uniformly random sphere points")
    ap.add_argument("--stages", action="store_true",
                    help="per-stage seconds of the default and Shepard builds as fractions of the bare KD-tree query "
                         "(wall and CPU), in this process")
    args = ap.parse_args(argv)
    sizes = [int(float(x)) for x in args.sizes.split(",") if x]
    if args.stages:
        rows = stage_table(sizes, args.repeat, args.sampling)
        if args.json:
            with open(args.json, "w") as fh:
                json.dump(rows, fh, indent=1)
        return
    if args.ratios:
        rows = ratio_table(sizes, args.repeat, args.sampling)
        if args.json:
            with open(args.json, "w") as fh:
                json.dump(rows, fh, indent=1)
        return
    meta = {
        "cores": os.cpu_count(), "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS", "unset"),
        "OMP_WAIT_POLICY": os.environ.get("OMP_WAIT_POLICY"),
        "loadavg_start": os.getloadavg(), "numpy": np.__version__, "python": sys.version.split()[0],
        "repeat": args.repeat, "memory": "tracemalloc peak above the pre-step level (numpy traced; C++ not)",
    }
    print(f"cores {meta['cores']}, OMP_NUM_THREADS={meta['OMP_NUM_THREADS']}, load average at start "
          f"{' '.join(f'{x:.2f}' for x in meta['loadavg_start'])} (other jobs may share the machine)")
    print(f"unit sphere, Fibonacci points, exact normals, f = cos(xz - sin y), kernel {KERNEL}; "
          f"median of {args.repeat} runs; peak MB = tracemalloc\n")
    pc = kp = None
    if args.peers:
        try:
            import pycompadre as pc
        except ImportError as exc:  # pragma: no cover - environment
            print(f"pycompadre not installed ({exc}); GMLS rows skipped")
        else:
            kp = pc.KokkosParser(sys.argv[:1])
    t0 = time.perf_counter()
    warm_up()
    print(f"compiled kernels loaded (or compiled) in {time.perf_counter() - t0:.1f} s")
    print(f"{'N':>8} {'step':<31} {'median s':>9} {'peak MB':>8} {'lap L2':>10}  note")
    all_rows, results = [], {}
    for n in sizes:
        t0 = time.perf_counter()
        rows, res = bench_size(n, args.repeat, not args.no_mem, args.peers_max if args.peers else 0, pc)
        all_rows += rows
        results[n] = res
        print(f"{'':>8} (N = {n}: {time.perf_counter() - t0:.0f} s of benchmarking)\n", flush=True)
    if args.scan.lower() != "none":
        if os.path.exists(args.scan):
            t0 = time.perf_counter()
            rows, results["scan"] = bench_scan(args.scan, args.repeat, pc if args.peers else None)
            all_rows += rows
            print(f"{'':>8} (scan: {time.perf_counter() - t0:.0f} s of benchmarking)\n", flush=True)
        else:
            print(f"scan {args.scan} not found: skipped\n")
    meta["loadavg_end"] = os.getloadavg()
    meta["maxrss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    lines, checks = targets(results)
    print("targets (issue 8):")
    print("\n".join(lines))
    print(f"\nload average at end {' '.join(f'{x:.2f}' for x in meta['loadavg_end'])}; process maxrss {meta['maxrss_mb']:.0f} MB")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"meta": meta, "rows": all_rows, "results": {str(k): v for k, v in results.items()}, "targets": checks},
                      fh, indent=1, default=float)
        print(f"wrote {args.json}")
    del kp


if __name__ == "__main__":
    main()
