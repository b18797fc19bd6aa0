"""Synthetic noise and corruption with ground truth (Sections 3.4, 4.10).

Levels are relative to the mean edge length ``l`` (Eq. 4.36): ``sigma = level * l``. Every random
choice takes ``rng`` (seed or Generator; None is seed 0); inputs are never modified.
"""

from ._core import NoiseResult
from .animation import ANIMATION_KINDS, animation_noise, animation_noise_result, spatial_mask
from .corruption import (
    OUTLIER_PATTERNS,
    CorruptionResult,
    add_outliers,
    corrupt_outliers,
    make_holes,
    remove_vertices,
)
from .generator import GENERATOR_KINDS, GENERATOR_LEVELS, generate
from .static import (
    KINDS,
    anisotropic,
    apply,
    apply_result,
    gaussian,
    impulsive,
    quantize,
    region_varying,
    uniform,
)

__all__ = [
    "ANIMATION_KINDS",
    "GENERATOR_KINDS",
    "GENERATOR_LEVELS",
    "KINDS",
    "OUTLIER_PATTERNS",
    "CorruptionResult",
    "NoiseResult",
    "add_outliers",
    "animation_noise",
    "animation_noise_result",
    "anisotropic",
    "apply",
    "apply_result",
    "corrupt_outliers",
    "gaussian",
    "generate",
    "impulsive",
    "make_holes",
    "quantize",
    "region_varying",
    "remove_vertices",
    "spatial_mask",
    "uniform",
]
