"""Repository-level pytest set-up: the deprecated shim modules (old flat paths of the modules that
moved into scans/, reference/ and viz/) are not collected for doctests: importing them warns."""

from pathlib import Path

collect_ignore = [str(p) for p in sorted((Path(__file__).parent / "manifold_sph").glob("*.py"))
                  if p.read_text(encoding="utf-8").startswith('"""Deprecated location of')]
