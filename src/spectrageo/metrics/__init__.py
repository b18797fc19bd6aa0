"""Quality metrics of Section 4.9: theta, vertex/normal distances, NMSVE, exact Hausdorff, KG error,
STED, registration errors and bit rates.

Quick use::

    from spectrageo import metrics
    d = metrics.compare(V_denoised, V_ground_truth, F)      # theta_deg, dmean, ..., hd_max
    a = metrics.compare_animation(frames, frames_ref, F)   # per-frame means, kg, sted

Units: ``theta_deg`` in degrees; ``dmean``, ``dmax``, ``hd_*`` in model units (not normalised);
``dist_n``, ``dmean_n`` unitless in [0, 2]; ``nmsve`` normalised by the squared bounding-box
diagonal; ``kg`` in percent.
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
    HausdorffResult,
    SurfaceDistance,
    hausdorff,
    point_to_surface,
    surface_distance_per_vertex,
)

__all__ = [
    "METRIC_KEYS",
    "HausdorffResult",
    "StedResult",
    "SurfaceDistance",
    "bits_per_vertex",
    "compare",
    "compare_animation",
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
    "theta_deg",
    "theta_per_frame",
    "translation_error",
    "vertex_errors",
    "vertex_normal_errors",
]
