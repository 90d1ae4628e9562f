"""SPEM: every case at full size, the layout comparison and the particles-per-wavelength table.

Run: .venv/bin/python benchmarks/spem_cases.py  (several minutes: the sbp set-up; prints JSON lines)
"""

from __future__ import annotations

import json
import math

from manifold_sph.spem.analysis import measured_phase_velocity, null_mode_response, phase_velocity, ppw_for_phase_error
from manifold_sph.spem.cases import run_cavity, run_line1d, run_planewave, run_pml, run_waveguide


def show(tag, r):
    print(json.dumps({"run": tag, **r.to_dict()}))


def main():
    show("line1d", run_line1d())
    show("line1d source h=3e-3", run_line1d(h=3e-3))
    show("cavity", run_cavity(n_radial=40, spectrum_periods=10.0))
    show("cavity staggered", run_cavity(n_radial=40, layout="staggered"))
    show("cavity diagonal", run_cavity(n_radial=40, form="diagonal"))
    show("waveguide", run_waveguide())
    for ppw in (20, 30, 40):
        show(f"planewave yee ppw={ppw}", run_planewave(ppw=ppw))
    show("planewave staggered ppw=40", run_planewave(ppw=40, layout="staggered"))
    show("planewave staggered interior source", run_planewave(ppw=20, layout="staggered", source_span="interior"))
    show("planewave yee interior source", run_planewave(ppw=20, layout="yee", source_span="interior"))
    show("pml yee", run_pml())
    show("pml yee n=4", run_pml(order=4))
    show("pml staggered", run_pml(layout="staggered"))
    rows = []
    for layout, hr in (("yee", 0.6), ("yee", 0.7), ("yee", 1.0), ("yee", 1.5), ("staggered", 0.7), ("staggered", 1.5)):
        rows.append({"layout": layout, "h_ratio": hr, "ppw_1pct": ppw_for_phase_error(0.01, layout, h_ratio=hr),
                     "v_phase_20ppw_axis": phase_velocity(20, 0.0, layout, h_ratio=hr),
                     "v_phase_20ppw_diag": phase_velocity(20, math.pi / 4, layout, h_ratio=hr),
                     **null_mode_response(layout, h_ratio=hr)})
    rows.append({"layout": "Yee FDTD (S = 1/sqrt 2)", "ppw_1pct": ppw_for_phase_error(0.01, fdtd=True)})
    for r in rows:
        print(json.dumps({"run": "dispersion", **r}))
    # measured in a PEC square (40 spacings), TM_mm modes: every layout, irregular ones with coupling="sbp"
    for layout, coupling, hr in (("yee", "direct", 0.7), ("yee", "sbp", 0.7), ("staggered", "direct", 0.7),
                                 ("jittered", "sbp", 0.8), ("jittered", "sbp", 1.0), ("poisson", "sbp", 1.0),
                                 ("jittered", "direct", 0.7)):
        try:
            pts = [measured_phase_velocity(layout, m, coupling=coupling, h_ratio=hr) for m in (2, 3, 4, 5, 6, 8)]
        except ValueError as exc:  # the direct coupling is refused where a mode would grow
            print(json.dumps({"run": "measured dispersion", "layout": layout, "coupling": coupling, "h_ratio": hr,
                              "refused": str(exc)}))
            continue
        ok = []  # ppw values (descending) down to the first one that misses 1 %
        for v, p in pts:
            if abs(v - 1) > 0.01:
                break
            ok.append(p)
        print(json.dumps({"run": "measured dispersion", "layout": layout, "coupling": coupling, "h_ratio": hr,
                          "v_phase_by_ppw": {f"{p:.1f}": round(v, 5) for v, p in pts},
                          "smallest_ppw_within_1pct": min(ok) if ok else None}))
    show("planewave jittered sbp h=0.8 ppw=40", run_planewave(ppw=40, layout="jittered", coupling="sbp", h_ratio=0.8,
                                                              size=0.25))
    show("cavity sbp", run_cavity(n_radial=40, coupling="sbp"))


if __name__ == "__main__":
    main()
