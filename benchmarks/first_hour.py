"""A user's first hour: the six tasks with defaults on every test model and on noisy scans made from them.

For each model of ``../shared/data/models`` (and the scans folder's with ``--scans``) and a noisy,
non-uniform scan sampled from its mesh (density varying tenfold across the model, Gaussian noise
of 0.1 local spacings along the normal, a hole), runs in Python, with every default:

    read -> normals -> Surface -> 20 eigenpairs -> H and K -> geodesic -> heat -> picture

and prints one row per cloud: the seconds of each task, what each returned (zero eigenvalues,
non-finite curvatures, unreached particles, the heat range), the warnings of reading and of the
build, and with ``--spread`` the colour spread of the default picture of H against the best
tuned one (``manifold_sph.viz.style.colour_spread``; the target is >= 0.80). With ``--cli`` the
same tasks run through the command line (``normals``, ``eigs``, ``curvature --out --save``,
``geodesic --source-xyz``, ``heat``), one row of exit codes and note lines per cloud.

A task that raises is reported as ``FAIL`` with the error's first words: a refused file is a
result, not a crash of the benchmark.

Usage::

    python benchmarks/first_hour.py [--models DIR] [--scans] [--only cow,homer] [--no-noisy]
                                    [--spread] [--cli] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

import manifold_sph as ms
from manifold_sph.reference.sampling import sample_triangles
from manifold_sph.scans.io import read_mesh

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"


def noisy_scan(path: Path, seed: int = 0) -> np.ndarray:
    """A noisy, non-uniform scan of the mesh at ``path``: as many points as vertices, area-sampled
    with a density ten times higher at one end than the other, 0.1 local spacings of normal noise,
    and a hole of a tenth of the model's size removed."""
    rng = np.random.default_rng(seed)
    V, F = read_mesh(path)
    n = len(np.unique(V, axis=0))
    pts, _ = sample_triangles(V, F, 4 * n, seed=seed)
    axis = int(np.argmax(np.ptp(pts, axis=0)))
    t = (pts[:, axis] - pts[:, axis].min()) / np.ptp(pts[:, axis])
    pts = pts[rng.random(len(pts)) < 0.1 + 0.9 * t]  # density from 0.1 to 1 along the longest axis
    pts = pts[rng.choice(len(pts), min(n, len(pts)), replace=False)]
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    from scipy.spatial import cKDTree

    tree = cKDTree(pts)
    spacing = tree.query(pts, k=2)[0][:, 1]
    _, nearest_face = cKDTree((V[F].mean(axis=1))).query(pts)
    nrm = fn[nearest_face] / np.maximum(np.linalg.norm(fn[nearest_face], axis=1, keepdims=True), 1e-300)
    pts = pts + (0.1 * spacing * rng.standard_normal(len(pts)))[:, None] * nrm
    centre = pts[rng.integers(len(pts))]
    hole = np.linalg.norm(pts - centre, axis=1) < 0.05 * np.ptp(pts, axis=0).max()
    return pts[~hole]


def clouds(args) -> list[tuple[str, Path, np.ndarray | None]]:
    """(name, mesh file, points or None for the file itself)."""
    files = sorted(Path(args.models).glob("*.obj"))
    if args.scans:
        files += sorted((SHARED / "scans").glob("*.*[!d]"))
    if args.only:
        files = [f for f in files if f.stem in args.only.split(",")]
    out = []
    for f in files:
        out.append((f.stem, f, None))
        if not args.no_noisy:
            out.append((f"{f.stem}~noisy", f, noisy_scan(f)))
    return out


def timed(fn):
    t = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            value, error = fn(), None
        except Exception as exc:  # noqa: BLE001 - a failure is the result
            value, error = None, f"{type(exc).__name__}: {' '.join(str(exc).split())[:90]}"
    said = [w for w in caught if issubclass(w.category, ms.ManifoldSPHWarning)]
    return value, error, time.perf_counter() - t, len(said)


def python_row(name: str, path: Path, pts: np.ndarray | None, spread: bool, tmp: Path) -> dict:
    row = {"cloud": name}
    source = path if pts is None else pts
    cloud, err, sec, said = timed(lambda: ms.as_cloud(source))
    row.update(read=f"{sec:.1f}", n=len(cloud) if cloud else 0, read_warn=said)
    if err:
        row["fail"] = f"read: {err}"
        return row
    _, err, sec, _ = timed(lambda: ms.estimate_normals(cloud.points))
    row["normals"] = "FAIL" if err else f"{sec:.1f}"
    s, err, sec, said = timed(lambda: ms.Surface(cloud))
    row.update(surface=f"{sec:.1f}", build_warn=said)
    if err:
        row["fail"] = f"Surface: {err}"
        return row
    res, err, sec, _ = timed(lambda: s.eigs(20))
    if err:
        row["eigs"] = f"FAIL {err}"
    else:
        lam = res.values
        zero = int((np.abs(lam) <= 1e-8 * np.abs(lam).max()).sum())
        row["eigs"] = f"{sec:.1f}s {zero} zero"
    HK, err, sec, _ = timed(lambda: (s.mean_curvature(), s.gaussian_curvature()))
    row["HK"] = f"FAIL {err}" if err else f"{sec:.1f}s {int((~np.isfinite(HK[0])).sum() + (~np.isfinite(HK[1])).sum())} nonfinite"
    top = int(np.argmax(s.points[:, 1]))
    d, err, sec, _ = timed(lambda: s.geodesic_distance([top]))
    row["geodesic"] = f"FAIL {err}" if err else f"{sec:.1f}s {int((~np.isfinite(np.asarray(d))).sum())} unreached"
    u0 = (s.points[:, 1] > np.percentile(s.points[:, 1], 90)).astype(float)
    sol, err, sec, _ = timed(lambda: ms.pde.heat(s, u0, reach=0.1))  # the README's call: units of the cloud
    row["heat"] = f"FAIL {err}" if err else f"{sec:.1f}s [{float(sol.u.min()):.2g}, {float(sol.u.max()):.2g}]"
    if isinstance(HK, tuple):
        from manifold_sph.viz.render import render_field, rendering_available

        if rendering_available()[0]:
            img, err, sec, _ = timed(lambda: render_field(s, {"H": HK[0]}, title=f"H, {name}",
                                                          filename=tmp / f"{name}_H.png", overwrite=True))
            row["picture"] = f"FAIL {err}" if err else f"{sec:.1f}"
            if spread and not err:
                row["spread_H"] = f"{spread_ratio(s, HK[0]):.2f}"
                row["spread_y"] = f"{spread_ratio(s, s.points[:, 1]):.2f}"
    return row


