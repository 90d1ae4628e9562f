"""manifold-sph: consistent SPH differential operators on point-cloud surfaces.

The pipeline: point cloud -> neighbourhood -> tangent frames -> local 2D
coordinates -> scheme -> sparse operator matrices.
"""

from .pointcloud import PointCloud
from .surface import Surface
from .domain import Domain2D

__version__ = "0.1.0"

__all__ = ["PointCloud", "Surface", "Domain2D", "__version__"]
