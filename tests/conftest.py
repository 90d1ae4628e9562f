"""Shared test set-up: the off-screen rendering probe and the ``gl`` marker.

Tests marked ``@pytest.mark.gl`` need off-screen OpenGL; the probe renders once per
test run in a child process with no DISPLAY (a GL crash must not take pytest down),
and when it fails those tests are skipped with the probe's reason. Tests that check
pictures only where rendering works take the ``gl`` fixture.
"""

from __future__ import annotations

import functools
import json
import os
import subprocess
import sys

import pytest

_CONFIG = None  # pytest's config, kept by pytest_configure for the probe's shared folder


def pytest_configure(config):
    global _CONFIG
    _CONFIG = config


@functools.lru_cache(maxsize=None)
def gl_probe() -> tuple[bool, str]:
    """``(available, reason)`` of off-screen rendering here, probed once per test run in a child process.

    Under pytest-xdist the workers share one probe through a file in the run's temporary root
    (the parent of the workers' ``basetemp``, removed with pytest's old temporary folders),
    named after the run (``PYTEST_XDIST_TESTRUNUID``) and taken under a lock: the first worker
    probes, the others read.
    """
    run = os.environ.get("PYTEST_XDIST_TESTRUNUID")
    try:
        import fcntl
    except ImportError:  # no POSIX locks (Windows): every worker probes
        run = None
    if not run or _CONFIG is None or not hasattr(_CONFIG, "workerinput"):
        return _probe()
    try:
        root = _CONFIG._tmp_path_factory.getbasetemp().parent
    except Exception:  # noqa: BLE001 - no shared folder: this worker probes alone
        return _probe()
    path = root / f"manifold-sph-gl-probe-{run}.json"
    with open(path.with_suffix(".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if path.exists():
            ok, why = json.loads(path.read_text())
            return bool(ok), str(why)
        result = _probe()
        path.write_text(json.dumps(result))
    return result


@pytest.fixture(scope="session")
def gl() -> bool:
    """Whether off-screen rendering works (tests that check pictures only when it does)."""
    return gl_probe()[0]


def _probe() -> tuple[bool, str]:
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
