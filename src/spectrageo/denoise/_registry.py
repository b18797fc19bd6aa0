"""Registry of static mesh denoisers: ``name -> function(V, F, **options) -> V_denoised``."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .._errors import InvalidInputError


@dataclass(frozen=True)
class DenoiserInfo:
    name: str
    func: Callable[..., np.ndarray]
    summary: str
    reference: str
    presets: tuple[str, ...] = ()


_REGISTRY: dict[str, DenoiserInfo] = {}
# modules that register denoisers on import (a missing module is simply skipped)
_PLUGINS = (
    "spectrageo.denoise.smoothing",
    "spectrageo.denoise.bilateral",
    "spectrageo.denoise.gnf",
    "spectrageo.denoise.tsgsp",
)
_loaded = False


def register(name: str, *, summary: str, reference: str, presets: tuple[str, ...] = ()):
    """Decorator: register ``func(V, F, **options) -> (n, 3) array`` under ``name``."""

    def deco(func):
        _REGISTRY[name] = DenoiserInfo(name, func, summary, reference, presets)
        return func

    return deco


def _load() -> None:
    global _loaded
    if _loaded:
        return
    for mod in _PLUGINS:
        try:
            importlib.import_module(mod)
        except ModuleNotFoundError as exc:
            if exc.name != mod:
                raise
    _loaded = True


def available() -> list[str]:
    """Names of the registered denoisers, in registration order."""
    _load()
    return list(_REGISTRY)


def get(name: str) -> DenoiserInfo:
    _load()
    if name not in _REGISTRY:
        raise InvalidInputError(
            f"unknown denoising method {name!r}; available: {', '.join(_REGISTRY) or 'none'}."
        )
    return _REGISTRY[name]


def denoise(V, F, *, method: str = "tsgsp", **options) -> np.ndarray:
    """Denoise the vertex positions of mesh ``(V, F)`` with the registered ``method``."""
    return get(method).func(V, F, **options)
