"""Quality metrics of Section 4.9: theta, vertex and normal distances, NMSVE, Hausdorff, Chamfer,
F-score, KG error, STED, registration errors and bit rates.
"""

from .dynamic import (
    StedResult,
    compare_animation,
    hausdorff_per_frame,
    kg_error,
    sted,
    sted_components,
    theta_per_frame,
)
from .registration import bits_per_vertex, rotation_error_deg, translation_error
from .static import (
    METRIC_KEYS,
    compare,
    dist_n,
    dmax,
    dmean,
    dmean_n,
    face_angle_errors,
    nmsve,
    theta_deg,
    vertex_errors,
    vertex_normal_errors,
)
from .surface import (
    SURFACE_KEYS,
    HausdorffResult,
    SurfaceDistance,
    compare_surfaces,
    hausdorff,
    point_to_surface,
    surface_distance_per_vertex,
    surface_samples,
)

__all__ = [
    "METRIC_KEYS",
    "SURFACE_KEYS",
    "HausdorffResult",
    "StedResult",
    "SurfaceDistance",
    "bits_per_vertex",
    "compare",
    "compare_animation",
    "compare_surfaces",
    "dist_n",
    "dmax",
    "dmean",
    "dmean_n",
    "face_angle_errors",
    "hausdorff",
    "hausdorff_per_frame",
    "kg_error",
    "nmsve",
    "point_to_surface",
    "rotation_error_deg",
    "sted",
    "sted_components",
    "surface_distance_per_vertex",
    "surface_samples",
    "theta_deg",
    "theta_per_frame",
    "translation_error",
    "vertex_errors",
    "vertex_normal_errors",
]
