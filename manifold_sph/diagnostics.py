"""What a build adapted, collected into one report: one warning per build, details on request.

Building a :class:`~manifold_sph.Surface` adapts to the cloud it is given: normals
estimated from bare points, wider supports for sparse points, normals flipped to agree
with their neighbours, particles whose local fits fall back to a simpler scheme,
near-duplicate points merged in the area solve, cells of the stable Laplacian that had
to be repaired. Each of these is one :class:`Adaptation` in the surface's
:class:`BuildReport` (``Surface.report()``); the build ends with at most one
:class:`~manifold_sph.ManifoldSPHWarning` that summarises them in one sentence.

Modules feed the report of the build in progress with :func:`note`. Outside a build
(a function called on its own) :func:`note` issues the warning itself, so a caller
always hears of an adaptation exactly once::

    from manifold_sph.diagnostics import note
    note("merged", f"{k} near-duplicate points were merged", count=k,
         detail="...why, and what the user can do...", indices=idx)

A build collects with :func:`collecting`; nested collections of the same report
are one.

Examples
--------
>>> import warnings
>>> report = BuildReport("Surface of 1,000 points")
>>> with collecting(report, warn=False):          # a build warns once on exit
...     note("widened", "12 points in sparse parts got wider supports", count=12)
...     note("normals", "normals were estimated from the points", severity="info")
>>> [a.key for a in report]
['widened', 'normals']
>>> print(report.summary())  # doctest: +ELLIPSIS
Surface of 1,000 points: 12 points in sparse parts got wider supports; ... Surface.report() has the details.
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import os
import sys
import warnings
from collections.abc import Iterator
from types import FrameType

import numpy as np

from .exceptions import ManifoldSPHWarning
from .results import Result

__all__ = ["Adaptation", "BuildReport", "collecting", "note"]

SEVERITIES = ("info", "adapted")


@dataclasses.dataclass(frozen=True, repr=False)
class Adaptation(Result):
    """One thing a build adapted to the cloud.

    Attributes
    ----------
    key : str
        Short machine name (``"widened"``, ``"flipped"``, ``"fallback"``, ``"merged"``,
        ``"normals"``, ...); one entry per key and report.
    summary : str
        One clause in the user's terms, e.g. ``"274 points in sparse parts got wider supports"``.
    detail : str
        Why it happened and what the user can do about it.
    count : int or None
        How many particles it concerns.
    indices : ndarray of int or None
        Which particles (input order).
    severity : {"info", "adapted"}
        ``"info"`` entries (the expected path, e.g. normals estimated from bare points)
        are listed but do not cause a warning on their own.
    """

    key: str
    summary: str
    detail: str = ""
    count: int | None = None
    indices: np.ndarray | None = None
    severity: str = "adapted"


@dataclasses.dataclass(repr=False, eq=False)
class BuildReport(Result):
    """The adaptations of one build, in order; feed it with :func:`note` inside :func:`collecting`.

    Parameters
    ----------
    subject : str
        What was built, as the summary names it (``"Surface of 2,903 points"``).
    adaptations : list of Adaptation
        The entries, one per key, in the order they were first recorded (``to_dict`` lists them;
        ``to_dict(json=True)`` gives indices as lists).
    """

    subject: str
    adaptations: list[Adaptation] = dataclasses.field(default_factory=list)

    def __post_init__(self) -> None:
        self.subject = str(self.subject)
        self._items: dict[str, Adaptation] = {}
        for item in list(self.adaptations):
            self.add(item)

    def add(self, item: Adaptation) -> None:
        """Record ``item``; a later entry with the same key replaces the earlier one."""
        if not isinstance(item, Adaptation):
            raise TypeError(f"item must be an Adaptation, got {type(item).__name__}")
        self._items.pop(item.key, None)
        self._items[item.key] = item
        self.adaptations[:] = self._items.values()

    def __iter__(self) -> Iterator[Adaptation]:
        return iter(list(self._items.values()))

    def __len__(self) -> int:
        return len(self._items)

    def __contains__(self, key: object) -> bool:
        return key in self._items

    def __getitem__(self, key: str) -> Adaptation:
        return self._items[key]

    @property
    def adapted(self) -> bool:
        """True when at least one entry is more than information (the build then warns)."""
        return any(a.severity == "adapted" for a in self._items.values())

    def summary(self, keys: list[str] | None = None) -> str:
        """One sentence: the subject and the summaries of the entries (of ``keys``, default all)."""
        items = [a for a in self._items.values() if keys is None or a.key in keys]
        if not items:
            return f"{self.subject}: built as given, nothing adapted."
        return f"{self.subject}: " + "; ".join(a.summary for a in items) + ". Surface.report() has the details."

    def __str__(self) -> str:
        if not self._items:
            return f"{self.subject}: built as given, nothing adapted."
        lines = [f"{self.subject}:"]
        for a in self._items.values():
            lines.append(f"- {a.summary}.")
            if a.detail:
                lines.append(f"  {a.detail}")
            if a.indices is not None and len(a.indices):
                shown = ", ".join(str(int(i)) for i in np.asarray(a.indices)[:10])
                more = f", ... ({len(a.indices)} in all)" if len(a.indices) > 10 else ""
                lines.append(f"  Points: {shown}{more}.")
        return "\n".join(lines)

    def __repr__(self) -> str:
        return f"BuildReport({self.subject!r}, {[a.key for a in self._items.values()]})"

    def warn(self, keys: list[str] | None = None) -> None:
        """One :class:`~manifold_sph.ManifoldSPHWarning` with :meth:`summary`, if an entry of ``keys`` adapted.

        The warning points at the first caller outside the package (the user's line).
        """
        items = [a for a in self._items.values() if keys is None or a.key in keys]
        if any(a.severity == "adapted" for a in items):
            warnings.warn(self.summary(keys), ManifoldSPHWarning, stacklevel=_user_stacklevel())


_ACTIVE: contextvars.ContextVar[BuildReport | None] = contextvars.ContextVar("manifold_sph_build_report", default=None)


@contextlib.contextmanager
def collecting(report: BuildReport, *, warn: bool = True) -> Iterator[BuildReport]:
    """Make ``report`` the one :func:`note` feeds; on exit, warn once about what was added.

    Inside a collection of the same report this is a no-op (the outer one warns).
    With ``warn=False`` nothing is warned on exit.
    """
    if _ACTIVE.get() is report:
        yield report
        return
    before = {k: id(a) for k, a in report._items.items()}
    token = _ACTIVE.set(report)
    try:
        yield report
    finally:
        _ACTIVE.reset(token)
    new = [k for k, a in report._items.items() if before.get(k) != id(a)]
    if warn and new:
        report.warn(new)


def note(key: str, summary: str, *, detail: str = "", count: int | None = None,
         indices: np.ndarray | None = None, severity: str = "adapted") -> None:
    """Record an adaptation in the report of the build in progress, or warn when there is none.

    Parameters
    ----------
    key : str
        Short machine name; one entry per key and report.
    summary : str
        One clause in the user's terms (no Python attribute names).
    detail : str
        Why, and what the user can do.
    count : int, optional
    indices : array_like of int, optional
    severity : {"info", "adapted"}
        ``"info"``: listed in the report, no warning of its own.
    """
    if severity not in SEVERITIES:
        raise ValueError(f"severity must be one of {list(SEVERITIES)}, got {severity!r}")
    idx = None if indices is None else np.asarray(indices).copy()
    item = Adaptation(str(key), str(summary), str(detail), None if count is None else int(count), idx, severity)
    report = _ACTIVE.get()
    if report is not None:
        report.add(item)
    elif severity == "adapted":
        text = item.summary + (f". {item.detail}" if item.detail else "")
        warnings.warn(text, ManifoldSPHWarning, stacklevel=_user_stacklevel())


_PACKAGE_DIR = os.path.dirname(os.path.abspath(__file__))


def _user_stacklevel() -> int:
    """The ``stacklevel`` of :func:`warnings.warn`, called by our caller, that names the first frame
    outside the package (and outside :mod:`contextlib`, whose frames a ``with`` block adds)."""
    frame: FrameType | None = sys._getframe(1)  # the function that calls warnings.warn: stacklevel 1
    level = 1
    skip = (_PACKAGE_DIR + os.sep, os.path.dirname(contextlib.__file__) + os.sep + "contextlib")
    while frame is not None and frame.f_code.co_filename.startswith(skip):
        frame = frame.f_back
        level += 1
    return level
