"""Tests of manifold_sph.reference.errors: pointwise/global measures, boxplot, convergence orders."""

import json
import math

import numpy as np
import pytest

from manifold_sph.reference.errors import (
    BoxplotSummary,
    ConvergenceTable,
    absolute_error,
    boxplot_summary,
    convergence_study,
    error_summary,
    fit_order,
    l2_error,
    linf_error,
    phase_error,
    relative_error,
)

# --- pointwise ----------------------------------------------------------------------


def test_absolute_error_scalar_and_vector_exact_values():
    np.testing.assert_array_equal(absolute_error([1.0, -2.0, 3.0], [1.5, 2.0, 3.0]), [0.5, 4.0, 0.0])
    a = np.array([[3.0, 4.0, 0.0], [1.0, 1.0, 1.0]])
    e = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 3.0]])
    np.testing.assert_array_equal(absolute_error(a, e), [5.0, 2.0])
    out = absolute_error(a, e)
    assert out.dtype == np.float64 and out.shape == (2,)


def test_relative_error_exact_values():
    np.testing.assert_allclose(relative_error([1.1, 2.0, -4.4], [1.0, -2.0, -4.0]), [0.1, 2.0, 0.1], rtol=1e-13)
    a = np.array([[3.0, 4.0], [0.0, 2.0]])
    e = np.array([[0.0, 0.0], [0.0, 1.0]])
    # first point: |exact| = 0 < floor -> 5 / 1e-6
    np.testing.assert_allclose(relative_error(a, e), [5e6, 1.0], rtol=1e-13)


def test_relative_error_floor_behaviour():
    exact = np.array([0.0, 1e-8, 1e-6, 1e-3])
    approx = exact + 1e-9
    r = relative_error(approx, exact)  # floor 1e-6
    np.testing.assert_allclose(r, [1e-3, 1e-3, 1e-3, 1e-6], rtol=1e-9)
    r2 = relative_error(approx, exact, floor=1e-2)
    np.testing.assert_allclose(r2, 1e-9 / 1e-2, rtol=1e-9)
    # above the floor the floor has no effect
    np.testing.assert_allclose(relative_error([2.0], [1.0], floor=0.5), [1.0], rtol=1e-15)


@pytest.mark.parametrize("theta", [0.0, 1e-9, 1e-4, 0.3, math.pi / 2, 2.5, math.pi - 1e-7, math.pi])
def test_phase_error_equals_rotation_angle_2d(theta):
    rng = np.random.default_rng(0)
    v = rng.normal(size=(50, 2))
    c, s = math.cos(theta), math.sin(theta)
    rot = np.array([[c, -s], [s, c]])
    scale = rng.uniform(0.1, 10, size=(50, 1))  # the angle ignores lengths
    ang = phase_error(scale * v @ rot.T, v)
    # the 2 atan2 form is accurate to ~1e-15 absolute even for tiny angles
    np.testing.assert_allclose(ang, theta, atol=2e-15 * max(1.0, theta))


def test_phase_error_3d_rotation_about_axis():
    rng = np.random.default_rng(1)
    theta = 0.7
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    # vectors orthogonal to the axis rotate by exactly theta
    v = np.cross(axis, rng.normal(size=(20, 3)))
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    Rm = np.eye(3) + math.sin(theta) * K + (1 - math.cos(theta)) * K @ K
    np.testing.assert_allclose(phase_error(v @ Rm.T, v), theta, atol=1e-14)


def test_phase_error_degenerate_rule_is_nan_free():
    a = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 0.0], [1e-13, 0.0], [-1.0, 0.0]])
    e = np.array([[0.0, 0.0], [0.0, 0.0], [0.0, 3.0], [1.0, 0.0], [2.0, 0.0]])
    with np.errstate(all="raise"):
        ang = phase_error(a, e)
    np.testing.assert_array_equal(ang, [0.0, math.pi / 2, math.pi / 2, math.pi / 2, math.pi])
    # with a smaller floor the 1e-13 vector counts as a direction
    assert phase_error(a[3:4], e[3:4], floor=1e-15)[0] == 0.0


