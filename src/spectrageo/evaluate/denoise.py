"""Evaluation of the static mesh denoisers on noisy / ground-truth pairs (thesis Tables 5.4-5.5).

``spectrageo evaluate denoise [--data DIR] [--methods a,b] [--out FILE]`` runs every registered
denoiser (default settings) on every pair ``<data>/denoise/<Model>/{Noisy,Original}.*`` and reports
the metrics of Section 4.9 (theta, Dmean d, Dmax d, dist n, NMSVE, Dmean n, one-sided Hausdorff) and
the wall time. Optional peers run in the same session when their package is importable (the
``bench`` extra): PyMeshLab's two-step smoothing and Taubin smoothing, Open3D's Taubin smoothing.

``spectrageo evaluate denoise --split tuning|validation|both`` runs the generality protocol
instead (:func:`evaluate_generality`): fixed, disjoint tuning and validation splits of the shared
data (:data:`TUNING_PAIRS`, :data:`TUNING_MESHES`, :data:`VALIDATION_MESHES`), the validation
meshes corrupted by :func:`spectrageo.noise.generate` (five kinds at three levels), the package's
methods with default settings (timed warm, optionally also through the CLI) and the peers each at
its best single setting on the tuning split and at its per-case oracle over :data:`PEER_GRIDS`.
"""

from __future__ import annotations

from ._denoise_cases import (
    COLUMNS,
    GRID_COLUMNS,
    LEFT_OUT,
    PEER_FIXED,
    PEER_GRIDS,
    PEERS,
    PROTOCOL_COLUMNS,
    PROTOCOL_METHODS,
    SAME_SHAPE_AS_TUNING,
    SPLIT_CHOICES,
    TUNING_MESHES,
    TUNING_PAIRS,
    VALIDATION_MESHES,
    GeneralityResult,
    ProtocolCase,
    protocol_cases,
    setting_label,
)
from ._denoise_cases import _load_clean as _load_clean
from ._denoise_protocol import _peer_available as _peer_available
from ._denoise_protocol import _peer_grid as _peer_grid
from ._denoise_protocol import _run_peer as _run_peer
from ._denoise_protocol import (
    choose_fixed,
    evaluate_denoise,
    evaluate_generality,
    learned_sizes,
    peer_rows,
)
from ._denoise_report import (
    THESIS_THETA,
    format_csv,
    format_generality,
    format_learned_sizes,
    format_markdown,
    format_summary,
    generality_summary,
    write_generality,
    write_tables,
)

__all__ = [
    "COLUMNS",
    "GRID_COLUMNS",
    "PEERS",
    "PEER_FIXED",
    "PEER_GRIDS",
    "PROTOCOL_COLUMNS",
    "PROTOCOL_METHODS",
    "SPLIT_CHOICES",
    "SAME_SHAPE_AS_TUNING",
    "THESIS_THETA",
    "TUNING_MESHES",
    "TUNING_PAIRS",
    "VALIDATION_MESHES",
    "LEFT_OUT",
    "GeneralityResult",
    "ProtocolCase",
    "choose_fixed",
    "evaluate_denoise",
    "evaluate_generality",
    "format_csv",
    "format_generality",
    "format_learned_sizes",
    "format_markdown",
    "format_summary",
    "generality_summary",
    "learned_sizes",
    "peer_rows",
    "protocol_cases",
    "setting_label",
    "write_generality",
    "write_tables",
]
