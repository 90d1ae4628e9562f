"""Every ``manifold-sph spem`` case on every layout and support the CLI accepts, against the default lattice.

For each case the default run (``--layout yee``, default ``--h-ratio``) is the reference; every other
layout the CLI accepts for that case and every support (``--h-ratio``) in ``--h-ratios`` is run through
the CLI itself (``manifold_sph.spem.cli.main([... "--json"])``, in-process) and reported with its exit
code, error, error over the default-lattice error, steps over the default's, set-up and run seconds.
Where the Yee FDTD references of ``benchmarks/spem_vs_yee.py`` / ``benchmarks/spem_tez.py`` apply (the
TMz cavity, the cylinder scatterers), the staircased Yee error at the same spacing is printed beside.
``PML dB`` is the reflection of the run's absorbing layer measured on probes: the plane wave's and the
waveguide's ``pml_reflection_db`` (``spem.certify.pml_certificate`` on the run's layout, support and
coupling), the pml case's worse of its normal and oblique reflections.

The line ``VIOLATION`` marks a run that exits 0 with an error above ``--limit`` (default 10) times its
default-lattice error (target: none); ``steps x`` above 2 marks a time step collapsed by the layout.
Exit 2 is a setting refused before the run (outside its validated range), exit 3 a run whose certificates
(``spem.certify.certificate_failures``: the PML reflection, the energy drift) fall outside their validated
range: its numbers are printed with the reason.

    python benchmarks/spem_matrix.py --quick            # reduced resolution, every case (about 10 min)
    python benchmarks/spem_matrix.py                    # the CLI's own defaults (long)
    python benchmarks/spem_matrix.py --cases planewave,pml --h-ratios default,1.3
    python benchmarks/spem_matrix.py --quick --cases cavity --h-ratios default --couplings default,adjoint
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from manifold_sph.spem.cli import main as spem_main  # noqa: E402

TMZ_LAYOUTS = ("yee", "staggered", "jittered", "poisson", "poisson-joint", "poisson-balanced")
#: case -> (layouts the CLI accepts, extra CLI arguments in --quick mode)
CASES = {
    "line1d": ((None,), []),
    "cavity": (TMZ_LAYOUTS, ["--n-radial", "10"]),
    "waveguide": (TMZ_LAYOUTS, ["--ppw", "40"]),
    "planewave": (TMZ_LAYOUTS, ["--ppw", "20", "--size", "0.25"]),
    "pml": (TMZ_LAYOUTS, []),
    "scatter-pec": (("yee", "jittered"), ["--n-radial", "4"]),
    "scatter-dielectric": (("yee", "jittered"), ["--n-radial", "4"]),
    "scatter-coated": (("yee", "jittered"), ["--n-radial", "4"]),
    "tez-cavity": (("yee", "jittered", "poisson"), []),
    "tez-disk": (("yee", "jittered", "poisson"), ["--n-radial", "10"]),
    "tez-scatter-pec": (("yee", "jittered"), ["--n-radial", "8"]),  # at 4 the lattice drifts (exit 3)
    "tez-scatter-dielectric": (("yee", "jittered"), ["--n-radial", "4"]),
}
#: extra arguments a layout needs for a case (the CLI refuses the layout without them)
NEEDS = {("tez-cavity", "poisson"): ["--wall-closure"]}
#: cases without --h-ratio
NO_SUPPORT = ("line1d",)


def run_cli(argv: list[str]) -> tuple[int, dict | None, str, float]:
    """(exit code, JSON result or None, the error line, wall seconds) of ``manifold-sph spem ARGV --json``."""
    out, err = io.StringIO(), io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = spem_main([*argv, "--json"])
        except SystemExit as exc:  # argparse refusals
            code = int(exc.code or 0)
    seconds = time.perf_counter() - t0
    text = out.getvalue().strip().splitlines()
    data = json.loads(text[-1]) if code in (0, 3) and text else None  # 3: printed, not certified
    message = (err.getvalue().strip().splitlines() or [""])[-1]
    return code, data, message, seconds


def error_of(d: dict) -> float | None:
    """The case's error: ``error``, else (the PML cases) the worst reflection as an amplitude ratio."""
    if d.get("error") is not None:
        return float(d["error"])
    dbs = [v for k, v in d.items() if k.startswith("reflection") and v is not None]
    flat = [x for v in dbs for x in (v if isinstance(v, list) else [v])]
    return 10 ** (max(flat) / 20) if flat else None


def pml_db(d: dict) -> str:
    """The run's PML reflection in dB, as printed (blank where the case has none or did not measure it)."""
    v = d.get("pml_reflection_db")
    if v is None and d.get("case") == "pml":
        vals = [d.get("reflection_normal_db"), d.get("reflection_oblique_db")]
        vals = [x for x in vals if x is not None]
        v = max(vals) if vals else None
    return "" if v is None else f"{v:.1f}"


def timing(d: dict, wall: float) -> tuple[float, float]:
    """(set-up, run) seconds from the case's own fields."""
    if "setup_seconds" in d:
        return float(d["setup_seconds"]), float(d["seconds"]) - float(d["setup_seconds"])
    if "step_seconds" in d:
        return float(d["seconds"]) - float(d["step_seconds"]), float(d["step_seconds"])
    return math.nan, float(d.get("seconds", wall))


