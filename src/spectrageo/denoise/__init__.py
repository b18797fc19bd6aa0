"""Mesh denoising methods and their registry.

Every denoiser is registered under a name with :func:`register` and can be listed with
:func:`available` and run with :func:`denoise`; ``spectrageo demo`` and ``spectrageo denoise`` use the
registry, so a new method joins them automatically.
"""

from ._registry import DenoiserInfo, available, denoise, get, register

__all__ = ["DenoiserInfo", "available", "denoise", "get", "register"]
