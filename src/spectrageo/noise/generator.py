"""The corruption generator of the denoising generality protocol: five kinds at a relative level.

Each kind reaches ``level * l`` (Eq. 4.36): ``gaussian-normal`` and ``impulsive`` along the normals
(on :data:`IMPULSIVE_FRACTION` of the vertices), ``gaussian-random`` per coordinate,
``region-varying`` as the RMS of a ramp of ratio :data:`REGION_RATIO`, ``anisotropic`` along a
random axis (:data:`ANISOTROPIC_RATIO` across).
"""

from __future__ import annotations

import zlib

import numpy as np

from .._validation import as_faces, as_points, as_rng, check_choice
from ._core import NoiseResult, check_level, mean_spacing
from .static import anisotropic, gaussian, impulsive, region_varying

#: corruption kinds of the generality protocol, in report order
GENERATOR_KINDS = (
    "gaussian-normal",
    "gaussian-random",
    "impulsive",
    "region-varying",
    "anisotropic",
)
#: the three relative levels (sigma_E of Eq. 4.36) of the protocol, as in the thesis' figures
GENERATOR_LEVELS = (0.1, 0.3, 0.5)
#: fraction of vertices hit by impulsive noise
IMPULSIVE_FRACTION = 0.1
#: loud-to-quiet ratio of the region-varying noise level before rescaling
REGION_RATIO = 7.0
#: across-axis / along-axis standard deviation of the anisotropic noise
ANISOTROPIC_RATIO = 0.25


def generate(V, F, *, kind: str, level: float, rng=None) -> NoiseResult:
    """Corrupt a clean mesh ``(V, F)`` with one :data:`GENERATOR_KINDS` ``kind`` at ``level``; the same seed gives the same output."""
    check_choice(kind, "kind", GENERATOR_KINDS)
    level = check_level(level)
    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F")
    rng = as_rng(rng)
    if kind == "gaussian-normal":
        res = gaussian(V, F, level=level, rng=rng, direction="normal")
    elif kind == "gaussian-random":
        res = gaussian(V, F, level=level, rng=rng, direction="random")
    elif kind == "impulsive":
        res = impulsive(V, F, fraction=IMPULSIVE_FRACTION, level=level, rng=rng)
    elif kind == "anisotropic":
        res = anisotropic(V, F, level=level, ratio=ANISOTROPIC_RATIO, frame="axis", rng=rng)
    else:
        # ramp from 1 to REGION_RATIO (relative units), then rescale the draws so that the RMS of
        # the per-vertex standard deviation is level * l (scaling a zero-mean Gaussian draw by a
        # constant scales its standard deviation by the same constant)
        raw = region_varying(V, F, levels=(1.0, REGION_RATIO), mode="smooth", rng=rng)
        rms = float(np.sqrt(np.mean(raw.scale**2)))  # RMS of the 1 l .. 7 l field, model units
        k = level * mean_spacing(V, F) / rms if rms > 0 else 0.0
        D = raw.displacement * k
        res = NoiseResult(V + D, D, raw.mask, raw.scale * k, None, "region_varying")
    return NoiseResult(res.vertices, res.displacement, res.mask, res.scale, res.labels, kind)


def case_seed(*parts, seed: int = 0) -> int:
    """A stable seed for one protocol case from its identifying parts (model, kind, level):
    CRC-32 of their text plus ``seed`` (independent of Python's hash randomisation)."""
    text = "|".join(f"{p:g}" if isinstance(p, float) else str(p) for p in parts)
    return (zlib.crc32(text.encode("utf-8")) + int(seed)) % (2**32)


__all__ = [
    "ANISOTROPIC_RATIO",
    "GENERATOR_KINDS",
    "GENERATOR_LEVELS",
    "IMPULSIVE_FRACTION",
    "REGION_RATIO",
    "case_seed",
    "generate",
]
