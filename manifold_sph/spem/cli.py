"""``manifold-sph spem CASE``: run a SPEM validation case and print its errors.

The main CLI (:mod:`manifold_sph.cli.spem`) registers this subcommand with
:func:`add_parser` and dispatches to :func:`run`; :func:`main` runs it
standalone (``python -m manifold_sph.spem.cli``).

Examples
--------
>>> main(["waveguide", "--ppw", "40", "--json"])  # doctest: +ELLIPSIS
{"case": "waveguide", ...
0
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence

import numpy as np

from .._validation import check_output_path

__all__ = ["add_parser", "run", "main"]


def _positive(kind):
    def conv(text):
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a {kind.__name__}, got {text!r}") from None
        if not v > 0:
            raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
        return v

    return conv


def _periods(text: str) -> float | str:
    """``--periods``: ``auto`` or a positive number."""
    return "auto" if text == "auto" else _positive(float)(text)


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``spem`` subcommand to an ``argparse`` subparsers object and return it."""
    from .cases import CASES
    from .layouts import LAYOUTS
    from .operators import COUPLINGS, DEFAULT_COUPLING, FORMS

    p = subparsers.add_parser("spem", help="SPEM time-domain Maxwell cases (line1d, cavity, waveguide, planewave, pml)",
                              description="Run a SPEM validation case against its exact solution.")
    p.add_argument("case", choices=(*CASES, *SCATTERING_CASES))
    p.add_argument("--layout", default="yee", choices=LAYOUTS + ("poisson-joint", "poisson-balanced"),
                   help="particle layout (default yee; poisson-joint, poisson-balanced: for --coupling mimetic)")
    p.add_argument("--form", default="fpm", choices=FORMS, help="derivative system (default fpm)")
    p.add_argument("--kernel", default="cubic", help="kernel (default cubic)")
    p.add_argument("--h-ratio", type=_positive(float), default=None, help="h / dr (default 0.7; 1.5 with --coupling mimetic)")
    p.add_argument("--coupling", default=DEFAULT_COUPLING, choices=COUPLINGS,
                   help=f"E/H coupling (default {DEFAULT_COUPLING}: energy-conserving on every layout; mimetic: "
                        "energy-conserving and second order on jittered and Poisson layouts, slower set-up; "
                        "direct is refused where it would grow)")
    p.add_argument("--ppw", type=_positive(float), default=None, help="particles per wavelength (planewave, waveguide)")
    p.add_argument("--n-radial", type=_positive(int), default=None, help="cavity: particles along the radius (default 40)")
    p.add_argument("--r0", type=_positive(float), default=None, help="cavity radius (default 0.1 m)")
    p.add_argument("--eps-r", type=_positive(float), default=None, help="cavity permittivity (default 10)")
    p.add_argument("--spectrum-periods", type=_positive(float), default=None,
                   help="cavity: periods recorded for the resonance spectrum")
    p.add_argument("--size", type=_positive(float), default=None, help="planewave: square side (default 0.5 m)")
    p.add_argument("--freq", type=_positive(float), default=None, help="line1d/planewave frequency (Hz)")
    p.add_argument("--pml-cells", type=_positive(int), default=None, help="PML thickness in spacings")
    p.add_argument("--sides", default=None, choices=("mirror", "pml"),
                   help="planewave: side walls, mirror (PMC, exact for the plane wave; default except on the staggered "
                        "layout) or pml (layers)")
    p.add_argument("--png", default=None, help="write the final field to this PNG")
    p.add_argument("--gif", default=None, help="write an animation of the field to this GIF")
    p.add_argument("--frames", type=_positive(int), default=24, help="GIF frames (default 24)")
    p.add_argument("--overwrite", action="store_true", help="allow replacing existing picture files")
    p.add_argument("--progress", action="store_true", help="show a progress bar")
    p.add_argument("--json", action="store_true", help="print JSON")
    _add_scattering_arguments(p)
    return p


