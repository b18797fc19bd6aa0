"""Validated, numpy-backed containers: :class:`Mesh`, :class:`PointCloud`, :class:`MeshAnimation`
(frames (T, n, 3) with one face array) and :class:`PointCloudSequence` (sizes may vary). Input
arrays are never modified.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_faces, as_points


def _check_per_item(arr: Any, n: int, name: str, width: int | None = 3) -> np.ndarray | None:
    if arr is None:
        return None
    a = np.asarray(arr)
    expected = (n, width) if width is not None else (n,)
    if a.shape != expected:
        raise InvalidInputError(f"`{name}` must have shape {expected}; got {a.shape}.")
    if a.dtype.kind == "f" and not np.isfinite(a).all():
        raise InvalidInputError(f"`{name}` contains NaN or inf values.")
    return a


def _check_attributes(attrs: dict[str, Any] | None, n: int, what: str) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    for key, value in (attrs or {}).items():
        a = np.asarray(value)
        if a.ndim < 1 or a.shape[0] != n:
            raise InvalidInputError(
                f"{what} attribute `{key}` must have {n} rows (one per {what}); got shape {a.shape}."
            )
        out[str(key)] = a
    return out


@dataclass(frozen=True, eq=False)
class Mesh:
    """Triangle mesh: ``vertices`` (n, 3) float64, ``faces`` (m, 3) int64, optional
    ``vertex_normals`` (n, 3), ``vertex_colors`` (n, 3|4) and ``vertex_attributes`` /
    ``face_attributes`` (dicts of per-element arrays).
    """

    vertices: np.ndarray
    faces: np.ndarray
    vertex_normals: np.ndarray | None = None
    vertex_colors: np.ndarray | None = None
    vertex_attributes: dict[str, np.ndarray] = field(default_factory=dict)
    face_attributes: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        V = as_points(self.vertices, "vertices")
        F = as_faces(self.faces, V.shape[0], "faces")
        object.__setattr__(self, "vertices", V)
        object.__setattr__(self, "faces", F)
        n, m = V.shape[0], F.shape[0]
        object.__setattr__(
            self, "vertex_normals", _check_per_item(self.vertex_normals, n, "vertex_normals")
        )
        if self.vertex_colors is not None:
            c = np.asarray(self.vertex_colors)
            if c.ndim != 2 or c.shape[0] != n or c.shape[1] not in (3, 4):
                raise InvalidInputError(
                    f"`vertex_colors` must have shape ({n}, 3) or ({n}, 4); got {c.shape}."
                )
            object.__setattr__(self, "vertex_colors", c)
        object.__setattr__(
            self, "vertex_attributes", _check_attributes(self.vertex_attributes, n, "vertex")
        )
        object.__setattr__(
            self, "face_attributes", _check_attributes(self.face_attributes, m, "face")
        )

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])

    @property
    def V(self) -> np.ndarray:  # noqa: N802 - thesis notation
        return self.vertices

    @property
    def F(self) -> np.ndarray:  # noqa: N802 - thesis notation
        return self.faces

    def bbox(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounding box ``(min, max)``."""
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    def with_vertices(self, vertices: np.ndarray) -> Mesh:
        """Same connectivity, new positions (attributes kept, stored normals dropped)."""
        return Mesh(
            vertices,
            self.faces,
            vertex_colors=self.vertex_colors,
            vertex_attributes=dict(self.vertex_attributes),
            face_attributes=dict(self.face_attributes),
        )

    def __repr__(self) -> str:
        return f"Mesh(n_vertices={self.n_vertices}, n_faces={self.n_faces})"


@dataclass(frozen=True, eq=False)
class PointCloud:
    """Point cloud with optional normals (n, 3), colours (n, 3|4) and per-point scalar attributes."""

    points: np.ndarray
    normals: np.ndarray | None = None
    colors: np.ndarray | None = None
    attributes: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        P = as_points(self.points, "points")
        n = P.shape[0]
        object.__setattr__(self, "points", P)
        object.__setattr__(self, "normals", _check_per_item(self.normals, n, "normals"))
        if self.colors is not None:
            c = np.asarray(self.colors)
            if c.ndim != 2 or c.shape[0] != n or c.shape[1] not in (3, 4):
                raise InvalidInputError(
                    f"`colors` must have shape ({n}, 3) or ({n}, 4); got {c.shape}."
                )
            object.__setattr__(self, "colors", c)
        object.__setattr__(self, "attributes", _check_attributes(self.attributes, n, "point"))

    @property
    def n_points(self) -> int:
        return int(self.points.shape[0])

    n_vertices = n_points

    def bbox(self) -> tuple[np.ndarray, np.ndarray]:
        return self.points.min(axis=0), self.points.max(axis=0)

    def select(self, keep: np.ndarray) -> PointCloud:
        """Subset by a boolean mask or index array; normals, colours and attributes follow."""
        keep = np.asarray(keep)
        if keep.dtype == bool and keep.shape != (self.n_points,):
            raise InvalidInputError(
                f"`keep` mask must have shape ({self.n_points},); got {keep.shape}."
            )
        return PointCloud(
            self.points[keep],
            None if self.normals is None else self.normals[keep],
            None if self.colors is None else self.colors[keep],
            {k: v[keep] for k, v in self.attributes.items()},
        )

    def __repr__(self) -> str:
        extras = [x for x in ("normals", "colors") if getattr(self, x) is not None]
        return f"PointCloud(n_points={self.n_points}{', ' + ', '.join(extras) if extras else ''})"


