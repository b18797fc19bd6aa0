"""Completion of incomplete static and dynamic 3D models (thesis Section 5.3).

- :func:`inpaint`: missing vertices of a mesh with known connectivity, by matrix completion of
  k-ring patch matrices (``"mc"``, Eq. 5.77-5.89) or the baselines Laplacian interpolation
  (``"li"``) and least-squares meshes (``"lsm"``).
- :func:`fill_holes`: holes with unknown connectivity: implant points, triangulate, complete.
- :func:`complete_animation`: missing vertices of a mesh animation, online (Algorithm 12,
  anchors and satellites, Eq. 5.91-5.92), with the baselines ``"li"`` (per frame), ``"lia"``
  (Laplacian interpolation of the motion) and ``"mc"`` (offline matrix completion).
- :func:`complete_sequence`: missing points of a point-cloud sequence, online (Algorithm 13,
  weighted regularised Laplacian interpolation, Eq. 5.94-5.97).

Every function keeps the vertex order and returns the known vertices unchanged; unknown rows of
the input may hold anything (NaN included).
"""

from .dynamic import ANIMATION_METHODS, SEQUENCE_METHODS, complete_animation, complete_sequence
from .holes import fill_holes
from .static import INPAINT_METHODS, inpaint, patch_indices

__all__ = [
    "ANIMATION_METHODS",
    "INPAINT_METHODS",
    "SEQUENCE_METHODS",
    "complete_animation",
    "complete_sequence",
    "fill_holes",
    "inpaint",
    "patch_indices",
]
