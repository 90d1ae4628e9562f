"""Reference shapes, samplers, exact functions and error studies.

- :mod:`.shapes` (implicit surfaces with exact normals, curvatures and operators);
- :mod:`.sampling` (Fibonacci, Poisson-disk, random and jittered samples, all seeded);
- :mod:`.functions` (test functions with exact gradients and Hessians);
- :mod:`.errors` (error norms, convergence studies and fitted orders);
- :mod:`.accuracy` (the operators' errors against the exact references).
"""

import importlib as _importlib

_SUBMODULES = ('shapes', 'sampling', 'functions', 'errors', 'accuracy')


def __getattr__(name: str):
    if name in _SUBMODULES:
        return _importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_SUBMODULES))
