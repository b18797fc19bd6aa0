"""Spectral processing: GFT/IGFT, low-pass filtering, orthogonal iterations and submeshes."""

from .gft import Eigenbasis, fix_signs, gft, igft, lowpass_whole
from .lowpass import LowpassOptions, LowpassResult, lowpass
from .orthogonal import (
    DOIResult,
    OIResult,
    ShiftedFactor,
    SubmeshBases,
    SubmeshOptions,
    dynamic_orthogonal_iteration,
    orthogonal_iteration,
    orthogonal_iteration_result,
    shifted_factor,
    submesh_eigenbases,
    submesh_eigenbases_result,
)
from .partition import (
    Submeshes,
    overlapped_submeshes,
    reassemble,
    submesh_laplacian,
)

__all__ = [
    "DOIResult",
    "Eigenbasis",
    "LowpassOptions",
    "LowpassResult",
    "OIResult",
    "ShiftedFactor",
    "SubmeshBases",
    "SubmeshOptions",
    "Submeshes",
    "dynamic_orthogonal_iteration",
    "fix_signs",
    "gft",
    "igft",
    "lowpass",
    "lowpass_whole",
    "orthogonal_iteration",
    "orthogonal_iteration_result",
    "overlapped_submeshes",
    "reassemble",
    "shifted_factor",
    "submesh_eigenbases",
    "submesh_eigenbases_result",
    "submesh_laplacian",
]
