"""Off-screen pictures of fields on point clouds (PyVista/VTK, no display needed).

Every function renders off-screen (VTK picks an EGL or OSMesa window when
there is no X server), returns the image as a ``(height, width, 3)`` uint8
array (``(height, width, 4)`` with ``transparent=True``) and writes a PNG when
given ``filename``; an existing file is never overwritten unless
``overwrite=True``.

- :func:`render_field`: a scalar field on the points (drawn as spheres),
  optionally with tangent vectors as arrow glyphs.
- :func:`render_panels`: side-by-side panels, e.g. function | exact |
  approximation | error (:func:`render_comparison`).
- :func:`animate`: a time series (snapshots of a PDE solver) to GIF (Pillow)
  or MP4 (``imageio`` with ``imageio-ffmpeg``), with an optional progress bar.
- :data:`CAMERAS`: the fixed views ``"iso"``, ``"equator"`` and
  ``"north_pole"`` (the views of the sphere in the thesis [1], docs/method.md).
- :func:`detect_up_axis`: the up axis guessed from a cloud (``up="auto"``).
- :func:`color_limits`: explicit or robust (percentile-clipped) colour limits.
- :func:`rendering_available`: whether off-screen rendering works here.

Examples
--------
>>> import numpy as np
>>> from manifold_sph.reference import shapes
>>> cloud = shapes.sphere(500)
>>> color_limits(cloud.points[:, 2])
(-1.0, 1.0)
>>> if rendering_available()[0]:  # doctest: +SKIP
...     img = render_field(cloud, cloud.points[:, 2], window_size=(160, 120))
...     img.shape
(120, 160, 3)
"""

from __future__ import annotations

import contextlib
import numbers
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import as_field, as_points, check_bool, check_in, check_int, check_output_path, check_positive

if TYPE_CHECKING:  # no run-time imports: pyvista and the operator stack load only when used
    from ..operators import OperatorSet
    from ..pde import Solution
    from ..pointcloud import PointCloud

__all__ = [
    "CAMERAS",
    "animate",
    "color_limits",
    "render_comparison",
    "render_field",
    "render_panels",
    "detect_up_axis",
    "rendering_available",
    "save_png",
]

#: Camera presets: name -> (direction from the centre to the camera, view-up).
#: ``"equator"`` looks at the equator from the +x side with z up, ``"north_pole"``
#: looks down the z axis, ``"iso"`` is an oblique view from (1, 1, 1) (tilted
#: slightly so that no axis is hidden).
CAMERAS: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = {
    "iso": ((1.0, 0.8, 0.7), (0.0, 0.0, 1.0)),
    "equator": ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
    "north_pole": ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
    "south_pole": ((0.0, 0.0, -1.0), (0.0, 1.0, 0.0)),
    "side": ((0.0, -1.0, 0.0), (0.0, 0.0, 1.0)),
    "top": ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
}

_AVAILABLE: tuple[bool, str] | None = None


# --- small helpers -------------------------------------------------------------------


def _as_points3(points) -> np.ndarray:
    """(N, 3) coordinates from an array (N, 2 or 3), a PointCloud, a Surface or a Domain2D."""
    if hasattr(points, "points") and not isinstance(points, np.ndarray):
        points = points.points
    p = as_points("points", points, dim=(2, 3))
    if p.shape[0] == 0:
        raise ValueError("points must hold at least one point, got shape (0, 3)")
    if p.shape[1] == 2:
        p = np.column_stack([p, np.zeros(len(p))])
    return p


def _check_window(window_size) -> tuple[int, int]:
    if (
        isinstance(window_size, (str, bytes))
        or not isinstance(window_size, Sequence)
        or len(window_size) != 2
    ):
        raise TypeError(f"window_size must be a pair (width, height) of integers, got {window_size!r}")
    w = check_int("window_size[0] (width)", window_size[0], minimum=16)
    h = check_int("window_size[1] (height)", window_size[1], minimum=16)
    return w, h


def _check_target(filename, overwrite: bool, suffixes: tuple[str, ...]) -> Path:
    overwrite = check_bool("overwrite", overwrite)
    if not isinstance(filename, (str, os.PathLike)):
        raise TypeError(f"filename must be a str or path, got {type(filename).__name__}")
    path = Path(filename)
    if path.suffix.lower() not in suffixes:
        raise ValueError(f"filename must end in {' or '.join(suffixes)}, got {str(path)!r}")
    return check_output_path("filename", path, overwrite)  # the package's one overwrite guard


