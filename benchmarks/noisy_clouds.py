"""Does ``Surface(points)`` build on noisy, non-uniform and outlier-laden bare clouds?

Prints one row per cloud: how it was made, its size, whether the default build
(``scheme="msph"``) and ``scheme="standard"`` succeeded, and what the build repaired or
reported (normals flipped to agree with their neighbours, normals replaced by their
neighbours', particles whose support was widened, strays among them, particles left unfiltered).

Clouds:

- the unit sphere (``--n`` Fibonacci points) with Gaussian noise of 0.25, 0.5, 0.75 and 1
  spacings (``spacing = sqrt(4 pi / n)``), ``--seeds`` seeds each;
- every model of ``../shared/data/models`` (missing: skipped): its vertices as bare
  points, and a non-uniform resampling of its triangles (``--model-n`` area-uniform points
  thinned to a density ratio 4 along the longest axis) with noise of 0.5 and 1 local
  spacings and 3 strays far away (10 and 1e4 bounding-box diagonals) and 3 near (2-4
  spacings off the surface).

The normals are estimated once per cloud (as ``Surface(points)`` does) and the two schemes
built on them. Run ``python benchmarks/noisy_clouds.py --help`` for the options; the
default run takes a few minutes on two cores.
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

from manifold_sph import Surface
from manifold_sph.reference import shapes
from manifold_sph.reference.sampling import sample_triangles
from manifold_sph.scans.io import read_mesh

MODELS = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "models"


def _normals(points: np.ndarray) -> np.ndarray:
    from manifold_sph.normals import estimate_normals

    return estimate_normals(points, degree=2)


def _build(points, normals, scheme):
    """``(status, repairs)`` of one build: "ok" or the error's first words."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            s = Surface(points, normals, scheme=scheme)
        except Exception as exc:  # noqa: BLE001 - the table reports every failure
            return f"ERROR {type(exc).__name__}: {str(exc)[:70]}", ""
    parts = []
    for name in ("flipped", "repaired", "widened", "strays", "unfiltered"):
        idx = getattr(s, name, None)
        if idx is not None and len(idx):
            parts.append(f"{name} {len(idx)}")
    return "ok", ", ".join(parts)


def _sphere_clouds(n, seeds, noises):
    base = shapes.sphere(n).points
    spacing = np.sqrt(4 * np.pi / n)
    for noise in noises:
        for seed in range(seeds):
            rng = np.random.default_rng(seed)
            yield f"sphere noise {noise:g} seed {seed}", base + rng.normal(scale=noise * spacing, size=base.shape)


def _model_clouds(model_n, seed):
    for path in sorted(MODELS.glob("*.obj")):
        V, F = read_mesh(path)
        V = np.unique(V, axis=0) if path.stem == "teapot" else V
        if len(np.unique(V, axis=0)) < len(V):
            V = np.unique(V, axis=0)
        yield f"{path.stem} vertices", V
        V, F = read_mesh(path)
        rng = np.random.default_rng(seed)
        p, _ = sample_triangles(V, F, 2 * model_n, seed=seed)
        lo, hi = p.min(axis=0), p.max(axis=0)
        axis = int(np.argmax(hi - lo))
        s = (p[:, axis] - lo[axis]) / max(hi[axis] - lo[axis], 1e-300)  # 0..1 along the longest axis
        keep = rng.random(p.shape[0]) < 0.25 + 0.75 * s  # density ratio 4 end to end
        p = p[keep][:model_n]
        diag = float(np.linalg.norm(hi - lo))
        area = float(np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1).sum() / 2)
        spacing = np.sqrt(area / p.shape[0]) / np.sqrt(0.25 + 0.75 * s[keep][:model_n])[:, None]
        centre = 0.5 * (lo + hi)
        for noise in (0.5, 1.0):
            q = p + rng.normal(size=p.shape) * noise * spacing
            d = rng.normal(size=(3, 3))
            d /= np.linalg.norm(d, axis=1)[:, None]
            far = centre + np.array([10.0, 1e4, 10.0])[:, None] * diag * d
            near = q[rng.integers(0, q.shape[0], 3)] + (2 + 2 * rng.random((3, 1))) * spacing.mean() * d
            yield f"{path.stem} resampled noise {noise:g} + 6 strays", np.vstack([q, far, near])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=20000, help="points on the noisy spheres")
    ap.add_argument("--seeds", type=int, default=6, help="seeds per noise level of the spheres")
    ap.add_argument("--model-n", type=int, default=8000, help="points of each model's resampling")
    ap.add_argument("--only", choices=("sphere", "models"), default=None)
    args = ap.parse_args()
    clouds = []
    if args.only in (None, "sphere"):
        clouds += list(_sphere_clouds(args.n, args.seeds, (0.25, 0.5, 0.75, 1.0)))
    if args.only in (None, "models"):
        clouds += list(_model_clouds(args.model_n, seed=0))
    print(f"{'cloud':44s} {'N':>6s}  {'msph':8s} {'standard':8s} {'s':>5s}  repairs (msph)")
    failures = 0
    for name, pts in clouds:
        t = time.perf_counter()
        nrm = _normals(pts)
        a, rep = _build(pts, nrm, "msph")
        b, _ = _build(pts, nrm, "standard")
        failures += (a != "ok") + (b != "ok")
        print(f"{name:44s} {len(pts):6d}  {a[:8]:8s} {b[:8]:8s} {time.perf_counter() - t:5.1f}  {rep}")
        for msg in {a, b} - {"ok"}:
            print(f"    {msg}")
    print(f"{len(clouds)} clouds, {2 * len(clouds)} builds, {failures} failed")


if __name__ == "__main__":
    main()
