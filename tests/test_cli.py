"""The manifold-sph command line: tables, JSON, exit codes."""

import json

from manifold_sph.cli import main


def test_operators_json(capsys):
    assert main(["operators", "--n", "1002", "--scheme", "cspm", "--function", "xyz", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    (row,) = out["rows"]
    assert row["scheme"] == "cspm" and row["n"] == 1002
    assert 0 < row["lap_l2"] < 0.05


def test_operators_table(capsys):
    assert main(["operators", "--n", "500", "--shape", "torus"]) == 0
    out = capsys.readouterr().out
    for scheme in ("standard", "cspm", "msph", "ncsph"):
        assert scheme in out


def test_convergence(capsys):
    assert main(["convergence", "--sizes", "1002,4032", "--scheme", "msph", "--json"]) == 0
    table = json.loads(capsys.readouterr().out)
    assert table["orders"]["lap_l2"] > 1.8


def test_user_mistake_is_one_line_exit_2(capsys):
    assert main(["operators", "--n", "5"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("manifold-sph: error:") and err.count("\n") == 1
    assert "Traceback" not in err


def test_bad_sizes_exit_2(capsys):
    try:
        main(["convergence", "--sizes", "1002"])
    except SystemExit as exc:
        assert exc.code == 2
    assert "at least two sizes" in capsys.readouterr().err