def save_png(image: ArrayLike, filename: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
    """Write an RGB or RGBA uint8 image array to a PNG file.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3) or (H, W, 4), uint8
    filename : str or path
        Ends in ``.png``; its folder must exist.
    overwrite : bool
        Replace an existing file (default False: raise FileExistsError).

    Returns
    -------
    pathlib.Path

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> save_png(np.zeros((4, 6, 3), np.uint8), d / "black.png").name
    'black.png'
    >>> save_png(np.zeros((4, 6, 3), np.uint8), d / "black.png")
    Traceback (most recent call last):
    ...
    FileExistsError: filename '...black.png' exists; pass overwrite=True to replace it
    """
    from PIL import Image

    img = np.asarray(image)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] not in (3, 4):
        raise ValueError(f"image must be a uint8 array of shape (H, W, 3) or (H, W, 4), got {img.dtype} array of shape {img.shape}")
    path = _check_target(filename, overwrite, (".png",))
    Image.fromarray(img).save(path)
    return path


def color_limits(
    values: ArrayLike, clim: tuple[float, float] | None = None, robust: float | bool | None = None
) -> tuple[float, float]:
    """Colour limits of a field: explicit, full range, or robust (percentile clipping).

    Parameters
    ----------
    values : array_like
        Finite values (a scalar field, or several stacked).
    clim : (float, float), optional
        Explicit limits ``(low, high)``, returned as given (``low < high``).
    robust : float or bool, optional
        Clip ``robust`` percent at each end (``True`` means 2 %): the range of
        the bulk of the values, so that a few outliers (e.g. the sausage's tips)
        do not wash out the picture. Default: the full range.

    Returns
    -------
    (float, float)
        Rounded outwards to 3 significant digits of the range; a constant field
        gets a small range around its value.

    Examples
    --------
    >>> v = np.r_[np.linspace(0.0, 1.0, 99), 50.0]
    >>> color_limits(v)
    (0.0, 50.0)
    >>> color_limits(v, robust=2)
    (0.02, 0.99)
    >>> color_limits(v, clim=(0, 2))
    (0.0, 2.0)
    >>> color_limits([3.0, 3.0])
    (2.97, 3.03)
    """
    if clim is not None:
        if isinstance(clim, (str, bytes)) or not isinstance(clim, Sequence) or len(clim) != 2:
            raise TypeError(f"clim must be a pair (low, high) of numbers, got {clim!r}")
        if not all(isinstance(c, numbers.Real) and not isinstance(c, bool) for c in clim):
            raise TypeError(f"clim must be a pair (low, high) of numbers, got {clim!r}")
        if not all(np.isfinite(c) for c in clim):
            raise ValueError(f"clim must be finite, got {clim!r}")
        lo, hi = float(clim[0]), float(clim[1])
        if not lo < hi:
            raise ValueError(f"clim must satisfy low < high, got {clim!r}")
        return lo, hi
    v = np.asarray(values, dtype=np.float64).ravel()
    if v.size == 0:
        raise ValueError("values must hold at least one value to choose colour limits")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"values must be finite to choose colour limits, got {int((~np.isfinite(v)).sum())} NaN or inf value(s)")
    if robust is None or robust is False:
        lo, hi = float(v.min()), float(v.max())
    else:
        p = 2.0 if robust is True else check_positive("robust", robust)
        if p >= 50:
            raise ValueError(f"robust must be a percentage below 50, got {robust!r}")
        lo, hi = (float(x) for x in np.percentile(v, [p, 100.0 - p]))
    if hi - lo <= 1e-12 * max(1.0, abs(hi), abs(lo)):
        d = 0.01 * max(abs(lo), 1e-12) if lo != 0 else 1e-3
        lo, hi = lo - d, hi + d
    # round outwards to 3 significant digits of the range: tidy colour-bar labels, nothing clipped
    e = int(np.floor(np.log10(hi - lo))) - 2
    m = 10.0**e
    digits = max(-e, 0)
    lo_r = round(np.floor(lo / m) * m, digits)
    hi_r = round(np.ceil(hi / m) * m, digits)
    return float(lo_r), float(hi_r)


