"""Hostile inputs against the public entry points, each outcome classified automatically.

Each case calls one public entry point (``read``, ``write``, ``as_cloud``,
``estimate_normals``, ``Surface`` and its methods, ``Domain2D``, ``pde.heat`` / ``wave`` /
``poisson``, ``viz.render.render_field``, the CLI through ``manifold_sph.cli.app.main``)
with one hostile input and is classified:

- ``clear``: ValueError / TypeError / FileNotFoundError / FileExistsError / ImportError
  (and their subclasses: IsADirectoryError, NotADirectoryError, ReadError) whose message
  names the argument (its name as a word, or the file's path);
- ``misleading``: one of those exceptions whose message does not name it;
- ``crash``: any other exception (IndexError, LinAlgError, numba errors, ...), or a case
  that does not finish within ``--timeout`` seconds;
- ``correct``: returned finite values that agree with an exact or invariant reference
  (each case states its check and tolerance; e.g. a cloud scaled by ``s`` has Laplacian
  ``L f / s^2`` to a relative 1e-6);
- ``warned``: as ``correct``, with a ManifoldSPHWarning;
- ``silent wrong``: returned NaN / inf, or disagreed with the reference, without a warning;
- ``warned wrong``: as ``silent wrong``, with a ManifoldSPHWarning;
- ``returned (unchecked)`` / ``warned (unchecked)``: returned finite values where the case
  has no reference.

A CLI case is ``clear`` when it exits with code 2 and prints exactly one error line
(argparse's usage block aside) naming the option or the file, ``misleading`` when it exits
with 2 otherwise, ``crash`` on any other non-zero code, and ``silent wrong`` when it exits
0 on an input it must refuse.

Every random input is seeded. ``--quick`` runs a handful of cases, among them stubs of
known outcome (a stub raising IndexError must be ``crash``, ...) that test the classifier.

    python benchmarks/hostile_sweep.py [--quick] [--json FILE] [--only WORD] [--timeout S]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import re
import shutil
import signal
import sys
import tempfile
import time
import warnings
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

CLEAR_TYPES = (ValueError, TypeError, FileNotFoundError, FileExistsError, ImportError, IsADirectoryError,
               NotADirectoryError)
PROBLEMS = ("crash", "silent wrong", "warned wrong", "misleading")
OUTCOMES = ("clear", "correct", "warned", "returned (unchecked)", "warned (unchecked)", *PROBLEMS, "skipped")
SCALES = (1e-150, 1e-100, 1e-3, 1e3, 1e100, 1e150)
SCALE_RTOL = 1e-6  # a scaled cloud's results are the unscaled ones times a power of s, to round-off
N_SPHERE = 400


class CaseTimeout(Exception):
    """A case ran longer than its time limit."""


class Skip(Exception):
    """The case depends on a build that was refused (classified elsewhere)."""


@dataclass
class Case:
    """One hostile call: ``run()`` makes it; ``names`` are what a clear refusal must name;
    ``check(value) -> (ok, detail)`` compares a returned value with its reference."""

    name: str
    entry: str
    run: Callable[[], Any]
    names: Sequence[str] = ()
    check: Callable[[Any], tuple[bool, str]] | None = None
    quick: bool = False
    cli: bool = False
    refuse: bool = True  # CLI: exit 0 is wrong


@dataclass
class Outcome:
    case: str
    entry: str
    outcome: str
    message: str
    seconds: float = 0.0
    extra: dict = field(default_factory=dict)


# ------------------------------------------------------------------ the classifier
def names_in(message: str, names: Sequence[str]) -> bool:
    """Whether ``message`` names one of ``names`` (a word, an option such as ``--k``, or a path)."""
    low = message.lower()
    for n in names:
        n = str(n)
        if ("/" in n or "\\" in n) and (n.lower() in low or Path(n).name.lower() in low):
            return True
        if re.search(rf"(?<![\w-]){re.escape(n.lower())}(?![\w])", low):
            return True
    return False


def finite(value: Any) -> bool:
    """Whether every number in a returned value (arrays, tuples, clouds, results) is finite."""
    if value is None or isinstance(value, (str, bytes, Path, bool)):
        return True
    if isinstance(value, (int, float, complex, np.number)):
        return bool(np.isfinite(value))
    if isinstance(value, np.ndarray):
        return value.dtype.kind not in "fc" or bool(np.all(np.isfinite(value)))
    if isinstance(value, dict):
        return all(finite(v) for v in value.values())
    if isinstance(value, (list, tuple)):
        return all(finite(v) for v in value)
    for attr in ("points", "normals", "values", "vectors", "u"):
        v = getattr(value, attr, None)
        if isinstance(v, np.ndarray) and not finite(v):
            return False
    return True


def _alarm(seconds: float):
    def handler(signum, frame):
        raise CaseTimeout(f"did not finish in {seconds:g} s")

    return handler


def run_case(case: Case, timeout: float = 120.0) -> Outcome:
    """Run one case and classify its outcome."""
    from manifold_sph import ManifoldSPHWarning

    t0 = time.perf_counter()
    old = signal.signal(signal.SIGALRM, _alarm(timeout))
    signal.setitimer(signal.ITIMER_REAL, timeout)
    exc: BaseException | None = None
    value = None
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                value = case.run()
            except Skip as e:
                return Outcome(case.name, case.entry, "skipped", str(e), time.perf_counter() - t0)
            except Exception as e:  # noqa: BLE001 - every exception is classified
                exc = e
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    seconds = time.perf_counter() - t0
    if case.cli:
        return _classify_cli(case, value, exc, seconds)
    if exc is not None:
        msg = f"{type(exc).__name__}: {' '.join(str(exc).split())}"
        if isinstance(exc, CLEAR_TYPES) and not isinstance(exc, CaseTimeout):
            kind = "clear" if names_in(str(exc), case.names) else "misleading"
        else:
            kind = "crash"
        return Outcome(case.name, case.entry, kind, msg, seconds)
    ours = [w for w in caught if issubclass(w.category, ManifoldSPHWarning)]
    others = [w for w in caught if not issubclass(w.category, ManifoldSPHWarning)]
    warned = bool(ours)
    note = (" | warning: " + " ".join(str(ours[0].message).split())) if ours else ""
    if others:
        note += f" | {others[0].category.__name__}: " + " ".join(str(others[0].message).split())
    try:
        fin = finite(value)
    except Exception as e:  # noqa: BLE001
        fin, note = False, note + f" | finiteness check failed: {e!r}"
    if not fin:
        return Outcome(case.name, case.entry, "warned wrong" if warned else "silent wrong",
                       "returned NaN or inf" + note, seconds)
    if case.check is None:
        return Outcome(case.name, case.entry, "warned (unchecked)" if warned else "returned (unchecked)",
                       "returned" + note, seconds)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ok, detail = case.check(value)
    except Skip as e:
        return Outcome(case.name, case.entry, "skipped", str(e), seconds)
    except Exception as e:  # noqa: BLE001 - a check that cannot apply means the value is not what it should be
        ok, detail = False, f"check failed on the returned value: {type(e).__name__}: {e}"
    if ok:
        return Outcome(case.name, case.entry, "warned" if warned else "correct", detail + note, seconds)
    return Outcome(case.name, case.entry, "warned wrong" if warned else "silent wrong", detail + note, seconds)


def _classify_cli(case: Case, value, exc, seconds) -> Outcome:
    if exc is not None:
        return Outcome(case.name, case.entry, "crash", f"{type(exc).__name__}: {exc}", seconds)
    code, out, err = value
    lines = [ln for ln in err.splitlines() if ln.strip()]
    # argparse's usage block: 'usage: ...' and its indented continuation lines
    message = [ln for ln in lines if not (ln.startswith("usage:") or ln.startswith(" "))]
    excerpt = " / ".join(message)[:300] or "(no message)"
    if code == 0:
        kind = "silent wrong" if case.refuse else "returned (unchecked)"
        return Outcome(case.name, case.entry, kind, f"exit 0; {excerpt}", seconds)
    if code == 2:
        one = len(message) == 1 and "Traceback" not in err
        kind = "clear" if one and names_in(message[0], case.names) else "misleading"
        return Outcome(case.name, case.entry, kind, f"exit 2; {excerpt}", seconds, {"lines": len(message)})
    return Outcome(case.name, case.entry, "crash", f"exit {code}; {excerpt}", seconds)


def cli(argv: list[str]) -> tuple[int, str, str]:
    """Run ``manifold_sph.cli.app.main(argv)``: (exit code, stdout, stderr)."""
    from manifold_sph.cli.app import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as e:  # argparse's errors
            code = e.code if isinstance(e.code, int) else 1
    return int(code or 0), out.getvalue(), err.getvalue()


# ------------------------------------------------------------------ references
def rel(a, b) -> float:
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape:
        raise ValueError(f"shape {a.shape} where the reference has {b.shape}")
    return float(np.linalg.norm(a - b) / max(np.linalg.norm(b), 1e-300))


def close(a, b, tol: float, what: str) -> tuple[bool, str]:
    e = rel(a, b)
    return e <= tol, f"{what}: relative difference {e:.2e} (tolerance {tol:.0e})"


class Refs:
    """Clean clouds and their results, computed once and kept."""

    def __init__(self) -> None:
        from manifold_sph.reference import shapes

        c = shapes.sphere(N_SPHERE)
        self.P, self.N = c.points.copy(), c.normals.copy()
        self.f = self.P[:, 0] * self.P[:, 1] * self.P[:, 2]  # Lap_S(xyz) = -12 xyz on the unit sphere
        self.x = self.P[:, 0].copy()
        self._memo: dict[Any, Any] = {}
        rng = np.random.default_rng(7)
        g = np.linspace(0.0, 1.0, 22)
        X, Y = np.meshgrid(g, g)
        q = np.column_stack([X.ravel(), Y.ravel()]) + rng.uniform(-0.01, 0.01, (g.size**2, 2))
        self.Q = np.clip(q, 0.0, 1.0)  # a jittered grid of the unit square (msph is exact on quadratics)
        self.tmp = Path(tempfile.mkdtemp(prefix="hostile_sweep_"))

    def memo(self, key, make):
        """``make()`` once per key; an exception is kept and re-raised as Skip."""
        if key not in self._memo:
            try:
                self._memo[key] = ("ok", make())
            except Exception as e:  # noqa: BLE001
                self._memo[key] = ("err", e)
        kind, v = self._memo[key]
        if kind == "err":
            raise Skip(f"{key[0] if isinstance(key, tuple) else key} refused: {type(v).__name__}: {str(v)[:120]}")
        return v

    def surface(self, normals: bool = True):
        from manifold_sph import Surface

        return self.memo(("clean", normals), lambda: Surface(self.P, self.N if normals else None))

    def result(self, what: str, normals: bool = True):
        return self.memo(("ref", what, normals), lambda: METHODS[what][0](self.surface(normals), 1.0, self))


def _heat(s, scale, r):
    from manifold_sph import pde

    return pde.heat(s, r.x, reach=0.1)


def _wave(s, scale, r):
    from manifold_sph import pde

    return pde.wave(s, r.x, reach=0.2)


def _poisson(s, scale, r):
    from manifold_sph import pde

    return pde.poisson(s, -2.0 * r.x / scale**2)  # Lap x = -2 x on the unit sphere


def _dirichlet(s, scale, r):
    from manifold_sph import pde

    held = np.arange(0, len(r.x), 7)
    return pde.poisson(s, -2.0 * r.x / scale**2, dirichlet=(held, r.x[held]))


#: Surface methods on a cloud scaled by ``s``: call(surface, s, refs) and the power of s that
#: maps the value to the unscaled one's (value * s**p == unscaled value), and what to compare.
METHODS: dict[str, tuple[Callable, float, Callable]] = {
    "laplacian": (lambda s, sc, r: s.laplacian(r.f), 2, lambda v: v),
    "gradient": (lambda s, sc, r: s.gradient(r.f), 1, lambda v: v),
    "eigs(10)": (lambda s, sc, r: s.eigs(10), 2, lambda v: v.values),
    "mean_curvature": (lambda s, sc, r: s.mean_curvature(), 1, lambda v: v),
    "geodesic_distance(0)": (lambda s, sc, r: s.geodesic_distance(0), -1, lambda v: v),
    "smooth": (lambda s, sc, r: s.smooth(), -1, lambda v: v.points),
    "pde.heat(reach=0.1)": (_heat, 0, lambda v: v.u),
    "pde.wave(reach=0.2)": (_wave, 0, lambda v: v.u),
    "pde.poisson": (_poisson, 0, lambda v: v),
    "pde.poisson(dirichlet)": (_dirichlet, 0, lambda v: v),
    "laplacian(form='stable')": (lambda s, sc, r: s.laplacian(r.f, form="stable"), 2, lambda v: v),
    "eigs(5, sigma=3 / s^2)": (lambda s, sc, r: s.eigs(5, sigma=3.0 / sc**2), 2, lambda v: v.values),
    "gaussian_curvature": (lambda s, sc, r: s.gaussian_curvature(), 2, lambda v: v),
    "geodesic_distance(0, method='heat')": (lambda s, sc, r: s.geodesic_distance(0, method="heat"), -1, lambda v: v),
    "pde.heat(crank-nicolson)": (lambda s, sc, r: _pde("heat", s, r, method="crank-nicolson"), 0, lambda v: v.u),
    "pde.heat(explicit)": (lambda s, sc, r: _pde("heat", s, r, method="explicit"), 0, lambda v: v.u),
    "pde.heat(laplacian='stable')": (lambda s, sc, r: _pde("heat", s, r, laplacian="stable"), 0, lambda v: v.u),
    "pde.wave(laplacian='stable')": (lambda s, sc, r: _pde("wave", s, r, laplacian="stable"), 0, lambda v: v.u),
}


def _pde(name, s, r, **kw):
    from manifold_sph import pde

    return getattr(pde, name)(s, r.x, reach=0.1, **kw)


def _exact_checks(r: Refs) -> dict[str, Callable[[Any], tuple[bool, str]]]:
    """Checks of the clean sphere's results against the exact ones (tolerances for 400 Fibonacci points)."""
    P, f, x = r.P, r.f, r.x
    lam = np.array([0, 2, 2, 2, 6, 6, 6, 6, 6, 12.0])
    geo = np.arccos(np.clip(P @ P[0], -1, 1))
    return {
        "laplacian": lambda v: close(v, -12 * f, 0.05, "Lap(xyz) vs -12 xyz"),
        "gradient": lambda v: close(v, np.column_stack([P[:, 1] * P[:, 2], P[:, 0] * P[:, 2], P[:, 0] * P[:, 1]])
                                    - 3 * f[:, None] * P, 0.1, "grad(xyz) vs its tangential part"),
        "eigs(10)": lambda v: (bool(np.abs(v.values - lam).max() < 0.1 * 12), f"eigenvalues vs l(l+1): max "
                                                                             f"difference {np.abs(v.values - lam).max():.3f} (tol 1.2)"),
        "mean_curvature": lambda v: (bool(np.abs(v - 1).max() < 0.02), f"H vs 1: max |H-1| {np.abs(v - 1).max():.2e} (tol 0.02)"),
        "geodesic_distance(0)": lambda v: (bool(np.abs(v - geo).max() < 0.15), f"vs arccos(p0.p): max "
                                                                               f"{np.abs(v - geo).max():.3f} (tol 0.15)"),
        "smooth": lambda v: (bool(np.abs(np.linalg.norm(v.points, axis=1) - 1).max() < 0.01),
                             f"smoothed points off the sphere by {np.abs(np.linalg.norm(v.points, axis=1) - 1).max():.1e} (tol 1e-2)"),
        "pde.heat(reach=0.1)": lambda v: close(v.u, x * np.exp(-2 * v.times[-1]), 0.02, "heat of x vs x exp(-2t)"),
        "pde.wave(reach=0.2)": lambda v: close(v.u, x * np.cos(math.sqrt(2) * v.times[-1]), 0.05,
                                               "wave of x vs x cos(sqrt2 t)"),
        "pde.poisson": lambda v: close(v, x, 0.05, "Lap u = -2x vs u = x"),
        "pde.poisson(dirichlet)": lambda v: close(v, x, 0.05, "Lap u = -2x, u = x at every 7th vs u = x"),
        "laplacian(form='stable')": lambda v: close(v, -12 * f, 0.25, "stable Lap(xyz) vs -12 xyz"),
        "eigs(5, sigma=3 / s^2)": lambda v: (bool(np.abs(np.sort(v.values) - [2, 2, 2, 6, 6]).max() < 0.6),
                                             f"5 nearest 3 vs 2,2,2,6,6: {np.round(np.sort(v.values), 3).tolist()} (tol 0.6)"),
        "gaussian_curvature": lambda v: (bool(np.abs(v - 1).max() < 0.05), f"K vs 1: max |K-1| {np.abs(v - 1).max():.2e} (tol 0.05)"),
        "geodesic_distance(0, method='heat')": lambda v: (bool(np.abs(v - geo).max() < 0.15),
                                                          f"vs arccos(p0.p): max {np.abs(v - geo).max():.3f} (tol 0.15)"),
        "pde.heat(crank-nicolson)": lambda v: close(v.u, x * np.exp(-2 * v.times[-1]), 0.02, "heat of x vs x exp(-2t)"),
        "pde.heat(explicit)": lambda v: close(v.u, x * np.exp(-2 * v.times[-1]), 0.02, "heat of x vs x exp(-2t)"),
        "pde.heat(laplacian='stable')": lambda v: close(v.u, x * np.exp(-2 * v.times[-1]), 0.02, "heat of x vs x exp(-2t)"),
        "pde.wave(laplacian='stable')": lambda v: close(v.u, x * np.cos(math.sqrt(2) * v.times[-1]), 0.05,
                                                        "wave of x vs x cos(sqrt2 t)"),
    }


