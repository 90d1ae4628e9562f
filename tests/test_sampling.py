"""Tests of manifold_sph.reference.sampling and of the samplings of the shapes."""

import math

import numpy as np
import pytest

from manifold_sph.reference import sampling as S
from manifold_sph.reference.sampling import (
    fibonacci_sphere,
    local_density,
    nearest_neighbor_cv,
    nearest_neighbor_distances,
    sample_surface,
    square,
)
from manifold_sph.reference.shapes import DoubleTorus, Sausage, Sphere, Torus

SHAPES = {"sphere": Sphere(), "torus": Torus(), "double_torus": DoubleTorus(), "sausage": Sausage()}
CASES = [(name, smp) for name, sh in SHAPES.items() for smp in sh.samplings]


def _distinct(p):
    return len(np.unique(p, axis=0)) == len(p)


@pytest.mark.parametrize("name, sampling", CASES)
def test_reproducible_exact_n_distinct_on_surface(name, sampling):
    shape = SHAPES[name]
    n = 311
    a = shape.sample(n, sampling, seed=7).points
    b = shape.sample(n, sampling, seed=7).points
    assert a.shape == (n, 3) and a.dtype == np.float64
    np.testing.assert_array_equal(a, b)
    assert _distinct(a)
    assert np.abs(shape.phi(a)).max() <= 1e-12
    c = shape.sample(n, sampling, seed=8).points
    if sampling == "fibonacci":  # deterministic lattice, seed unused
        np.testing.assert_array_equal(a, c)
    else:
        assert not np.allclose(np.sort(a, axis=0), np.sort(c, axis=0))


def test_fibonacci_lattice():
    p = fibonacci_sphere(1000)
    assert p.shape == (1000, 3)
    np.testing.assert_allclose(np.linalg.norm(p, axis=1), 1, atol=1e-15)
    # equal-area bands in z: z_i = 1 - (2 i + 1)/n, no point at a pole
    np.testing.assert_allclose(p[:, 2], 1 - (2 * np.arange(1000) + 1) / 1000, atol=1e-15)
    assert np.hypot(p[:, 0], p[:, 1]).min() > 0.04
    assert _distinct(p)
    # near uniform: nearest-neighbour distances vary little
    assert nearest_neighbor_cv(p) < 0.05
    s = Sphere(2.0, center=(1, 0, 0)).sample(1000)
    np.testing.assert_allclose(s.points, 2 * p + [1, 0, 0], atol=1e-15)


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_poisson_more_uniform_than_random(name):
    shape = SHAPES[name]
    n = 2000
    cv_p = nearest_neighbor_cv(shape.sample(n, "poisson", seed=0).points)
    cv_r = nearest_neighbor_cv(shape.sample(n, "random", seed=0).points)
    # random points on a surface: CV ~ 0.52; the relaxed ones ~ 0.07
    assert cv_r > 0.4
    assert cv_p < 0.15 and cv_p < 0.3 * cv_r
    # and the mean spacing matches the hexagonal spacing of the area
    d = nearest_neighbor_distances(shape.sample(n, "poisson", seed=0).points)
    hexs = math.sqrt(2 / math.sqrt(3) * shape.area / n)
    assert 0.85 * hexs < d.mean() < 1.05 * hexs


def test_random_is_area_uniform():
    """Counts in equal-area regions agree with the binomial law (torus: inner vs outer half)."""
    t = Torus()
    n = 20000
    p = t.sample(n, "random", seed=3).points
    rho = np.hypot(p[:, 0], p[:, 1])
    # outer half (rho > R) has area 2 pi r (pi R + 2 r) 2 ... fraction (pi R + 2 r) / (2 pi R)
    frac = (math.pi * t.R + 2 * t.r) / (2 * math.pi * t.R)
    assert abs(np.mean(rho > t.R) - frac) < 4 * math.sqrt(frac * (1 - frac) / n)
    s = Sausage()
    p = s.sample(n, "random", seed=3).points
    # the two halves theta > 0, theta < 0 have equal area
    assert abs(np.mean(s.arc_angle(p) > 0) - 0.5) < 4 * math.sqrt(0.25 / n)
    # sphere: z uniform in [-1, 1] (Archimedes)
    z = Sphere().sample(n, "random", seed=3).points[:, 2]
    assert abs(np.mean(z > 0.5) - 0.25) < 4 * math.sqrt(0.25 * 0.75 / n)


@pytest.mark.parametrize("name", sorted(SHAPES))
@pytest.mark.parametrize("ratio", [4.0, 0.5])
def test_variable_density_ratio(name, ratio):
    shape = SHAPES[name]
    p = shape.sample(4000, "variable", seed=1, density_ratio=ratio).points
    assert _distinct(p) and np.abs(shape.phi(p)).max() <= 1e-12
    s = shape.axis_coordinate(p)
    dens = local_density(p, k=10)
    measured = np.median(dens[np.abs(s - 0.5) < 0.15]) / np.median(dens[np.abs(s + 0.5) < 0.15])
    assert abs(measured / ratio - 1) < 0.25
    if name == "sphere":  # equal-area hemispheres: point counts in the ratio
        counts = np.sum(s > 0) / np.sum(s < 0)
        assert abs(counts / ratio - 1) < 0.15


