"""spectrageo: spectral processing of static and dynamic 3D geometry (meshes, point clouds,
animations, sequences): Laplacians, GFT, low-rank solvers and the thesis's applications.
"""

from ._errors import (
    ConvergenceError,
    ConvergenceWarning,
    InvalidInputError,
    RepairWarning,
    SpectrageoError,
    UnsupportedFormatError,
)
from .geometry import Mesh, MeshAnimation, PointCloud, PointCloudSequence

__version__ = "0.1.0"

__all__ = [
    "ConvergenceError",
    "ConvergenceWarning",
    "InvalidInputError",
    "Mesh",
    "MeshAnimation",
    "PointCloud",
    "PointCloudSequence",
    "RepairWarning",
    "SpectrageoError",
    "UnsupportedFormatError",
    "__version__",
]
