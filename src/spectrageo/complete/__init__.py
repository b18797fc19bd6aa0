"""Completion of incomplete static and dynamic 3D models (thesis Section 5.3).

:func:`inpaint` (Eq. 5.77-5.89), :func:`fill_holes`, :func:`complete_animation` (Algorithm 12)
and :func:`complete_sequence` (Algorithm 13) keep the vertex order and the known rows unchanged.
"""

from .dynamic import ANIMATION_METHODS, SEQUENCE_METHODS, complete_animation, complete_sequence
from .holes import FilledMesh, OpenLoop, fill_holes
from .static import INPAINT_METHODS, inpaint, patch_indices

__all__ = [
    "ANIMATION_METHODS",
    "INPAINT_METHODS",
    "SEQUENCE_METHODS",
    "FilledMesh",
    "OpenLoop",
    "complete_animation",
    "complete_sequence",
    "fill_holes",
    "inpaint",
    "patch_indices",
]