@contextlib.contextmanager
def _quiet_vtk():
    """Silence VTK's warnings (e.g. "bad X server connection" before it falls back to EGL), text verbatim.

    Text is drawn verbatim: VTK (>= 9.3) hands every string that contains a
    ``|`` (its column separator) or a pair of ``$`` to the MathText backend
    (matplotlib's mathtext), which drops the ``|`` and the spaces ("|H| max"
    came out as "Hmax"). While rendering, the default text backend is set to
    FreeType (plain text, no detection) and restored afterwards.
    """
    from vtkmodules.vtkCommonCore import vtkObject

    old = vtkObject.GetGlobalWarningDisplay()
    vtkObject.GlobalWarningDisplayOff()
    renderer = old_backend = None
    try:
        from vtkmodules.vtkRenderingCore import vtkTextRenderer

        renderer = vtkTextRenderer.GetInstance()
    except ImportError:  # pragma: no cover - every VTK wheel has it
        pass
    if renderer is not None:
        old_backend = renderer.GetDefaultBackend()
        renderer.SetDefaultBackend(vtkTextRenderer.FreeType)
    try:
        yield
    finally:
        if renderer is not None:
            renderer.SetDefaultBackend(old_backend)
        vtkObject.SetGlobalWarningDisplay(old)


def _plotter(window_size, shape=(1, 1), background="white"):
    import pyvista as pv

    p = pv.Plotter(off_screen=True, window_size=list(window_size), shape=shape, border=False)
    p.set_background(background)
    return p


def rendering_available() -> tuple[bool, str]:
    """Whether off-screen rendering works here, and why not.

    Renders one tiny scene (once per process) and checks that pixels came back.

    Returns
    -------
    (bool, str)
        ``(True, "<render window class>")`` or ``(False, reason)``.
    """
    global _AVAILABLE
    if _AVAILABLE is None:
        try:
            import pyvista as pv

            with _quiet_vtk():
                p = _plotter((32, 32))
                try:
                    p.add_mesh(pv.Sphere(), color="red")
                    img = p.screenshot(return_img=True)
                    kind = type(p.render_window).__name__
                finally:
                    p.close()
            ok = img is not None and np.asarray(img).std() > 0
            _AVAILABLE = (True, kind) if ok else (False, f"{kind} rendered a blank image")
        except Exception as exc:  # noqa: BLE001 - any VTK/GL failure means "not available"
            _AVAILABLE = (False, f"off-screen rendering failed: {type(exc).__name__}: {exc}")
    return _AVAILABLE


def _spacing(points: np.ndarray) -> float:
    """Median nearest-neighbour distance (a robust particle spacing)."""
    from scipy.spatial import cKDTree

    if len(points) < 2:
        return 1.0
    d, _ = cKDTree(points).query(points, k=2)
    s = float(np.median(d[:, 1]))
    return s if s > 0 else 1.0


def _point_size(points: np.ndarray, spacing: float, window_size) -> float:
    ext = float(np.max(np.ptp(points, axis=0)))
    if ext <= 0:
        return 10.0
    pix_per_unit = 0.8 * min(window_size) / ext
    return float(np.clip(1.1 * spacing * pix_per_unit, 2.0, 40.0))


_AXES = {"x": 0, "y": 1, "z": 2}


def detect_up_axis(points: ArrayLike | PointCloud | OperatorSet) -> str:
    """The up axis of a cloud, guessed from its extents: ``"y"`` or ``"z"``.

    The rule (chosen by looking at public test meshes, the Stanford bunny and the
    package's shapes): ``"z"`` when z is the longest extent (within 5 %, e.g.
    the sphere and many CAD parts) or the cloud is flat in z (z extent below
    a quarter of the longest: tori, planar domains); otherwise ``"y"``, the
    convention of most graphics and scan files (OBJ/PLY: the bunny, the
    teapot, the cow, homer, cheburashka). Models it gets wrong (measured: the
    beetle and Igea, whose longest extents include z) need ``up=`` explicitly.

    Parameters
    ----------
    points : array_like (N, 3) or (N, 2), PointCloud, Surface or Domain2D

    Returns
    -------
    str
        ``"y"`` or ``"z"``.

    Examples
    --------
    >>> from manifold_sph.reference import shapes
    >>> detect_up_axis(shapes.torus(200)), detect_up_axis(shapes.sphere(200))
    ('z', 'z')
    >>> import numpy as np
    >>> teapot_like = np.random.default_rng(0).random((100, 3)) * [6.4, 3.2, 4.0]
    >>> detect_up_axis(teapot_like)
    'y'
    """
    ext = np.ptp(_as_points3(points), axis=0)
    top = ext.max()
    if top <= 0 or ext[2] >= 0.95 * top or ext[2] < 0.25 * top:
        return "z"
    return "y"