def test_phase_error_needs_vectors():
    with pytest.raises(ValueError, match=r"vector fields of shape \(N, d\), got shape \(3,\)"):
        phase_error([1.0, 2.0, 3.0], [1.0, 2.0, 3.0])


# --- global -----------------------------------------------------------------------


def test_l2_and_linf_exact_values():
    a = np.array([1.0, 3.0, 5.0])
    e = np.array([0.0, 4.0, 5.0])
    # diff = (1, -1, 0); |e|_2 = sqrt(41)
    assert l2_error(a, e) == pytest.approx(math.sqrt(2) / math.sqrt(41), rel=1e-15)
    assert l2_error(a, e, relative=False) == pytest.approx(math.sqrt(2 / 3), rel=1e-15)
    assert linf_error(a, e) == pytest.approx(1 / 5, rel=1e-15)
    assert linf_error(a, e, relative=False) == 1.0


def test_l2_linf_vector_fields():
    a = np.array([[3.0, 4.0], [1.0, 1.0]])
    e = np.array([[0.0, 0.0], [1.0, 2.0]])
    # pointwise errors (5, 1); |e| per point (0, sqrt5)
    assert l2_error(a, e) == pytest.approx(math.sqrt(26) / math.sqrt(5), rel=1e-15)
    assert l2_error(a, e, relative=False) == pytest.approx(math.sqrt(13), rel=1e-15)
    assert linf_error(a, e) == pytest.approx(5 / math.sqrt(5), rel=1e-15)
    assert linf_error(a, e, relative=False) == pytest.approx(5.0, rel=1e-15)


def test_zero_exact_relative_undefined():
    with pytest.raises(ValueError, match="relative L2 error is undefined: exact is identically zero"):
        l2_error([1.0, 2.0], [0.0, 0.0])
    with pytest.raises(ValueError, match="relative Linf error is undefined"):
        linf_error([1.0, 2.0], [0.0, 0.0])
    assert l2_error([1.0, 2.0], [0.0, 0.0], relative=False) == pytest.approx(math.sqrt(2.5))


def test_relative_flag_must_be_bool():
    with pytest.raises(TypeError, match="relative must be True or False, got str 'yes'"):
        l2_error([1.0], [1.0], relative="yes")


def test_error_summary_values_and_mask():
    a = np.array([1.0, 3.0, 9.0, 2.0])
    e = np.array([0.0, 4.0, 1.0, 2.0])
    s = error_summary(a, e)
    assert set(s) == {"l2_rel", "linf_rel", "l2_abs", "linf_abs", "argmax", "n"}
    assert s["n"] == 4 and s["argmax"] == 2
    assert s["linf_abs"] == 8.0
    assert s["l2_rel"] == pytest.approx(l2_error(a, e), rel=1e-15)
    assert s["linf_rel"] == pytest.approx(8.0 / 4.0, rel=1e-15)
    assert s["l2_abs"] == pytest.approx(math.sqrt(66 / 4), rel=1e-15)
    json.dumps(s)
    # mask out the worst point: argmax indexes the full array
    m = np.array([True, True, False, True])
    sm = error_summary(a, e, mask=m)
    assert sm["n"] == 3 and sm["argmax"] == 0 and sm["linf_abs"] == 1.0
    assert sm["linf_rel"] == pytest.approx(1.0 / 4.0)
    # index masks give the same
    assert error_summary(a, e, mask=[0, 1, 3]) == sm


def test_error_summary_bad_mask():
    a = np.ones(4)
    with pytest.raises(ValueError, match=r"mask must be a boolean array of shape \(4,\) .* got shape \(3,\)"):
        error_summary(a, a, mask=np.array([True, False, True]))
    with pytest.raises(ValueError, match="mask selects no points"):
        error_summary(a, a, mask=np.zeros(4, dtype=bool))
    with pytest.raises(ValueError, match=r"mask indices must lie in \[-4, 4\), got range \[0, 7\]"):
        error_summary(a, a, mask=[0, 7])
    with pytest.raises(TypeError, match="mask must be a boolean array .* or a 1-D array of integer indices"):
        error_summary(a, a, mask=[0.5, 1.0])


