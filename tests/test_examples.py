"""Smoke tests: every example runs with --quick and writes its pictures (plots always, 3D ones when GL works)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
NAMES = sorted(p.stem for p in EXAMPLES.glob("*.py") if not p.stem.startswith("_"))


def _load(name):
    sys.path.insert(0, str(EXAMPLES))
    try:
        spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        return mod
    finally:
        sys.path.remove(str(EXAMPLES))


def test_examples_exist():
    assert {"area_elements", "sausage_neighbourhood", "sphere_operators", "torus_laplacians", "heat_sphere",
            "wave_sphere", "sausage_outliers", "planar_schemes", "scan_geometry"} <= set(NAMES)


@pytest.mark.parametrize("name", NAMES)
def test_example_quick(name, tmp_path, capsys):
    from manifold_sph.viz.render import rendering_available

    mod = _load(name)
    assert mod.main(["--out", str(tmp_path), "--quick"]) == 0
    written = [line.split(" ", 1)[1] for line in capsys.readouterr().out.splitlines() if line.startswith("wrote ")]
    if rendering_available()[0] or name not in ("sausage_neighbourhood",):
        assert written, f"{name} wrote nothing"
    for path in written:
        assert Path(path).stat().st_size > 1000
    # a second run without --overwrite refuses to replace the pictures (checked on the fastest example)
    if written and name == "area_elements":
        with pytest.raises(FileExistsError):
            mod.main(["--out", str(tmp_path), "--quick"])