def expect_refusal(value) -> tuple[bool, str]:
    return False, f"returned {type(value).__name__} where a refusal was expected"


# ------------------------------------------------------------------ the table of cases
def _wrap_method(r: Refs, key, build: Callable, what: str, scale: float, ref_normals: bool, tol: float,
                 transform=None) -> Case:
    call, power, pick = METHODS[what]

    def run():
        s = r.memo(key, build)
        return call(s, scale, r)

    def check(v):
        base = pick(r.result(what, ref_normals))
        got = np.asarray(pick(v), dtype=float) * scale**power
        if transform is not None:
            got = transform(what, got)
        return close(got, base, tol, f"{what} * s^{power:g} vs the clean cloud's")

    return Case(f"{key[0]}", f"Surface.{what}" if not what.startswith("pde") else what, run, ("points",), check)


def surface_cases(r: Refs) -> list[Case]:
    from manifold_sph import Surface, as_cloud, estimate_normals
    from manifold_sph.reference import shapes

    cases: list[Case] = []
    P, N, f = r.P, r.N, r.f
    n = len(P)
    exact = _exact_checks(r)

    # the clean cloud against the exact references
    for what in METHODS:
        call = METHODS[what][0]
        cases.append(Case("clean sphere (exact normals)", f"Surface.{what}", lambda c=call: c(r.surface(True), 1.0, r),
                          (), exact[what], quick=what == "laplacian"))

    # scale: results equal the unscaled ones times a power of s
    for normals in (True, False):
        for s in SCALES:
            tag = f"sphere x {s:g}" + ("" if normals else " bare")
            key = (tag,)
            pts, nrm = P * s, (N if normals else None)
            cases.append(Case(tag, "Surface", lambda p=pts, q=nrm, k=key: _build_kept(r, k, lambda: Surface(p, q)),
                              ("points", "normals"),
                              lambda v, s_=s, nm=normals: close(v.laplacian(f) * s_**2, r.result("laplacian", nm),
                                                                 SCALE_RTOL, "Lap f * s^2 vs unscaled")))
            for what in METHODS:
                cases.append(_wrap_method(r, key, lambda p=pts, q=nrm: Surface(p, q), what, s, normals, SCALE_RTOL))
    rnd = shapes.sphere(N_SPHERE, sampling="random", seed=1)
    fr = rnd.points.prod(axis=1)
    for scheme in ("cspm", "standard", "ncsph", "msph4"):
        for pts0, nrm0, g, tag0 in ((P, N, f, "sphere"), (rnd.points, rnd.normals, fr, "random sphere")):
            key0 = ("scheme", scheme, tag0)
            make = (lambda p=pts0, q=nrm0, sc=scheme, g_=g: Surface(p, q, scheme=sc).laplacian(g_))
            for s in (1.0, *SCALES):
                if s != 1.0:
                    check = (lambda v, s_=s, k=key0, mk=make: close(v * s_**2, r.memo(k, mk), SCALE_RTOL, "Lap f * s^2 vs unscaled"))
                elif scheme == "standard" and tag0 == "random sphere":
                    check = None  # standard SPH is not consistent on irregular points (docs): no exact reference
                else:
                    check = (lambda v, g_=g: close(v, -12 * g_, 0.3, "Lap(xyz) vs -12 xyz"))
                cases.append(Case(f"{tag0} x {s:g}, scheme={scheme}", "Surface.laplacian",
                                  lambda p=pts0, q=nrm0, s_=s, sc=scheme, g_=g: Surface(p * s_, q, scheme=sc).laplacian(g_),
                                  ("points",), check))
    for s in SCALES:
        cases.append(Case(f"sphere x {s:g} bare", "estimate_normals", lambda s_=s: estimate_normals(P * s_),
                          ("points",), lambda v: close(v, r.memo("normals", lambda: estimate_normals(P)), SCALE_RTOL,
                                                       "normals vs the unscaled cloud's")))

    # noisy bare clouds (issue 38 item 0): they build; rotated, the same spectrum
    lam = np.array([2, 2, 2, 6, 6, 6, 6, 6, 12.0])
    for sigma in (0.5, 1.0):
        for seed in range(3):
            c = shapes.sphere(2000)
            q = c.points + sigma * math.sqrt(4 * math.pi / 2000) * np.random.default_rng(seed).normal(size=c.points.shape)
            key = (f"noisy sphere (2000, {sigma} spacing, seed {seed})",)
            cases.append(Case(key[0], "Surface", lambda q_=q, k=key: _build_kept(r, k, lambda: Surface(q_)), ("points",),
                              lambda v: (bool(np.abs(v.eigs(10).values[1:] / lam - 1).max() < 0.25),
                                         f"eigenvalues 1-9 vs l(l+1): max relative {np.abs(v.eigs(10).values[1:] / lam - 1).max():.3f} "
                                         "(tol 0.25, noisy)")))
            Qr, _ = np.linalg.qr(np.random.default_rng(100 + seed).normal(size=(3, 3)))
            outward = q / np.linalg.norm(q, axis=1)[:, None]
            for rot, tag in ((np.eye(3), ""), (Qr, " rotated")):
                cases.append(Case(key[0] + tag, "estimate_normals", lambda q_=q, Q_=rot: estimate_normals(q_ @ Q_.T) @ Q_,
                                  ("points",), lambda v, o=outward: (bool(np.all(np.einsum("ij,ij->i", v, o) > 0)),
                                                                     f"{int(np.sum(np.einsum('ij,ij->i', v, o) <= 0))} of "
                                                                     f"{len(v)} normals point inward")))
            cases.append(Case(key[0] + " rotated", "Surface.eigs(10)",
                              lambda q_=q, Q_=Qr: Surface(q_ @ Q_.T).eigs(10), ("points",),
                              lambda v, k=key: close(v.values, r.memo(k, lambda: None).eigs(10).values, 1e-6,
                                                     "eigenvalues vs the unrotated noisy cloud's")))
    # adaptive h at every scale
    for s in SCALES:
        ref_key = ("adaptive",)
        cases.append(Case(f"sphere x {s:g}, h='adaptive'", "Surface.laplacian",
                          lambda s_=s: Surface(P * s_, N, h="adaptive").laplacian(f), ("points", "h"),
                          lambda v, s_=s, k=ref_key: close(v * s_**2, r.memo(k, lambda: Surface(P, N, h="adaptive").laplacian(f)),
                                                           SCALE_RTOL, "Lap f * s^2 vs unscaled")))

    # translation and rotation: the same operators
    rng = np.random.default_rng(3)
    Qm, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    Qm *= np.sign(np.linalg.det(Qm))
    moved = {
        "sphere + (1e3, -2e3, 5e2)": (P + [1e3, -2e3, 5e2], N, 1e-4, None),  # round-off moves support-boundary ties
        "sphere + 1e6": (P + 1e6, N, 1e-3, None),
        "sphere rotated": (P @ Qm.T, N @ Qm.T, 1e-6, Qm),
    }
    for tag, (pts, nrm, tol, rot) in moved.items():
        key = (tag,)
        cases.append(Case(tag, "Surface", lambda p=pts, q=nrm, k=key: _build_kept(r, k, lambda: Surface(p, q)), (),
                          lambda v, t=tol: close(v.laplacian(f), r.result("laplacian"), t, "Lap f vs the original's")))

        def tr(what, got, rot=rot):
            return got @ rot if rot is not None and what == "gradient" else got  # rotate the vectors back

        for what in ("eigs(10)", "mean_curvature", "geodesic_distance(0)", "gradient", "pde.heat(reach=0.1)"):
            cases.append(_wrap_method(r, key, lambda p=pts, q=nrm: Surface(p, q), what, 1.0, True, tol, tr))

    # duplicates, outliers, clusters
    dup = np.arange(0, n, 13)
    Pd, Nd = np.vstack([P, P[dup]]), np.vstack([N, N[dup]])
    cases.append(Case("exact duplicates (array)", "Surface", lambda: Surface(Pd, Nd), ("points", "duplicates"),
                      expect_refusal))
    cases.append(Case("exact duplicates merged", "as_cloud+Surface",
                      lambda: Surface(as_cloud(Pd, normals=Nd, duplicates="merge")), ("points",),
                      lambda v: close(v.laplacian(np.concatenate([f, f[dup]])[: v.n_points]) if v.n_points == n
                                      else v.laplacian(np.concatenate([f, f[dup]])), r.result("laplacian") if v.n_points == n
                                      else np.concatenate([r.result("laplacian"), r.result("laplacian")[dup]]), 1e-8,
                                      "merged cloud's Lap f vs the clean one")))
    near = P[dup] + 1e-9 * rng.normal(size=(dup.size, 3))
    Pn, Nn = np.vstack([P, near]), np.vstack([N, N[dup]])
    fn = Pn[:, 0] * Pn[:, 1] * Pn[:, 2]
    cases.append(Case("near duplicates (1e-9)", "Surface", lambda: Surface(Pn, Nn), ("points", "duplicates"),
                      lambda v: close(v.laplacian(fn)[:n], r.result("laplacian"), 0.02, "Lap f on the originals vs clean")))
    cases.append(Case("near duplicates (1e-9) bare", "Surface", lambda: Surface(Pn), ("points", "duplicates"),
                      lambda v: close(v.laplacian(fn)[:n], r.result("laplacian", False), 0.05,
                                      "Lap f on the originals vs clean bare")))
    Po, No = np.vstack([P, [[1e6, 0, 0]]]), np.vstack([N, [[1.0, 0, 0]]])
    fo = Po[:, 0] * Po[:, 1] * Po[:, 2]

    def outlier_check(v, nm=True):
        ok1, d1 = close(v.laplacian(fo)[:n], r.result("laplacian", nm), 0.05, "Lap f on the sphere vs clean")
        area = float(np.sum(v.area.dV[:n]))
        ok2 = abs(area - 4 * np.pi) < 0.05 * 4 * np.pi
        return ok1 and ok2, f"{d1}; sphere's area {area:.3f} vs 4 pi (tol 5%)"

    cases.append(Case("one far outlier (1e6)", "Surface", lambda: Surface(Po, No), ("points",), outlier_check))
    cases.append(Case("one far outlier (1e6) bare", "Surface", lambda: Surface(Po), ("points",),
                      lambda v: outlier_check(v, False)))
    Pc, Nc = np.vstack([P, P + [1e4, 0, 0]]), np.vstack([N, N])
    fc = np.concatenate([f, f])
    cases.append(Case("two far clusters (1e4)", "Surface", lambda: _build_kept(r, ("clusters",), lambda: Surface(Pc, Nc)),
                      ("points",), lambda v: close(v.laplacian(fc), np.concatenate([r.result("laplacian")] * 2), 1e-4,
                                                   "Lap f on each cluster vs clean")))
    cases.append(Case("two far clusters (1e4)", "Surface.eigs(10)",
                      lambda: r.memo(("clusters",), lambda: Surface(Pc, Nc)).eigs(10), ("k",),
                      lambda v: close(v.values, r.result("eigs(10)").values, 1e-4,
                                      "eigenvalues vs the one sphere's (largest component)")))

    # lines and planes
    t = np.linspace(0, 1, 300)
    line = np.column_stack([t, 2 * t, -t])
    cases.append(Case("collinear points", "Surface", lambda: Surface(line), ("points",), expect_refusal))
    cases.append(Case("collinear points", "estimate_normals", lambda: estimate_normals(line), ("points",), expect_refusal))
    Q3 = np.column_stack([r.Q, np.zeros(len(r.Q))])
    inner = np.all((r.Q > 0.25) & (r.Q < 0.75), axis=1)
    fq = r.Q[:, 0] ** 2 + r.Q[:, 1] ** 2
    plane_check = lambda v: close(v.laplacian(fq)[inner], np.full(inner.sum(), 4.0), 0.05, "Lap(x^2+y^2) = 4 inside")  # noqa: E731
    cases.append(Case("planar points + normals", "Surface", lambda: Surface(Q3, np.tile([0, 0, 1.0], (len(Q3), 1))),
                      ("points",), plane_check))
    cases.append(Case("planar points bare", "Surface", lambda: Surface(Q3), ("points",), plane_check))
    cases.append(Case("planar points", "estimate_normals", lambda: estimate_normals(Q3), ("points",),
                      lambda v: (bool(np.abs(v[:, 2]).min() > 0.99 and abs(v[:, 2].sum()) == len(v) * abs(v[:, 2]).mean()),
                                 f"min |n_z| {np.abs(v[:, 2]).min():.4f}, all one orientation "
                                 f"{bool(np.all(v[:, 2] > 0) or np.all(v[:, 2] < 0))}")))

    # normals: zero, non-unit, NaN, wrong shape
    Nz = N.copy()
    Nz[::50] = 0.0
    cases.append(Case("8 zero normals", "Surface", lambda: Surface(P, Nz), ("normals",),
                      lambda v: close(v.laplacian(f), r.result("laplacian"), 0.05, "Lap f vs clean")))
    scale_rows = np.random.default_rng(4).uniform(0.1, 10, (n, 1))
    cases.append(Case("non-unit normals (x0.1..10)", "Surface", lambda: Surface(P, N * scale_rows), ("normals",),
                      lambda v: close(v.laplacian(f), r.result("laplacian"), 1e-10, "Lap f vs unit normals'")))
    for tag, bad in (("NaN normal", np.nan), ("inf normal", np.inf)):
        Nb = N.copy()
        Nb[5, 1] = bad
        cases.append(Case(tag, "Surface", lambda b=Nb: Surface(P, b), ("normals",), expect_refusal))
    cases.append(Case("normals (N-1, 3)", "Surface", lambda: Surface(P, N[:-1]), ("normals",), expect_refusal))
    cases.append(Case("normals (N, 2)", "Surface", lambda: Surface(P, N[:, :2]), ("normals",), expect_refusal))
    cases.append(Case("normals as a string", "Surface", lambda: Surface(P, "up"), ("normals",), expect_refusal))
    return cases


