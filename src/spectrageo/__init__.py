"""spectrageo: spectral processing of static and dynamic 3D geometry.

Triangle meshes, point clouds, mesh animations and point-cloud sequences; graph Laplacians, the
graph Fourier transform, orthogonal iterations over overlapped submeshes, and low-rank solvers (RPCA,
matrix completion, incremental SVD, LASSO). Built on them: denoising of meshes and mesh animations
(spectral and learned), outlier removal for point clouds and point-cloud sequences, saliency and its
applications, compression of meshes and mesh animations (``spectrageo.compress``), completion of
holes and missing frames (``spectrageo.complete``), registration and identification in cluttered
scans (``spectrageo.register``), batch and tiled processing on Dask (``spectrageo.distributed``),
plus quality metrics, synthetic noise with ground truth and evaluation harnesses.
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
