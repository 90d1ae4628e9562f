"""Off-screen pictures of fields on point clouds (PyVista/VTK, no display needed).

Every function renders off-screen (VTK picks an EGL or OSMesa window when
there is no X server), returns the image as a ``(height, width, 3)`` uint8
array (``(height, width, 4)`` with ``transparent=True``) and writes a PNG when
given ``filename``; an existing file is never overwritten unless
``overwrite=True``. The points may be anything point-like
(:func:`manifold_sph.as_cloud`: arrays, clouds, Surfaces, files, Open3D / PyVista /
trimesh objects); planar (N, 2) points lie in z = 0.

The defaults show the field (:mod:`.style`): a robust colour range, a diverging map
centred at 0 for signed fields, the object standing on its up axis, each point drawn as
a disc in its tangent plane sized from its own spacing (so that the surface is closed
and its back side hidden; spheres where there are no normals), NaN and inf values in
a neutral dark grey with a count in the corner, titles that fit.

- :func:`render_field`: a scalar field on the points, optionally with tangent vectors
  as arrow glyphs; :func:`show` the same as a :class:`Picture` (shown in a notebook).
- :func:`render_panels`: side-by-side panels, e.g. function | exact |
  approximation | error (:func:`render_comparison`).
- :func:`animate`: a time series (snapshots of a PDE solver) to GIF or MP4 (the
  ``video`` extra: ``pip install "manifold-sph[video]"``), with an optional progress bar.
- :data:`CAMERAS`: the fixed views ``"iso"``, ``"equator"`` and
  ``"north_pole"`` (the views of the sphere in the thesis [1], docs/method.md).
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

import base64
import contextlib
import io
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import (
    as_field,
    as_points,
    check_bool,
    check_in,
    check_int,
    check_output_path,
    check_positive,
    check_real_array,
)
from .style import NAN_COLOR, color_limits, detect_up_axis, field_colormap, fit_title, splat_radii, up_vector

if TYPE_CHECKING:  # no run-time imports: pyvista and the operator stack load only when used
    from ..pde import Solution

__all__ = [
    "CAMERAS",
    "Picture",
    "animate",
    "color_limits",
    "detect_up_axis",
    "render_comparison",
    "render_field",
    "render_panels",
    "rendering_available",
    "save_png",
    "show",
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


def _geometry(points) -> tuple[np.ndarray, np.ndarray | None]:
    """(N, 3) coordinates and unit normals (or None) of anything point-like.

    Arrays are taken as they are ((N, 2) planar points in z = 0; any number of points,
    repeats allowed); everything else goes through :func:`manifold_sph.as_cloud` (clouds,
    Surfaces, files, other libraries' objects); a Domain2D gives its planar points.
    """
    from ..pointcloud import as_cloud, is_point_array

    normals = None
    if is_point_array(points):
        p = as_points("points", points, dim=(2, 3))
    elif hasattr(points, "cloud") or not hasattr(points, "points"):
        cloud = as_cloud(points)
        p, normals = cloud.points, cloud.normals
    else:  # an operator set on planar points (Domain2D)
        p = as_points("points", points.points, dim=(2, 3))
        normals = getattr(points, "normals", None)
    if p.shape[0] == 0:
        raise ValueError("points must hold at least one point, got shape (0, 3)")
    if p.shape[1] == 2:
        p = np.column_stack([p, np.zeros(len(p))])
        normals = np.tile([0.0, 0.0, 1.0], (len(p), 1))
    if normals is not None:
        normals = np.asarray(normals, dtype=np.float64)
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        normals = normals / np.where(length > 0, length, 1.0) if normals.shape == p.shape else None
    return p, normals


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
    renderer = None
    old_backend: int | None = None
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
        if renderer is not None and old_backend is not None:
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


def _set_camera(plotter, points: np.ndarray, camera, zoom: float = 1.0, up: Any = "auto") -> None:
    """Place the camera: a preset of :data:`CAMERAS` turned so that its z is ``up``, or an
    explicit ``(direction, view_up)`` pair (``up`` then validated and unused)."""
    u = up_vector(points, up)
    if isinstance(camera, str):
        check_in("camera", camera, CAMERAS)
        if camera == "iso" and np.ptp(points @ u) <= 1e-6 * max(float(np.ptp(points, axis=0).max()), 1e-300):
            camera = "top"  # a planar cloud is seen from its normal, not at a slant
        direction, view_up = (np.asarray(v, dtype=np.float64) for v in CAMERAS[camera])
        a = int(np.argmax(np.abs(u)))
        if abs(u[a]) > 1 - 1e-12:  # a coordinate axis: the presets' z swapped with it (and turned over for -a)
            perm = [0, 1, 2]
            perm[a], perm[2] = 2, a
            direction, view_up = direction[perm] * np.sign(u[a]), view_up[perm] * np.sign(u[a])
        else:  # any other direction: the rotation taking z to it
            direction, view_up = _rotate_z_to(u) @ direction, _rotate_z_to(u) @ view_up
    else:
        try:
            direction, view_up = (np.asarray(camera[0], float), np.asarray(camera[1], float))
        except (TypeError, ValueError, IndexError):
            raise TypeError(f"camera must be one of {sorted(CAMERAS)} or a pair (direction, view_up) of 3-vectors, "
                            f"got {camera!r}") from None
        if direction.shape != (3,) or view_up.shape != (3,) or not np.linalg.norm(direction) > 0:
            raise ValueError(f"camera must be a pair (direction, view_up) of non-zero 3-vectors, got {camera!r}")
    centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
    d = direction / np.linalg.norm(direction)
    plotter.camera_position = [tuple(centre + 5.0 * max(np.ptp(points, axis=0).max(), 1e-9) * d), tuple(centre), tuple(view_up)]
    plotter.reset_camera()
    if zoom != 1.0:
        plotter.camera.zoom(zoom)


def _rotate_z_to(u: np.ndarray) -> np.ndarray:
    """The rotation matrix taking (0, 0, 1) to the unit vector ``u`` (Rodrigues)."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, u)
    s, c = np.linalg.norm(axis), float(z @ u)
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    k = axis / s
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + s * K + (1 - c) * K @ K


def _set_text(actor, text: str) -> None:
    """Change the text of an actor from ``Plotter.add_text`` (a text actor or a corner annotation)."""
    if hasattr(actor, "SetInput"):
        actor.SetInput(text)
    else:  # vtkCornerAnnotation: the lower-left corner is slot 0
        actor.SetText(0, text)


def _font(window_size, largest: int) -> int:
    """A font size that fits the window: ``largest`` from 640 pixels wide, smaller below."""
    return int(max(6, min(largest, round(largest * window_size[0] / 640))))


def _title_text(plotter, text, window_size, largest: int = 12):
    """The title at the top, in the largest font (up to ``largest``) that fits the width (two lines if needed)."""
    if text:
        fitted, size = fit_title(str(text), window_size[0], _font(window_size, largest))
        plotter.add_text(fitted, position="upper_edge", font_size=size, color="black")


#: Splats (one disc per point) up to this many points; spheres (point sprites) above.
MAX_SPLATS = 1_500_000
_SPLAT_SIDES = 8
_STYLES = ("auto", "splats", "spheres")


class _Scene:
    """The points of a picture, prepared once: discs in the tangent planes (splats) where the
    normals are known, else spheres of one size from the median spacing."""

    def __init__(self, points, style, point_size, window_size, zoom):
        self.points, self.normals = _geometry(points)
        check_in("style", style, _STYLES)
        n = len(self.points)
        if style == "auto":
            style = "splats" if self.normals is not None and point_size is None and n <= MAX_SPLATS else "spheres"
        if style == "splats" and self.normals is None:
            raise ValueError("style='splats' needs normals: give a PointCloud or Surface with normals, or style='spheres'")
        self.style = style
        self.spacing = _spacing(self.points)
        if point_size is not None:
            self.point_size = check_positive("point_size", point_size)
        else:
            self.point_size = _point_size(self.points, self.spacing, window_size) * zoom
        self.repeat = 1
        if style == "splats":
            self.repeat = _SPLAT_SIDES + 1
            self.radii = splat_radii(self.points)

    def mesh(self):
        """The PolyData drawn: the discs (each point repeated ``self.repeat`` times) or the points."""
        import pyvista as pv

        if self.style != "splats":
            return pv.PolyData(self.points)
        nrm, r = self.normals, self.radii
        assert nrm is not None  # splats need normals (checked in __init__)
        helper = np.where(np.abs(nrm[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        t1 = np.cross(nrm, helper)
        t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
        t2 = np.cross(nrm, t1)
        ang = 2 * np.pi * np.arange(_SPLAT_SIDES) / _SPLAT_SIDES
        rim = (np.cos(ang)[None, :, None] * t1[:, None, :] + np.sin(ang)[None, :, None] * t2[:, None, :]) * r[:, None, None]
        pts = np.concatenate([self.points[:, None, :], self.points[:, None, :] + rim], axis=1).reshape(-1, 3)
        base = (np.arange(len(self.points)) * self.repeat)[:, None]
        k = np.arange(_SPLAT_SIDES)
        tri = np.stack([np.broadcast_to(base, (len(base), _SPLAT_SIDES)), base + 1 + k, base + 1 + (k + 1) % _SPLAT_SIDES], axis=2)
        faces = np.concatenate([np.full(tri.shape[:2] + (1,), 3), tri], axis=2).reshape(-1)
        mesh = pv.PolyData(pts, faces)
        mesh.point_data["Normals"] = np.repeat(nrm, self.repeat, axis=0)
        mesh.point_data.active_normals_name = "Normals"
        return mesh

    def values(self, field):
        return np.repeat(field, self.repeat) if self.repeat > 1 else field


def _field_and_name(field, n: int, bar_title):
    """``field`` as (N,) float64 (NaN and inf allowed: drawn grey), and the colour-bar title: the
    given one, else the name of a one-entry mapping ``{name: values}``, else "value"."""
    if field is None:
        return None, bar_title
    if isinstance(field, Mapping):
        if len(field) != 1:
            raise ValueError(f"field must be an array or a mapping with one entry {{name: values}}, got {len(field)} entries")
        (name, field), = field.items()
        bar_title = bar_title or str(name)
    check_real_array("field", field)
    try:
        f = np.asarray(field, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"field must be a numeric array, got {type(field).__name__}") from exc
    if f.shape != (n,):
        raise ValueError(f"field must have shape ({n},), got shape {f.shape}")
    if not np.isfinite(f).any():
        raise ValueError(f"field must hold at least one finite value, got {n} NaN or inf")
    f = np.where(np.isfinite(f), f, np.nan)
    return f, (bar_title or "value")


def _add_cloud(plotter, scene, field, vectors, *, cmap, lim, bar_title, show_scalar_bar, vector_scale,
               vector_color, window_size, n_labels=5, max_arrows=400):
    """Add the points (coloured by ``field`` between ``lim``) and optional arrows; return the points' actor."""
    import pyvista as pv

    pts, n = scene.points, len(scene.points)
    mesh = scene.mesh()
    common = dict(ambient=0.25, diffuse=0.75, specular=0.1)
    if scene.style != "splats":
        common.update(render_points_as_spheres=True, point_size=scene.point_size)
    if field is None and vectors is not None:
        field = np.linalg.norm(vectors, axis=1)
        bar_title = bar_title or "|v|"
    if field is not None:
        lo, hi = lim
        mesh.point_data["field"] = scene.values(np.clip(field, lo, hi))
        actor = plotter.add_mesh(
            mesh, scalars="field", cmap=field_colormap(lo, hi, cmap), clim=(lo, hi), nan_color=NAN_COLOR,
            show_scalar_bar=show_scalar_bar, **common,
            scalar_bar_args={
                "title": bar_title or "", "color": "black", "n_labels": n_labels, "fmt": "%.3g", "vertical": False,
                "position_x": 0.2, "position_y": 0.03, "width": 0.6, "height": 0.1,
                "title_font_size": _font(window_size, 14), "label_font_size": _font(window_size, 12),
            },
        )
        missing = int(np.isnan(field).sum())
        if missing:
            plotter.add_text(f"{missing} without a value (NaN/inf): dark grey", position="lower_left",
                             font_size=_font(window_size, 9), color="black")
        if show_scalar_bar:
            bar = plotter.scalar_bars[bar_title or ""] if (bar_title or "") in plotter.scalar_bars else None
            if bar is not None:
                bar.SetTextPositionToPrecedeScalarBar()  # labels below the bar, title above
    else:
        actor = plotter.add_mesh(mesh, color="lightgray", **common)
    if vectors is not None:
        mag = np.linalg.norm(vectors, axis=1)
        vmax = float(mag.max())
        if vmax > 0:
            keep = mag > 1e-3 * vmax
            if keep.sum() > max_arrows:  # a spread-out subset, deterministic
                idx = np.flatnonzero(keep)
                keep = np.zeros(n, dtype=bool)
                keep[np.random.default_rng(0).choice(idx, max_arrows, replace=False)] = True
            arrow_spacing = scene.spacing * np.sqrt(n / max(int(keep.sum()), 1))
            factor = (vector_scale if vector_scale is not None else 0.9 * arrow_spacing) / vmax
            lift = 0.6 * scene.spacing if scene.style != "splats" else 0.15 * scene.spacing
            base = pts[keep] + (0.0 if scene.normals is None else lift * scene.normals[keep])
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


def _vectors(vectors, n):
    if vectors is None:
        return None
    v = np.asarray(vectors, dtype=np.float64)
    if v.ndim == 2 and v.shape == (n, 2):
        v = np.column_stack([v, np.zeros(n)])
    return as_field("vectors", v, n, 3)


# --- public renderers -----------------------------------------------------------------


def render_field(
    points: Any,
    field: ArrayLike | Mapping[str, ArrayLike] | None = None,
    *,
    vectors: ArrayLike | None = None,
    title: str | None = None,
    bar_title: str | None = None,
    cmap: Any = "auto",
    clim: tuple[float, float] | None = None,
    robust: float | bool | None = True,
    camera: str | tuple[ArrayLike, ArrayLike] = "iso",
    up: Any = "auto",
    zoom: float = 1.0,
    window_size: tuple[int, int] = (800, 600),
    style: str = "auto",
    point_size: float | None = None,
    vector_scale: float | None = None,
    vector_color: str = "black",
    show_scalar_bar: bool = True,
    background: str = "white",
    transparent: bool = False,
    filename: str | os.PathLike[str] | None = None,
    overwrite: bool = False,
) -> np.ndarray:
    """Render a scalar field on a point cloud, off-screen.

    Parameters
    ----------
    points : point-like
        An array (N, 3) or (N, 2) (planar, drawn in z = 0), a PointCloud, Surface,
        Domain2D, a file, or an Open3D / PyVista / trimesh object
        (:func:`manifold_sph.as_cloud`).
    field : array_like, shape (N,), or {name: array}, optional
        Colours of the points (a one-entry mapping also names the colour bar). NaN and
        inf (e.g. particles a geodesic did not reach) are drawn in dark grey, counted
        in the lower-left corner. Without a field the points are grey, or coloured by
        the length of ``vectors``.
    vectors : array_like, shape (N, 3) or (N, 2), optional
        Drawn as arrows (e.g. a tangential gradient), longest arrow
        ``vector_scale`` long (default 2.5 particle spacings).
    title : str, optional
        Text at the top, in the largest font that fits (two lines if needed).
    bar_title : str, optional
        Title of the colour bar (default: the name of a mapping ``field``, else "value").
    cmap : "auto", str or matplotlib colour map
        "auto": a diverging map (coolwarm) centred at 0, each sign on its own scale, for a
        signed range (``low < 0 < high``), viridis otherwise.
    clim : (float, float), optional
        Explicit colour limits; values outside are clipped to the end colours.
    robust : bool or float
        ``True`` (default): the 2-98 % range, narrowed to 2 robust standard deviations
        around the median for heavy tails; a number: that percentage clipped at each
        end; ``False``: the full range (:func:`~manifold_sph.viz.style.color_limits`).
    camera : str or (direction, view_up)
        A key of :data:`CAMERAS` (``"iso"``, ``"equator"``, ``"north_pole"``, ...)
        or a pair of 3-vectors (direction from the centre to the camera, up).
        The presets are written for z up and turned to the ``up`` axis; a planar cloud
        is seen from its normal with "iso" (the default).
    up : "auto", "x", "y", "z", "-x", "-y", "-z" or a 3-vector
        The axis that points up in the camera presets. ``"auto"`` (default): the
        axis the object stands on (:func:`~manifold_sph.viz.style.detect_up_axis`).
        Ignored (but validated) for an explicit ``(direction, view_up)`` pair.
    zoom : float
        Camera zoom after fitting the cloud in the view.
    window_size : (int, int)
        ``(width, height)`` in pixels of the image.
    style : {"auto", "splats", "spheres"}
        "splats": each point a disc in its tangent plane, its radius from its own
        spacing (the surface looks closed, its back side hidden; needs normals);
        "spheres": round points of one size. "auto": splats where the normals are
        known (a PointCloud with normals, a Surface) and ``point_size`` is not given.
    point_size : float, optional
        Sphere diameter in pixels (default: from the particle spacing); implies spheres.
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
    >>> img = render_field(cloud, {"z": cloud.points[:, 2]}, window_size=(120, 100))  # doctest: +SKIP
    >>> img.shape  # doctest: +SKIP
    (100, 120, 3)
    """
    ws = _check_window(window_size)
    if filename is not None:
        _check_target(filename, overwrite, (".png",))
    zoom = check_positive("zoom", zoom)
    scene = _Scene(points, style, point_size, ws, zoom)
    n = len(scene.points)
    fld, bar_title = _field_and_name(field, n, bar_title)
    vec = _vectors(vectors, n)
    if vec is not None and point_size is None:
        scene.point_size *= 0.8  # smaller spheres, so that the arrows lying on the surface show
    transparent = check_bool("transparent", transparent)
    show_bar = check_bool("show_scalar_bar", show_scalar_bar)
    shown = fld if fld is not None else (None if vec is None else np.linalg.norm(vec, axis=1))
    lim = color_limits(shown, clim, robust) if shown is not None else None
    up_vector(scene.points, up)  # validated before any rendering
    with _quiet_vtk():
        p = _plotter(ws, background=background)
        try:
            _add_cloud(p, scene, fld, vec, cmap=cmap, lim=lim, bar_title=bar_title, show_scalar_bar=show_bar,
                       vector_scale=vector_scale, vector_color=vector_color, window_size=ws)
            _title_text(p, title, ws)
            _set_camera(p, scene.points, camera, zoom, up)
            return _finish(p, transparent, filename, overwrite)
        finally:
            p.close()


class Picture:
    """A rendered image that shows itself in a notebook (``_repr_png_``).

    Attributes
    ----------
    image : numpy.ndarray, shape (H, W, 3) or (H, W, 4), uint8
    """

    def __init__(self, image: np.ndarray) -> None:
        self.image = np.asarray(image, dtype=np.uint8)

    def _repr_png_(self) -> bytes:
        from PIL import Image

        buf = io.BytesIO()
        Image.fromarray(self.image).save(buf, format="PNG")
        return buf.getvalue()

    def _repr_html_(self) -> str:
        data = base64.b64encode(self._repr_png_()).decode("ascii")
        return f'<img src="data:image/png;base64,{data}" width="{self.image.shape[1]}"/>'

    def save(self, filename: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
        """Write the PNG file (never over an existing file unless ``overwrite``)."""
        return save_png(self.image, filename, overwrite=overwrite)

    def __array__(self, dtype: Any = None, copy: bool | None = None) -> np.ndarray:
        return self.image if dtype is None else self.image.astype(dtype)

    @property
    def shape(self) -> tuple[int, ...]:
        return self.image.shape

    def __repr__(self) -> str:
        return f"Picture({self.image.shape[1]}x{self.image.shape[0]})"


def show(points: Any, field: ArrayLike | Mapping[str, ArrayLike] | None = None, **options: Any) -> Picture:
    """:func:`render_field` as a :class:`Picture`: shown when it is the value of a notebook cell.

    ``window_size`` defaults to (640, 480) here. Also ``PointCloud.show(field)`` and
    ``Surface.show(field)``.

    Examples
    --------
    >>> from manifold_sph.reference import shapes
    >>> cloud = shapes.sphere(400)
    >>> show(cloud, {"z": cloud.points[:, 2]})  # doctest: +SKIP
    Picture(640x480)
    """
    options.setdefault("window_size", (640, 480))
    return Picture(render_field(points, field, **options))


def render_panels(
    points: Any,
    fields: Mapping[str, ArrayLike],
    *,
    vectors: Mapping[str, ArrayLike] | None = None,
    shared_clim: bool | Sequence[str] = False,
    cmap: Any = "auto",
    clim: tuple[float, float] | None = None,
    robust: float | bool | None = True,
    camera: str | tuple[ArrayLike, ArrayLike] = "iso",
    up: Any = "auto",
    zoom: float = 1.0,
    panel_size: tuple[int, int] = (400, 400),
    style: str = "auto",
    point_size: float | None = None,
    background: str = "white",
    transparent: bool = False,
    filename: str | os.PathLike[str] | None = None,
    overwrite: bool = False,
) -> np.ndarray:
    """Side-by-side panels of several scalar fields on the same points.

    Parameters
    ----------
    points : point-like
        As in :func:`render_field`.
    fields : mapping of str -> array_like (N,)
        Panel title -> field, left to right.
    vectors : mapping of str -> array_like (N, 3), optional
        Arrows to draw in the panels with those titles.
    shared_clim : bool or sequence of str
        ``True``: one colour range for all panels; a sequence of titles: one
        range shared by those panels (e.g. exact and approximation), the others
        their own.
    cmap : "auto", str, colour map, or mapping of str -> str
        One colour map, or one per panel title ("auto" for the others).
    clim, robust
        As in :func:`render_field` (applied to every panel or to the shared group).
    camera, up, zoom, style, point_size, background, transparent, filename, overwrite
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
    ws = _check_window((w * len(fields), h))
    if filename is not None:
        _check_target(filename, overwrite, (".png",))
    zoom = check_positive("zoom", zoom)
    scene = _Scene(points, style, point_size, (w, h), zoom)
    n = len(scene.points)
    titles = [str(t) for t in fields]
    flds = {t: _field_and_name(fields[k], n, "")[0] for t, k in zip(titles, fields)}
    vecs = {}
    for t, v in (vectors or {}).items():
        if str(t) not in flds:
            raise ValueError(f"vectors has key {t!r} which is not a panel title; titles are {titles!r}")
        vecs[str(t)] = _vectors(v, n)
    if isinstance(shared_clim, (bool, np.bool_)):
        group = titles if shared_clim else []
    else:
        group = [str(t) for t in shared_clim]
        for t in group:
            if t not in flds:
                raise ValueError(f"shared_clim names {t!r}, which is not a panel title; titles are {titles!r}")
    group_lim = color_limits(np.concatenate([flds[t] for t in group]), clim, robust) if group else None
    transparent = check_bool("transparent", transparent)
    up_vector(scene.points, up)
    with _quiet_vtk():
        p = _plotter(ws, shape=(1, len(titles)), background=background)
        try:
            for i, t in enumerate(titles):
                p.subplot(0, i)
                lim = group_lim if t in group else color_limits(flds[t], clim, robust)
                cm = cmap.get(t, "auto") if isinstance(cmap, Mapping) else cmap
                # VTK shares a colour bar between meshes with the same bar title: keep them unique.
                _add_cloud(p, scene, flds[t], vecs.get(t), cmap=cm, lim=lim, bar_title=" " * (i + 1),
                           show_scalar_bar=True, vector_scale=None, vector_color="black", window_size=(w, h), n_labels=3)
                _title_text(p, t, (w, h), 11)
                _set_camera(p, scene.points, camera, zoom, up)
            return _finish(p, transparent, filename, overwrite)
        finally:
            p.close()


def render_comparison(
    points: Any,
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
    points : point-like
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
    n = len(_geometry(points)[0])
    exact = as_field("exact", exact, n)
    approx = as_field("approx", approx, n)
    fields = {names[0]: as_field("f", f, n), names[1]: exact, names[2]: approx, names[3]: np.abs(approx - exact)}
    kwargs.setdefault("shared_clim", [names[1], names[2]])
    kwargs.setdefault("cmap", {names[3]: "magma"})
    return render_panels(points, fields, **kwargs)


def animate(
    points: Any,
    snapshots: ArrayLike | Solution,
    filename: str | os.PathLike[str],
    *,
    times: ArrayLike | None = None,
    fps: float = 10.0,
    title: str | None = None,
    bar_title: str | None = None,
    cmap: Any = "auto",
    clim: tuple[float, float] | None = None,
    robust: float | bool | None = True,
    camera: str | tuple[ArrayLike, ArrayLike] = "iso",
    up: Any = "auto",
    zoom: float = 1.0,
    window_size: tuple[int, int] = (480, 400),
    style: str = "auto",
    point_size: float | None = None,
    background: str = "white",
    progress: bool = False,
    overwrite: bool = False,
) -> Path:
    """Write a time series of scalar fields to an animated GIF or an MP4 video.

    One colour range for all frames (``clim``, or the robust range of all the
    snapshots), so that decay and propagation are visible. GIFs are written with Pillow
    (installed with matplotlib); MP4 needs ``imageio`` and ``imageio-ffmpeg``: the ``video``
    extra, ``pip install "manifold-sph[video]"``.

    Parameters
    ----------
    points : point-like
        As in :func:`render_field`.
    snapshots : array_like, shape (S, N), or an object with ``.snapshots`` (and ``.times``)
        E.g. the :class:`~manifold_sph.pde.Solution` of :func:`manifold_sph.pde.heat` or :func:`~manifold_sph.pde.wave`.
    filename : str or path
        ``.gif`` (Pillow, 256-colour palette per frame) or ``.mp4`` (H.264 through
        pyvista's ``open_movie``, the ``video`` extra).
    times : array_like, shape (S,), optional
        Shown in a corner as ``t = ...`` (default: ``snapshots.times`` if present).
    fps : float
        Frames per second.
    progress : bool
        Show a tqdm progress bar on stderr (default False: library calls are quiet).
    title, bar_title, cmap, clim, robust, camera, up, zoom, window_size, style, point_size, background, overwrite
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
    ws = _check_window(window_size)
    zoom = check_positive("zoom", zoom)
    scene = _Scene(points, style, point_size, ws, zoom)
    n = len(scene.points)
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
    path = _check_target(filename, overwrite, (".gif", ".mp4"))
    mp4 = path.suffix.lower() == ".mp4"
    _check_video(mp4)
    if mp4:
        ws = (ws[0] + ws[0] % 2, ws[1] + ws[1] % 2)  # H.264 wants even sizes
    lim = color_limits(snaps, clim, robust)
    up_vector(scene.points, up)
    from tqdm import tqdm

    # frames go to a temporary file beside the target (MP4 streamed through pyvista's
    # writer, GIF frames gathered and written by Pillow), renamed into place only when complete
    tmp = path.with_name(path.stem + ".partial" + path.suffix.lower())
    try:
        with _quiet_vtk():
            p = _plotter(ws, background=background)
            try:
                actor = _add_cloud(p, scene, snaps[0], None, cmap=cmap, lim=lim, bar_title=bar_title or "value",
                                   show_scalar_bar=True, vector_scale=None, vector_color="black", window_size=ws)
                _title_text(p, title, ws)
                clock = p.add_text(" ", position="lower_left", font_size=_font(ws, 9), color="black") if times is not None else None
                _set_camera(p, scene.points, camera, zoom, up)
                if mp4:
                    p.open_movie(str(tmp), framerate=fps, codec="libx264", macro_block_size=2, pixelformat="yuv420p")
                else:
                    p.show(auto_close=False, interactive=False)
                frames = []
                for k in tqdm(range(snaps.shape[0]), desc=f"frames -> {path.name}", disable=not progress, unit="frame"):
                    data = actor.mapper.dataset
                    data.point_data["field"][:] = scene.values(np.clip(snaps[k], *lim))
                    data.Modified()
                    if clock is not None and times is not None:  # a clock is shown with times only
                        _set_text(clock, f"t = {times[k]:.4g}")
                    if mp4:
                        p.write_frame()
                    else:
                        p.render()
                        frames.append(p.screenshot(return_img=True))
                if mp4:
                    writer, p.mwriter = p.mwriter, None
                    writer.close()  # here, not in p.close(), which would hide a failed write
            finally:
                p.close()
        if not mp4:
            _write_gif(tmp, frames, fps)
        if path.exists() and not overwrite:  # appeared meanwhile
            raise FileExistsError(f"{str(path)!r} exists; pass overwrite=True to replace it")
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


def _write_gif(path: Path, frames: list, fps: float) -> None:
    """Frames (H, W, 3) uint8 -> a looping GIF with Pillow, one adaptive palette per frame."""
    from PIL import Image

    images = [Image.fromarray(np.ascontiguousarray(f[..., :3])).quantize(colors=256, method=Image.Quantize.MEDIANCUT)
              for f in frames]
    images[0].save(path, format="GIF", save_all=True, append_images=images[1:], duration=max(1, round(1000 / fps)),
                   loop=0, disposal=1, optimize=False)


def _check_video(mp4: bool) -> None:
    """A clear error when the MP4 writers (the ``video`` extra) are not installed."""
    if not mp4:
        return
    try:
        import imageio  # noqa: F401
    except ImportError:
        raise ImportError(
            "MP4 output needs imageio: install manifold-sph[video] (pip install 'manifold-sph[video]'), or write a .gif"
        ) from None
    try:
        import imageio_ffmpeg  # noqa: F401
    except ImportError:
        raise ImportError(
            "MP4 output needs imageio-ffmpeg: install manifold-sph[video] (pip install 'manifold-sph[video]'), "
            "or write a .gif"
        ) from None
