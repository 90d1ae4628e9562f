"""The C allocator (glibc's malloc): give freed memory back, and tune it for a build.

Large temporary arrays dominate an operator build. glibc serves an allocation above its mmap
threshold with a fresh ``mmap`` (zeroed pages, a page fault per 4 KiB on first touch) and
otherwise from its heap, where freed blocks are reused. By default the threshold grows with
the sizes a program frees, so a build's repeated temporaries come from the heap. Setting
``MALLOC_TRIM_THRESHOLD_`` freezes that threshold at 128 KiB, and Dask's nanny sets it for
every worker process: there, every temporary array of a build is a fresh mapping
(docs/distributed.md, "Throughput and scaling", gives the cost). :func:`build_heap` restores
heap reuse for the length of a build and gives the memory back after it. Where the C library
is not glibc both are no-ops.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from typing import Any

__all__ = ["TRIM_MIN_POINTS", "build_heap", "release_freed_memory"]

#: Builds of fewer points skip :func:`release_freed_memory`: below it a call costs more than the little
#: memory it returns is worth.
TRIM_MIN_POINTS = 400_000

#: glibc's ``mallopt`` parameters.
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
#: glibc's initial thresholds (both 128 KiB).
_DEFAULT_THRESHOLD = 128 * 1024
#: The mmap threshold during a build: glibc's largest (32 MiB on 64-bit systems); larger arrays are
#: mapped as usual.
_BUILD_MMAP_THRESHOLD = 32 * 1024 * 1024

_LIBC: Any = None  # the C library once looked up; False where it is not glibc


def _libc() -> Any:
    global _LIBC
    if _LIBC is None:
        try:
            import ctypes

            lib = ctypes.CDLL("libc.so.6")
            _LIBC = lib if hasattr(lib, "mallopt") and hasattr(lib, "malloc_trim") else False
        except (OSError, AttributeError):
            _LIBC = False
    return _LIBC


def release_freed_memory(n_points: int | None = None) -> None:
    """Give the memory freed by a build step back to the system (glibc's ``malloc_trim``; nothing elsewhere).

    Buffers allocated and freed on worker threads stay in their threads' malloc arenas, resident
    (the grid search's chunk buffers, the area solve's vectors), under the assembly's peak.
    ``n_points``: the build's size;
    below :data:`TRIM_MIN_POINTS` nothing is done.

    Examples
    --------
    >>> release_freed_memory(10)  # a small build: nothing to do
    """
    if n_points is not None and n_points < TRIM_MIN_POINTS:
        return
    lib = _libc()
    if lib:
        lib.malloc_trim(0)


def _threshold(env: str) -> int:
    try:
        return int(os.environ.get(env, _DEFAULT_THRESHOLD))
    except ValueError:
        return _DEFAULT_THRESHOLD


@contextlib.contextmanager
def build_heap() -> Iterator[None]:
    """``with build_heap():`` temporary arrays up to 32 MiB reuse the heap, freed memory stays until the block ends.

    On exit the thresholds return to the process's settings (``MALLOC_TRIM_THRESHOLD_`` and
    ``MALLOC_MMAP_THRESHOLD_`` where set, else glibc's 128 KiB) and the freed memory goes back to
    the system. Meant for a worker process's build (one at a time: the setting is process-wide).

    Examples
    --------
    >>> with build_heap():
    ...     pass
    """
    lib = _libc()
    if not lib:
        yield
        return
    lib.mallopt(_M_MMAP_THRESHOLD, _BUILD_MMAP_THRESHOLD)
    lib.mallopt(_M_TRIM_THRESHOLD, 2 * _BUILD_MMAP_THRESHOLD)
    try:
        yield
    finally:
        lib.mallopt(_M_TRIM_THRESHOLD, _threshold("MALLOC_TRIM_THRESHOLD_"))
        lib.mallopt(_M_MMAP_THRESHOLD, _threshold("MALLOC_MMAP_THRESHOLD_"))
        lib.malloc_trim(0)
