"""The README: every Python snippet runs, in order, on a sample scan, and does what it says;
its shell commands name real subcommands and options; it stays short."""

import pathlib
import re
import shlex
import warnings

import numpy as np
import pytest

import manifold_sph as ms
from manifold_sph.cli.app import build_parser
from manifold_sph.reference import shapes

README = pathlib.Path(__file__).resolve().parents[1] / "README.md"
TEXT = README.read_text(encoding="utf-8")
BLOCKS = re.findall(r"```python\n(.*?)```", TEXT, flags=re.S)


def _scan(path: pathlib.Path) -> None:
    """A sample scan: 3,000 uniformly random points of a torus, noise of 0.2 % of its size, no normals."""
    rng = np.random.default_rng(7)
    x = shapes.torus(3000, R=1.0, r=0.4, sampling="random", seed=7).points
    x = x + 0.0028 * rng.standard_normal(x.shape)
    ms.write(path, ms.PointCloud(x))


def test_readme_is_short_and_its_first_block_holds_the_two_commands():
    assert len(TEXT.splitlines()) <= 250
    first = re.search(r"```bash\n(.*?)```", TEXT, flags=re.S).group(1).strip().splitlines()
    assert len(first) == 2 and "manifold-sph demo" in first[0] and "pytest" in first[1]
    assert "libusb-1.0-0" in first[0] and "libusb-1.0-0" in first[1]
    assert "ruff check ." in first[1] and "mypy" in first[1]  # the checks run with the tests


@pytest.mark.gl
def test_readme_python_snippets_run_in_order(tmp_path, monkeypatch):
    assert len(BLOCKS) >= 8, "the README's everyday tasks are Python snippets"
    monkeypatch.chdir(tmp_path)
    _scan(tmp_path / "scan.ply")
    ns: dict = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ms.ManifoldSPHWarning)  # the build's one summary warning: expected here
        for k, block in enumerate(BLOCKS):
            exec(compile(block, f"{README}:python block {k}", "exec"), ns)
    s, z = ns["s"], ns["z"]
    n = len(s.points)
    assert s.normals_estimated and ns["normals"].shape == (n, 3)
    np.testing.assert_allclose(ns["L"] @ z, ns["lap"], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose((ns["G"] @ z).reshape(-1, 3), ns["grad"], rtol=1e-12, atol=1e-12)
    assert ns["ev"].values.shape == (20,) and abs(ns["ev"].values[0]) < 1e-8
    H = ns["H"]
    # the torus (R = 1, r = 0.4): H = (R + 2 r cos v) / (2 r (R + r cos v)), cos v = (rho - R) / r
    cos_v = np.clip((np.hypot(s.points[:, 0], s.points[:, 1]) - 1.0) / 0.4, -1, 1)
    exact = (1.0 + 0.8 * cos_v) / (0.8 * (1.0 + 0.4 * cos_v))
    assert np.median(np.abs(H - exact)) < 0.1 * np.abs(exact).mean(), np.median(np.abs(H - exact))
    assert ns["d"][0] == 0 and np.all(ns["d"] >= 0)
    heat = ns["heat"]
    assert heat.snapshots.shape[1] == n and heat.u.max() < ns["u0"].max()
    assert (tmp_path / "H.png").stat().st_size > 1000 and (tmp_path / "heat.gif").exists()
    assert (tmp_path / "scan_with_normals.ply").exists()
    assert ns["r"].error < 0.1


def test_readme_shell_commands_parse():
    block = re.search(r"\*\*The same from the shell\.\*\*.*?```\n(.*?)```", TEXT, flags=re.S).group(1)
    parser = build_parser()
    lines = [line for line in block.strip().splitlines() if "--help" not in line]
    assert len(lines) >= 5
    for line in lines:
        argv = shlex.split(line)[1:]
        parser.parse_args(argv)  # SystemExit(2) names the unknown command or option
