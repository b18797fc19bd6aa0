"""Outlier removal for point clouds and point-cloud sequences (thesis Section 5.4).

* :func:`remove_outliers` -- Algorithm 14 (RPCA of the kNN patch matrix, Eq. 5.98-5.99, options
  :class:`RPCAOptions`) and the statistical / radius baselines, one contract (``keep`` mask,
  ``scores``, kept ``points``).
* :func:`robot_pipeline` -- Section 5.4.2: RPCA removal, k = 7 connectivity, bilateral filtering
  (Eq. 5.100-5.101).
* :func:`clean_sequence` -- Section 5.4.3: spatio-temporal RPCA (Eq. 5.102-5.103) and weighted
  Laplacian refill (Eq. 5.104-5.109).
"""

from ._organized import OrganizedGrid
from ._rpca_types import scan_options, viewpoint_options
from .robot import RobotResult, bilateral_point_filter, knn_triangles, robot_pipeline
from .rpca import PatchRPCAResult, RPCAOptions, knn_patch_matrix, rpca_scores
from .sequence import SequenceResult, clean_sequence, weighted_laplacian
from .static import (
    OutlierResult,
    auto_threshold,
    detect_outliers,
    radius_scores,
    remove_outliers,
    sor_scores,
    valley_threshold,
)

__all__ = [
    "OrganizedGrid",
    "OutlierResult",
    "PatchRPCAResult",
    "RPCAOptions",
    "RobotResult",
    "SequenceResult",
    "auto_threshold",
    "bilateral_point_filter",
    "clean_sequence",
    "detect_outliers",
    "knn_patch_matrix",
    "knn_triangles",
    "radius_scores",
    "remove_outliers",
    "robot_pipeline",
    "rpca_scores",
    "scan_options",
    "sor_scores",
    "valley_threshold",
    "viewpoint_options",
    "weighted_laplacian",
]
