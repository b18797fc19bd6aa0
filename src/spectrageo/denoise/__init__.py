"""Mesh denoising methods and their registry.

Every denoiser is registered under a name with :func:`register` and can be listed with
:func:`available` and run with :func:`denoise`; ``spectrageo demo`` and ``spectrageo denoise`` use the
registry, so a new method joins them automatically.
"""

from . import bilateral, gnf, smoothing, tsgsp  # noqa: F401 (register the methods)
from ._guard import noise_level
from ._registry import DenoiserInfo, available, denoise, get, register
from .dynamic import (  # noqa: F401 (mesh animations)
    denoise_animation,
    dynamic_methods,
    register_animation_method,
)

__all__ = [
    "DenoiserInfo",
    "available",
    "denoise",
    "get",
    "noise_level",
    "register",
    "register_animation_method",
]
