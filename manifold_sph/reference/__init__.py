"""Reference shapes, samplers, exact functions and error studies.

- :mod:`.shapes` (implicit surfaces with exact normals, curvatures and operators);
- :mod:`.sampling` (Fibonacci, Poisson-disk, random and jittered samples, all seeded);
- :mod:`.functions` (test functions with exact gradients and Hessians);
- :mod:`.errors` (error norms, convergence studies and fitted orders);
- :mod:`.accuracy` (the operators' errors against the exact references).
"""

from .._lazy import lazy_submodules as _lazy

_SUBMODULES = ('shapes', 'sampling', 'functions', 'errors', 'accuracy')
__getattr__, __dir__ = _lazy(__name__, globals(), _SUBMODULES)