def _build_kept(r: Refs, key, make):
    """Build through the memo so that the method rows reuse it, and re-raise a refusal."""
    try:
        return r.memo(key, make)
    except Skip:
        return make()  # the refusal itself, for this row to classify


def shape_cases(r: Refs) -> list[Case]:
    """Wrong shapes and types at every entry point that takes points."""
    from manifold_sph import Domain2D, Surface, as_cloud, estimate_normals, write

    P = r.P
    rng = np.random.default_rng(11)
    bad = {
        "(N, 2) points": P[:, :2].copy(),
        "(N, 4) points": np.column_stack([P, P[:, 0]]),
        "1-D points": P[:, 0].copy(),
        "3-D points": P[:, :, None].copy(),
        "(3, N) points": P.T.copy(),
        "empty (0, 3)": np.zeros((0, 3)),
        "one point": P[:1].copy(),
        "two points": P[:2].copy(),
        "NaN in points": np.where(np.arange(len(P))[:, None] == 7, np.nan, P),
        "inf in points": np.where(np.arange(len(P))[:, None] == 7, np.inf, P),
        "string": "not a cloud at all",
        "dict": {"points": P},
        "complex points": P.astype(complex) + 1j,
        "object array": np.array(P.tolist() + [[1, "a", None]], dtype=object),
        "bool array": rng.random((len(P), 3)) > 0.5,
        "list of str": [["a", "b", "c"]] * 20,
        "None": None,
    }
    targets: dict[str, Callable] = {
        "Surface": lambda p: Surface(p),
        "as_cloud": lambda p: as_cloud(p),
        "estimate_normals": lambda p: estimate_normals(p),
        "Domain2D": lambda p: Domain2D(p),
        "write": lambda p: write(r.tmp / f"w{rng.integers(1 << 30)}.ply", p),
    }
    cases = []
    for tag, p in bad.items():
        for entry, fn in targets.items():
            if entry == "Domain2D" and tag == "(N, 2) points":
                continue  # valid planar input (the Domain2D rows below)
            names = ("points", "cloud", "obj") if entry in ("write", "as_cloud") else ("points",)
            if entry == "write" and tag == "string":
                continue
            if tag == "string":
                names = names + ("not a cloud at all",)
            check = expect_refusal
            if entry == "write" and tag in ("one point", "two points"):
                check = None  # documented: write takes any non-empty cloud
            cases.append(Case(tag, entry, lambda f_=fn, p_=p: f_(p_), names, check, quick=tag == "(N, 2) points"
                              and entry == "Surface"))
    # integer coordinates are coordinates
    Pi = np.round(P * 100).astype(np.int64)
    cases.append(Case("int64 points", "Surface", lambda: Surface(Pi), ("points",),
                      lambda v: close(v.laplacian(r.f), r.memo(("int", 0), lambda: Surface(Pi.astype(float))).laplacian(r.f),
                                      1e-12, "vs the float64 copy")))
    return cases