_OPTION_CASES = {
    "ppw": ("planewave", "waveguide"), "n_radial": ("cavity",), "r0": ("cavity",), "eps_r": ("cavity",),
    "spectrum_periods": ("cavity",), "size": ("planewave",), "freq": ("line1d", "planewave"),
    "pml_cells": ("planewave", "pml"), "sides": ("planewave",), "layout": ("cavity", "waveguide", "planewave", "pml"),
    "coupling": ("cavity", "waveguide", "planewave", "pml"), "h_ratio": ("cavity", "waveguide", "planewave", "pml"),
}


def _kwargs(args) -> dict:
    from .operators import DEFAULT_COUPLING

    kw = {"form": args.form, "kernel": args.kernel, "progress": args.progress}
    for name, cases in _OPTION_CASES.items():
        v = getattr(args, name)
        if v is None or (name in ("layout", "coupling") and v == {"layout": "yee", "coupling": DEFAULT_COUPLING}[name]):
            continue
        if args.case not in cases:
            raise ValueError(f"--{name.replace('_', '-')} does not apply to case {args.case!r} (only {', '.join(cases)})")
        kw["side" if name == "sides" else name] = v
    if args.png or args.gif:
        if args.case == "pml":
            raise ValueError("pictures are not available for the pml case (it compares probe series)")
        kw["every"] = 1 if args.gif else None  # every step for a GIF (--frames of them drawn), else the final state
    return kw


def _check_target(path, overwrite):
    """The package's one overwrite guard (folder, missing folder, existing file), before the run."""
    if path:
        try:
            check_output_path("output", path, overwrite, hint="--overwrite")
        except (FileExistsError, FileNotFoundError, IsADirectoryError) as exc:
            raise ValueError(str(exc)) from None


def _draw(ax, points, values, vmax):
    if points.shape[1] == 1:
        ax.plot(points[:, 0], values, ".", ms=2)
        ax.set_ylim(-1.1 * vmax, 1.1 * vmax)
        ax.set_xlabel("z (m)")
        return
    ax.scatter(points[:, 0], points[:, 1], c=values, s=2, cmap="RdBu_r", vmin=-vmax, vmax=vmax)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")


def _pictures(result, args):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pts, times, snaps = result.fields.points, result.fields.times, result.fields.snapshots
    if args.gif:  # --frames states, evenly spaced in time, the first and the last among them
        pick = np.unique(np.linspace(0, len(times) - 1, min(args.frames, len(times))).round().astype(int))
        times, snaps = times[pick], snaps[pick]
    vmax = float(abs(snaps).max()) or 1.0
    if args.png:
        fig, ax = plt.subplots(figsize=(5, 4.5))
        _draw(ax, pts, snaps[-1], vmax)
        ax.set_title(f"{result.case}: E at t = {times[-1] * 1e9:.3f} ns")
        fig.savefig(args.png, dpi=110, bbox_inches="tight")
        plt.close(fig)
    if args.gif:
        from matplotlib.animation import FuncAnimation, PillowWriter

        fig, ax = plt.subplots(figsize=(5, 4.5))

        def frame(k):
            ax.clear()
            _draw(ax, pts, snaps[k], vmax)
            ax.set_title(f"{result.case}: E at t = {times[k] * 1e9:.3f} ns")

        FuncAnimation(fig, frame, frames=len(snaps)).save(args.gif, writer=PillowWriter(fps=8))
        plt.close(fig)


def run(args: argparse.Namespace) -> int:
    """Run the ``spem`` subcommand; 0 on success, 2 on a user mistake or a setting outside its validated range,
    3 when the run's certificates (PML reflection, energy drift: :func:`.certify.certificate_failures`) fall
    outside their validated range (the result is printed, the reason on stderr)."""
    from .cases import run_case

    if args.case in SCATTERING_CASES or any(getattr(args, n, None) is not None for n in _SCATTERING_OPTIONS):
        return _run_scattering(args)
    try:
        kw = _kwargs(args)
        if getattr(args, "time_correction", False):
            raise ValueError("--time-correction applies only to the cases scatter-pec, scatter-dielectric, "
                             "scatter-coated")
        if getattr(args, "wall_closure", False):
            raise ValueError("--wall-closure applies only to case 'tez-cavity'")
        if getattr(args, "mimetic_fast", False):
            if args.case != "cavity":
                raise ValueError("--mimetic-fast applies only to the cases cavity, scatter-pec, scatter-dielectric, "
                                 "scatter-coated")
            if args.coupling != "mimetic":
                raise ValueError("--mimetic-fast applies only with --coupling mimetic")
            kw["mimetic_fast"] = True
        _check_target(args.png, args.overwrite)
        _check_target(args.gif, args.overwrite)
        result = run_case(args.case, **kw)
    except (ValueError, TypeError) as exc:
        print(f"manifold-sph spem: error: {exc}", file=sys.stderr)
        return 2
    if args.png or args.gif:
        _pictures(result, args)
    return _report(result, args)


