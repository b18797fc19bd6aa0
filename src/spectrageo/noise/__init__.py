"""Synthetic noise and corruption with ground truth (Sections 3.4, 4.10).

Design: the individual generators return a result object carrying the ground truth --
:class:`NoiseResult` (``vertices``, ``displacement``, ``mask``, ``scale``, ``labels``) for noise,
:class:`CorruptionResult` (kept ``vertices``/``faces``, ``removed`` mask, ``index_map``, ``kept``) for
missing data -- while :func:`add_outliers` returns ``(P_out, labels)``. The dispatchers :func:`apply`
and :func:`animation_noise` return plain arrays of noisy positions (``return_result=True`` gives the
NoiseResult). Every random choice takes ``rng`` (seed or Generator; None = seed 0); inputs are never
modified.

Levels are relative to the mean edge length (Eq. 4.36): ``sigma = level * l``.

:func:`generate` is the corruption generator of the denoising generality protocol (five kinds,
:data:`GENERATOR_KINDS`, at the levels :data:`GENERATOR_LEVELS`).
"""

from ._core import NoiseResult
from .animation import ANIMATION_KINDS, animation_noise, spatial_mask
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
    "anisotropic",
    "apply",
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
