"""Matplotlib figures of accuracy studies (no display needed; no pyplot state).

- :func:`convergence_plot`: errors against N or h in log-log, one line per
  error and study, the fitted order in the legend (the convergence figures
  of the thesis [1], docs/method.md).
- :func:`error_boxplot`: Tukey boxplots of pointwise errors, one box per scheme
  ([1] Figures 14-34 and 41-49).
- :func:`area_histogram`: histograms of the area elements ``dV`` ([1] Fig. 40).
- :func:`save_figure`: write a figure, refusing to overwrite unless asked.

Every function returns a :class:`matplotlib.figure.Figure` (built without
``pyplot``, so nothing is shown and no global state is kept) and writes it when
given ``filename``.

Examples
--------
>>> import numpy as np
>>> from manifold_sph.reference.errors import convergence_study
>>> t = convergence_study([1000, 4000, 16000], lambda n: {"lap_l2": 5.0 / n, "lap_linf": 9.0 / n})
>>> fig = convergence_plot(t)
>>> [line.get_label() for line in fig.axes[0].get_lines()]
['lap L2 (order 2.00)', 'lap Linf (order 2.00)']
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from .._validation import check_bool, check_in, check_int, check_output_path, check_positive
from ..reference.errors import ConvergenceTable, boxplot_summary

if TYPE_CHECKING:  # matplotlib loads only when a plot is made
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["convergence_plot", "error_boxplot", "area_histogram", "save_figure"]

_MARKERS = "os^Dv<>pPX*h"


def _new_figure(figsize):
    from matplotlib.figure import Figure

    if (
        isinstance(figsize, (str, bytes))
        or not isinstance(figsize, Sequence)
        or len(figsize) != 2
    ):
        raise TypeError(f"figsize must be a pair (width, height) in inches, got {figsize!r}")
    w = check_positive("figsize[0]", figsize[0])
    h = check_positive("figsize[1]", figsize[1])
    return Figure(figsize=(w, h), layout="constrained")


def _axes(ax, figsize):
    if ax is None:
        fig = _new_figure(figsize)
        return fig, fig.add_subplot()
    from matplotlib.axes import Axes

    if not isinstance(ax, Axes):
        raise TypeError(f"ax must be a matplotlib Axes, got {type(ax).__name__}")
    return ax.figure, ax


def save_figure(fig: Figure, filename: str | os.PathLike[str], *, overwrite: bool = False, dpi: int = 100) -> Path:
    """Write a figure to ``filename`` (format from the suffix: .png, .pdf, .svg).

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    filename : str or path
        Its folder must exist.
    overwrite : bool
        Replace an existing file (default False: FileExistsError).
    dpi : int

    Returns
    -------
    pathlib.Path

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> fig = area_histogram(np.full(10, 0.1))
    >>> save_figure(fig, d / "a.png").name
    'a.png'
    >>> save_figure(fig, d / "a.png")
    Traceback (most recent call last):
    ...
    FileExistsError: filename '...a.png' exists; pass overwrite=True to replace it
    """
    overwrite = check_bool("overwrite", overwrite)
    if not isinstance(filename, (str, os.PathLike)):
        raise TypeError(f"filename must be a str or path, got {type(filename).__name__}")
    path = Path(filename)
    check_in("the suffix of filename", path.suffix.lower(), (".png", ".pdf", ".svg"))
    path = check_output_path("filename", path, overwrite)  # the package's one overwrite guard
    fig.savefig(path, dpi=check_int("dpi", dpi, minimum=10))
    return path


def _pretty(name: str) -> str:
    """'lap_l2' -> 'lap L2', 'grad_linf_abs' -> 'grad Linf abs'."""
    parts = name.split("_")
    return " ".join({"l2": "L2", "linf": "Linf", "rel": "rel", "abs": "abs"}.get(p, p) for p in parts)


def convergence_plot(
    tables: ConvergenceTable | Mapping[str, ConvergenceTable],
    *,
    errors: Sequence[str] | None = None,
    x: str = "N",
    reference_order: float | None = None,
    title: str | None = None,
    ylabel: str = "error",
    ax: Axes | None = None,
    figsize: tuple[float, float] = (6.0, 4.5),
    filename: str | os.PathLike[str] | None = None,
    overwrite: bool = False,
) -> Figure:
    """Log-log convergence plot of one or several studies, fitted orders in the legend.

    Parameters
    ----------
    tables : ConvergenceTable or mapping of str -> ConvergenceTable
        From :func:`manifold_sph.reference.errors.convergence_study` or
        :func:`manifold_sph.reference.accuracy.convergence`; a mapping (e.g. scheme ->
        table) puts its key in front of each label.
    errors : sequence of str, optional
        Names of the errors to draw (default all). Names containing ``linf``
        are dashed, the others solid; e.g. ``lap_l2, lap_linf`` (relative) and
        ``lap_l2_abs`` (absolute) if the study recorded them.
    x : {"N", "h"}
        Abscissa: the number of points, or the spacing ``h``. For a study over
        N, ``h = N ** (-1 / dim)`` (up to a constant factor, which does not
        change the slopes); for a study over h, N is ``h ** -dim``.
    reference_order : float, optional
        Draw a grey reference slope ``h ** p`` through the first point of the
        first line.
    title, ylabel : str
    ax : matplotlib Axes, optional
        Draw into it (default: a new figure).
    figsize : (float, float)
    filename, overwrite
        As in :func:`save_figure`.

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> from manifold_sph.reference.errors import convergence_study
    >>> t = convergence_study([0.1, 0.05], lambda h: {"e": h ** 2}, kind="h")
    >>> ax = convergence_plot({"cspm": t}, x="N").axes[0]
    >>> ax.get_xscale(), ax.get_lines()[0].get_label()
    ('log', 'cspm: e (order 2.00)')
    """
    check_in("x", x, ("N", "h"))
    if isinstance(tables, ConvergenceTable):
        studies = {"": tables}
    elif isinstance(tables, Mapping) and tables and all(isinstance(t, ConvergenceTable) for t in tables.values()):
        studies = {str(k): t for k, t in tables.items()}
    else:
        raise TypeError(
            f"tables must be a ConvergenceTable or a non-empty mapping of name -> ConvergenceTable, got {type(tables).__name__}"
        )
    fig, ax = _axes(ax, figsize)
    first: tuple[np.ndarray, np.ndarray, int] | None = None  # the first curve: (x, errors, dim)
    for s, (label, t) in enumerate(studies.items()):
        names = list(t.names) if errors is None else list(errors)
        for name in names:
            if name not in t.errors:
                raise ValueError(f"errors names {name!r}, which the study did not record; it has {list(t.names)!r}")
        sizes = np.asarray(t.sizes, dtype=np.float64)
        if t.kind == "N":
            xs = sizes if x == "N" else sizes ** (-1.0 / t.dim)
        else:
            xs = sizes if x == "h" else sizes ** (-float(t.dim))
        for j, name in enumerate(names):
            order = t.orders[name]
            o = f"order {order:.2f}" if np.isfinite(order) else "no order"
            lab = f"{label + ': ' if label else ''}{_pretty(name)} ({o})"
            style = "--" if "linf" in name.lower() else "-"
            ax.loglog(xs, t.errors[name], style, marker=_MARKERS[(s * len(names) + j) % len(_MARKERS)], label=lab)
            if first is None:
                first = (xs, np.asarray(t.errors[name]), t.dim)
    if reference_order is not None and first is not None:  # first: None when errors=[] (no curve)
        p = float(reference_order)
        xs, es, dim = first
        hs = xs if x == "h" else xs ** (-1.0 / dim)
        ref = es[0] * (hs / hs[0]) ** p
        ax.loglog(xs, ref, ":", color="0.5", label=f"slope h^{p:g}")
    ax.set_xlabel("N (number of points)" if x == "N" else "h (particle spacing, up to a constant)")
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize="small")
    if filename is not None:
        save_figure(fig, filename, overwrite=overwrite)
    return fig


def _samples(name: str, data) -> dict[str, np.ndarray]:
    if isinstance(data, Mapping):
        items = {str(k): v for k, v in data.items()}
    else:
        items = {"": data}
    if not items:
        raise ValueError(f"{name} must hold at least one sample")
    out = {}
    for k, v in items.items():
        try:
            arr = np.asarray(v, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"{name}[{k!r}] must be a 1-D numeric array, got {type(v).__name__}") from exc
        if arr.ndim != 1 or arr.size == 0:
            raise ValueError(f"{name}[{k!r}] must be a non-empty 1-D array, got shape {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name}[{k!r}] must be finite, got {int((~np.isfinite(arr)).sum())} NaN or inf value(s)")
        out[k] = arr
    return out


def error_boxplot(
    errors: ArrayLike | Mapping[str, ArrayLike],
    *,
    log: bool = True,
    title: str | None = None,
    ylabel: str = "pointwise error",
    ax: Axes | None = None,
    figsize: tuple[float, float] = (6.0, 4.5),
    filename: str | os.PathLike[str] | None = None,
    overwrite: bool = False,
) -> Figure:
    """Tukey boxplots of pointwise errors, one box per scheme (or any label).

    Whiskers at the most extreme values within 1.5 IQR of the quartiles,
    outliers drawn as points (the same rule as
    :func:`manifold_sph.reference.errors.boxplot_summary`); the number of outliers is
    written under each label.

    Parameters
    ----------
    errors : mapping of str -> array_like (N,), or array_like (N,)
        Pointwise errors (e.g. ``|lap_sph - lap_exact|``) per scheme.
    log : bool
        Logarithmic error axis (zero errors are clipped to the smallest positive one).
    title, ylabel, ax, figsize, filename, overwrite
        As in :func:`convergence_plot`.

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> fig = error_boxplot({"cspm": rng.random(100), "msph": rng.random(100) / 10})
    >>> [t.get_text() for t in fig.axes[0].get_xticklabels()]
    ['cspm\\n(0 outliers)', 'msph\\n(0 outliers)']
    """
    samples = _samples("errors", errors)
    fig, ax = _axes(ax, figsize)
    data = list(samples.values())
    if log:
        pos = np.concatenate([d[d > 0] for d in data])
        tiny = float(pos.min()) if pos.size else 1e-16
        data = [np.maximum(d, tiny) for d in data]
    labels = [f"{k}\n({boxplot_summary(v).outliers.size} outliers)" for k, v in samples.items()]
    ax.boxplot(data, whis=1.5, flierprops={"marker": ".", "markersize": 3, "alpha": 0.5})
    ax.set_xticks(range(1, len(labels) + 1), labels)
    if log:
        ax.set_yscale("log")
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    ax.grid(True, axis="y", which="both", alpha=0.3)
    if filename is not None:
        save_figure(fig, filename, overwrite=overwrite)
    return fig


def area_histogram(
    dV: ArrayLike | Mapping[str, ArrayLike],
    *,
    bins: int = 50,
    reference: float | None = None,
    title: str | None = None,
    ax: Axes | None = None,
    figsize: tuple[float, float] = (6.0, 4.5),
    filename: str | os.PathLike[str] | None = None,
    overwrite: bool = False,
) -> Figure:
    """Histogram of area elements (one or several sets, overlaid).

    Parameters
    ----------
    dV : array_like (N,) or mapping of str -> array_like (N,)
        Area elements, e.g. ``{"numerical": s.dV, "shepard": t.dV}``.
    bins : int
    reference : float, optional
        A vertical line, e.g. the uniform value ``area / N``.
    title, ax, figsize, filename, overwrite
        As in :func:`convergence_plot`.

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> fig = area_histogram({"a": np.full(50, 0.1), "b": np.linspace(0.05, 0.15, 50)}, reference=0.1)
    >>> [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    ['reference 0.1', 'a (0 negative)', 'b (0 negative)']
    """
    samples = _samples("dV", dV)
    bins = check_int("bins", bins, minimum=1)
    fig, ax = _axes(ax, figsize)
    allv = np.concatenate(list(samples.values()))
    lo, hi = float(allv.min()), float(allv.max())
    if hi <= lo:
        lo, hi = lo - 0.5 * abs(lo) - 1e-12, hi + 0.5 * abs(hi) + 1e-12
    edges = np.linspace(lo, hi, bins + 1)
    if reference is not None:
        ax.axvline(float(reference), color="k", ls=":", label=f"reference {float(reference):.3g}")
    for k, v in samples.items():
        neg = int((v < 0).sum())
        ax.hist(v, bins=edges.tolist(), alpha=0.6, label=f"{k + ' ' if k else ''}({neg} negative)")
    ax.set_xlabel("area element dV")
    ax.set_ylabel("number of particles")
    if title:
        ax.set_title(title)
    ax.legend(fontsize="small")
    if filename is not None:
        save_figure(fig, filename, overwrite=overwrite)
    return fig
