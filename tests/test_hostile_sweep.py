"""The hostile-input sweep's classifier (benchmarks/hostile_sweep.py), run as a user runs it.

``--quick`` runs stubs of known outcome (an IndexError must be a crash, a ValueError naming
its argument a clear refusal, ...) and a handful of real cases whose outcome is known.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_quick_sweep_classifies_known_outcomes(tmp_path):
    out = tmp_path / "sweep.json"
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    run = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "hostile_sweep.py"), "--quick", "--json", str(out)],
                         capture_output=True, text=True, env=env, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    got = {(c["entry"], c["case"]): c["outcome"] for c in json.loads(out.read_text())["cases"]}
    assert got[("harness", "stub IndexError")] == "crash"
    assert got[("harness", "stub clear refusal")] == "clear"
    assert got[("harness", "stub misleading refusal")] == "misleading"  # a ValueError that does not name k
    assert got[("harness", "stub NaN result")] == "silent wrong"
    assert got[("harness", "stub wrong result")] == "silent wrong"
    assert got[("harness", "stub right result")] == "correct"
    assert got[("harness", "stub timeout")] == "crash"
    # real cases: refusals that name their argument, and an exact reference met
    assert got[("Surface", "(N, 2) points")] == "clear"
    assert got[("Surface.laplacian", "NaN in f")] == "clear"
    assert got[("read", "missing file")] == "clear"
    assert got[("cli", "eigs sphere.ply --k 0")] == "clear"
    assert got[("Surface.laplacian", "clean sphere (exact normals)")] == "correct"
    assert "summary by outcome" in run.stdout and "stub IndexError" in run.stdout