def _report(result, args, extra: dict | None = None) -> int:
    """Print the result (and ``extra``, the CLI's own fields); 0 when certified, 3 (the reasons on stderr) when
    a certificate is outside its range."""
    public = {**result.to_dict(), **(extra or {})}
    if args.json:
        print(json.dumps(public))
    else:
        for k, v in public.items():
            print(f"{k:>28s}  {v:.6g}" if isinstance(v, float) else f"{k:>28s}  {v}")
    failures = getattr(result, "certificate_failures", ())
    if failures:
        print(f"manifold-sph spem: error: the run is not certified: {'; '.join(failures)}", file=sys.stderr)
        return 3
    return 0


# ----------------------------------------------------------------------------- scattering and TEz cases
#: The cylinder scattering cases of :mod:`.scattering` and the TEz cavities of :mod:`.tez`, beside :data:`.cases.CASES`.
SCATTERING_CASES = ("scatter-pec", "scatter-dielectric", "scatter-coated", "tez-cavity", "tez-disk", "tez-scatter-pec",
                    "tez-scatter-dielectric")
_SCATTERING_OPTIONS = ("ka", "core_radius", "periods", "interface")
_NOT_FOR_SCATTERING = ("spectrum_periods", "size", "freq", "pml_cells", "r0", "png", "gif", "ppw")


def _add_scattering_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("scatter-pec, scatter-dielectric, scatter-coated (plane wave on a cylinder of radius "
                             "0.1 m; also --n-radial, default 8, --eps-r, default 4, --layout yee|jittered, "
                             "--coupling, --h-ratio), tez-cavity (TEz modes of a 0.1 x 0.06 m PEC rectangle; "
                             "--n-radial: spacings along 0.06 m, default 12; --layout yee|jittered) and "
                             "tez-disk (TE11 + TE21 of a circular "
                             "PEC cavity of radius 0.1 m, curved walls; --n-radial, default 20; --coupling sbp|adjoint), "
                             "tez-scatter-pec, tez-scatter-dielectric (TEz plane wave on a cylinder of radius 0.1 m: "
                             "exact Hz series, split-field PML; --n-radial, default 8, --eps-r, default 4, --layout "
                             "yee|jittered, --coupling sbp|adjoint, --h-ratio, default 0.8, --ka, --periods, default auto; "
                             "tez-scatter-dielectric: --interface average|corrected|auto)")
    g.add_argument("--ka", type=_positive(float), default=None, help="wavenumber times radius (default 2)")
    g.add_argument("--core-radius", type=_positive(float), default=None,
                   help="scatter-coated: PEC core radius in m (default 0.05)")
    g.add_argument("--periods", type=_periods, default=None,
                   help="scatter-*, tez-scatter-*: periods of the drive, or auto (default: until the steady phasor "
                        "extrapolated from the periods run is steady to 1e-4; the JSON's 'periods', 'transient' and "
                        "'gain' say what ran; a transient left above 1e-3 or a resonant mode (gain above 10) exits 3; "
                        "a number: the Fourier-analysed phasor of its last 2 periods); tez-cavity, tez-disk: periods "
                        "before the error is taken (default 1)")
    g.add_argument("--time-correction", action="store_true",
                   help="scatter-*: remove the leap-frog's time dispersion at the drive frequency (pays with "
                        "--coupling mimetic)")
    g.add_argument("--wall-closure", action="store_true",
                   help="tez-cavity: the walls as closure columns with fitted volumes (the default on jittered layouts "
                        "and with --h-ratio above 0.7; converges on irregular layouts)")
    g.add_argument("--mimetic-fast", action="store_true",
                   help="cavity and scatter-*, with --coupling mimetic: the faster correction (G exact for quadratics)")
    g.add_argument("--interface", choices=("auto", "average", "jump", "corrected"), default=None,
                   help="scatter-dielectric, scatter-coated (auto, average, jump): the permittivity next to "
                        "r = radius (default auto: jump-corrected on the dielectric, cell-averaged on the coated "
                        "cylinder); tez-scatter-dielectric (average, corrected, auto): the anisotropic cell "
                        "average (default), the jump-corrected curl pair (--layout yee, --coupling sbp, "
                        "contrast up to 8 only) or auto (corrected where it runs, else the average); the JSON's "
                        "'average' says which ran")


