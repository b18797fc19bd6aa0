"""Mesh denoising methods and their registry.

Every denoiser is registered under a name with :func:`register` and can be listed with
:func:`available` and run with :func:`denoise`; ``spectrageo demo`` and ``spectrageo denoise`` use the
registry, so a new method joins them automatically.
"""

from ._guard import noise_level
from ._registry import DenoiserInfo, available, denoise, get, register
from .dynamic import denoise_animation, dynamic_methods  # noqa: F401 (mesh animations)

__all__ = ["DenoiserInfo", "available", "denoise", "get", "noise_level", "register"]
