"""Scan processing: files, normals, cleaning and open boundaries.

- :mod:`.io` (``read``, ``write``, ``read_mesh``: PLY, PCD, OBJ, XYZ/CSV, NPY/NPZ, LAS/LAZ, E57),
  with :mod:`.io_read` and :mod:`.io_write` behind it;
- :mod:`.convert` (``to_pyvista``, ``from_open3d``, ...: PyVista, trimesh and Open3D objects);
- :mod:`.normals` (``estimate_normals``: jet normals, orientation, confidence), with :mod:`.poles`
  (``voronoi_poles``, the optional Voronoi-pole candidates) behind it;
- :mod:`.cleaning` (``clean``: duplicates and outliers);
- :mod:`.boundary` (``detect_boundary``: rims and holes).
"""

from .._lazy import lazy_submodules as _lazy

_SUBMODULES = ('io', 'io_read', 'io_write', 'convert', 'normals', 'poles', 'cleaning', 'boundary')
__getattr__, __dir__ = _lazy(__name__, globals(), _SUBMODULES)
