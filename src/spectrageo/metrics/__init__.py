"""Quality metrics of Section 4.9: theta, vertex/normal distances, NMSVE, exact Hausdorff, KG error,
STED, registration errors and bit rates.

Quick use::

    from spectrageo import metrics
    d = metrics.compare(V_denoised, V_ground_truth, F)      # theta_deg, dmean, ..., hd_max
    s = metrics.compare_surfaces((V, F), (V_other, F_other))  # no correspondence: hd, chamfer, fscore
    a = metrics.compare_animation(frames, frames_ref, F)   # per-frame means, kg, sted

Units: ``theta_deg`` in degrees; ``dmean``, ``dmax``, ``hd_*`` in model units (not normalised);
``dist_n``, ``dmean_n`` unitless in [0, 2]; ``nmsve`` normalised by the squared bounding-box
diagonal; ``kg`` in percent. ``hd_mean``/``hd_max`` are symmetric (both directions, surfaces
sampled at vertices, edge midpoints and face centroids; see :mod:`spectrageo.metrics.surface`);
``chamfer`` (not squared) in model units; ``fscore``, ``precision``, ``recall`` in [0, 1].
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