def yee_reference(case: str, args: list[str]) -> float | None:
    """The staircased Yee error of the same case and spacing, where a reference exists."""
    n = int(args[args.index("--n-radial") + 1]) if "--n-radial" in args else None
    try:
        if case == "cavity":
            from spem_vs_yee import run_yee_cavity

            return float(run_yee_cavity(n or 40)["error"])
        if case.startswith("scatter-"):
            from spem_vs_yee import run_yee_scattering

            kind = case.split("-", 1)[1]
            periods = float(args[args.index("--periods") + 1]) if "--periods" in args else 60.0  # steady (auto: 9-29)
            kw = {"core_radius": 0.05} if kind == "coated" else {}
            return float(run_yee_scattering(kind, n or 8, periods=periods, **kw)["error"])
        if case.startswith("tez-scatter-"):
            from spem_tez import run_yee_tez_scattering

            kind = case.rsplit("-", 1)[1]
            periods = float(args[args.index("--periods") + 1]) if "--periods" in args else "auto"
            return float(run_yee_tez_scattering(kind, n or 8, periods=periods)["error"])
    except (ImportError, KeyError, TypeError, ValueError) as exc:
        print(f"  (Yee reference for {case} unavailable: {exc})", file=sys.stderr)
    return None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="reduced resolution (the same for every run of a case)")
    ap.add_argument("--cases", default=",".join(CASES), help="comma-separated cases (default all)")
    ap.add_argument("--layouts", default=None, help="comma-separated layouts (default every layout a case accepts)")
    ap.add_argument("--h-ratios", default="default,1.0,1.3,1.5", help="supports: 'default' and h/dr values")
    ap.add_argument("--couplings", default="default", help="couplings: 'default' and --coupling values (e.g. default,adjoint)")
    ap.add_argument("--limit", type=float, default=10.0, help="error ratio that counts as a violation (default 10)")
    ap.add_argument("--no-yee", action="store_true", help="skip the Yee references")
    ap.add_argument("--json", default=None, help="also write every row to this JSON file")
    a = ap.parse_args()
    rows = []
    violations = 0
    head = (f"{'case':>22s} {'layout':>16s} {'h/dr':>7s} {'exit':>4s} {'error':>9s} {'err x':>7s} {'steps':>8s} "
            f"{'steps x':>7s} {'setup s':>8s} {'run s':>8s} {'Yee':>9s} {'PML dB':>7s}")
    print(head)
    print("-" * len(head))
    for case in a.cases.split(","):
        layouts, quick = CASES[case]
        extra = quick if a.quick else []
        code, base, msg, wall = run_cli([case, *extra])
        if code != 0:
            print(f"{case:>22s} default run failed ({code}): {msg}")
            continue
        e0, s0 = error_of(base), int(base.get("steps", 0))
        yee = None if a.no_yee else yee_reference(case, extra)
        setup, run = timing(base, wall)
        print(f"{case:>22s} {'yee (default)':>16s} {'default':>7s} {0:>4d} {e0:9.3g} {1.0:7.2f} {s0:8d} {1.0:7.2f} "
              f"{setup:8.2f} {run:8.2f} {yee if yee is None else format(yee, '9.3g')!s:>9s} {pml_db(base):>7s}", flush=True)
        rows.append({"case": case, "layout": "yee", "h_ratio": None, "exit": 0, "error": e0, "steps": s0,
                     "setup_seconds": setup, "run_seconds": run, "yee_error": yee, "pml_db": pml_db(base)})
        chosen = layouts if a.layouts is None else [x for x in layouts if x in a.layouts.split(",")]
        runs = [(layout, hr, cp) for layout in chosen for hr in a.h_ratios.split(",") for cp in a.couplings.split(",")]
        for layout, hr, cp in runs:
            if (layout in (None, "yee") and hr == "default" and cp == "default") \
                    or (case in NO_SUPPORT and (hr != "default" or cp != "default")):
                continue
            argv = [case, *extra]
            if layout is not None:
                argv += ["--layout", layout, *NEEDS.get((case, layout), [])]
            if hr != "default":
                argv += ["--h-ratio", hr]
            if cp != "default":
                argv += ["--coupling", cp]
            label = layout if cp == "default" else f"{layout} {cp}"
            code, d, msg, wall = run_cli(argv)
            if d is None:
                print(f"{case:>22s} {label!s:>16s} {hr:>7s} {code:>4d}  refused: {msg[:110]}", flush=True)
                rows.append({"case": case, "layout": layout, "coupling": cp, "h_ratio": hr, "exit": code,
                             "message": msg})
                continue
            e = error_of(d)
            steps = int(d.get("steps", 0))
            ratio = e / e0 if e is not None and e0 else math.nan
            setup, run = timing(d, wall)
            flag = "" if code == 0 else f"  not certified: {msg.split('not certified: ')[-1][:90]}"
            if code == 0 and ratio > a.limit:
                flag = "  VIOLATION"
                violations += 1
            if s0 and steps > 2 * s0:
                flag += "  steps>2x"
            print(f"{case:>22s} {label!s:>16s} {hr:>7s} {code:>4d} {e:9.3g} {ratio:7.2f} {steps:8d} "
                  f"{steps / s0 if s0 else math.nan:7.2f} {setup:8.2f} {run:8.2f} {'':>9s} {pml_db(d):>7s}{flag}",
                  flush=True)
            rows.append({"case": case, "layout": layout, "coupling": cp, "h_ratio": hr, "exit": code, "error": e,
                         "steps": steps,
                         "setup_seconds": setup, "run_seconds": run, "error_ratio": ratio, "pml_db": pml_db(d)})
    print(f"\n{violations} run(s) exit 0 with an error above {a.limit:g}x the default-lattice error")
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