def _resolve_up(points, up) -> int:
    """Index of the up axis from ``up`` ("auto", "x", "y" or "z")."""
    if not isinstance(up, str):
        raise TypeError(f"up must be one of 'auto', 'x', 'y', 'z' (a string), got {type(up).__name__} {up!r}")
    if up not in ("auto", "x", "y", "z"):
        raise ValueError(f"up must be one of 'auto', 'x', 'y', 'z', got {up!r}")
    return _AXES[detect_up_axis(points) if up == "auto" else up]


def _set_camera(plotter, points: np.ndarray, camera, zoom: float = 1.0, up: str = "z") -> None:
    if isinstance(camera, str):
        check_in("camera", camera, CAMERAS)
        direction, view_up = CAMERAS[camera]
        # the presets are written for z up: swap the z component with the up axis
        a = _resolve_up(points, up)
        perm = [0, 1, 2]
        perm[a], perm[2] = 2, a
        direction = tuple(direction[i] for i in perm)
        up = tuple(view_up[i] for i in perm)
    else:
        _resolve_up(points, up)  # validated; an explicit (direction, view_up) pair is used as given
        try:
            direction, up = (np.asarray(camera[0], float), np.asarray(camera[1], float))
        except (TypeError, ValueError, IndexError):
            raise TypeError(f"camera must be one of {sorted(CAMERAS)} or a pair (direction, view_up) of 3-vectors, got {camera!r}") from None
        if direction.shape != (3,) or up.shape != (3,) or not np.linalg.norm(direction) > 0:
            raise ValueError(f"camera must be a pair (direction, view_up) of non-zero 3-vectors, got {camera!r}")
    centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    plotter.camera_position = [tuple(centre + 5.0 * max(np.ptp(points, axis=0).max(), 1e-9) * d), tuple(centre), tuple(up)]
    plotter.reset_camera()
    if zoom != 1.0:
        plotter.camera.zoom(zoom)


def _set_text(actor, text: str) -> None:
    """Change the text of an actor from ``Plotter.add_text`` (a text actor or a corner annotation)."""
    if hasattr(actor, "SetInput"):
        actor.SetInput(text)
    else:  # vtkCornerAnnotation: the lower-left corner is slot 0
        actor.SetText(0, text)


def _font(window_size, largest: int) -> int:
    """A font size that fits the window: ``largest`` from 640 pixels wide, smaller below."""
    return int(max(6, min(largest, round(largest * window_size[0] / 640))))


def _title_text(plotter, text, font_size):
    if text:
        plotter.add_text(str(text), position="upper_edge", font_size=font_size, color="black")


def _add_cloud(
    plotter,
    points,
    field,
    vectors,
    *,
    spacing,
    point_size,
    cmap,
    clim,
    robust,
    bar_title,
    show_scalar_bar,
    vector_scale,
    vector_color,
    n_labels=5,
    max_arrows=400,
    normals=None,
):
    """Add points (as spheres, coloured by ``field``) and optional arrow glyphs; return the points' actor."""
    import pyvista as pv

    n = len(points)
    mesh = pv.PolyData(points)
    if field is None and vectors is not None:
        field = np.linalg.norm(vectors, axis=1)
        bar_title = bar_title or "|v|"
    if field is not None:
        lo, hi = color_limits(field, clim, robust)
        mesh.point_data["field"] = np.clip(field, lo, hi)
        actor = plotter.add_mesh(
            mesh,
            scalars="field",
            cmap=cmap,
            clim=(lo, hi),
            render_points_as_spheres=True,
            point_size=point_size,
            show_scalar_bar=show_scalar_bar,
            scalar_bar_args={
                "title": bar_title or "",
                "color": "black",
                "n_labels": n_labels,
                "fmt": "%.3g",
                "vertical": False,
                "position_x": 0.2,
                "position_y": 0.03,
                "width": 0.6,
                "height": 0.1,
                "title_font_size": 14,
                "label_font_size": 12,
            },
        )
    else:
        actor = plotter.add_mesh(mesh, color="lightgray", render_points_as_spheres=True, point_size=point_size)
    if field is not None and show_scalar_bar:
        bar = plotter.scalar_bars[bar_title or ""] if (bar_title or "") in plotter.scalar_bars else None
        if bar is not None:
            bar.SetTextPositionToPrecedeScalarBar()  # labels below the bar, title above
    if vectors is not None:
        mag = np.linalg.norm(vectors, axis=1)
        vmax = float(mag.max())
        if vmax > 0:
            keep = mag > 1e-3 * vmax
            if keep.sum() > max_arrows:  # a spread-out subset, deterministic
                idx = np.flatnonzero(keep)
                keep = np.zeros(n, dtype=bool)
                keep[np.random.default_rng(0).choice(idx, max_arrows, replace=False)] = True
            arrow_spacing = spacing * np.sqrt(n / max(int(keep.sum()), 1))
            factor = (vector_scale if vector_scale is not None else 0.9 * arrow_spacing) / vmax
            base = points[keep] + (0.0 if normals is None else 0.6 * spacing * normals[keep])
            arrows = pv.PolyData(base)
            arrows.point_data["vec"] = vectors[keep]
            geom = pv.Arrow(tip_length=0.35, tip_radius=0.12, shaft_radius=0.04)
            glyphs = arrows.glyph(orient="vec", scale="vec", factor=factor, geom=geom)
            plotter.add_mesh(glyphs, color=vector_color, show_scalar_bar=False)
    return actor


