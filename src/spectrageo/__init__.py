"""spectrageo: spectral processing of static and dynamic 3D geometry.

Triangle meshes, point clouds, mesh animations and point-cloud sequences; graph Laplacians, the
graph Fourier transform, orthogonal iterations, RPCA and matrix completion; denoising, compression,
completion, outlier removal, saliency and registration built on them.
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
