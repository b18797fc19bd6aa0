"""Spectral processing: GFT/IGFT, low-pass filtering, orthogonal iterations and submeshes."""

from .gft import Eigenbasis, fix_signs, gft, igft, lowpass_whole
from .lowpass import LowpassOptions, LowpassResult, lowpass
from .orthogonal import (
    DOIResult,
    OIResult,
    ShiftedFactor,
    SubmeshOptions,
    dynamic_orthogonal_iteration,
    orthogonal_iteration,
    shifted_factor,
    submesh_eigenbases,
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
    "SubmeshOptions",
    "Submeshes",
    "dynamic_orthogonal_iteration",
    "fix_signs",
    "gft",
    "igft",
    "lowpass",
    "lowpass_whole",
    "orthogonal_iteration",
    "overlapped_submeshes",
    "reassemble",
    "shifted_factor",
    "submesh_eigenbases",
    "submesh_laplacian",
]
