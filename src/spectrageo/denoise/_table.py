"""The table of static mesh denoisers, filled by this package's method modules and by the
``spectrageo.denoisers`` entry points (:func:`spectrageo._plugins.load_plugins`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .._errors import InvalidInputError
from .._plugins import load_plugins

#: entry-point group of the denoisers registered by other packages
PLUGIN_GROUP = "spectrageo.denoisers"


@dataclass(frozen=True)
class DenoiserInfo:
    """A registered denoiser: ``func(V, F, **options) -> (n, 3)``, a one-line summary, a reference,
    its presets, and whether :func:`spectrageo.denoise.denoise` applies the trust region."""

    name: str
    func: Callable[..., np.ndarray]
    summary: str
    reference: str
    presets: tuple[str, ...] = ()
    trusted: bool = False


_REGISTRY: dict[str, DenoiserInfo] = {}


def register(
    name: str, *, summary: str, reference: str, presets: tuple[str, ...] = (), trusted: bool = False
):
    """Decorator: register ``func(V, F, **options) -> (n, 3) array`` under ``name``."""

    def deco(func):
        _REGISTRY[name] = DenoiserInfo(name, func, summary, reference, tuple(presets), trusted)
        return func

    return deco


def available() -> list[str]:
    """Names of the registered denoisers, this package's first, then the plugins'."""
    load_plugins(PLUGIN_GROUP)
    return list(_REGISTRY)


def get(name: str) -> DenoiserInfo:
    """The registered denoiser ``name``; InvalidInputError if neither this package nor a plugin
    registers it."""
    if name not in _REGISTRY:
        load_plugins(PLUGIN_GROUP)
    if name not in _REGISTRY:
        raise InvalidInputError(
            f"unknown denoising method {name!r}; available: {', '.join(_REGISTRY) or 'none'}."
        )
    return _REGISTRY[name]