@dataclass(frozen=True, eq=False)
class MeshAnimation:
    """Mesh animation with fixed connectivity: ``frames`` (T, n, 3) and shared ``faces`` (m, 3)."""

    frames: np.ndarray
    faces: np.ndarray

    def __post_init__(self) -> None:
        fr = np.asarray(self.frames)
        if fr.ndim != 3 or fr.shape[2] != 3:
            raise InvalidInputError(f"`frames` must have shape (T, n, 3); got {fr.shape}.")
        if fr.shape[0] == 0 or fr.shape[1] == 0:
            raise InvalidInputError(f"`frames` is empty; got shape {fr.shape}.")
        fr = np.ascontiguousarray(fr, dtype=np.float64)
        if not np.isfinite(fr).all():
            bad = np.argwhere(~np.isfinite(fr).all(axis=2))[0]
            raise InvalidInputError(
                f"`frames` contains NaN or inf coordinates (first at frame {bad[0]}, vertex {bad[1]})."
            )
        object.__setattr__(self, "frames", fr)
        object.__setattr__(self, "faces", as_faces(self.faces, fr.shape[1], "faces"))

    @property
    def n_frames(self) -> int:
        return int(self.frames.shape[0])

    @property
    def n_vertices(self) -> int:
        return int(self.frames.shape[1])

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])

    def frame(self, t: int) -> Mesh:
        return Mesh(self.frames[t], self.faces)

    def __iter__(self) -> Iterator[Mesh]:
        for t in range(self.n_frames):
            yield self.frame(t)

    def __len__(self) -> int:
        return self.n_frames

    def bbox(self) -> tuple[np.ndarray, np.ndarray]:
        return self.frames.min(axis=(0, 1)), self.frames.max(axis=(0, 1))

    def with_frames(self, frames: np.ndarray) -> MeshAnimation:
        return MeshAnimation(frames, self.faces)

    @classmethod
    def from_meshes(cls, meshes: Sequence[Mesh]) -> MeshAnimation:
        """Stack meshes that share one connectivity into an animation."""
        if len(meshes) == 0:
            raise InvalidInputError("`meshes` is empty; an animation needs at least one frame.")
        F0 = meshes[0].faces
        for t, m in enumerate(meshes[1:], start=1):
            if m.n_vertices != meshes[0].n_vertices or not np.array_equal(m.faces, F0):
                raise InvalidInputError(
                    f"frame {t} does not share the connectivity of frame 0 "
                    f"({m.n_vertices} vs {meshes[0].n_vertices} vertices or different faces)."
                )
        return cls(np.stack([m.vertices for m in meshes]), F0)

    def __repr__(self) -> str:
        return f"MeshAnimation(n_frames={self.n_frames}, n_vertices={self.n_vertices}, n_faces={self.n_faces})"


@dataclass(frozen=True, eq=False)
class PointCloudSequence:
    """Sequence of point clouds (sizes may vary per frame)."""

    frames: list[PointCloud]

    def __post_init__(self) -> None:
        items = list(self.frames)
        if not items:
            raise InvalidInputError("`frames` is empty; a sequence needs at least one frame.")
        out = []
        for t, f in enumerate(items):
            if isinstance(f, PointCloud):
                out.append(f)
            else:
                try:
                    out.append(PointCloud(f))
                except InvalidInputError as exc:
                    raise InvalidInputError(f"frame {t}: {exc}") from exc
        object.__setattr__(self, "frames", out)

    @property
    def n_frames(self) -> int:
        return len(self.frames)

    @property
    def n_points(self) -> list[int]:
        return [f.n_points for f in self.frames]

    def is_fixed_size(self) -> bool:
        return len(set(self.n_points)) == 1

    def as_array(self) -> np.ndarray:
        """(T, n, 3) array when every frame has the same number of points."""
        if not self.is_fixed_size():
            raise InvalidInputError(
                "frames have different point counts; cannot stack into (T, n, 3)."
            )
        return np.stack([f.points for f in self.frames])

    def __iter__(self) -> Iterator[PointCloud]:
        return iter(self.frames)

    def __len__(self) -> int:
        return self.n_frames

    def __getitem__(self, t: int) -> PointCloud:
        return self.frames[t]

    def bbox(self) -> tuple[np.ndarray, np.ndarray]:
        lo = np.min([f.points.min(axis=0) for f in self.frames], axis=0)
        hi = np.max([f.points.max(axis=0) for f in self.frames], axis=0)
        return lo, hi

    def __repr__(self) -> str:
        return f"PointCloudSequence(n_frames={self.n_frames})"


Geometry = Mesh | PointCloud | MeshAnimation | PointCloudSequence