@pytest.mark.parametrize("func", [absolute_error, relative_error, l2_error, linf_error, error_summary])
def test_shape_mismatch_names_both_shapes(func):
    with pytest.raises(ValueError, match=r"approx and exact must have the same shape, got approx shape \(3,\) and exact shape \(3, 2\)"):
        func(np.ones(3), np.ones((3, 2)))


@pytest.mark.parametrize("func", [absolute_error, relative_error, phase_error, l2_error, linf_error, error_summary])
def test_nan_inf_rejected(func):
    good = np.ones((3, 2))
    bad = good.copy()
    bad[1, 0] = np.nan
    with pytest.raises(ValueError, match=r"approx must be finite, .* 1 NaN or inf value\(s\) \(first at index \(1, 0\)\)"):
        func(bad, good)
    bad[1, 0] = np.inf
    with pytest.raises(ValueError, match=r"exact must be finite"):
        func(good, bad)


def test_other_bad_inputs():
    with pytest.raises(ValueError, match=r"must have shape \(N,\) or \(N, d\), got shape \(2, 2, 2\)"):
        absolute_error(np.ones((2, 2, 2)), np.ones((2, 2, 2)))
    with pytest.raises(ValueError, match="at least one point, got N = 0"):
        l2_error([], [])
    with pytest.raises(ValueError, match="floor must be a finite positive number, got 0.0"):
        relative_error([1.0], [1.0], floor=0.0)
    with pytest.raises(TypeError, match="approx must be a numeric array"):
        absolute_error(["a", "b"], [1.0, 2.0])


# --- boxplot ------------------------------------------------------------------------


def test_boxplot_planted_outlier():
    rng = np.random.default_rng(5)
    x = rng.uniform(0.0, 1.0, 200)
    x[37] = 50.0
    x[101] = -40.0
    b = boxplot_summary(x)
    assert isinstance(b, BoxplotSummary)
    assert b.outliers.tolist() == [37, 101]
    assert b.n == 200
    q1, med, q3 = np.percentile(x, [25, 50, 75])
    assert (b.q1, b.median, b.q3) == (q1, med, q3)
    assert b.iqr == pytest.approx(q3 - q1, rel=1e-15)
    rest = np.delete(x, [37, 101])
    assert b.whisker_low == rest.min() and b.whisker_high == rest.max()
    assert b.whisker_high <= q3 + 1.5 * b.iqr and b.whisker_low >= q1 - 1.5 * b.iqr
    assert json.loads(json.dumps(b.to_dict(json=True)))["outliers"] == [37, 101]


def test_boxplot_exact_small_sample():
    # 1..8: q1 = 2.75, q3 = 6.25 (linear interpolation), fences -2.5 and 11.5
    x = np.array([1, 2, 3, 4, 5, 6, 7, 8, 11.5, 11.6])
    b = boxplot_summary(x)
    q1, q3 = np.percentile(x, [25, 75])
    hi = q3 + 1.5 * (q3 - q1)
    assert b.outliers.tolist() == [int(i) for i in np.flatnonzero(x > hi)]
    b2 = boxplot_summary([1.0, 2.0, 3.0, 4.0, 100.0])
    assert (b2.q1, b2.median, b2.q3, b2.iqr) == (2.0, 3.0, 4.0, 2.0)
    assert (b2.whisker_low, b2.whisker_high) == (1.0, 4.0)
    assert b2.outliers.tolist() == [4]
    # constant sample: iqr 0, nothing is an outlier
    b3 = boxplot_summary(np.full(5, 0.3))
    assert b3.iqr == 0.0 and b3.outliers.size == 0 and b3.whisker_low == b3.whisker_high == 0.3


def test_boxplot_bad_input():
    with pytest.raises(ValueError, match=r"errors must be a non-empty 1-D array of shape \(N,\), got shape \(0,\)"):
        boxplot_summary([])
    with pytest.raises(ValueError, match=r"got shape \(2, 2\)"):
        boxplot_summary(np.ones((2, 2)))
    with pytest.raises(ValueError, match="errors must be finite"):
        boxplot_summary([1.0, np.nan])


