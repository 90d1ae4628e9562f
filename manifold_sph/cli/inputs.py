"""The grammar every ``manifold-sph`` command on a cloud shares: the input file, the Surface
options, ``--out`` (the picture), ``--save`` (the per-point values), sources, notes.

- ``FILE`` (positional): a point-cloud or mesh file, read as :func:`manifold_sph.read`
  reads it (``--duplicates merge`` by default);
- ``--scheme``, ``--neighbors``, ``--area``, ``--h``: the :class:`~manifold_sph.Surface` options;
- ``--out FILE``: the picture this command draws (``.png``; heat and wave also ``.gif`` /
  ``.mp4``), with the picture defaults of :mod:`manifold_sph.viz.style` and ``--up``,
  ``--camera``, ``--size``, ``--cmap``, ``--clim``, ``--robust``;
- ``--save FILE``: the per-point values (``.npy``: the array; ``.ply`` / ``.vtp`` / ``.vtk`` /
  ``.npz`` / ``.csv``: the points, their normals and the values as fields);
- a progress bar over the long steps (reading, normals, operators, the computation, the picture).

The library's warnings become one line each on stderr (``manifold-sph: note: ...``, no source
line), each said once (:func:`notes`).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import warnings
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .common import UserError, check_free, h_arg, pair_arg, percent_arg, positive_int_arg

__all__ = ["FORMATS_HELP", "SAVE_SUFFIXES", "add_input", "add_surface_options", "add_out", "add_save",
           "add_colour_options", "check_outputs", "read_input", "build_surface", "save_values", "draw", "progress", "notes"]

FORMATS_HELP = "ply, pcd, xyz, csv, pts, obj, npy, npz, las, laz, e57, vtk, vtp"
#: What ``--save`` writes, by extension.
SAVE_SUFFIXES = (".npy", ".npz", ".ply", ".vtp", ".vtk", ".csv")


def add_input(q: argparse.ArgumentParser, *, optional: bool = False, help: str | None = None) -> None:
    """The positional input file and ``--duplicates``."""
    text = help or f"point cloud or mesh file ({FORMATS_HELP}); its normals are used if it has them (a mesh's " \
                   "faces give them), else estimated"
    if optional:
        q.add_argument("file", nargs="?", default=None, help=text)
    else:
        q.add_argument("file", help=text)
    q.add_argument("--duplicates", default="merge", choices=["merge", "error"],
                   help="exact duplicate points: merge them into the first (default, said once) or refuse the file")


def add_surface_options(q: argparse.ArgumentParser, schemes: list[str], *, scheme: str = "msph",
                        neighbors: int | None = None, kernel: bool = False) -> None:
    """``--scheme``, ``--neighbors``, ``--area``, ``--h`` (and ``--kernel`` if asked)."""
    q.add_argument("--scheme", default=scheme, choices=schemes, help=f"SPH scheme (default {scheme})")
    q.add_argument("--neighbors", type=positive_int_arg, default=neighbors,
                   help=f"mean neighbour count (default {neighbors if neighbors else 'the scheme' + chr(39) + 's'})")
    q.add_argument("--area", default="numerical", choices=["numerical", "geometric", "shepard"],
                   help="area elements (default numerical; shepard for noisy scans)")
    q.add_argument("--h", type=h_arg, default=None,
                   help="smoothing length: a number, or 'adaptive' (each particle its own, for variable density)")
    if kernel:
        q.add_argument("--kernel", default="quintic", help="kernel (default quintic)")


def add_out(q: argparse.ArgumentParser, what: str = "the picture", suffixes: tuple[str, ...] = (".png",),
            repeat: bool = False) -> None:
    """``--out FILE``: the picture(s) the command draws."""
    kinds = " / ".join(suffixes)
    q.add_argument("--out", default=[] if repeat else None, action="append" if repeat else "store", metavar="FILE",
                   help=f"write {what} to this {kinds} file" + ("; repeat for several" if repeat else ""))
    q.set_defaults(out_suffixes=suffixes)


def add_colour_options(q: argparse.ArgumentParser) -> None:
    """``--cmap``, ``--clim``, ``--robust`` (the picture defaults otherwise)."""
    q.add_argument("--cmap", default=None,
                   help="matplotlib colour map (default: diverging centred at 0 for signed values, else viridis)")
    q.add_argument("--clim", type=pair_arg, default=None, help="colour limits LOW,HIGH")
    q.add_argument("--robust", type=percent_arg, default=None,
                   help="clip this percentage at each end of the colour range (0: the full range; default: 2-98 %% "
                        "narrowed for heavy tails)")


def add_save(q: argparse.ArgumentParser, what: str = "the per-point values") -> None:
    """``--save FILE``: the per-point values."""
    q.add_argument("--save", default=None, metavar="FILE",
                   help=f"save {what}: .npy (the array) or .ply / .vtp / .vtk / .npz / .csv (points, normals and values)")


def check_outputs(args: argparse.Namespace) -> None:
    """Check the input file, ``--out`` and ``--save`` before any work: extensions, folders, existing files."""
    if getattr(args, "file", None) and not Path(args.file).exists():
        raise FileNotFoundError(f"no such file: {str(args.file)!r}")
    outs = args.out if isinstance(getattr(args, "out", None), list) else [getattr(args, "out", None)]
    paths = []
    for out in (o for o in outs if o):
        suffixes = getattr(args, "out_suffixes", (".png",))
        if Path(out).suffix.lower() not in suffixes:
            raise UserError(f"--out must name a {' or '.join(suffixes)} file, got {out!r}")
        paths.append(out)
    if getattr(args, "save", None):
        if Path(args.save).suffix.lower() not in SAVE_SUFFIXES:
            raise UserError(f"--save must name a {', '.join(SAVE_SUFFIXES)} file, got {args.save!r}")
        paths.append(args.save)
    for p in paths:
        if not Path(p).parent.is_dir():
            raise UserError(f"{p!r}: the folder {str(Path(p).parent)!r} does not exist")
    check_free(paths, getattr(args, "overwrite", False))
    if any(Path(p).suffix.lower() in (".png", ".gif", ".mp4") for p in paths):
        from ..viz.render import rendering_available

        ok, why = rendering_available()
        if not ok:
            raise RuntimeError(f"cannot render here: {why}")


@contextlib.contextmanager
def progress(args: argparse.Namespace, total: int, desc: str) -> Iterator[Any]:
    """A tqdm bar on stderr over ``total`` steps (on a terminal, and not with ``--json``), cleared when
    done; ``bar.step(name)`` names the next step, ``bar.update()`` ends it."""
    from tqdm import tqdm

    with tqdm(total=total, desc=desc, disable=True if getattr(args, "json", False) else None, file=sys.stderr, leave=False,
              bar_format="{desc}: {n_fmt}/{total_fmt} |{bar}| {elapsed}") as bar:
        bar.step = lambda name: bar.set_description_str(f"{desc}: {name}")  # type: ignore[attr-defined]
        yield bar


def read_input(args: argparse.Namespace, bar: Any = None) -> tuple[Any, dict[str, np.ndarray]]:
    """The cloud of ``FILE`` and its per-point fields (duplicates as ``--duplicates`` says)."""
    from ..scans.io import read

    if bar is not None:
        bar.step("reading")
    cloud, fields = read(args.file, duplicates=getattr(args, "duplicates", "merge"), return_fields=True)
    if bar is not None:
        bar.update()
    return cloud, fields


def build_surface(args: argparse.Namespace, cloud: Any, bar: Any = None) -> tuple[Any, bool]:
    """The Surface of ``cloud`` with the command's options, normals estimated first (as a step of
    its own) when the cloud has none; and whether they were estimated."""
    from ..normals import estimate_normals
    from ..pointcloud import PointCloud
    from ..schemes import get_scheme
    from ..surface import Surface

    estimated = cloud.normals is None
    if bar is not None and not estimated:
        bar.total -= 1  # no normals step
        bar.refresh()
    if estimated:
        if bar is not None:
            bar.step("normals")
        degree = int(min(max(getattr(get_scheme(args.scheme), "degree", 2), 2), 4))  # as Surface estimates them
        cloud = PointCloud(cloud.points, estimate_normals(cloud.points, degree=degree), geometry=cloud.geometry)
        if bar is not None:
            bar.update()
    if bar is not None:
        bar.step("operators")
    options = {k: getattr(args, k) for k in ("neighbors", "area", "h", "kernel") if getattr(args, k, None) is not None}
    s = Surface(cloud, scheme=args.scheme, **options)
    if bar is not None:
        bar.update()
    return s, estimated


def _atomic_npy(path: Path, values: np.ndarray) -> None:
    tmp = path.with_name(f".{path.name}.partial.npy")
    try:
        np.save(tmp, values)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def save_values(args: argparse.Namespace, cloud: Any, values: Mapping[str, np.ndarray]) -> str | None:
    """Write ``--save``: ``.npy`` holds the one array of ``values`` (or, for several, the first);
    other formats the points, normals and every array as fields. The path, or None."""
    if not getattr(args, "save", None):
        return None
    path = Path(args.save)
    if path.suffix.lower() == ".npy":
        _atomic_npy(path, np.asarray(next(iter(values.values()))))
    else:
        from ..scans.io import write

        fields = {k: np.where(np.isfinite(v), v, np.nan) if path.suffix.lower() in (".vtp", ".vtk", ".npz") else v
                  for k, v in values.items()}
        bad = [k for k, v in fields.items() if not np.all(np.isfinite(v))]
        if bad:
            raise UserError(f"--save {args.save!r}: {bad[0]!r} holds NaN or inf values (unreached particles); "
                            "save to .npy, .npz, .vtp or .vtk, which keep them")
        write(path, cloud, fields, overwrite=getattr(args, "overwrite", False))
    return str(path)


def draw(args: argparse.Namespace, points: Any, values: np.ndarray | None, *, title: str, name: str,
         out: str | os.PathLike[str] | None = None, **options: Any) -> str | None:
    """Render ``values`` (named ``name`` on the colour bar) to ``out`` (default ``--out``) with the
    picture defaults; ``--cmap``, ``--clim``, ``--robust``, ``--up``, ``--camera``, ``--size`` as given."""
    out = out if out is not None else getattr(args, "out", None)
    if not out:
        return None
    from ..viz.render import render_field

    robust = getattr(args, "robust", None)
    kw: dict[str, Any] = dict(
        title=title, camera=getattr(args, "camera", "iso"), up=getattr(args, "up", "auto"),
        window_size=getattr(args, "size", None) or (800, 600), clim=getattr(args, "clim", None),
        robust=True if robust is None else (robust if robust > 0 else False),
        cmap=getattr(args, "cmap", None) or "auto", filename=out, overwrite=getattr(args, "overwrite", False),
    )
    kw.update(options)
    field = None if values is None else {name: values}
    render_field(points, field, **kw)
    return str(out)


@contextlib.contextmanager
def notes() -> Iterator[None]:
    """The library's warnings while a command runs, each said once as one line on stderr
    (``manifold-sph: note: ...``), without Python's source line."""
    from ..exceptions import ManifoldSPHWarning

    said: set[str] = set()

    def show(message, category, filename, lineno, file=None, line=None):  # noqa: ANN001 - warnings.showwarning's
        text = " ".join(str(message).split()).replace(" Surface.report() has the details.", "")  # a Python call
        if issubclass(category, ManifoldSPHWarning) and text not in said:
            said.add(text)
            from tqdm import tqdm

            tqdm.write(f"manifold-sph: note: {text}", file=sys.stderr)  # on a line of its own, above any bar
        elif not issubclass(category, ManifoldSPHWarning):
            previous(message, category, filename, lineno, file, line)

    previous = warnings.showwarning
    with warnings.catch_warnings():
        warnings.simplefilter("always", ManifoldSPHWarning)
        warnings.showwarning = show
        try:
            yield
        finally:
            warnings.showwarning = previous
