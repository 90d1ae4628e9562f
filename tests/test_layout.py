"""The package layout: the core in pipeline order at the top, scans / reference / viz / spem beside it,
no compatibility modules, and importing the core loads no renderer."""

from __future__ import annotations

import json
import pathlib
import subprocess
import sys

import manifold_sph

PACKAGE = pathlib.Path(manifold_sph.__file__).parent


def test_every_submodule_is_an_attribute_and_the_core_does_not_import_viz():
    for name in manifold_sph._SUBMODULES:
        assert getattr(manifold_sph, name).__name__ == f"manifold_sph.{name}"
    code = (
        "import sys, json\n"
        "import manifold_sph; manifold_sph.Surface\n"
        "print(json.dumps(any(m.startswith(('pyvista', 'manifold_sph.viz')) for m in sys.modules)))\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr[-1500:]
    assert json.loads(res.stdout.strip().splitlines()[-1]) is False


def test_no_module_is_a_compatibility_shim():
    """Every module of the package defines something: none only re-exports another under an old name."""
    for path in PACKAGE.rglob("*.py"):
        text = path.read_text(encoding="utf-8")
        assert "sys.modules[__name__] =" not in text, path
        assert "DeprecationWarning" not in text, f"{path}: the package deprecates nothing (see CHANGELOG.md)"