def _finish(plotter, transparent, filename, overwrite):
    img = plotter.screenshot(return_img=True, transparent_background=transparent)
    img = np.ascontiguousarray(np.asarray(img, dtype=np.uint8))
    if filename is not None:
        save_png(img, filename, overwrite=overwrite)
    return img


def _normals_of(points, n):
    """Unit normals of a PointCloud or Surface (to lift arrows off the spheres), or None."""
    nrm = getattr(points, "normals", None) if not isinstance(points, np.ndarray) else None
    if nrm is None:
        return None
    nrm = np.asarray(nrm, dtype=np.float64)
    if nrm.shape != (n, 3):
        return None
    length = np.linalg.norm(nrm, axis=1, keepdims=True)
    return nrm / np.where(length > 0, length, 1.0)


def _prepare(points, field, vectors, window_size, filename, overwrite):
    pts = _as_points3(points)
    n = len(pts)
    fld = None if field is None else as_field("field", field, n)
    vec = None
    if vectors is not None:
        v = np.asarray(vectors, dtype=np.float64)
        if v.ndim == 2 and v.shape == (n, 2):
            v = np.column_stack([v, np.zeros(n)])
        vec = as_field("vectors", v, n, 3)
    ws = _check_window(window_size)
    if filename is not None:
        _check_target(filename, overwrite, (".png",))
    return pts, fld, vec, ws


# --- public renderers -----------------------------------------------------------------


