"""Scan processing: files, normals, cleaning and open boundaries.

- :mod:`.io` (``read``, ``write``, ``read_mesh``: PLY, PCD, OBJ, XYZ/CSV, NPY/NPZ, LAS/LAZ, E57),
  with :mod:`.io_read` and :mod:`.io_write` behind it;
- :mod:`.normals` (``estimate_normals``: jet normals, orientation, confidence);
- :mod:`.cleaning` (``clean``: duplicates and outliers);
- :mod:`.boundary` (``detect_boundary``: rims and holes).
"""

import importlib as _importlib

_SUBMODULES = ('io', 'io_read', 'io_write', 'normals', 'cleaning', 'boundary')


def __getattr__(name: str):
    if name in _SUBMODULES:
        return _importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_SUBMODULES))
