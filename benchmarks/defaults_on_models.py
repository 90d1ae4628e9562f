"""Every model of ../shared/data/models with all defaults: builds for every scheme, finite operators, bounded heat.

For each model (vertices only, duplicates merged, normals estimated) and each scheme,
prints whether ``Surface(V, scheme=...)`` builds, whether its Laplacian and a default
heat run (``laplacian="auto"``, 20 steps) are finite and bounded by the initial range,
how many supports were widened, the stable Laplacian's report and the time.

Usage: ``python benchmarks/defaults_on_models.py``.
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np

from manifold_sph import Surface, pde

MODELS = Path(__file__).resolve().parents[2] / "shared" / "data" / "models"


def main():
    import trimesh

    if not MODELS.is_dir():
        raise SystemExit(f"models folder {MODELS} absent")
    for f in sorted(MODELS.glob("*.obj")):
        if f.stem == "alligator":  # planar: a Domain2D case
            continue
        mesh = trimesh.load(f, process=False, force="mesh")
        V = np.unique(np.asarray(mesh.vertices, dtype=float), axis=0)
        for scheme in ("msph", "cspm", "ncsph", "standard", "msph4"):
            t = time.perf_counter()
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    s = Surface(V, scheme=scheme)
                    z = V[:, 1] - V[:, 1].mean()
                    u = pde.heat(s, z, dt=1e-3 * np.ptp(V) ** 2, steps=20).u
                finite = bool(np.all(np.isfinite(s.laplacian_matrix().data)) and np.all(np.isfinite(u)))
                bounded = bool(np.abs(u).max() <= np.abs(z).max() * (1 + 1e-9))
                print(f"{f.stem:12s} {scheme:9s} finite={finite} bounded={bounded} widened={len(s.widened)} "
                      f"{s.stable_report} {time.perf_counter() - t:.1f}s", flush=True)
            except Exception as e:  # noqa: BLE001 - a failure is the result
                print(f"{f.stem:12s} {scheme:9s} FAILED {type(e).__name__}: {str(e)[:120]}", flush=True)


if __name__ == "__main__":
    main()
