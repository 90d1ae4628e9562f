"""manifold-sph: consistent SPH differential operators on point-cloud surfaces.

The pipeline: point cloud -> neighbourhood -> tangent frames -> local 2D
coordinates -> scheme -> sparse operator matrices -> PDEs -> renderer.
"""

from .pointcloud import PointCloud
from .surface import Surface
from .domain import Domain2D
from .io import read, write
from .normals import estimate_normals
from .threads import get_num_threads, set_num_threads

__version__ = "0.1.0"

__all__ = ["PointCloud", "Surface", "Domain2D", "read", "write", "estimate_normals", "get_num_threads", "set_num_threads", "__version__"]
