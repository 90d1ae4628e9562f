"""Scan processing: files, conversions, cleaning and open boundaries.

- :mod:`.io` (``read``, ``write``, ``read_mesh``: PLY, PCD, OBJ, XYZ/CSV, NPY/NPZ, LAS/LAZ, E57),
  with :mod:`.io_read` and :mod:`.io_write` behind it;
- :mod:`.convert` (``to_pyvista``, ``from_open3d``, ...: PyVista, trimesh and Open3D objects);
- :mod:`.cleaning` (``clean``: duplicates and outliers);
- :mod:`.boundary` (``detect_boundary``: rims and holes).
"""

from .._lazy import lazy_submodules as _lazy

_SUBMODULES = ('io', 'io_read', 'io_write', 'convert', 'cleaning', 'boundary')
__getattr__, __dir__ = _lazy(__name__, globals(), _SUBMODULES)