def field_cases(r: Refs) -> list[Case]:
    """Bad fields and options to the operators, curvature, geodesics, eigs and the PDEs."""
    from manifold_sph import Surface, pde

    P, N, f = r.P, r.N, r.f
    n = len(P)
    S = r.surface  # the clean sphere with exact normals
    fnan, finf = f.copy(), f.copy()
    fnan[3], finf[3] = np.nan, np.inf
    f2 = P[:, 1].copy()
    cases: list[Case] = []
    for tag, g in (("NaN in f", fnan), ("inf in f", finf), ("f of N-1", f[:-1]), ("f (N, 2)", np.column_stack([f, f])),
                   ("f as a string", "xyz"), ("f as a dict", {"f": f})):
        cases.append(Case(tag, "Surface.laplacian", lambda g_=g: S().laplacian(g_), ("f",), expect_refusal,
                          quick=tag == "NaN in f"))
        cases.append(Case(tag, "Surface.gradient", lambda g_=g: S().gradient(g_), ("f",), expect_refusal))
    lin = lambda v, a, b: close(v, S().laplacian(a) + (1j * S().laplacian(b) if b is not None else 0), 1e-12,  # noqa: E731
                                "vs L applied to its parts")
    cases.append(Case("complex f", "Surface.laplacian", lambda: S().laplacian(f + 1j * f2), ("f",),
                      lambda v: lin(v, f, f2)))
    cases.append(Case("bool f", "Surface.laplacian", lambda: S().laplacian(f > 0), ("f",),
                      lambda v: lin(v, (f > 0).astype(float), None)))
    cases.append(Case("object-array f", "Surface.laplacian", lambda: S().laplacian(np.array(f.tolist(), dtype=object)),
                      ("f",), lambda v: lin(v, f, None)))
    cases.append(Case("int f", "Surface.laplacian", lambda: S().laplacian(np.arange(n)), ("f",),
                      lambda v: lin(v, np.arange(n, dtype=float), None)))

    # options of Surface
    cases.append(Case("h=1e-12", "Surface", lambda: Surface(P, N, h=1e-12), ("h",),
                      lambda v: close(v.laplacian(f), -12 * f, 0.05, "Lap(xyz) vs -12 xyz")))
    for opt, vals in (("h", (np.nan, -1.0, 0.0, np.inf, "big")), ("neighbors", (0, -5, 2.5, np.nan, 10**9, True, "27")),
                      ("normal_threshold", (np.nan, 2.0, -2.0)), ("max_condition", (np.nan, -1.0)),
                      ("scheme", ("bogus", 3)), ("kernel", ("bogus",)), ("area", ("bogus",))):
        for val in vals:
            cases.append(Case(f"{opt}={val!r}", "Surface", lambda o=opt, v=val: Surface(P, N, **{o: v}), (opt,),
                              expect_refusal))
    cases.append(Case("neighbors=5000 (> N)", "Surface", lambda: Surface(P, N, neighbors=5000), ("neighbors",), None))

    # eigs
    geo0 = lambda: r.result("geodesic_distance(0)")  # noqa: E731
    for val in (0, -1, n, n + 5, 2.5, "10", np.nan, True, None):
        cases.append(Case(f"eigs(k={val!r})", "Surface.eigs", lambda v=val: S().eigs(v), ("k",), expect_refusal))
    cases.append(Case("eigs(10, sigma=nan)", "Surface.eigs", lambda: S().eigs(10, sigma=np.nan), ("sigma",), expect_refusal))
    cases.append(Case("eigs(10, component='bogus')", "Surface.eigs", lambda: S().eigs(10, component="bogus"),
                      ("component",), expect_refusal))
    cases.append(Case("eigs(n - 2)", "Surface.eigs", lambda: S().eigs(n - 2), ("k",),
                      lambda v: (v.values.size == n - 2 and bool(np.all(np.diff(v.values) >= -1e-9)),
                                 f"{v.values.size} ascending eigenvalues")))
    # geodesics
    for val in (n, -n - 1, 2.5, "0", np.nan, [], [0, n], None):
        cases.append(Case(f"geodesic_distance({val!r})", "Surface.geodesic_distance",
                          lambda v=val: S().geodesic_distance(v), ("sources", "source"), expect_refusal))
    cases.append(Case("geodesic_distance(-1)", "Surface.geodesic_distance", lambda: S().geodesic_distance(-1),
                      ("sources", "source"), lambda v: close(v, S().geodesic_distance(n - 1), 1e-12,
                                                             "vs the distance from particle N-1")))
    cases.append(Case("geodesic_distance(0, to=n)", "Surface.geodesic_distance", lambda: S().geodesic_distance(0, to=n),
                      ("to",), expect_refusal))
    cases.append(Case("geodesic_distance(0, method='bogus')", "Surface.geodesic_distance",
                      lambda: S().geodesic_distance(0, method="bogus"), ("method",), expect_refusal))
    cases.append(Case("geodesic_distance([0, 0])", "Surface.geodesic_distance", lambda: S().geodesic_distance([0, 0]),
                      ("sources",), lambda v: close(v, geo0(), 1e-12, "vs the distance from 0")))
    # curvature, smoothing
    for kw in ({"method": "bogus"}, {"scale": -1.0}, {"scale": np.nan}, {"scale": 0.0}, {"scale": "big"}):
        cases.append(Case(f"mean_curvature({kw})", "Surface.mean_curvature", lambda k=kw: S().mean_curvature(**k),
                          tuple(kw), expect_refusal))
    for kw in ({"method": "bogus"}, {"scale": -1.0}, {"scale": np.nan}, {"iterations": -1}, {"iterations": 2.5}):
        cases.append(Case(f"smooth({kw})", "Surface.smooth", lambda k=kw: S().smooth(**k), tuple(kw), expect_refusal))
    cases.append(Case("smooth(iterations=0)", "Surface.smooth", lambda: S().smooth(iterations=0), ("iterations",),
                      lambda v: close(v.points, P, 0.0, "vs the unsmoothed points")))

    # PDEs
    x = r.x
    for fn_name in ("heat", "wave"):
        fn = getattr(pde, fn_name)
        opts: list[tuple[str, dict]] = [
            ("reach", {"reach": np.nan}), ("reach", {"reach": -1.0}), ("reach", {"reach": 0.0}), ("reach", {"reach": np.inf}),
            ("dt", {"dt": np.nan, "steps": 5}), ("dt", {"dt": -1.0, "steps": 5}), ("dt", {"dt": 0.0, "steps": 5}),
            ("dt", {"dt": np.inf, "steps": 5}), ("steps", {"dt": 1e-3, "steps": -1}), ("steps", {"dt": 1e-3, "steps": 2.5}),
            ("steps", {"dt": 1e-3, "steps": np.nan}), ("fixed", {"reach": 0.1, "fixed": [n]}),
            ("fixed", {"reach": 0.1, "fixed": [0.5]}), ("every", {"reach": 0.1, "every": 0}),
            ("callback", {"reach": 0.1, "callback": 3}), ("u0", {"reach": 0.1, "_u0": np.where(np.arange(n) == 2, np.nan, x)}),
            ("u0", {"reach": 0.1, "_u0": x[:-1]}), ("reach", {"reach": 0.1, "t_end": 1.0}),
        ]
        if fn_name == "heat":
            opts += [("diffusivity", {"reach": 0.1, "diffusivity": v}) for v in (0.0, -1.0, np.nan, np.inf)]
            opts += [("method", {"reach": 0.1, "method": "bogus"}), ("dt", {"dt": 1.0, "steps": 3, "method": "explicit"})]
        else:
            opts += [("c", {"reach": 0.1, "c": v}) for v in (0.0, -1.0, np.nan)]
            opts += [("v0", {"reach": 0.1, "v0": np.where(np.arange(n) == 2, np.nan, x)}),
                     ("dt", {"dt": 10.0, "steps": 3})]
        for name, kw in opts:
            kw = dict(kw)
            u0 = kw.pop("_u0", x)
            cases.append(Case(f"{fn_name}({', '.join(f'{k}={v!r}' for k, v in kw.items() if k != 'fixed') or ''}"
                              f"{'fixed=' + repr(kw['fixed']) if 'fixed' in kw else ''}{'bad u0' if name == 'u0' else ''})",
                              f"pde.{fn_name}", lambda f_=fn, u=u0, k=kw: f_(S(), u, **k),
                              (name, "t_end") if name == "reach" else (name,), expect_refusal))
        cases.append(Case(f"{fn_name}(steps=0)", f"pde.{fn_name}", lambda f_=fn: f_(S(), x, dt=1e-3, steps=0), ("steps",),
                          lambda v: close(v.u, x, 0.0, "vs u0")))
        cases.append(Case(f"{fn_name}(fixed=[-1])", f"pde.{fn_name}", lambda f_=fn: f_(S(), x, reach=0.1, fixed=[-1]),
                          ("fixed",), lambda v: (bool(v.u[-1] == x[-1]), f"u[-1] {v.u[-1]:.6g} held at {x[-1]:.6g}")))
    cases.append(Case("heat(laplacian=complex matrix)", "pde.heat",
                      lambda: pde.heat(S(), x, reach=0.1, laplacian=S().laplacian_matrix() * (1 + 1j)),
                      ("laplacian",), expect_refusal))
    for tag, rhs, kw, nm in (("NaN rhs", np.where(np.arange(n) == 2, np.nan, -2 * x), {}, "rhs"),
                             ("rhs of N-1", (-2 * x)[:-1], {}, "rhs"), ("non-zero-mean rhs", np.ones(n), {}, "rhs"),
                             ("dirichlet index n", -2 * x, {"dirichlet": ([n], [0.0])}, "dirichlet"),
                             ("dirichlet NaN value", -2 * x, {"dirichlet": ([0], [np.nan])}, "dirichlet"),
                             ("dirichlet lengths differ", -2 * x, {"dirichlet": ([0, 1], [0.0])}, "dirichlet"),
                             ("tol=nan", -2 * x, {"tol": np.nan}, "tol"), ("tol=-1", -2 * x, {"tol": -1.0}, "tol"),
                             ("solver='bogus'", -2 * x, {"solver": "bogus"}, "solver")):
        cases.append(Case(f"poisson({tag})", "pde.poisson", lambda b=rhs, k=kw: pde.poisson(S(), b, **k), (nm,),
                          expect_refusal))
    cases.append(Case("poisson(dirichlet at x)", "pde.poisson",
                      lambda: pde.poisson(S(), -2 * x, dirichlet=(np.arange(0, n, 7), x[::7])), ("dirichlet",),
                      lambda v: close(v, x, 0.02, "vs u = x")))
    return cases


