"""``manifold-sph normals | eigs``: a scan's normals and the spectrum of its stable Laplacian."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from .common import SubParsers, UserError, add_picture_options, positive_int_arg
from .inputs import (
    add_colour_options,
    add_input,
    add_out,
    add_save,
    add_surface_options,
    build_surface,
    check_outputs,
    draw,
    progress,
    read_input,
    save_values,
)

__all__ = ["add_parsers"]


def add_parsers(sub: SubParsers, schemes: list[str]) -> None:
    """Register ``normals`` and ``eigs``."""
    nor = sub.add_parser("normals", help="estimate the outward normals of a point-cloud file")
    add_input(nor, help="point cloud or mesh file (ply, pcd, xyz, csv, pts, obj, npy, npz, las, laz, e57, vtk, vtp)")
    nor.add_argument("--k", type=positive_int_arg, default=None, help="neighbours per fit (default: the jet's own)")
    nor.add_argument("--degree", type=int, default=2, choices=[1, 2, 3, 4], help="jet degree (default 2)")
    add_save(nor, "the cloud with its normals (and the confidence as a field; .npy: the normals)")
    add_out(nor, "a picture of the confidence of each normal")
    add_colour_options(nor)
    nor.add_argument("--json", action="store_true", help="print the summary as JSON")
    add_picture_options(nor)
    nor.set_defaults(func=_cmd_normals)

    eig = sub.add_parser("eigs", help="the lowest eigenpairs of the stable Laplacian of a point-cloud file")
    add_input(eig)
    eig.add_argument("--k", type=positive_int_arg, default=20, help="number of eigenpairs (default 20)")
    add_surface_options(eig, schemes)
    add_save(eig, "the eigenvectors (.npy: an (N, k) array; .ply/.vtp: fields mode_0, mode_1, ...)")
    add_out(eig, "a picture of one eigenvector (--mode)")
    eig.add_argument("--mode", type=int, default=1, help="the eigenvector drawn by --out (0-based, default 1)")
    add_colour_options(eig)
    eig.add_argument("--json", action="store_true", help="print the eigenvalues as JSON")
    add_picture_options(eig)
    eig.set_defaults(func=_cmd_eigs)


def _cmd_normals(args) -> int:
    from ..normals import estimate_normals
    from ..pointcloud import PointCloud

    check_outputs(args)
    t0 = time.perf_counter()
    with progress(args, 3, "normals") as bar:
        cloud, _ = read_input(args, bar)
        bar.step("fits and orientation")
        n, conf = estimate_normals(cloud.points, args.k, degree=args.degree, return_confidence=True)
        bar.update()
        out = PointCloud(cloud.points, n)
        bar.step("output")
        saved = save_values(args, out, {"confidence": conf}) if not (args.save or "").lower().endswith(".npy") else None
        if args.save and args.save.lower().endswith(".npy"):
            saved = save_values(args, out, {"normals": n})
        draw(args, out, conf, title=f"normal confidence, {Path(args.file).name}", name="confidence")
        bar.update()
    summary = {"command": "normals", "file": str(args.file), "n": len(out), "degree": args.degree,
               "low_confidence": int((conf < 0.5).sum()), "seconds": round(time.perf_counter() - t0, 3)}
    if saved:
        summary["save"] = saved
    if args.out:
        summary["out"] = str(args.out)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(f"normals of {args.file} (N = {summary['n']}, jet degree {args.degree}): {summary['low_confidence']} "
              f"with confidence below 0.5 ({summary['seconds']:.2f} s)")
        for f in (saved, args.out):
            if f:
                print(f"wrote {f}")
    return 0


def _cmd_eigs(args) -> int:
    check_outputs(args)
    t0 = time.perf_counter()
    with progress(args, 5, "eigs") as bar:
        cloud, _ = read_input(args, bar)
        if args.k >= len(cloud) - 1:
            raise UserError(f"--k must be below N - 1 = {len(cloud) - 1} for {args.file!r}, got {args.k}")
        if not 0 <= args.mode < args.k:
            raise UserError(f"--mode must be an eigenvector index 0 to {args.k - 1}, got {args.mode}")
        s, estimated = build_surface(args, cloud, bar)
        bar.step("eigenpairs")
        res = s.eigs(args.k)
        lam, vec = res.values, res.vectors
        bar.update()
        bar.step("output")
        saved = save_values(args, s, {"modes" if args.save and args.save.lower().endswith(".npy") else "mode": vec})
        draw(args, s, vec[:, args.mode], title=f"eigenvector {args.mode} (lambda = {lam[args.mode]:.4g}), "
             f"{Path(args.file).name}", name=f"v{args.mode}")
        bar.update()
    zero = int((np.abs(lam) <= 1e-8 * max(float(np.abs(lam).max()), 1e-300)).sum())
    summary = {"command": "eigs", "file": str(args.file), "n": int(s.n_points), "scheme": args.scheme,
               "normals_estimated": estimated, "eigenvalues": [float(v) for v in lam], "zero_eigenvalues": zero,
               "seconds": round(time.perf_counter() - t0, 3)}
    if saved:
        summary["save"] = saved
    if args.out:
        summary["out"] = str(args.out)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(f"{args.k} lowest eigenvalues of the stable Laplacian of {args.file} (N = {summary['n']}, {args.scheme}), "
              f"{summary['seconds']:.2f} s:")
        print("  " + " ".join(f"{v:.5g}" for v in lam))
        if zero > 1:
            print(f"{zero} zero eigenvalues: the cloud has {zero} separate pieces")
        for f in (saved, args.out):
            if f:
                print(f"wrote {f}")
    return 0
