"""Deprecated location of :mod:`manifold_sph.reference.errors` (moved in 0.2; this path works until 0.3)."""

import importlib as _importlib
import sys as _sys
import warnings as _warnings

_warnings.warn("manifold_sph.errors moved to manifold_sph.reference.errors: import it from there", DeprecationWarning, stacklevel=2)
_sys.modules[__name__] = _importlib.import_module("manifold_sph.reference.errors")
