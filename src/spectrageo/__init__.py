"""spectrageo: spectral processing of static and dynamic 3D geometry.

Triangle meshes, point clouds, mesh animations and point-cloud sequences; graph Laplacians, the
graph Fourier transform, orthogonal iterations over overlapped submeshes, and low-rank solvers (RPCA,
matrix completion, incremental SVD, LASSO). Built on them: denoising of meshes and mesh animations,
outlier removal for point clouds and point-cloud sequences, and saliency with its applications, plus
quality metrics, synthetic noise with ground truth and evaluation harnesses. Compression, completion
of geometry and registration are not implemented (only their metrics: bit rates, registration
errors).
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