# --- fit_order ----------------------------------------------------------------------


@pytest.mark.parametrize("p", [1.0, 2.0, 3.5])
@pytest.mark.parametrize("dim", [1, 2, 3])
def test_fit_order_recovers_known_order_from_N(p, dim):
    N = np.array([100, 300, 1000, 3000, 10000])
    e = 0.7 * N ** (-p / dim)  # e = C h^p with h ~ N^(-1/dim)
    assert fit_order(N, e, kind="N", dim=dim) == pytest.approx(p, abs=1e-12)


def test_fit_order_recovers_known_order_from_h():
    h = np.array([0.2, 0.1, 0.05, 0.025])
    assert fit_order(h, 3.0 * h**2, kind="h") == pytest.approx(2.0, abs=1e-12)
    assert fit_order(h[::-1], 3.0 * h[::-1] ** 1.5, kind="h") == pytest.approx(1.5, abs=1e-12)
    # dim is irrelevant for kind="h"
    assert fit_order(h, h**2, kind="h", dim=3) == pytest.approx(2.0, abs=1e-12)


def test_fit_order_least_squares_with_noise():
    N = np.array([100.0, 400.0, 1600.0])
    e = N ** (-1.0) * np.array([1.0, 1.1, 1.0])
    # slope of least squares through (log N, log e): by hand
    x, y = np.log(N), np.log(e)
    slope = np.sum((x - x.mean()) * (y - y.mean())) / np.sum((x - x.mean()) ** 2)
    assert fit_order(N, e) == pytest.approx(-2 * slope, rel=1e-12)


def test_fit_order_bad_inputs():
    with pytest.raises(ValueError, match=r"sizes must be a 1-D array with at least 2 entries to fit an order, got shape \(1,\)"):
        fit_order([100], [0.1])
    with pytest.raises(ValueError, match=r"sizes must be strictly increasing for kind='N', got \[100.0, 100.0, 400.0\]"):
        fit_order([100, 100, 400], [0.1, 0.1, 0.05])
    with pytest.raises(ValueError, match=r"sizes must be strictly monotonic .* for kind='h'"):
        fit_order([0.1, 0.05, 0.2], [1.0, 0.5, 2.0], kind="h")
    with pytest.raises(ValueError, match=r"sizes must be positive, got sizes\[0\] = -1.0"):
        fit_order([-1, 100], [0.1, 0.05])
    with pytest.raises(ValueError, match=r"errors must be positive to fit an order on a log scale, got errors\[1\] = 0.0 "
                                         r"\(a zero or negative error cannot be fitted\)"):
        fit_order([100, 200], [0.1, 0.0])
    with pytest.raises(ValueError, match=r"errors\[0\] = -0.1"):
        fit_order([100, 200], [-0.1, 0.05])
    with pytest.raises(ValueError, match=r"errors must have shape \(2,\) to match sizes, got shape \(3,\)"):
        fit_order([100, 200], [0.1, 0.05, 0.01])
    with pytest.raises(ValueError, match="errors must be finite"):
        fit_order([100, 200], [0.1, np.inf])
    with pytest.raises(ValueError, match=r"kind must be one of \['N', 'h'\], got 'n'"):
        fit_order([100, 200], [0.1, 0.05], kind="n")
    with pytest.raises(ValueError, match="dim must be at least 1, got 0"):
        fit_order([100, 200], [0.1, 0.05], dim=0)


# --- convergence_study ----------------------------------------------------------------