def render_field(
    points: ArrayLike | PointCloud | OperatorSet,
    field: ArrayLike | None = None,
    *,
    vectors: ArrayLike | None = None,
    title: str | None = None,
    bar_title: str | None = None,
    cmap: str = "viridis",
    clim: tuple[float, float] | None = None,
    robust: float | bool | None = None,
    camera: str | tuple[ArrayLike, ArrayLike] = "iso",
    up: str = "auto",
    zoom: float = 1.0,
    window_size: tuple[int, int] = (800, 600),
    point_size: float | None = None,
    vector_scale: float | None = None,
    vector_color: str = "black",
    show_scalar_bar: bool = True,
    background: str = "white",
    transparent: bool = False,
    filename: str | os.PathLike[str] | None = None,
    overwrite: bool = False,
) -> np.ndarray:
    """Render a scalar field on a point cloud, points drawn as spheres, off-screen.

    Parameters
    ----------
    points : array_like (N, 3) or (N, 2), PointCloud, Surface or Domain2D
        Planar points are drawn in the plane z = 0.
    field : array_like, shape (N,), optional
        Colours of the points; without it the points are grey, or coloured by
        the length of ``vectors`` when those are given.
    vectors : array_like, shape (N, 3) or (N, 2), optional
        Drawn as arrows (e.g. a tangential gradient), longest arrow
        ``vector_scale`` long (default 2.5 particle spacings).
    title : str, optional
        Text at the top of the picture.
    bar_title : str, optional
        Title of the colour bar.
    cmap : str
        Matplotlib colour map name.
    clim : (float, float), optional
        Explicit colour limits; values outside are clipped to the end colours.
    robust : float or bool, optional
        Percentile clipping of the colour range (see :func:`color_limits`).
    camera : str or (direction, view_up)
        A key of :data:`CAMERAS` (``"iso"``, ``"equator"``, ``"north_pole"``, ...)
        or a pair of 3-vectors (direction from the centre to the camera, up).
        The presets are written for z up and turned to the ``up`` axis.
    up : {"auto", "x", "y", "z"}
        The axis that points up in the named camera presets. ``"auto"``
        (default) guesses it from the cloud's extents (:func:`detect_up_axis`:
        y for most graphics/scan models, z for the package's shapes, flat
        clouds and clouds longest in z). Ignored (but validated) for an
        explicit ``(direction, view_up)`` pair.
    zoom : float
        Camera zoom after fitting the cloud in the view.
    window_size : (int, int)
        ``(width, height)`` in pixels of the image.
    point_size : float, optional
        Sphere diameter in pixels (default: from the particle spacing).
    show_scalar_bar : bool
    background : str
    transparent : bool
        Transparent background: the image is RGBA.
    filename : str or path, optional
        Also write the image to this PNG file.
    overwrite : bool
        Replace an existing ``filename`` (default False: FileExistsError).

    Returns
    -------
    numpy.ndarray, shape (height, width, 3) or (height, width, 4), uint8

    Examples
    --------
    >>> from manifold_sph.reference import shapes
    >>> cloud = shapes.sphere(400)
    >>> img = render_field(cloud, cloud.points[:, 2], window_size=(120, 100))  # doctest: +SKIP
    >>> img.shape  # doctest: +SKIP
    (100, 120, 3)
    """
    pts, fld, vec, ws = _prepare(points, field, vectors, window_size, filename, overwrite)
    zoom = check_positive("zoom", zoom)
    transparent = check_bool("transparent", transparent)
    spacing = _spacing(pts)
    ps = _point_size(pts, spacing, ws) * zoom if point_size is None else check_positive("point_size", point_size)
    if vec is not None and point_size is None:
        ps *= 0.8  # smaller spheres, so that the arrows lying on the surface show
    with _quiet_vtk():
        p = _plotter(ws, background=background)
        try:
            _add_cloud(
                p, pts, fld, vec, spacing=spacing, point_size=ps, cmap=cmap, clim=clim, robust=robust,
                bar_title=bar_title, show_scalar_bar=check_bool("show_scalar_bar", show_scalar_bar),
                vector_scale=vector_scale, vector_color=vector_color, normals=_normals_of(points, len(pts)),
            )
            _title_text(p, title, _font(ws, 12))
            _set_camera(p, pts, camera, zoom, up)
            return _finish(p, transparent, filename, overwrite)
        finally:
            p.close()


def render_panels(
    points: ArrayLike | PointCloud | OperatorSet,
    fields: Mapping[str, ArrayLike],
    *,
    vectors: Mapping[str, ArrayLike] | None = None,
    shared_clim: bool | Sequence[str] = False,
    cmap: str | Mapping[str, str] = "viridis",
    clim: tuple[float, float] | None = None,
    robust: float | bool | None = None,
    camera: str | tuple[ArrayLike, ArrayLike] = "iso",
    up: str = "auto",
    zoom: float = 1.0,
    panel_size: tuple[int, int] = (400, 400),
    point_size: float | None = None,
    background: str = "white",
    transparent: bool = False,
    filename: str | os.PathLike[str] | None = None,
    overwrite: bool = False,
) -> np.ndarray:
    """Side-by-side panels of several scalar fields on the same points.

    Parameters
    ----------
    points : array_like (N, 3) or (N, 2), PointCloud, Surface or Domain2D
    fields : mapping of str -> array_like (N,)
        Panel title -> field, left to right.
    vectors : mapping of str -> array_like (N, 3), optional
        Arrows to draw in the panels with those titles.
    shared_clim : bool or sequence of str
        ``True``: one colour range for all panels; a sequence of titles: one
        range shared by those panels (e.g. exact and approximation), the others
        their own.
    cmap : str or mapping of str -> str
        One colour map, or one per panel title.
    clim, robust
        As in :func:`render_field` (applied to every panel or to the shared group).
    camera, up, zoom, point_size, background, transparent, filename, overwrite
        As in :func:`render_field`.
    panel_size : (int, int)
        ``(width, height)`` of one panel; the image is ``len(fields)`` panels wide.

    Returns
    -------
    numpy.ndarray, shape (height, n_panels * width, 3 or 4), uint8
    """
    if not isinstance(fields, Mapping) or len(fields) == 0:
        raise TypeError(f"fields must be a non-empty mapping of panel title -> field, got {type(fields).__name__}")
    w, h = _check_window(panel_size)
    pts, _, _, ws = _prepare(points, None, None, (w * len(fields), h), filename, overwrite)
    n = len(pts)
    titles = [str(t) for t in fields]
    flds = {t: as_field(f"fields[{t!r}]", fields[k], n) for t, k in zip(titles, fields)}
    vecs = {}
    for t, v in (vectors or {}).items():
        if str(t) not in flds:
            raise ValueError(f"vectors has key {t!r} which is not a panel title; titles are {titles!r}")
        v = np.asarray(v, dtype=np.float64)
        if v.ndim == 2 and v.shape == (n, 2):
            v = np.column_stack([v, np.zeros(n)])
        vecs[str(t)] = as_field(f"vectors[{t!r}]", v, n, 3)
    if isinstance(shared_clim, (bool, np.bool_)):
        group = titles if shared_clim else []
    else:
        group = [str(t) for t in shared_clim]
        for t in group:
            if t not in flds:
                raise ValueError(f"shared_clim names {t!r}, which is not a panel title; titles are {titles!r}")
    group_lim = color_limits(np.concatenate([flds[t] for t in group]), clim, robust) if group else None
    transparent = check_bool("transparent", transparent)
    zoom = check_positive("zoom", zoom)
    spacing = _spacing(pts)
    ps = _point_size(pts, spacing, (w, h)) * zoom if point_size is None else check_positive("point_size", point_size)
    with _quiet_vtk():
        p = _plotter(ws, shape=(1, len(titles)), background=background)
        try:
            for i, t in enumerate(titles):
                p.subplot(0, i)
                lim = group_lim if t in group else color_limits(flds[t], clim, robust)
                cm = cmap.get(t, "viridis") if isinstance(cmap, Mapping) else cmap
                # VTK shares a colour bar between meshes with the same bar title: keep them unique.
                _add_cloud(
                    p, pts, flds[t], vecs.get(t), spacing=spacing, point_size=ps, cmap=cm, clim=lim, robust=None,
                    bar_title=" " * (i + 1), show_scalar_bar=True, vector_scale=None, vector_color="black", n_labels=3,
                    normals=_normals_of(points, n),
                )
                _title_text(p, t, _font((w, h), 11))
                _set_camera(p, pts, camera, zoom, up)
            return _finish(p, transparent, filename, overwrite)
        finally:
            p.close()