# ----------------------------------------------------------------------------
# square
# ----------------------------------------------------------------------------
@pytest.mark.parametrize("sampling", S.SQUARE_SAMPLINGS)
def test_square_basic(sampling):
    b = (-1.0, 2.0, 0.5, 1.5)
    p = square(1007, bounds=b, sampling=sampling, seed=4)
    assert p.shape == (1007, 2) and _distinct(p)
    assert np.all((p[:, 0] > b[0]) & (p[:, 0] < b[1]) & (p[:, 1] > b[2]) & (p[:, 1] < b[3]))
    np.testing.assert_array_equal(p, square(1007, bounds=b, sampling=sampling, seed=4))
    assert not np.array_equal(p, square(1007, bounds=b, sampling=sampling, seed=5))


def test_square_poisson_uniform_up_to_the_boundary():
    n = 1007
    p = square(n, seed=0)
    cv_p = nearest_neighbor_cv(p)
    cv_r = nearest_neighbor_cv(square(n, sampling="random", seed=0))
    cv_h = nearest_neighbor_cv(square(n, sampling="halton", seed=0))
    assert cv_p < 0.12 and cv_p < 0.3 * cv_r and cv_p < cv_h
    spacing = math.sqrt(2 / math.sqrt(3) * 4 / n)
    wall = np.min(np.stack([p[:, 0] + 1, 1 - p[:, 0], p[:, 1] + 1, 1 - p[:, 1]]), axis=0)
    # the outer rows sit about half a spacing inside, none stick to the wall
    assert 0.2 * spacing < wall.min() < 0.7 * spacing
    assert np.sum(wall < spacing) > 4 * 2 / spacing * 0.8  # every side populated
    # no depletion near the boundary: the strip of width 2 spacings holds its share
    strip = np.mean(wall < 2 * spacing)
    frac = 1 - (1 - 2 * spacing) ** 2
    assert abs(strip / frac - 1) < 0.1


def test_square_variable_density():
    p = square(4000, sampling="variable", seed=2, density_ratio=3.0)
    s = p[:, 1]
    dens = local_density(p, k=10)
    measured = np.median(dens[np.abs(s - 0.5) < 0.15]) / np.median(dens[np.abs(s + 0.5) < 0.15])
    assert abs(measured / 3.0 - 1) < 0.25


def test_halton_is_scipy_scrambled_halton():
    from scipy.stats import qmc

    p = square(64, bounds=(0, 1, 0, 1), sampling="halton", seed=11)
    q = qmc.Halton(d=2, scramble=True, seed=np.random.default_rng(11)).random(64)
    np.testing.assert_array_equal(p, q)


# ----------------------------------------------------------------------------
# helpers and bad input
# ----------------------------------------------------------------------------
def test_local_density_and_cv_helpers():
    rng = np.random.default_rng(0)
    p = rng.random((20000, 2)) * [4.0, 1.0]  # 5000 points per unit area
    d = local_density(p, k=10)
    inner = (p[:, 0] > 0.2) & (p[:, 0] < 3.8) & (p[:, 1] > 0.2) & (p[:, 1] < 0.8)
    assert abs(np.mean(d[inner]) / 5000 - 1) < 0.15
    assert 0.45 < nearest_neighbor_cv(p) < 0.58
    with pytest.raises(ValueError, match="k must be smaller than the number of points 3"):
        local_density(p[:3], k=3)


@pytest.mark.parametrize(
    "call, exc, match",
    [
        (lambda: square(9), ValueError, "n must be at least 10, got 9"),
        (lambda: square(100, sampling="grid"), ValueError, r"sampling must be one of \['halton', 'poisson', 'random', 'variable'\]"),
        (lambda: square(100, bounds=(1, -1, 0, 1)), ValueError, "bounds must satisfy xmin < xmax"),
        (lambda: square(100, bounds=(0, 1, 0)), ValueError, "bounds must be 4 numbers"),
        (lambda: square(100, bounds=(0, np.nan, 0, 1)), ValueError, "bounds must be finite"),
        (lambda: square(100, sampling="variable", density_ratio=0.0), ValueError, "density_ratio must be a finite positive number"),
        (lambda: square(100, seed=1.5), TypeError, "seed must be an int"),
        (lambda: fibonacci_sphere(3), ValueError, "n must be at least 10, got 3"),
        (lambda: sample_surface(Torus(), 100, "fibonacci"), ValueError, r"sampling must be one of \['poisson', 'random', 'variable'\]"),
        (lambda: sample_surface(Torus(), 100, iterations=-1), ValueError, "iterations must be at least 0"),
        (lambda: Torus().sample(100, "variable", density_ratio=-2.0), ValueError, "density_ratio must be a finite positive number"),
    ],
)
def test_bad_input(call, exc, match):
    with pytest.raises(exc, match=match):
        call()


def test_seed_accepts_generator_and_none():
    t = Torus()
    a = t.sample(50, "random", seed=np.random.default_rng(3)).points
    np.testing.assert_array_equal(a, t.sample(50, "random", seed=3).points)
    assert len(t.sample(50, "random", seed=None)) == 50


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(SHAPES))
def test_poisson_large(name):
    """131,072 Poisson-disk points on every shape are as regular as the small samples (no timed
    assertion: sampling time is a benchmark's business)."""
    p = SHAPES[name].sample(131072, "poisson", seed=0).points
    assert len(p) == 131072
    assert nearest_neighbor_cv(p) < 0.1