def domain_cases(r: Refs) -> list[Case]:
    from manifold_sph import Domain2D

    Q = r.Q
    fq = Q[:, 0] ** 2 + Q[:, 0] * Q[:, 1]  # Lap = 2 exactly for msph
    cases: list[Case] = []
    for s in (1.0, *SCALES):
        cases.append(Case(f"square x {s:g}", "Domain2D", lambda s_=s: Domain2D(Q * s_), ("points",),
                          lambda v, s_=s: close(v.laplacian(fq) * s_**2, np.full(len(Q), 2.0), 1e-6,
                                                "Lap(x^2+xy) * s^2 vs 2")))
    Q3 = np.column_stack([Q, np.full(len(Q), 5.0)])
    cases.append(Case("(N, 3) at z = 5", "Domain2D", lambda: Domain2D(Q3), ("points",),
                      lambda v: close(v.laplacian(fq), np.full(len(Q), 2.0), 1e-6, "Lap(x^2+xy) vs 2")))
    Qn = np.column_stack([Q, np.random.default_rng(5).normal(size=len(Q))])
    cases.append(Case("(N, 3) not planar", "Domain2D", lambda: Domain2D(Qn), ("points",), expect_refusal))
    cases.append(Case("duplicates", "Domain2D", lambda: Domain2D(np.vstack([Q, Q[:5]])), ("points",), expect_refusal))
    cases.append(Case("near duplicates (1e-12)", "Domain2D", lambda: Domain2D(np.vstack([Q, Q[:5] + 1e-12])),
                      ("points",), lambda v: close(v.laplacian(np.concatenate([fq, fq[:5]]))[: len(Q)],
                                                   np.full(len(Q), 2.0), 1e-6, "Lap vs 2")))
    cases.append(Case("collinear", "Domain2D", lambda: Domain2D(np.column_stack([np.arange(200.0), 2 * np.arange(200.0)])), ("points",),
                      expect_refusal))
    cases.append(Case("far outlier (1e6)", "Domain2D", lambda: Domain2D(np.vstack([Q, [[1e6, 0]]])), ("points",),
                      lambda v: close(v.laplacian(np.append(fq, 0.0))[: len(Q)], np.full(len(Q), 2.0), 1e-6,
                                      "Lap vs 2 on the square")))
    for opt, vals in (("h", (np.nan, -1.0, 0.0)), ("neighbors", (0, -3, np.nan)), ("bounds", ((0, 0.5, 0, 1), (1, 0, 0, 1), "x")),
                      ("mirror", (True,))):
        for val in vals:
            cases.append(Case(f"{opt}={val!r}", "Domain2D", lambda o=opt, v=val: Domain2D(Q, **{o: v}), (opt, "bounds"),
                              expect_refusal))
    return cases


