"""Format-neutral result of a reader, turned into a validated container by the public API."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class RawGeometry:
    """What a single-file reader found; ``faces`` None (no face element) or (0, 3) both mean points."""

    vertices: np.ndarray
    faces: np.ndarray | None = None
    normals: np.ndarray | None = None
    colors: np.ndarray | None = None
    vertex_attributes: dict[str, np.ndarray] = field(default_factory=dict)
    face_attributes: dict[str, np.ndarray] = field(default_factory=dict)
    nan_policy_default: str = "raise"

    @property
    def has_faces(self) -> bool:
        return self.faces is not None and len(self.faces) > 0
