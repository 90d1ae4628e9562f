"""How the kernels compile: numba's ``njit`` with the package's options, and whether they are used (:data:`ENABLED`)."""

from __future__ import annotations

import importlib
import os
from types import ModuleType

import numpy as np

numba: ModuleType | None
try:
    numba = importlib.import_module("numba")
except ImportError:  # pragma: no cover - numba is a dependency; a platform without its wheels still works
    numba = None

__all__ = ["ENABLED", "numba", "njit", "inline", "U", "from_env"]



def from_env() -> bool:
    """``MANIFOLD_SPH_JIT`` as a bool (default True). Another value than 0/1, true/false,
    yes/no, on/off gives a ``ManifoldSPHWarning`` and the default: importing never fails on it."""
    raw = os.environ.get("MANIFOLD_SPH_JIT", "1")
    text = raw.strip().lower()
    if text in ("", "1", "true", "yes", "on"):
        return True
    if text in ("0", "false", "no", "off"):
        return False
    import warnings

    from ..exceptions import ManifoldSPHWarning

    warnings.warn(
        f"environment variable MANIFOLD_SPH_JIT must be 0 or 1 (or true/false, yes/no, on/off), got {raw!r}; "
        "using the default (1: compiled kernels on)",
        ManifoldSPHWarning,
        stacklevel=2,
    )
    return True


#: Whether the pipeline uses the compiled kernels (``MANIFOLD_SPH_JIT=0`` turns them off; so does
#: a missing numba, e.g. on a Python version it does not support yet: the numpy code then runs).
ENABLED = from_env() and numba is not None

# error_model="numpy": a division by zero gives inf or nan (then caught by the
# condition test), as in numpy, instead of raising.
njit = numba.njit(nogil=True, cache=True, error_model="numpy") if numba is not None else (lambda f: f)
# Small helpers of the scheme kernels, inlined into them at numba's level (as separate
# functions the shared helpers cost up to 1.7x in the cspm kernel, measured).
inline = numba.njit(nogil=True, cache=True, error_model="numpy", inline="always") if numba is not None else (lambda f: f)

# Indices into the pair and point arrays are cast to unsigned: numba then skips the
# wrap-around test of negative indices. It made a CSR product 1.5x slower than scipy's
# (measured, 3.5 million entries: 5.8 ms signed, 2.4 ms unsigned, scipy 4.0 ms).
U = np.uint64