def file_cases(r: Refs) -> list[Case]:
    from manifold_sph import Surface, read, write

    d = r.tmp
    P, N = r.P, r.N
    rng = np.random.default_rng(13)
    cases: list[Case] = []

    def same(v, pts=P, tol=0.0, what="points read back"):
        got = v.points if hasattr(v, "points") else v
        if got.shape != pts.shape:
            return False, f"{got.shape} points read back from {pts.shape}"
        e = float(np.max(np.abs(got - pts)) / max(np.max(np.abs(pts)), 1e-300))
        return e <= tol, f"{what}: max relative difference {e:.1e} (tolerance {tol:.0e})"

    good = {}
    for ext in ("ply", "pcd", "obj", "xyz", "npy", "csv"):
        pth = d / f"good.{ext}"
        write(pth, P if ext == "obj" else _cloud(P, N))
        good[ext] = pth
    for ext, pth in good.items():
        raw = pth.read_bytes()
        for frac in (0.5, 0.97):
            cut = d / f"truncated_{int(frac * 100)}.{ext}"
            end = int(len(raw) * frac)
            if ext in ("obj", "xyz", "csv"):  # ascii: cut after the first value of a row (cut inside a number, undetectable)
                end = raw.index(b"\n", end) + 1
                end = raw.index(b" " if ext != "csv" else b",", end + 2)
            cut.write_bytes(raw[:end])
            cases.append(Case(f"truncated {ext} ({frac:.0%})", "read", lambda p=cut: read(p), (str(cut),), expect_refusal))
        garbage = d / f"garbage.{ext}"
        garbage.write_bytes(rng.integers(0, 256, 3000, dtype=np.uint8).tobytes())
        cases.append(Case(f"garbage {ext}", "read", lambda p=garbage: read(p), (str(garbage),), expect_refusal))
        empty = d / f"empty.{ext}"
        empty.write_bytes(b"")
        cases.append(Case(f"empty {ext}", "read", lambda p=empty: read(p), (str(empty),), expect_refusal,
                          quick=ext == "ply"))
        cases.append(Case(f"round trip {ext}", "write+read", lambda p=pth: read(p), (str(pth),),
                          lambda v, e=ext: same(v, tol=0.0 if e in ("ply", "pcd", "npy") else 1e-15)))
    # an ascii row cut short, text in a number column
    rows = "".join(f"{a!r} {b!r} {c!r}\n" for a, b, c in P.tolist())
    for tag, text in (("xyz row with two values", rows + "0.5 0.25\n"), ("xyz row with text", rows + "0.5 abc 0.1\n"),
                      ("xyz NaN row", rows + "nan 0 0\n")):
        pth = d / f"{tag.replace(' ', '_')}.xyz"
        pth.write_text(text)
        cases.append(Case(tag, "read", lambda p=pth: read(p), (str(pth),), expect_refusal))
    ply_short = d / "ply_count_too_large.ply"
    ply_short.write_text(f"ply\nformat ascii 1.0\nelement vertex {len(P) + 10}\nproperty double x\nproperty double y\n"
                         f"property double z\nend_header\n" + rows)
    cases.append(Case("ply header count > rows", "read", lambda: read(ply_short), (str(ply_short),), expect_refusal))
    for tag, arr in (("npy (N, 2)", P[:, :2]), ("npy 1-D", P[:, 0]), ("npy complex", P.astype(complex)),
                     ("npy object", np.array(P.tolist(), dtype=object)), ("npy NaN", np.where(P > 0.99, np.nan, P))):
        pth = d / f"{tag.replace(' ', '_')}.npy"
        np.save(pth, arr, allow_pickle=True)
        cases.append(Case(tag, "read", lambda p=pth: read(p), (str(pth),), expect_refusal))
    # paths
    uni = d / "données ü 点云 with space" / "a b ü.ply"
    uni.parent.mkdir()
    cases.append(Case("unicode + spaces path", "write+read", lambda: (write(uni, _cloud(P, N)), read(uni))[1], (str(uni),),
                      same))
    cases.append(Case("missing file", "read", lambda: read(d / "nope" / "missing.ply"), (str(d / "nope" / "missing.ply"),),
                      expect_refusal, quick=True))
    cases.append(Case("a folder", "read", lambda: read(d), (str(d),), expect_refusal))
    folder_ply = d / "folder.ply"
    folder_ply.mkdir()
    cases.append(Case("a folder named .ply", "read", lambda: read(folder_ply), (str(folder_ply),), expect_refusal))
    cases.append(Case("a folder named .ply", "write", lambda: write(folder_ply, P), (str(folder_ply),), expect_refusal))
    cases.append(Case("a folder named .ply", "Surface", lambda: Surface(folder_ply), (str(folder_ply),), expect_refusal))
    cases.append(Case("missing parent folder", "write", lambda: write(d / "nope" / "x.ply", P), (str(d / "nope" / "x.ply"),),
                      expect_refusal))
    cases.append(Case("unknown extension", "write", lambda: write(d / "x.foo", P), ("format", str(d / "x.foo")),
                      expect_refusal))
    cases.append(Case("format='bogus'", "read", lambda: read(good["ply"], format="bogus"), ("format",), expect_refusal))
    cases.append(Case("normals='bogus'", "read", lambda: read(good["ply"], normals="bogus"), ("normals",), expect_refusal))
    cases.append(Case("duplicates='bogus'", "read", lambda: read(good["ply"], duplicates="bogus"), ("duplicates",),
                      expect_refusal))
    for ext in ("ply", "npy", "xyz"):
        existing = d / f"existing.{ext}"
        write(existing, P[:50])
        before = existing.read_bytes()

        def unchanged(v, e=existing, b=before):
            return e.read_bytes() == b, "the existing file " + ("unchanged" if e.read_bytes() == b else "REPLACED")

        cases.append(Case(f"existing {ext}, no overwrite", "write", lambda e=existing: write(e, P), (str(existing),),
                          unchanged))
    nan_field = d / "nan_field.ply"

    def nan_back(v):
        _, fl = read(nan_field, return_fields=True)
        ok = bool(np.all(np.isnan(fl["u"][:3])) and np.array_equal(fl["u"][3:], np.arange(3, len(P), dtype=float)))
        return ok, "NaN entries of the field read back as NaN, the others exactly" if ok else "field changed"

    u_nan = np.arange(len(P), dtype=float)
    u_nan[:3] = np.nan
    cases.append(Case("field with NaN entries", "write", lambda: write(nan_field, _cloud(P, N), {"u": u_nan}), ("u",),
                      nan_back))
    for tag, fields in (("field of N-1", {"u": np.zeros(len(P) - 1)}),
                        ("field named x", {"x": np.zeros(len(P))}), ("field named nx", {"nx": np.zeros(len(P))}),
                        ("complex field", {"u": np.zeros(len(P), complex)}), ("field as str", {"u": "abc"})):
        nm = next(iter(fields))
        cases.append(Case(tag, "write", lambda fl=fields: write(d / f"f{rng.integers(1 << 30)}.ply", _cloud(P, N), fl),
                          (nm, "fields"), expect_refusal))
    for s in (1e-150, 1e150):
        for ext in ("ply", "npy", "xyz", "pcd"):
            pth = d / f"scaled_{s:g}.{ext}"
            cases.append(Case(f"round trip x {s:g}", f"write+read {ext}", lambda p=pth, s_=s: (write(p, P * s_), read(p))[1],
                              (str(pth),), lambda v, s_=s, e=ext: same(v, P * s_, 0.0 if e in ("ply", "npy", "pcd") else 1e-15)))
    return cases


