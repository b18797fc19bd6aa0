"""Options of the mesh saliency map, validated once."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._errors import InvalidInputError
from .._validation import check_choice, check_positive
from ._common import NORMALS, check_int
from .geometric import SHRINKAGES, SOLVERS, SPARSE_NORMS


def _check_weights(weights) -> tuple[float, float]:
    try:
        w1, w2 = (float(w) for w in weights)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(
            f"`weights` must be two non-negative numbers (w1, w2); got {weights!r}."
        ) from exc
    if not (np.isfinite(w1) and np.isfinite(w2)) or w1 < 0 or w2 < 0 or w1 + w2 == 0:
        raise InvalidInputError(
            f"`weights` must be non-negative with a positive sum; got {weights!r}."
        )
    return w1, w2


@dataclass(frozen=True)
class SaliencyOptions:
    """How :func:`saliency` computes a map (Section 6.1.2), checked when built: ``k`` neighbours
    per patch (thesis 25), ``fast`` (Table 6.1), ``weights`` of Eq. (6.13), ``normals`` ("guided",
    "face" or (m, 3)) and the RPCA settings of :func:`geometric_face_values`.
    """

    k: int = 25
    fast: bool = False
    weights: tuple[float, float] = (1.0, 1.0)
    normals: Any = "guided"
    sparse_norm: str = "patch"
    shrinkage: str = "group"
    solver: str = "internal"
    tol: float = 1e-4
    max_iter: int = 300
    rng: Any = None

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "k", check_int(self.k, "k", minimum=2))
        if not isinstance(self.fast, bool | np.bool_):
            raise InvalidInputError(f"`fast` must be True or False; got {self.fast!r}.")
        set_(self, "weights", _check_weights(self.weights))
        if isinstance(self.normals, str):
            check_choice(self.normals, "normals", NORMALS)
        else:
            N = np.asarray(self.normals, dtype=np.float64)
            if N.ndim != 2 or N.shape[1] != 3:
                raise InvalidInputError(f"`normals` must have shape (m, 3); got {N.shape}.")
            if not np.isfinite(N).all():
                raise InvalidInputError("`normals` contains NaN or inf values.")
        check_choice(self.sparse_norm, "sparse_norm", SPARSE_NORMS)
        check_choice(self.shrinkage, "shrinkage", SHRINKAGES)
        check_choice(self.solver, "solver", SOLVERS)
        check_positive(self.tol, "tol")
        set_(self, "max_iter", check_int(self.max_iter, "max_iter"))
        if self.solver != "internal" and self.shrinkage == "group":
            raise InvalidInputError(
                f'`solver` = {self.solver!r} supports only shrinkage="elementwise"; '
                'got shrinkage="group".'
            )

    def geometric(self) -> dict[str, Any]:
        """Keywords of :func:`geometric_face_values`."""
        return {
            "sparse_norm": self.sparse_norm,
            "shrinkage": self.shrinkage,
            "solver": self.solver,
            "tol": self.tol,
            "max_iter": self.max_iter,
            "rng": self.rng,
        }


__all__ = ["SaliencyOptions"]