def render_comparison(
    points: ArrayLike | PointCloud | OperatorSet,
    f: ArrayLike,
    exact: ArrayLike,
    approx: ArrayLike,
    *,
    names: Sequence[str] = ("f", "exact", "SPH", "error"),
    **kwargs: Any,
) -> np.ndarray:
    """Four panels: function | exact | approximation | pointwise absolute error.

    The exact and approximate panels share one colour range; the error panel
    has its own (``"magma"``). Keyword arguments go to :func:`render_panels`.

    Parameters
    ----------
    points : array_like or PointCloud or Surface
    f, exact, approx : array_like, shape (N,)
        The function, the exact operator applied to it, the SPH approximation.
    names : 4 str
        Panel titles.

    Returns
    -------
    numpy.ndarray
        The image (see :func:`render_panels`).
    """
    if len(names) != 4:
        raise ValueError(f"names must hold 4 panel titles, got {len(names)}")
    n = len(_as_points3(points))
    exact = as_field("exact", exact, n)
    approx = as_field("approx", approx, n)
    fields = {names[0]: as_field("f", f, n), names[1]: exact, names[2]: approx, names[3]: np.abs(approx - exact)}
    kwargs.setdefault("shared_clim", [names[1], names[2]])
    kwargs.setdefault("cmap", {names[0]: "viridis", names[1]: "coolwarm", names[2]: "coolwarm", names[3]: "magma"})
    return render_panels(points, fields, **kwargs)


