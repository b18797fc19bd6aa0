"""Mesh and point-cloud saliency, features and their applications (thesis Section 6.1).

Maps (Eq. 6.1-6.16, 6.30-6.36), corner/edge/flat classes (Section 4.4), feature vertices and
curves (Eq. 6.5-6.7), simplification (Algorithm 15), guided denoising (Eq. 6.20-6.23) and
deviation inspection (Eq. 6.17-6.19).
"""

from ..geometry.features import FeatureClasses, classify_faces, classify_vertices
from ._common import face_patches
from ._options import SaliencyOptions
from .combined import (
    FAST_CLASSES,
    METHODS,
    SaliencyComponents,
    fast_mask,
    saliency,
    saliency_components,
)
from .denoise import (
    first_ring_patches,
    saliency_denoise,
    saliency_guided_normals,
    saliency_patch_weights,
    select_patches_by_saliency,
)
from .dynamic import AnimationSaliency, animation_saliency, area_change, first_ring_areas
from .features import (
    FeatureCurves,
    FeatureVertices,
    calinski_harabasz_1d,
    curve_descriptor,
    curve_similarity,
    feature_curves,
    feature_vertices,
    kmeans_1d,
    model_descriptor,
    similarity_matrix,
    vertex_spectral_saliency,
)
from .geometric import PatchRPCA, coherence_matrix, geometric_face_values, geometric_saliency
from .inspect import Inspection, inspect, normalize_unit_box
from .pointcloud import multiscale_features, normalize_saliency_pair, pointcloud_saliency
from .simplify import Simplified, class_keep_fractions, saliency_classes, simplify
from .spectral import spectral_face_values, spectral_saliency
from .tsgsp import tsgsp_saliency

__all__ = [
    "FAST_CLASSES",
    "METHODS",
    "AnimationSaliency",
    "FeatureClasses",
    "FeatureCurves",
    "FeatureVertices",
    "Inspection",
    "PatchRPCA",
    "SaliencyComponents",
    "SaliencyOptions",
    "Simplified",
    "animation_saliency",
    "area_change",
    "calinski_harabasz_1d",
    "class_keep_fractions",
    "classify_faces",
    "classify_vertices",
    "coherence_matrix",
    "curve_descriptor",
    "curve_similarity",
    "face_patches",
    "fast_mask",
    "feature_curves",
    "feature_vertices",
    "first_ring_areas",
    "first_ring_patches",
    "geometric_face_values",
    "geometric_saliency",
    "inspect",
    "kmeans_1d",
    "model_descriptor",
    "multiscale_features",
    "normalize_saliency_pair",
    "normalize_unit_box",
    "pointcloud_saliency",
    "saliency",
    "saliency_classes",
    "saliency_components",
    "saliency_denoise",
    "saliency_guided_normals",
    "saliency_patch_weights",
    "select_patches_by_saliency",
    "similarity_matrix",
    "simplify",
    "spectral_face_values",
    "spectral_saliency",
    "tsgsp_saliency",
    "vertex_spectral_saliency",
]