def test_convergence_study_synthetic_table():
    calls = []

    def run(n):
        calls.append(n)
        h = n ** -0.5
        return {"l2_rel": 2.0 * h**2, "linf_rel": 5.0 * h**1}

    sizes = [100, 400, 1600, 6400]
    t = convergence_study(sizes, run, kind="N", dim=2)
    assert isinstance(t, ConvergenceTable)
    assert calls == sizes
    np.testing.assert_array_equal(t.sizes, sizes)
    np.testing.assert_allclose(t.errors["l2_rel"], 2.0 / np.array(sizes), rtol=1e-15)
    np.testing.assert_allclose(t.errors["linf_rel"], 5.0 / np.sqrt(sizes), rtol=1e-15)
    assert t.orders["l2_rel"] == pytest.approx(2.0, abs=1e-12)
    assert t.orders["linf_rel"] == pytest.approx(1.0, abs=1e-12)
    assert t.local_orders["l2_rel"].shape == (3,)
    np.testing.assert_allclose(t.local_orders["l2_rel"], 2.0, atol=1e-12)
    np.testing.assert_allclose(t.local_orders["linf_rel"], 1.0, atol=1e-12)

    text = t.to_text()
    lines = text.splitlines()
    assert len(lines) == 1 + len(sizes) + 1
    assert lines[0].split() == ["N", "l2_rel", "order", "linf_rel", "order"]
    assert lines[1].split() == ["100", "2.000e-02", "-", "5.000e-01", "-"]
    assert lines[4].split() == ["6400", "3.125e-04", "2.00", "6.250e-02", "1.00"]
    assert lines[-1] == "fitted order:  l2_rel 2.00  linf_rel 1.00"
    # aligned: all table lines have the same width
    assert len({len(line) for line in lines[:-1]}) == 1

    d = json.loads(json.dumps(t.to_dict(json=True)))
    assert d["sizes"] == sizes and d["kind"] == "N" and d["dim"] == 2
    assert d["orders"]["l2_rel"] == pytest.approx(2.0, abs=1e-12)
    assert d["errors"]["linf_rel"][0] == pytest.approx(0.5)
    assert len(d["local_orders"]["linf_rel"]) == 3


def test_convergence_study_kind_h_and_dim3():
    t = convergence_study([0.2, 0.1, 0.05], lambda h: {"e": 4.0 * h**3}, kind="h")
    assert t.orders["e"] == pytest.approx(3.0, abs=1e-12)
    assert "h" == t.to_text().split()[0]
    t3 = convergence_study([1000, 8000, 64000], lambda n: {"e": n ** (-2 / 3)}, dim=3)
    assert t3.orders["e"] == pytest.approx(2.0, abs=1e-12)
    np.testing.assert_allclose(t3.local_orders["e"], 2.0, atol=1e-12)


def test_convergence_study_nonpositive_error_warns_and_nan_order():
    with pytest.warns(RuntimeWarning, match=r"error 'e' is 0.0 at size 400: a zero or negative error cannot be fitted"):
        t = convergence_study([100, 400, 1600], lambda n: {"e": 0.0 if n == 400 else 1.0 / n, "ok": 1.0 / n})
    assert math.isnan(t.orders["e"])
    assert np.isnan(t.local_orders["e"]).all()
    assert t.orders["ok"] == pytest.approx(2.0, abs=1e-12)
    assert t.to_text().splitlines()[-1] == "fitted order:  e -  ok 2.00"
    d = json.loads(json.dumps(t.to_dict(json=True), allow_nan=False))
    assert d["orders"]["e"] is None and d["local_orders"]["e"] == [None, None]


def test_convergence_study_bad_run():
    with pytest.raises(TypeError, match="run must be a callable"):
        convergence_study([1, 2], "nope")
    with pytest.raises(TypeError, match=r"run\(1\) must return a mapping of error names to numbers, got float"):
        convergence_study([1, 2], lambda n: 0.1)
    with pytest.raises(ValueError, match=r"run\(2\) returned errors \['b'\], but the first size returned \['a'\]"):
        convergence_study([1, 2], lambda n: {"a": 0.1} if n == 1 else {"b": 0.1})
    with pytest.raises(ValueError, match=r"run\(2\)\['a'\] must be finite, got nan"):
        convergence_study([1, 2], lambda n: {"a": 0.1 if n == 1 else float("nan")})
    with pytest.raises(TypeError, match=r"run\(1\)\['a'\] must be a real number, got str"):
        convergence_study([1, 2], lambda n: {"a": "x"})
    with pytest.raises(ValueError, match=r"sizes must be strictly increasing"):
        convergence_study([4, 2], lambda n: {"a": 1.0})
    with pytest.raises(ValueError, match="at least 2 entries"):
        convergence_study([4], lambda n: {"a": 1.0})
