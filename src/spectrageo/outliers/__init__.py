"""Outlier removal for point clouds and point-cloud sequences (thesis Section 5.4).

* :func:`remove_outliers` -- Algorithm 14 (RPCA of the kNN patch matrix, Eq. 5.98-5.99, options
  :class:`RPCAOptions`) and the statistical / radius baselines, one contract (``keep`` mask,
  ``scores``, kept ``points``).
* :func:`robot_pipeline` -- Section 5.4.2: RPCA removal, k = 7 connectivity, bilateral filtering
  (Eq. 5.100-5.101).
* :func:`clean_sequence` -- Section 5.4.3: spatio-temporal RPCA (Eq. 5.102-5.103) and weighted
  Laplacian refill (Eq. 5.104-5.109).

Names are imported from their submodules on first use, so that the NumPy path of the patch RPCA
(``RPCAOptions(backend="numpy")``) runs without loading numba.
"""

from .._plugins import lazy_exports

_EXPORTS = {
    "OrganizedGrid": "._organized",
    **dict.fromkeys(("scan_options", "viewpoint_options"), "._rpca_types"),
    **dict.fromkeys(
        ("RobotResult", "bilateral_point_filter", "knn_triangles", "robot_pipeline"), ".robot"
    ),
    **dict.fromkeys(("PatchRPCAResult", "RPCAOptions", "knn_patch_matrix", "rpca_scores"), ".rpca"),
    **dict.fromkeys(("SequenceResult", "clean_sequence", "weighted_laplacian"), ".sequence"),
    **dict.fromkeys(
        "OutlierResult auto_threshold detect_outliers radius_scores remove_outliers sor_scores "
        "valley_threshold".split(),
        ".static",
    ),
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
