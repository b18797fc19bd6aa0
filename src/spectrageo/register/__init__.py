"""Registration and identification of partially observed objects in cluttered scans (Section 6.2).

Public names are loaded on first use from their submodules.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    # registration (Sections 6.2.2, 6.2.4, 6.2.5)
    "PreparedTarget": "._api",
    "RegistrationResult": "._api",
    "prepare_target": "._api",
    "register": "._api",
    "broad_phase": "._api",
    "narrow_phase": "._api",
    "robustify": "._api",
    # segmentation and identification (Section 6.2.3)
    "adaptive_dbscan": "._segment",
    "Match": "._identify",
    "identify": "._identify",
    # synthetic scenes with ground truth for evaluation
    "make_scene": ".scenes",
    "Scene": ".scenes",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    try:
        module = _EXPORTS[name]
    except KeyError:
        raise AttributeError(f"module 'spectrageo.register' has no attribute {name!r}") from None
    value = getattr(importlib.import_module(module, __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return __all__
