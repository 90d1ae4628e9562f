"""Matplotlib figures: what is drawn matches the data (orders, boxplot statistics, histogram counts)."""

from __future__ import annotations

import numpy as np
import pytest

from manifold_sph.reference.errors import boxplot_summary, convergence_study
from manifold_sph.viz.plots import area_histogram, convergence_plot, error_boxplot, save_figure


@pytest.fixture()
def table():
    sizes = [1000, 4000, 16000, 64000]
    return convergence_study(
        sizes,
        lambda n: {"lap_l2": 3.0 / n, "lap_linf": 20.0 / n**0.75, "lap_l2_abs": 7.0 / n},
    )


def test_convergence_plot_orders_in_legend_and_log_axes(table):
    fig = convergence_plot(table, errors=["lap_l2", "lap_linf"])
    ax = fig.axes[0]
    assert ax.get_xscale() == ax.get_yscale() == "log"
    labels = [line.get_label() for line in ax.get_lines()]
    assert labels == ["lap L2 (order 2.00)", "lap Linf (order 1.50)"]
    styles = [line.get_linestyle() for line in ax.get_lines()]
    assert styles == ["-", "--"]  # L2 solid, Linf dashed
    x, y = ax.get_lines()[0].get_data()
    assert np.allclose(x, table.sizes) and np.allclose(y, table.errors["lap_l2"])


def test_convergence_plot_against_h_and_several_studies(table):
    fig = convergence_plot({"cspm": table, "msph": table}, x="h", errors=["lap_l2_abs"], reference_order=2)
    ax = fig.axes[0]
    lines = ax.get_lines()
    assert [ln.get_label() for ln in lines] == ["cspm: lap L2 abs (order 2.00)", "msph: lap L2 abs (order 2.00)", "slope h^2"]
    x, y = lines[0].get_data()
    assert np.allclose(x, np.asarray(table.sizes) ** -0.5)
    # error ~ h^2 on log axes: the slope of the drawn line is 2, like the reference
    slope = np.polyfit(np.log(x), np.log(y), 1)[0]
    ref_slope = np.polyfit(*np.log(lines[2].get_data()), 1)[0]
    assert slope == pytest.approx(2.0, abs=1e-9) and ref_slope == pytest.approx(2.0, abs=1e-9)
    assert ax.get_xlabel().startswith("h")


def test_convergence_plot_bad_input(table):
    with pytest.raises(ValueError, match=r"errors names 'grad_l2', which the study did not record; it has \['lap_l2'"):
        convergence_plot(table, errors=["grad_l2"])
    with pytest.raises(TypeError, match="tables must be a ConvergenceTable or a non-empty mapping"):
        convergence_plot([table])
    with pytest.raises(ValueError, match="x must be one of"):
        convergence_plot(table, x="n")


def test_error_boxplot_matches_tukey_summary():
    rng = np.random.default_rng(3)
    a = rng.lognormal(size=400)
    a[:5] = 1e3  # outliers
    b = rng.random(300)
    fig = error_boxplot({"standard": a, "cspm": b})
    ax = fig.axes[0]
    labels = [t.get_text() for t in ax.get_xticklabels()]
    ns = boxplot_summary(a).outliers.size
    assert ns >= 5 and labels == [f"standard\n({ns} outliers)", f"cspm\n({boxplot_summary(b).outliers.size} outliers)"]
    assert ax.get_yscale() == "log"
    # the median line of the first box is at the sample median
    medians = [ln for ln in ax.get_lines() if len(ln.get_ydata()) == 2 and ln.get_ydata()[0] == ln.get_ydata()[1]]
    assert any(np.isclose(ln.get_ydata()[0], np.median(a)) for ln in medians)


def test_error_boxplot_zero_errors_on_log_axis():
    fig = error_boxplot({"exact": np.array([0.0, 1e-3, 2e-3, 3e-3])})
    ax = fig.axes[0]
    assert ax.get_ylim()[0] > 0  # zeros clipped to the smallest positive error


def test_area_histogram_counts_and_negative():
    rng = np.random.default_rng(0)
    dv = rng.normal(1e-3, 2e-4, size=500)
    dv[:3] = -1e-4
    fig = area_histogram({"numerical": dv}, bins=20, reference=1e-3)
    ax = fig.axes[0]
    heights = [p.get_height() for p in ax.patches]
    assert len(heights) == 20 and sum(heights) == 500
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert texts == ["reference 0.001", "numerical (3 negative)"]


def test_bad_samples_and_saving(tmp_path):
    with pytest.raises(ValueError, match=r"errors\['a'\] must be finite, got 1 NaN"):
        error_boxplot({"a": [1.0, np.nan]})
    with pytest.raises(ValueError, match=r"dV\[''\] must be a non-empty 1-D array, got shape \(2, 2\)"):
        area_histogram(np.ones((2, 2)))
    with pytest.raises(ValueError, match="bins must be at least 1, got 0"):
        area_histogram(np.ones(3), bins=0)
    fig = area_histogram(np.linspace(0, 1, 10))
    path = save_figure(fig, tmp_path / "h.png")
    assert path.stat().st_size > 1000
    with pytest.raises(FileExistsError, match="h.png' exists; pass overwrite=True"):
        area_histogram(np.linspace(0, 1, 10), filename=path)
    save_figure(fig, path, overwrite=True)
    with pytest.raises(ValueError, match="the suffix of filename must be one of"):
        save_figure(fig, tmp_path / "h.jpg")
    with pytest.raises(TypeError, match="ax must be a matplotlib Axes, got str"):
        area_histogram(np.ones(3), ax="left")
