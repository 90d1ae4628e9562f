"""One convention for results: frozen dataclasses with named fields, ``to_dict()`` and a short repr."""

import ast
import dataclasses
import json
import pathlib
import warnings

import numpy as np
import pytest

from manifold_sph import Surface, pde
from manifold_sph.reference import shapes
from manifold_sph.spem import CavityResult, RunResult, TMzSolver, yee_layout
from manifold_sph.spem.cases import run_case

SPEM = pathlib.Path(__file__).resolve().parents[1] / "manifold_sph" / "spem"


@pytest.fixture(scope="module")
def surf():
    return Surface(shapes.sphere(400))


def test_heat_and_wave_return_a_solution_whatever_the_options(surf):
    z = surf.points[:, 2]
    plain = pde.heat(surf, z, dt=0.01, steps=6)
    saved = pde.heat(surf, z, dt=0.01, steps=6, every=4)
    for sol in (plain, saved):
        assert isinstance(sol, pde.Solution) and sol.laplacian == "strong"
        np.testing.assert_array_equal(sol.snapshots[0], z)
        np.testing.assert_array_equal(sol.snapshots[-1], sol.u)
    np.testing.assert_array_equal(plain.u, saved.u)
    assert plain.times.tolist() == [0.0, 0.06] and plain.snapshots.shape == (2, 400)
    assert np.allclose(saved.times, [0.0, 0.04, 0.06]) and saved.snapshots.shape == (3, 400)  # the last step is kept
    w = pde.wave(surf, z, dt=0.01, steps=5, laplacian="stable")
    assert isinstance(w, pde.Solution) and w.laplacian == "stable" and w.snapshots.shape == (2, 400)
    with pytest.raises(dataclasses.FrozenInstanceError):
        w.u = z
    assert set(w.to_dict()) == {"u", "times", "snapshots", "laplacian", "dt", "solver"}
    assert "array (400,)" in repr(w)  # arrays shown by shape, not printed



def test_spem_run_returns_a_run_result():
    lay = yee_layout((0.0, 0.1, 0.0, 0.1), 0.01)
    s = TMzSolver(lay)
    s.set_initial(np.sin(np.pi * lay.e[:, 0] / 0.1) * np.sin(np.pi * lay.e[:, 1] / 0.1))
    res = s.run(6, probes=[3, 4], every=3)
    assert isinstance(res, RunResult)
    assert res.times.shape == (6,) and res.probes.shape == (6, 2) and res.seconds >= 0
    assert res.snapshots.shape == (2, s.n_e) and np.allclose(res.snapshot_times, res.times[[2, 5]])
    np.testing.assert_array_equal(res.snapshots[-1], s.e_field)
    empty = s.run(2)
    assert empty.snapshots.shape == (0, s.n_e) and empty.probes.shape == (2, 0)


@pytest.fixture(scope="module")
def cavity():
    return run_case("cavity", n_radial=4, periods=0.2, every=3)  # every third step, and the final state


def test_spem_cases_return_named_fields_and_json(cavity):
    r = cavity
    assert isinstance(r, CavityResult) and r.case == "cavity" and r.particles > 0 and r.steps > 0
    assert 0 <= r.step_seconds <= r.seconds and r.dt > 0 and r.dr == pytest.approx(0.025)
    assert r.f1_measured is None and r.f1_exact == pytest.approx(362.85e6, rel=1e-3)
    d = r.to_dict()
    assert "fields" not in d and json.loads(json.dumps(d))["error"] == r.error
    f = r.fields  # the picture data: every third state and the final one
    assert f.snapshots.shape == (len(f.times), len(f.points)) and f.exact.shape == (len(f.points),)
    np.testing.assert_allclose(f.times[-1], r.steps * r.dt)
    assert len(f.times) == r.steps // 3 + (r.steps % 3 != 0)
    np.testing.assert_allclose(np.diff(f.times)[:-1], 3 * r.dt)
    with pytest.raises(ValueError, match="every must be"):
        run_case("cavity", n_radial=4, periods=0.2, every=0)


def _imports(path):
    tree = ast.parse(path.read_text())
    return {(n.module or "") for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.level == 1}


def test_spem_case_modules_import_one_way():
    """The cases build on the solvers and results, never the reverse; the shared helpers on no case."""
    cases = SPEM / "cases"
    assert not {"cavity", "line", "propagation", "scattering"} & _imports(cases / "common.py")
    for name in ("results.py", "tmz.py", "tez.py", "stepping.py", "stability.py", "mie.py", "interfaces.py"):
        assert not {"cases", "cli"} & _imports(SPEM / name), name
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        import manifold_sph.spem.cases.propagation  # noqa: F401 - importable on its own