def spread_ratio(s, values) -> float:
    """Colour spread of the default picture over the best of pictures clipped at 0-30 % (tests/test_render.py)."""
    from manifold_sph.viz.render import render_field
    from manifold_sph.viz.style import color_limits, colour_spread, field_colormap

    kw = dict(window_size=(320, 240), show_scalar_bar=False)
    tuned = max(colour_spread(render_field(s, values, robust=p, **kw), field_colormap(*color_limits(values, robust=p)))
                for p in (False, 2, 5, 10, 20, 30))
    default = colour_spread(render_field(s, values, **kw), field_colormap(*color_limits(values, robust=True)))
    return default / tuned if tuned > 0 else float("nan")  # nan: no picture spreads its colours (a constant field)


def cli_row(name: str, path: Path, pts: np.ndarray | None, tmp: Path) -> dict:
    src = path
    if pts is not None:
        src = tmp / f"{name}.ply"
        ms.write(src, pts, overwrite=True)
    runs = {
        "normals": ["normals", str(src), "--save", str(tmp / f"{name}_n.ply")],
        "eigs": ["eigs", str(src), "--k", "20", "--save", str(tmp / f"{name}_v.npy")],
        "curvature": ["curvature", str(src), "--out", str(tmp / f"{name}_Hc.png"), "--save", str(tmp / f"{name}_H.vtp")],
        "geodesic": ["geodesic", str(src), "--source-xyz", "0,1e9,0", "--save", str(tmp / f"{name}_d.npy")],
        "heat": ["heat", str(src), "--out", str(tmp / f"{name}_u.png")],
    }
    row = {"cloud": name}
    for task, argv in runs.items():
        t = time.perf_counter()
        res = subprocess.run([sys.executable, "-m", "manifold_sph.cli", *argv, "--overwrite"], capture_output=True,
                             text=True, timeout=1800)
        notes = res.stderr.count("manifold-sph: note:")
        row[task] = f"exit {res.returncode} {time.perf_counter() - t:.0f}s {notes} notes"
        if res.returncode:
            row[task] += " " + res.stderr.strip().splitlines()[-1][:80]
    return row


def print_table(rows: list[dict]) -> None:
    keys = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    widths = {k: max(len(k), *(len(str(r.get(k, ""))) for r in rows)) for k in keys}
    print("  ".join(k.ljust(widths[k]) for k in keys))
    for r in rows:
        print("  ".join(str(r.get(k, "")).ljust(widths[k]) for k in keys), flush=True)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--models", default=str(SHARED / "models"))
    p.add_argument("--scans", action="store_true", help="also the bunny and Igea of the scans folder")
    p.add_argument("--only", default=None, help="comma-separated model names")
    p.add_argument("--no-noisy", action="store_true", help="skip the noisy scans made from the models")
    p.add_argument("--spread", action="store_true", help="measure the colour spread of the default pictures")
    p.add_argument("--cli", action="store_true", help="also run the tasks through the command line")
    p.add_argument("--out", default=None, help="folder for the pictures (default: a temporary folder)")
    p.add_argument("--json", action="store_true")
    args = p.parse_args()
    if not Path(args.models).is_dir():
        raise SystemExit(f"models folder {args.models} absent")
    tmp = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="first_hour_"))
    tmp.mkdir(parents=True, exist_ok=True)
    rows, cli_rows = [], []
    for name, path, pts in clouds(args):
        rows.append(python_row(name, path, pts, args.spread, tmp))
        print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
        if args.cli:
            cli_rows.append(cli_row(name, path, pts, tmp))
            print(json.dumps(cli_rows[-1]), file=sys.stderr, flush=True)
    if args.json:
        print(json.dumps({"python": rows, "cli": cli_rows}, indent=2))
        return 0
    print(f"Python, defaults (seconds; warnings of reading and of the build); pictures in {tmp}")
    print_table(rows)
    if cli_rows:
        print("\nCommand line, defaults (exit code, seconds, note lines)")
        print_table(cli_rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
