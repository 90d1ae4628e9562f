"""How many threads the package uses.

Every threaded step (the KD-tree queries, the neighbour filter, the projection,
the kernel values, the assembly, ``op(f)`` and the area solve) runs on
:func:`get_num_threads` threads. The default is every core
(``os.cpu_count()``); the environment variable ``MANIFOLD_SPH_NUM_THREADS``,
read at import, or :func:`set_num_threads` change it, and :func:`limit` changes
it for a ``with`` block. Functions taking ``workers`` read ``-1`` as "the
package setting".

The heavy parts are numpy and scipy calls that release the GIL, so threads over
particle chunks use every core without copying the cloud into other processes.

Examples
--------
>>> from manifold_sph import threads
>>> with threads.limit(1):
...     threads.get_num_threads()
1
>>> threads.resolve_workers(3)
3
"""

from __future__ import annotations

import itertools
import os
import threading
import warnings
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager

from ._validation import check_int
from .exceptions import ManifoldSPHWarning

__all__ = ["get_num_threads", "set_num_threads", "limit", "resolve_workers", "run_chunks"]

ENV_VAR = "MANIFOLD_SPH_NUM_THREADS"


def _from_env() -> int | None:
    """The thread count set by ``MANIFOLD_SPH_NUM_THREADS``, or None (every core).

    A value that is not a positive integer (``0``, ``-3``, ``abc``, ``1.5``) gives a
    ``ManifoldSPHWarning`` naming it and the default; importing the package never fails
    because of it.

    Examples
    --------
    >>> import os, warnings
    >>> os.environ[ENV_VAR] = "abc"
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     value = _from_env()
    >>> value is None, "must be a positive integer" in str(caught[0].message)
    (True, True)
    >>> os.environ[ENV_VAR] = " 2 "; _from_env()
    2
    >>> del os.environ[ENV_VAR]
    """
    raw = os.environ.get(ENV_VAR)
    if raw is None or raw.strip() == "":
        return None
    text = raw.strip()
    if text.isascii() and text.isdigit() and int(text) >= 1:
        return int(text)
    warnings.warn(
        f"environment variable {ENV_VAR} must be a positive integer, got {raw!r}; "
        f"using the default (every core, {os.cpu_count() or 1})",
        ManifoldSPHWarning,
        stacklevel=2,
    )
    return None


_NUM_THREADS: int | None = _from_env()


def get_num_threads() -> int:
    """Threads the package uses (default: every core).

    Examples
    --------
    >>> get_num_threads() >= 1
    True
    """
    return _NUM_THREADS if _NUM_THREADS is not None else (os.cpu_count() or 1)


def set_num_threads(n: int | None) -> None:
    """Use ``n`` threads from now on (``None``: every core).

    Parameters
    ----------
    n : int or None
        A positive integer, or ``None`` for ``os.cpu_count()``.

    Examples
    --------
    >>> set_num_threads(1); get_num_threads()
    1
    >>> set_num_threads(None)
    """
    global _NUM_THREADS
    _NUM_THREADS = None if n is None else check_int("n", n, minimum=1)


@contextmanager
def limit(n: int | None) -> Iterator[None]:
    """``with limit(n):`` use ``n`` threads inside the block, then restore the setting.

    The setting is process-wide: a block entered in one thread applies to every
    thread until it exits (do not nest it across threads)."""
    global _NUM_THREADS
    before = _NUM_THREADS
    set_num_threads(n)
    try:
        yield
    finally:
        _NUM_THREADS = before


def resolve_workers(workers: int) -> int:
    """Threads for a ``workers`` argument: -1 is :func:`get_num_threads`, else a positive count.

    Examples
    --------
    >>> resolve_workers(-1) == get_num_threads()
    True
    """
    if workers == -1:
        return get_num_threads()
    return check_int("workers", workers, minimum=1)


_POOL: tuple | None = None  # (pid, size, executor): one pool per process, kept between calls
_POOL_LOCK = threading.Lock()
_LOCAL = threading.local()  # .inside: this thread runs chunks of a run_chunks call


def pool(size: int) -> ThreadPoolExecutor:
    """The package's thread pool, with at least ``size`` workers (created once per process:
    starting threads for every call cost 0.3 ms; a forked child gets a new pool)."""
    global _POOL
    size = check_int("size", size, minimum=1)
    with _POOL_LOCK:
        pid = os.getpid()
        if _POOL is None or _POOL[0] != pid or _POOL[1] < size:
            n = max(size, os.cpu_count() or 1)
            _POOL = (pid, n, ThreadPoolExecutor(max_workers=n, thread_name_prefix="manifold_sph"))
        return _POOL[2]


def in_chunk() -> bool:
    """Whether the calling thread is running a chunk of :func:`run_chunks` (nested parallel
    work should then run serially)."""
    return getattr(_LOCAL, "inside", False)


def run_chunks(job: Callable[[int], object], n_chunks: int, workers: int = -1) -> None:
    """Run ``job(c)`` for ``c`` in ``range(n_chunks)``, on threads when there are several.

    ``job`` must write disjoint outputs (numpy and the compiled kernels release the
    GIL in their heavy parts). The calling thread and ``workers - 1`` pool threads
    take chunks in turn; a call from inside a chunk runs serially (no deadlock).
    The first exception is re-raised once every thread has stopped.

    Examples
    --------
    >>> out = [0] * 4
    >>> def job(c):
    ...     out[c] = c * c
    >>> run_chunks(job, 4); out
    [0, 1, 4, 9]
    """
    nthreads = min(resolve_workers(workers), n_chunks)
    if nthreads <= 1 or in_chunk():
        for c in range(n_chunks):
            job(c)
        return
    counter = itertools.count()
    lock = threading.Lock()

    def loop():
        _LOCAL.inside = True
        try:
            while True:
                with lock:
                    c = next(counter)
                if c >= n_chunks:
                    return
                job(c)
        finally:
            _LOCAL.inside = False

    futures = [pool(nthreads - 1).submit(loop) for _ in range(nthreads - 1)]
    try:
        loop()
    finally:
        errors = []
        for f in futures:
            try:
                f.result()
            except BaseException as e:  # noqa: BLE001 - re-raised below
                errors.append(e)
    if errors:
        raise errors[0]