#: ``--interface`` of ``tez-scatter-dielectric`` -> ``average`` of :func:`.scattering.run_tez_scattering`.
TEZ_CLI_INTERFACES = {"average": "anisotropic", "corrected": "corrected", "auto": "auto"}
#: The default ``--interface`` of ``tez-scatter-dielectric``: the cell average, because with "auto" the
#: jittered run (where "auto" keeps the average) is above 10x the default lattice's (corrected) error;
#: docs/spem.md, "The TEz dielectric".
TEZ_DEFAULT_INTERFACE = "average"


def _tez_interface(choice: str, kw: dict) -> str:
    """The ``average`` of :func:`.scattering.run_tez_scattering` for ``--interface CHOICE``, or a ValueError
    naming the option, its value and what works where the corrected interface cannot run."""
    from .cases.scattering import TEZ_CORRECTED_CONTRAST_MAX

    if choice not in TEZ_CLI_INTERFACES:
        raise ValueError(f"--interface for case 'tez-scatter-dielectric' must be one of "
                         f"{', '.join(TEZ_CLI_INTERFACES)}, got {choice!r}")
    if choice == "corrected":
        eps_r = kw.get("eps_r", 4.0)
        contrast = max(eps_r, 1.0 / eps_r)
        why = None
        if kw["layout"] != "yee":
            why = (f"it is validated on the lattice only (--layout yee), got --layout {kw['layout']!r} (there it "
                   "is less accurate than the cell average: docs/spem.md)")
        elif kw["coupling"] != "sbp":
            why = f"it needs --coupling sbp (the corrected curl pair), got --coupling {kw['coupling']!r}"
        elif contrast > TEZ_CORRECTED_CONTRAST_MAX:
            why = (f"it is validated up to the contrast max(eps_r, 1 / eps_r) = {TEZ_CORRECTED_CONTRAST_MAX:g}, "
                   f"got --eps-r {eps_r:g} (contrast {contrast:g})")
        if why is not None:
            raise ValueError(f"--interface corrected cannot run here: {why}; use --interface auto (the correction "
                             "where it runs, else the cell average) or --interface average")
    return TEZ_CLI_INTERFACES[choice]


