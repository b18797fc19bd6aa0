"""Registration and identification of partially observed objects in cluttered scans (Section 6.2).

Public names are loaded on first use from their submodules.
"""

from .._plugins import lazy_exports

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
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