def _cloud(P, N):
    from manifold_sph import PointCloud

    return PointCloud(P, N)


def render_cases(r: Refs) -> list[Case]:
    from manifold_sph.viz.render import render_field, rendering_available

    ok, why = rendering_available()
    if not ok:
        def unavailable():
            raise Skip(f"rendering unavailable: {why}")

        return [Case("rendering unavailable", "viz.render.render_field", unavailable)]
    P, x = r.P, r.x
    win = (160, 120)

    def drawn(img, shape=win):
        h, w = shape[1], shape[0]
        good = img.shape[:2] == (h, w) and float(np.std(img[..., :3])) > 1.0
        return good, f"image {img.shape} for window {shape}, pixel std {float(np.std(img[..., :3])):.1f}"

    rf = lambda p, f, **k: render_field(p, f, window_size=k.pop("window_size", win), **k)  # noqa: E731
    cases = [
        Case("sphere", "viz.render.render_field", lambda: rf(P, x), (), drawn),
        Case("planar (N, 2)", "viz.render.render_field", lambda: rf(r.Q, r.Q[:, 0]), (), drawn),
        Case("field NaN", "viz.render.render_field", lambda: rf(P, np.where(x > 0.5, np.nan, x)), ("field",), drawn),
        Case("field all NaN", "viz.render.render_field", lambda: rf(P, np.full(len(P), np.nan)), ("field",), expect_refusal),
        Case("field of N-1", "viz.render.render_field", lambda: rf(P, x[:-1]), ("field",), expect_refusal),
        Case("points NaN", "viz.render.render_field", lambda: rf(np.where(P > 0.99, np.nan, P), x), ("points",),
             expect_refusal),
        Case("window (0, 0)", "viz.render.render_field", lambda: rf(P, x, window_size=(0, 0)), ("window_size",),
             expect_refusal),
        Case("window (-5, 10)", "viz.render.render_field", lambda: rf(P, x, window_size=(-5, 10)), ("window_size",),
             expect_refusal),
        Case("clim reversed", "viz.render.render_field", lambda: rf(P, x, clim=(1, -1)), ("clim",), expect_refusal),
        Case("clim NaN", "viz.render.render_field", lambda: rf(P, x, clim=(np.nan, 1)), ("clim",), expect_refusal),
        Case("one point", "viz.render.render_field", lambda: rf(P[:1], x[:1]), ("points",), None),
        Case("empty", "viz.render.render_field", lambda: rf(np.zeros((0, 3)), np.zeros(0)), ("points",), expect_refusal),
    ]
    for s in (1e-150, 1e150):
        cases.append(Case(f"sphere x {s:g}", "viz.render.render_field", lambda s_=s: rf(P * s_, x), (), drawn))
    existing = r.tmp / "existing.png"
    existing.write_bytes(b"not an image")
    cases.append(Case("existing png, no overwrite", "viz.render.render_field", lambda: rf(P, x, filename=existing),
                      (str(existing),), expect_refusal))
    cases.append(Case("png in missing folder", "viz.render.render_field",
                      lambda: rf(P, x, filename=r.tmp / "nope" / "a.png"), (str(r.tmp / "nope" / "a.png"),), expect_refusal))
    return cases