def _run_scattering(args: argparse.Namespace) -> int:
    """``spem scatter-*`` (:func:`.scattering.run_scattering`), ``spem tez-cavity`` (:func:`.tez.run_tez_cavity`)
    and ``spem tez-disk`` (:func:`.tez.run_tez_circular_cavity`)."""
    from .cases import run_scattering, run_tez_cavity, run_tez_circular_cavity
    from .operators import DEFAULT_COUPLING

    extra = None
    try:
        if args.case not in SCATTERING_CASES:
            given = [n for n in _SCATTERING_OPTIONS if getattr(args, n) is not None]
            raise ValueError(f"--{given[0].replace('_', '-')} applies only to the cases {', '.join(SCATTERING_CASES)}")
        for name in _NOT_FOR_SCATTERING:
            if getattr(args, name, None) not in (None, False):
                raise ValueError(f"--{name.replace('_', '-')} does not apply to case {args.case!r}")
        tez_cavity = args.case in ("tez-cavity", "tez-disk")
        if args.layout not in ("yee", "jittered") and not (tez_cavity and args.layout == "poisson"):
            allowed = "yee, jittered or poisson" if tez_cavity else "yee or jittered"
            raise ValueError(f"--layout for case {args.case!r} must be {allowed}, got {args.layout!r}")
        kw = {"layout": args.layout, "coupling": args.coupling or DEFAULT_COUPLING}
        if args.wall_closure and args.case != "tez-cavity":
            raise ValueError(f"--wall-closure applies only to case 'tez-cavity', not {args.case!r}")
        if args.case.startswith("tez-scatter-"):
            from .cases import run_tez_scattering

            kind = args.case.rsplit("-", 1)[1]
            for name in ("core_radius", "mimetic_fast", "time_correction") + (("interface",) if kind == "pec" else ()):
                if getattr(args, name) not in (None, False):
                    raise ValueError(f"--{name.replace('_', '-')} does not apply to case {args.case!r}")
            if args.form != "fpm" or args.kernel != "cubic":
                raise ValueError(f"--form and --kernel do not apply to case {args.case!r}")
            if args.eps_r is not None and kind == "pec":
                raise ValueError("--eps-r does not apply to tez-scatter-pec")
            for name in ("n_radial", "eps_r", "h_ratio", "ka", "periods"):
                if getattr(args, name) is not None:
                    kw[name] = getattr(args, name)
            if kind == "dielectric":
                kw["average"] = _tez_interface(args.interface or TEZ_DEFAULT_INTERFACE, kw)
            result = run_tez_scattering(kind, **kw)
            if kind == "dielectric":
                extra = {"interface": {v: k for k, v in TEZ_CLI_INTERFACES.items()}.get(result.average, result.average)}
        elif args.case in ("tez-cavity", "tez-disk"):
            if args.periods == "auto":
                raise ValueError(f"--periods auto applies only to the scattering cases, not {args.case!r} "
                                 "(give a number of periods)")
            for name in ("ka", "core_radius"):
                if getattr(args, name) is not None:
                    raise ValueError(f"--{name.replace('_', '-')} does not apply to case {args.case!r}")
            for flag in ("mimetic_fast", "time_correction", "interface"):
                if getattr(args, flag):
                    raise ValueError(f"--{flag.replace('_', '-')} does not apply to case {args.case!r}")
            n_key = "n" if args.case == "tez-cavity" else "n_radial"
            for name, key in (("n_radial", n_key), ("eps_r", "eps_r"), ("h_ratio", "h_ratio"), ("periods", "periods")):
                if getattr(args, name) is not None:
                    kw[key] = getattr(args, name)
            if args.case == "tez-cavity":
                if args.wall_closure:
                    kw["wall_closure"] = True
                result = run_tez_cavity(**kw)
            else:
                result = run_tez_circular_cavity(**kw)
        else:
            kind = args.case.split("-", 1)[1]
            kw.update(form=args.form, kernel=args.kernel)
            for name in ("n_radial", "eps_r", "h_ratio", "ka", "core_radius", "periods"):
                if getattr(args, name) is not None:
                    kw[name] = getattr(args, name)
            if "core_radius" in kw and kind != "coated":
                raise ValueError("--core-radius applies only to scatter-coated")
            if "eps_r" in kw and kind == "pec":
                raise ValueError("--eps-r does not apply to scatter-pec")
            if args.interface is not None:
                if kind == "pec":
                    raise ValueError("--interface does not apply to scatter-pec")
                if args.interface not in ("auto", "average", "jump"):
                    raise ValueError(f"--interface for case {args.case!r} must be one of auto, average, jump, "
                                     f"got {args.interface!r}")
                kw["interface"] = args.interface
            if args.mimetic_fast:
                if kw["coupling"] != "mimetic":
                    raise ValueError("--mimetic-fast applies only with --coupling mimetic")
                kw["mimetic_fast"] = True
            if args.time_correction:
                kw["time_correction"] = True
            result = run_scattering(kind, **kw)
    except (ValueError, TypeError) as exc:
        print(f"manifold-sph spem: error: {exc}", file=sys.stderr)
        return 2
    return _report(result, args, extra)


def main(argv: Sequence[str] | None = None) -> int:
    """Standalone entry point: ``python -m manifold_sph.spem.cli CASE [options]``."""
    parser = argparse.ArgumentParser(prog="manifold-sph")
    sub = parser.add_subparsers(dest="command", required=True)
    add_parser(sub)
    args = parser.parse_args(["spem", *(sys.argv[1:] if argv is None else argv)])
    return run(args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
