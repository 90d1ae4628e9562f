"""The README's Python example runs and does what it says."""

import pathlib
import re

import numpy as np

README = pathlib.Path(__file__).resolve().parents[1] / "README.md"


def test_readme_python_example_runs():
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    assert blocks, "README has no python example"
    ns = {}
    exec(compile(blocks[0], str(README), "exec"), ns)
    assert np.allclose(ns["L"] @ ns["f"], ns["lap"], rtol=1e-12, atol=1e-12)
    assert ns["grad"].shape == (4032, 3)
