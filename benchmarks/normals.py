"""Normals from bare points: manifold_sph against Open3D and CGAL, in one run.

Every cloud is estimated by the three libraries with their usual settings:

- **ours**: ``manifold_sph.estimate_normals(points)`` (the defaults: ``k="auto"``, outward);
- **Open3D**: ``estimate_normals(KDTreeSearchParamKNN(30))`` then
  ``orient_normals_consistent_tangent_plane(15)`` (a minimum spanning tree);
- **CGAL** (the ``cgal`` package of the ``bench`` extra): ``jet_estimate_normals(k=18)`` then
  ``mst_orient_normals(k=18)``.

The peers orient consistently but do not choose outward; their signs are taken as they come
(what a user gets). Columns per library: right signs (normal within 90 degrees of the
reference, %), unoriented angle RMSE (degrees), PGP10 (share within 10 degrees, %), seconds of
estimation and orientation (reading and conversions excluded).

The clouds:

- **published**: the PCPNet-style clouds with reference normals of the ``data/`` folder of
  github.com/galmetzer/dipole-normal-prop (MIT; fandisk, hand, ok, vase; see data/README.md).
  Give their folder with ``--data DIR`` or ``MANIFOLD_SPH_NORMALS_DATA``; skipped when absent.
  Each also with Gaussian noise of 0.12 % and 0.6 % of its bounding-box diagonal, and resampled
  non-uniformly: ``gradient`` (kept with probability falling linearly from 1 to 0.1 along the
  longest axis) and ``stripes`` (every other band of 1/8 of the longest axis kept at 1/3); seed 0;
- **models**: the vertices of the test meshes (``MANIFOLD_SPH_DATA``, default ``../shared/data``
  beside the repository), against the area-weighted vertex normals of their faces;
- **parts**: synthetic multi-part models of 24 closed parts that touch, cross and nest (a
  character: body, head, eyes and teeth through the head, limbs through the body, buttons and a
  hat touching, organs nested inside; and a scene of random primitives), sampled area-uniformly
  (seeds 0 and 1), against each part's own outward normals (a part inside another is a part of
  its own);
- **time**: the 100,000-point clouds of the same folder (boxunion, flower, galera; no reference
  normals): seconds only.

Run: ``python benchmarks/normals.py`` (all; about half an hour on 2 busy cores), or a subset:
``--only published,models,parts,time``; ``--peers none`` skips Open3D and CGAL.
The older studies of the clean path (limit surfaces, orders, thin synthetic clouds) are in
``benchmarks/normals_studies.py``.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
from normals_studies import MODELS, SCANS, mesh_reference

from manifold_sph.normals import estimate_normals
from manifold_sph.reference.sampling import sample_triangles

__all__ = ["MODELS", "SCANS", "mesh_reference", "published_clouds", "multi_part", "metrics"]

PUBLISHED = ("fandisk", "hand", "ok", "vase")
LARGE = ("boxunion", "flower", "galera")
NOISE = (0.0012, 0.006)


# ----------------------------------------------------------------------------- peers
def ours(P):
    t = time.perf_counter()
    n = estimate_normals(P)
    return n, time.perf_counter() - t


def open3d_normals(P, k=30, k_orient=15):
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(P))
    t = time.perf_counter()
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(k))
    pcd.orient_normals_consistent_tangent_plane(k_orient)
    return np.asarray(pcd.normals).copy(), time.perf_counter() - t


def cgal_normals(P, k=18):
    from CGAL import CGAL_Point_set_processing_3 as psp
    from CGAL.CGAL_Kernel import Point_3
    from CGAL.CGAL_Point_set_3 import Point_set_3

    ps = Point_set_3()
    for p in P:
        ps.insert(Point_3(float(p[0]), float(p[1]), float(p[2])))
    ps.add_normal_map()
    index = ps.add_int_map("index")
    for i in range(len(P)):
        index.set(i, i)
    t = time.perf_counter()
    psp.jet_estimate_normals(ps, k)
    psp.mst_orient_normals(ps, k)  # unoriented points are removed: they keep a zero normal here
    el = time.perf_counter() - t
    n = np.zeros_like(P)
    for j in ps.indices():
        v = ps.normal(j)
        n[index.get(j)] = (v.x(), v.y(), v.z())
    return n, el


METHODS = {"ours": ours, "Open3D": open3d_normals, "CGAL": cgal_normals}


def metrics(n, ref):
    """Right signs (%), unoriented angle RMSE (degrees), PGP10 (%)."""
    length = np.linalg.norm(n, axis=1) * np.linalg.norm(ref, axis=1)
    d = np.einsum("ij,ij->i", n, ref) / np.where(length > 0, length, 1.0)
    ang = np.degrees(np.arccos(np.clip(np.abs(d), 0.0, 1.0)))
    ang[length == 0] = 90.0
    return 100.0 * np.mean(d > 0), float(np.sqrt(np.mean(ang**2))), 100.0 * np.mean(ang < 10.0)


# ----------------------------------------------------------------------------- clouds
def data_dir(arg=None):
    d = arg or os.environ.get("MANIFOLD_SPH_NORMALS_DATA")
    return Path(d) if d else None


def _read_xyz(path):
    X = np.loadtxt(path)
    return X[:, :3], (X[:, 3:6] if X.shape[1] >= 6 else None)


def resample(P, ref, kind, seed=0):
    """Non-uniform resampling: ``gradient`` (kept with probability 1 -> 0.1 along the longest axis)
    or ``stripes`` (bands of 1/8 of the longest axis, every other one kept at 1/3)."""
    rng = np.random.default_rng(seed)
    ax = int(np.argmax(np.ptp(P, axis=0)))
    t = (P[:, ax] - P[:, ax].min()) / max(np.ptp(P[:, ax]), 1e-300)
    keep = 1.0 - 0.9 * t if kind == "gradient" else np.where(np.floor(8 * t) % 2 == 0, 1.0, 1.0 / 3.0)
    sel = rng.random(len(P)) < keep
    return P[sel], ref[sel]


def published_clouds(folder, names=PUBLISHED, seed=0):
    """(name, points, reference normals) of the published clouds, their noisy and resampled variants."""
    for name in names:
        path = folder / f"{name}.xyz"
        if not path.exists():
            print(f"{name}: {path} not found, skipped")
            continue
        P, ref = _read_xyz(path)
        yield name, P, ref
        diag = float(np.linalg.norm(np.ptp(P, axis=0)))
        for z in NOISE:
            yield f"{name} {100 * z:.2f} %", P + z * diag * np.random.default_rng(seed).normal(size=P.shape), ref
        for kind in ("gradient", "stripes"):
            yield (f"{name} {kind}", *resample(P, ref, kind, seed))


def _rotation(rng):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    a, b, c, d = q
    return np.array([[a * a + b * b - c * c - d * d, 2 * (b * c - a * d), 2 * (b * d + a * c)],
                     [2 * (b * c + a * d), a * a - b * b + c * c - d * d, 2 * (c * d - a * b)],
                     [2 * (b * d - a * c), 2 * (c * d + a * b), a * a - b * b - c * c + d * d]])


def _primitive(kind, size, rng):
    """A closed trimesh primitive of about ``size`` (vertices, faces), randomly rotated."""
    import trimesh

    if kind == "sphere":
        m = trimesh.creation.icosphere(subdivisions=4, radius=size)
    elif kind == "ellipsoid":
        m = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
        m.vertices *= size * np.array([1.0, rng.uniform(0.5, 0.9), rng.uniform(0.3, 0.7)])
    elif kind == "torus":
        m = trimesh.creation.torus(major_radius=size, minor_radius=size * rng.uniform(0.25, 0.4), major_sections=64, minor_sections=24)
    elif kind == "capsule":
        m = trimesh.creation.capsule(height=2.0 * size, radius=size * rng.uniform(0.25, 0.45), count=[32, 32])
    else:
        m = trimesh.creation.box(extents=size * rng.uniform(0.8, 1.6, 3))
    if m.volume < 0:  # faces wound outward: the cross products of their edges point out
        m.invert()
    return np.asarray(m.vertices) @ _rotation(rng).T, np.asarray(m.faces)


def _character(rng):
    """Parts (kind, size, centre) of a character: 24 closed parts that cross, touch and nest."""
    parts = [("ellipsoid", 1.0, (0.0, 0.0, 0.0)), ("sphere", 0.55, (0.0, 0.0, 1.15))]  # body, head (crossing)
    parts += [("sphere", 0.12, (x, -0.45, 1.3)) for x in (-0.2, 0.2)]  # eyes through the head
    parts += [("box", 0.06, (x, -0.5, 0.95)) for x in np.linspace(-0.15, 0.15, 4)]  # teeth through the head
    parts += [("capsule", 0.45, (s * 0.95, 0.0, 0.2)) for s in (-1, 1)]  # arms through the body
    parts += [("capsule", 0.45, (s * 0.4, 0.0, -1.05)) for s in (-1, 1)]  # legs through the body
    parts += [("sphere", 0.08, (0.0, -0.45 - 0.08 * 0.9, z)) for z in (0.25, 0.0, -0.25)]  # buttons touching
    parts += [("torus", 0.35, (0.0, 0.0, 1.72))]  # a hat ring resting on the head
    parts += [("sphere", 0.2, (0.3, 0.1, -0.1)), ("sphere", 0.15, (-0.3, 0.15, 0.1)), ("box", 0.2, (0.0, 0.2, -0.45))]  # nested
    parts += [("sphere", 0.25, (1.7, 0.0, -1.2)), ("box", 0.5, (-1.8, 0.3, -1.2)), ("torus", 0.3, (1.6, 0.8, 0.6)),
              ("sphere", 0.1, (1.6, 0.8, 0.6)), ("ellipsoid", 0.4, (-1.6, -0.9, 0.8))]  # props, one nested in a ring
    return [(k, s * rng.uniform(0.9, 1.1), np.asarray(c) + rng.normal(scale=0.02, size=3)) for k, s, c in parts]


def _scene(rng, n_parts=24):
    """Random primitives in a box; about a third placed to cross, touch or sit inside an earlier one."""
    parts = []
    for i in range(n_parts):
        kind = rng.choice(["sphere", "ellipsoid", "torus", "capsule", "box"])
        size = rng.uniform(0.2, 0.6)
        c = rng.uniform(-2.0, 2.0, 3)
        if i and rng.random() < 0.6:
            pk, ps, pc = parts[rng.integers(len(parts))]
            u = rng.normal(size=3)
            u /= np.linalg.norm(u)
            how = rng.choice(["cross", "touch", "inside"])
            if how == "inside" and pk in ("sphere", "ellipsoid", "box"):
                size = 0.25 * ps
                c = pc + 0.1 * ps * u
            else:
                c = pc + u * (ps + (0.5 if how == "cross" else 1.0) * size)
        parts.append((kind, size, c))
    return parts


def multi_part(kind="character", seed=0, density=1200.0, noise=0.0):
    """Points, each part's outward normals, the part of every point and the parts' kinds (area-uniform samples)."""
    rng = np.random.default_rng(seed)
    pts, nrm, names = [], [], []
    for i, (k, size, c) in enumerate(_character(rng) if kind == "character" else _scene(rng)):
        V, F = _primitive(k, size, rng)
        tri = V[F]
        area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum()
        p, f = sample_triangles(V, F, max(int(density * area), 60), seed=seed * 100 + i)
        fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        pts.append(p + c)
        names.append(k)
        nrm.append(fn[f] / np.linalg.norm(fn[f], axis=1)[:, None])
    P = np.vstack(pts)
    if noise:
        P = P + noise * np.linalg.norm(np.ptp(P, axis=0)) * rng.normal(size=P.shape)
    part = np.repeat(np.arange(len(pts)), [len(p) for p in pts])
    return P, np.vstack(nrm), part, names


# ----------------------------------------------------------------------------- table
def _row(name, P, ref, methods):
    cells = []
    for label in methods:
        try:
            n, el = METHODS[label](P)
        except RuntimeError as exc:  # a peer that refuses the cloud (Open3D's qhull on a planar one)
            cells.append(f"{'failed: ' + str(exc).split(':')[0]:>26s}")
            continue
        if ref is None:
            cells.append(f"{'':>6s} {'':>5s} {'':>4s} {el:6.1f}s")
        else:
            s, r, g = metrics(n, ref)
            cells.append(f"{s:6.2f} {r:5.1f} {g:4.0f} {el:6.1f}s")
    print(f"{name:22s} {len(P):7d} | " + " | ".join(cells), flush=True)


def _header(title, methods):
    print(f"\n{title:22s} {'points':>7s} | " + " | ".join(f"{m + ': signs RMSE PGP10 time':>26s}" for m in methods))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", help="folder of the published clouds (default: $MANIFOLD_SPH_NORMALS_DATA)")
    ap.add_argument("--only", default="published,models,parts,time")
    ap.add_argument("--peers", default="Open3D,CGAL")
    args = ap.parse_args(argv)
    methods = ["ours"] + [m for m in args.peers.split(",") if m in METHODS and m != "ours"]
    only = set(args.only.split(","))
    folder = data_dir(args.data)
    if "published" in only:
        _header("published clouds", methods)
        if folder is None or not folder.exists():
            print("(no data: give --data DIR or MANIFOLD_SPH_NORMALS_DATA; skipped)")
        else:
            for name, P, ref in published_clouds(folder):
                _row(name, P, ref, methods)
    if "models" in only:
        _header("model vertices", methods)
        for path in MODELS + SCANS[:1]:
            if not path.exists():
                print(f"{path.stem}: not found, skipped")
                continue
            P, ref, *_ = mesh_reference(path)
            _row(path.stem, P, ref, methods)
    if "parts" in only:
        _header("multi-part models", methods)
        for kind in ("character", "scene"):
            for seed in (0, 1):
                P, ref, part, _ = multi_part(kind, seed)
                _row(f"{kind} ({part.max() + 1} parts) {seed}", P, ref, methods)
    if "time" in only and folder is not None and folder.exists():
        _header("100,000 points (time)", methods)
        for name in LARGE:
            path = folder / f"{name}.xyz"
            if path.exists():
                _row(name, _read_xyz(path)[0], None, methods)


if __name__ == "__main__":
    main()