def animate(
    points: ArrayLike | PointCloud | OperatorSet,
    snapshots: ArrayLike | Solution,
    filename: str | os.PathLike[str],
    *,
    times: ArrayLike | None = None,
    fps: float = 10.0,
    title: str | None = None,
    bar_title: str | None = None,
    cmap: str = "viridis",
    clim: tuple[float, float] | None = None,
    robust: float | bool | None = None,
    camera: str | tuple[ArrayLike, ArrayLike] = "iso",
    up: str = "auto",
    zoom: float = 1.0,
    window_size: tuple[int, int] = (480, 400),
    point_size: float | None = None,
    background: str = "white",
    progress: bool = False,
    overwrite: bool = False,
) -> Path:
    """Write a time series of scalar fields to an animated GIF or an MP4 video.

    One colour range for all frames (``clim``, or the range of all the
    snapshots, robust if asked), so that decay and propagation are visible.

    Parameters
    ----------
    points : array_like (N, 3) or (N, 2), PointCloud, Surface or Domain2D
    snapshots : array_like, shape (S, N), or an object with ``.snapshots`` (and ``.times``)
        E.g. the :class:`~manifold_sph.pde.Solution` of :func:`manifold_sph.pde.heat` or :func:`~manifold_sph.pde.wave`.
    filename : str or path
        ``.gif`` or ``.mp4``, written frame by frame by pyvista's ``open_gif`` /
        ``open_movie`` (imageio); MP4 needs ``imageio-ffmpeg`` (the ``video`` extra:
        the ffmpeg binary ships inside its wheel).
    times : array_like, shape (S,), optional
        Shown in a corner as ``t = ...`` (default: ``snapshots.times`` if present).
    fps : float
        Frames per second.
    progress : bool
        Show a tqdm progress bar on stderr (default False: library calls are quiet).
    title, bar_title, cmap, clim, robust, camera, up, zoom, window_size, point_size, background, overwrite
        As in :func:`render_field`.

    Returns
    -------
    pathlib.Path
        The file written.
    """
    if hasattr(snapshots, "snapshots"):
        if times is None:
            times = getattr(snapshots, "times", None)
        snapshots = snapshots.snapshots
    pts = _as_points3(points)
    n = len(pts)
    try:
        snaps = np.asarray(snapshots, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"snapshots must be a numeric array of shape (S, {n}), got {type(snapshots).__name__}") from exc
    if snaps.ndim != 2 or snaps.shape[1] != n or snaps.shape[0] < 1:
        raise ValueError(f"snapshots must have shape (S, {n}) with S >= 1, got shape {snaps.shape}")
    if not np.all(np.isfinite(snaps)):
        raise ValueError(f"snapshots must be finite, got {int((~np.isfinite(snaps)).sum())} NaN or inf value(s)")
    if times is not None:
        times = as_field("times", times, snaps.shape[0])
    fps = check_positive("fps", fps)
    progress = check_bool("progress", progress)
    ws = _check_window(window_size)
    path = _check_target(filename, overwrite, (".gif", ".mp4"))
    mp4 = path.suffix.lower() == ".mp4"
    if mp4:
        ws = (ws[0] + ws[0] % 2, ws[1] + ws[1] % 2)  # H.264 wants even sizes
        try:
            import imageio_ffmpeg  # noqa: F401
        except ImportError:
            raise ValueError(
                "MP4 output needs the package imageio-ffmpeg (pip install 'manifold-sph[video]'); write a .gif instead"
            ) from None
    lim = color_limits(snaps, clim, robust)
    zoom = check_positive("zoom", zoom)
    spacing = _spacing(pts)
    ps = _point_size(pts, spacing, ws) * zoom if point_size is None else check_positive("point_size", point_size)
    from tqdm import tqdm

    # frames stream to a temporary file beside the target through pyvista's writers (imageio),
    # renamed into place only when complete
    tmp = path.with_name(path.stem + ".partial" + path.suffix.lower())
    try:
        with _quiet_vtk():
            p = _plotter(ws, background=background)
            try:
                actor = _add_cloud(
                    p, pts, snaps[0], None, spacing=spacing, point_size=ps, cmap=cmap, clim=lim, robust=None,
                    bar_title=bar_title, show_scalar_bar=True, vector_scale=None, vector_color="black",
                )
                _title_text(p, title, _font(ws, 12))
                clock = p.add_text(" ", position="lower_left", font_size=_font(ws, 9), color="black") if times is not None else None
                _set_camera(p, pts, camera, zoom, up)
                if mp4:
                    p.open_movie(str(tmp), framerate=fps, codec="libx264", macro_block_size=2, pixelformat="yuv420p")
                else:
                    p.open_gif(str(tmp), fps=fps, loop=0, palettesize=256)
                for k in tqdm(range(snaps.shape[0]), desc=f"frames -> {path.name}", disable=not progress, unit="frame"):
                    data = actor.mapper.dataset
                    data.point_data["field"][:] = np.clip(snaps[k], *lim)
                    data.Modified()
                    if clock is not None:
                        _set_text(clock, f"t = {times[k]:.4g}")
                    p.write_frame()
                writer, p.mwriter = p.mwriter, None
                writer.close()  # here, not in p.close(), which would hide a failed write
            finally:
                p.close()
        if path.exists() and not overwrite:  # appeared meanwhile
            raise FileExistsError(f"{str(path)!r} exists; pass overwrite=True to replace it")
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path
