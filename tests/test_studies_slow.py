"""Large-N accuracy targets of the operators issue (run with ``pytest -m slow``; minutes)."""

import pytest

from manifold_sph.reference import shapes
from manifold_sph.reference.accuracy import convergence, operator_errors

pytestmark = pytest.mark.slow

SIZES = [1002, 2012, 4032, 8672, 15872, 32672, 65536, 131072]


@pytest.mark.parametrize("scheme", ["cspm", "msph", "ncsph"])
def test_sphere_convergence_to_131072(scheme):
    table = convergence("sphere", SIZES, scheme, "cos_xz_sin_y")
    lap = table.errors["lap_l2"]
    assert lap[SIZES.index(4032)] <= 6.5e-3
    assert lap[-1] <= 2.0e-4
    assert table.orders["lap_l2"] >= 1.9
    if scheme in ("msph", "ncsph"):
        assert table.orders["lap_linf"] >= 1.8
    if scheme == "cspm":
        assert table.errors["grad_l2"][SIZES.index(4032)] <= 8e-3
        assert table.orders["grad_l2"] >= 1.9


def test_sausage_filter_matters():
    cloud = shapes.sausage(2652)
    with_filter = operator_errors(cloud, "xyz", ["cspm"])[0]["lap_l2"]
    without = operator_errors(cloud, "xyz", ["cspm"], normal_threshold=-1.0)[0]["lap_l2"]
    assert with_filter < without