def cli_cases(r: Refs) -> list[Case]:
    from manifold_sph import write

    d = r.tmp
    f = d / "cli sphere.ply"
    write(f, _cloud(r.P, r.N))
    out = d / "cli_out.npy"
    out.write_bytes(b"keep me")
    garbage = d / "cli_garbage.ply"
    garbage.write_bytes(np.random.default_rng(17).integers(0, 256, 2000, dtype=np.uint8).tobytes())
    F = str(f)
    rows: list[tuple[list[str], tuple[str, ...]]] = [
        (["eigs", F, "--k", "0"], ("--k",)), (["eigs", F, "--k", "-3"], ("--k",)), (["eigs", F, "--k", "100000"], ("--k",)),
        (["eigs", F, "--k", "abc"], ("--k",)), (["eigs", str(d / "missing.ply")], (str(d / "missing.ply"),)),
        (["eigs", str(d)], (str(d),)), (["eigs", str(garbage)], (str(garbage),)),
        (["geodesic", F, "--source", "999999"], ("--source",)), (["geodesic", F, "--source", "-99999"], ("--source",)),
        (["geodesic", F, "--source-xyz", "nan,0,0"], ("--source-xyz",)), (["geodesic", F, "--source", "0", "--to", "99999"], ("--to",)),
        (["heat", "--n", "300", "--dt", "nan"], ("--dt",)), (["heat", "--n", "300", "--dt", "-1"], ("--dt",)),
        (["heat", "--n", "300", "--reach", "-1"], ("--reach",)), (["heat", "--n", "300", "--reach", "inf"], ("--reach",)),
        (["heat", "--n", "300", "--steps", "-2"], ("--steps",)), (["heat", "--n", "5"], ("--n",)),
        (["heat", "--n", "300", "--diffusivity", "-1"], ("--diffusivity",)), (["heat", "--n", "300", "--every", "0"], ("--every",)),
        (["heat", "--n", "300", "--h", "-1"], ("--h",)), (["heat", "--n", "300", "--neighbors", "0"], ("--neighbors",)),
        (["wave", "--n", "300", "--c", "inf"], ("--c",)), (["wave", "--n", "300", "--c", "0"], ("--c",)),
        (["curvature", F, "--scale", "-1"], ("--scale",)), (["curvature", F, "--quantity", "bogus"], ("--quantity",)),
        (["normals", F, "--k", "1"], ("--k",)), (["normals", F, "--save", str(out)], (str(out), "--overwrite")),
        (["render", F, "--size", "0x0"], ("--size",)), (["render", F, "--field", "nope"], ("--field", "nope")),
        (["render", F, "--clim", "1,nan"], ("--clim",)), (["operators", "--n", "abc"], ("--n",)),
        (["convergence", "--sizes", "-5"], ("--sizes",)), (["poisson", "--n", "300", "--h", "nan"], ("--h",)),
        (["heat", "--n", "300", "--sampling", "random", "--seed", "-1"], ("--seed",)),
    ]
    cases = []
    for argv, names in rows:
        names = names + tuple(n.lstrip("-").replace("-", "_") for n in names if n.startswith("--"))
        cases.append(Case(" ".join(a if a != F else "sphere.ply" for a in argv), "cli", lambda a=argv: cli(a), names,
                          cli=True, quick=argv[:3] == ["eigs", F, "--k"] and argv[3] == "0"))
    return cases


def stub_cases() -> list[Case]:
    """Calls of known outcome: they test the classifier itself."""
    def crash():
        return [][1]

    def clear():
        raise ValueError("k must be a positive integer, got -1")

    def misleading():
        raise ValueError("height_tol must have shape (N,)")

    return [
        Case("stub IndexError", "harness", crash, ("k",), quick=True),
        Case("stub clear refusal", "harness", clear, ("k",), quick=True),
        Case("stub misleading refusal", "harness", misleading, ("k",), quick=True),
        Case("stub NaN result", "harness", lambda: np.array([1.0, np.nan]), ("k",), quick=True),
        Case("stub wrong result", "harness", lambda: 2.0, ("k",), lambda v: (v == 1.0, f"{v} vs 1"), quick=True),
        Case("stub right result", "harness", lambda: 1.0, ("k",), lambda v: (v == 1.0, f"{v} vs 1"), quick=True),
        Case("stub timeout", "harness", lambda: time.sleep(5), ("k",), quick=True),
    ]


def all_cases(r: Refs) -> list[Case]:
    return (surface_cases(r) + shape_cases(r) + field_cases(r) + domain_cases(r) + file_cases(r) + render_cases(r)
            + cli_cases(r))


# ------------------------------------------------------------------ report
def print_table(results: list[Outcome], width: int = 110) -> None:
    print(f"{'case':<44} {'entry point':<28} {'outcome':<20} {'s':>5}  message")
    for o in results:
        msg = o.message if len(o.message) <= width else o.message[: width - 3] + "..."
        print(f"{o.case[:44]:<44} {o.entry[:28]:<28} {o.outcome:<20} {o.seconds:5.1f}  {msg}")
    counts = Counter(o.outcome for o in results)
    print("\nsummary by outcome (" + f"{len(results)} cases):")
    for k in OUTCOMES:
        if counts.get(k):
            print(f"  {k:<22} {counts[k]:5d}")
    bad = [o for o in results if o.outcome in PROBLEMS]
    if bad:
        print("\nproblems:")
        for o in bad:
            print(f"  [{o.outcome}] {o.entry} / {o.case}: {o.message[:300]}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="a handful of cases, the classifier's stubs among them")
    ap.add_argument("--json", metavar="FILE", help="write the outcomes as JSON")
    ap.add_argument("--only", metavar="WORD", help="only cases whose name or entry point contains WORD")
    ap.add_argument("--timeout", type=float, default=120.0, help="seconds per case (default 120)")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    r = Refs()
    cases = stub_cases() + all_cases(r)
    if args.quick:
        cases = [c for c in cases if c.quick]
    else:
        cases = [c for c in cases if c.entry != "harness"]
    if args.only:
        cases = [c for c in cases if args.only.lower() in (c.name + " " + c.entry).lower()]
    results = []
    for c in cases:
        timeout = 1.0 if c.name == "stub timeout" else args.timeout
        results.append(run_case(c, timeout))
        print(f"{len(results):4d}/{len(cases)} {c.entry[:30]:<30} {c.name[:50]:<50} {results[-1].outcome}", file=sys.stderr,
              flush=True)
    print_table(results)
    print(f"\n{len(results)} cases in {time.perf_counter() - t0:.0f} s")
    shutil.rmtree(r.tmp, ignore_errors=True)
    if args.json:
        Path(args.json).write_text(json.dumps({"cases": [o.__dict__ for o in results],
                                               "counts": dict(Counter(o.outcome for o in results))}, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
