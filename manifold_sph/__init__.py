"""manifold-sph: consistent SPH differential operators on point-cloud surfaces."""

from .pointcloud import PointCloud

__version__ = "0.1.0"

__all__ = ["PointCloud", "__version__"]
