"""The API reference builds from the docstrings (pdoc, the ``docs`` extra) and the docs stay inside the repository."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _pdoc(tmp_path, mods):
    pytest.importorskip("pdoc", reason="the API reference needs the docs extra (pip install '.[docs]')")
    env = {**os.environ, "MPLBACKEND": "Agg"}
    res = subprocess.run([sys.executable, "-m", "pdoc", "-d", "numpy", "-o", str(tmp_path), *mods],
                         capture_output=True, text=True, timeout=900, env=env)
    assert res.returncode == 0, res.stderr[-2000:]
    return {p.stem for p in (tmp_path / "manifold_sph").glob("*.html")}


def _pdoc_here(tmp_path, mods):
    """pdoc's Python API in this process (the modules are imported already); the command line
    ``python -m pdoc`` of the README is run by the slow test below."""
    pytest.importorskip("pdoc", reason="the API reference needs the docs extra (pip install '.[docs]')")
    import pdoc
    import pdoc.render

    pdoc.render.configure(docformat="numpy")
    try:
        pdoc.pdoc(*mods, output_directory=tmp_path)
    finally:
        pdoc.render.configure()  # pdoc's defaults again
    return {p.stem for p in (tmp_path / "manifold_sph").glob("*.html")}


def test_api_reference_builds_for_the_core(tmp_path):
    """pdoc with the numpy docstring format renders the package page and the main modules (the
    whole reference, through ``python -m pdoc``, is the slow test below)."""
    pages = _pdoc_here(tmp_path, ["manifold_sph", "manifold_sph.operators", "manifold_sph.surface", "manifold_sph.pde"])
    assert {"surface", "pde"} <= pages
    surface = (tmp_path / "manifold_sph" / "surface.html").read_text()
    assert "laplacian_matrix" in surface and "stable_laplacian_matrix" in surface


@pytest.mark.slow
def test_api_reference_builds_for_every_submodule(tmp_path):
    import manifold_sph

    mods = ["manifold_sph"] + [f"manifold_sph.{m}" for m in manifold_sph._SUBMODULES]
    pages = _pdoc(tmp_path, mods)
    assert set(manifold_sph._SUBMODULES) <= pages, sorted(set(manifold_sph._SUBMODULES) - pages)


def test_docs_point_only_inside_the_repository():
    """Issue 17's target: no pointer to the project workspace or to the theses by their old names."""
    pattern = re.compile(r"METHOD\.md|\.\./shared|seed [12]\b|the seed's|the source's")
    files = [ROOT / "README.md", *sorted((ROOT / "manifold_sph").rglob("*.py")), *sorted((ROOT / "docs").glob("*.md"))]
    hits = [f"{f.relative_to(ROOT)}:{i}: {line.strip()}" for f in files
            for i, line in enumerate(f.read_text(encoding="utf-8").splitlines(), 1) if pattern.search(line)]
    assert not hits, "\n".join(hits[:20])
