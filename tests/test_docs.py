"""The API reference builds from the docstrings (pdoc, the ``docs`` extra) and the docs stay inside the repository."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_api_reference_builds(tmp_path):
    """``python -m pdoc -d numpy`` over every public submodule: one page each, no import failure."""
    pytest.importorskip("pdoc", reason="the API reference needs the docs extra (pip install '.[docs]')")
    import manifold_sph

    mods = ["manifold_sph"] + [f"manifold_sph.{m}" for m in manifold_sph._SUBMODULES]
    res = subprocess.run([sys.executable, "-m", "pdoc", "-d", "numpy", "-o", str(tmp_path), *mods],
                         capture_output=True, text=True, timeout=600, env={"MPLBACKEND": "Agg", **__import__("os").environ})
    assert res.returncode == 0, res.stderr[-2000:]
    pages = {p.stem for p in (tmp_path / "manifold_sph").glob("*.html")}
    assert set(manifold_sph._SUBMODULES) <= pages, sorted(set(manifold_sph._SUBMODULES) - pages)
    surface = (tmp_path / "manifold_sph" / "surface.html").read_text()
    assert "laplacian_matrix" in surface and "stable_laplacian_matrix" in surface


def test_docs_point_only_inside_the_repository():
    """Issue 17's target: no pointer to the project workspace or to the theses by their old names."""
    pattern = re.compile(r"METHOD\.md|\.\./shared|seed [12]\b|the seed's|the source's")
    files = [ROOT / "README.md", *sorted((ROOT / "manifold_sph").rglob("*.py")), *sorted((ROOT / "docs").glob("*.md"))]
    hits = [f"{f.relative_to(ROOT)}:{i}: {line.strip()}" for f in files
            for i, line in enumerate(f.read_text(encoding="utf-8").splitlines(), 1) if pattern.search(line)]
    assert not hits, "\n".join(hits[:20])
