"""The package layout: a flat core in pipeline order, and scans / reference / viz subpackages;
the old flat paths of the moved modules still work for one release, with a DeprecationWarning."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

import manifold_sph

MOVED = sorted(manifold_sph._MOVED.items())


@pytest.fixture(scope="module")
def fresh():
    """One fresh interpreter for both checks that need one: first whether ``import manifold_sph``
    and ``Surface`` load pyvista or viz, then the old paths' warnings (given once, on the first
    import of an old path)."""
    code = (
        "import sys, warnings, importlib, json\n"
        "import manifold_sph; manifold_sph.Surface\n"
        "viz = any(m.startswith(('pyvista', 'manifold_sph.viz')) for m in sys.modules)\n"
        "warnings.simplefilter('always')\n"
        f"moved = {dict(MOVED)!r}\n"
        "bad = []\n"
        "for old, new in moved.items():\n"
        "    with warnings.catch_warnings(record=True) as w:\n"
        "        mod = importlib.import_module('manifold_sph.' + old)\n"
        "    if mod is not importlib.import_module('manifold_sph.' + new):\n"
        "        bad.append((old, 'not the moved module'))\n"
        "    if not any(f'manifold_sph.{old} moved to manifold_sph.{new}' in str(x.message)\n"
        "               and x.category is DeprecationWarning for x in w):\n"
        "        bad.append((old, 'no warning'))\n"
        "print(json.dumps({'viz': viz, 'bad': bad}))\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stdout + res.stderr[-1500:]
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_old_paths_resolve_to_the_moved_modules_with_a_warning(fresh):
    assert fresh["bad"] == []


def test_attribute_access_to_old_names_warns():
    with pytest.warns(DeprecationWarning, match="manifold_sph.shapes moved to manifold_sph.reference.shapes"):
        shapes = manifold_sph.shapes
    from manifold_sph.reference import shapes as new

    assert shapes is new


def test_every_submodule_is_an_attribute_and_the_core_does_not_import_viz(fresh):
    for name in manifold_sph._SUBMODULES:
        assert getattr(manifold_sph, name).__name__ == f"manifold_sph.{name}"
    assert fresh["viz"] is False
