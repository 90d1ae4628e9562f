"""Shared test set-up: the off-screen rendering probe and the ``gl`` marker.

Tests marked ``@pytest.mark.gl`` need off-screen OpenGL; the probe renders once per
session in a child process with no DISPLAY (a GL crash must not take pytest down),
and when it fails those tests are skipped with the probe's reason.
"""

from __future__ import annotations

import functools
import os
import subprocess
import sys

import pytest


@functools.lru_cache(maxsize=None)
def gl_probe() -> tuple[bool, str]:
    """``(available, reason)`` of off-screen rendering here, probed once in a child process."""
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    code = "from manifold_sph.viz.render import rendering_available as r; ok, why = r(); print(ok, why)"
    try:
        res = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    except subprocess.TimeoutExpired:
        return False, "the rendering probe timed out"
    line = res.stdout.strip().splitlines()[-1] if res.stdout.strip() else ""
    if res.returncode != 0 or not line.startswith("True"):
        return False, f"off-screen rendering is not available here: {line or res.stderr.strip()[-300:]}"
    return True, line


def pytest_collection_modifyitems(config, items):
    gl_items = [item for item in items if item.get_closest_marker("gl") is not None]
    if not gl_items:
        return
    ok, why = gl_probe()
    if not ok:
        for item in gl_items:
            item.add_marker(pytest.mark.skip(reason=why))
