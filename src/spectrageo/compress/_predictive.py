"""The ``predictive`` static codec: uniform quantisation and parallelogram prediction.

Normalised coordinates are rounded to the grid of step ``q`` (a fraction of the bounding-box
diagonal), so every coordinate is within ``q / 2`` of the input and every vertex within
``q sqrt(3) / 2``, a bound on the symmetric vertex-to-surface Hausdorff distance (under
``max_error`` a vertex may instead take any grid point within the bound, one near its
prediction). The integer
coordinates are predicted along a traversal of the connectivity (multi-parallelogram, the
subset chosen by the encoder) and the residuals coded with an adaptive binary range coder
(:mod:`._predictive_kernel`; residual format 3, chunk tag 8, since
docs/decisions.md#codec-counted-residuals; format 2 (tag 7) and format 1 (tag 6) files still
decode); decoding is integer
arithmetic and one product by ``q``, so it is bit-identical on every machine. See
docs/decisions.md#codec-predictive.
"""

from __future__ import annotations

import math
import struct

import numpy as np

from .._errors import InvalidInputError
from ._container import Reader, f32_below, varint
from ._rate import STEP_MAX, STEP_MIN

TAG_RESIDUALS = 6
#: residual chunk of format 2 (:func:`._predictive_kernel._visit2`)
TAG_RESIDUALS_2 = 7
#: residual chunk of format 3: format 2 with counted adaptive models
#: (docs/decisions.md#codec-counted-residuals)
TAG_RESIDUALS_3 = 8
#: residual format the encoder writes (1, 2 or 3)
FORMAT = 3
_TAGS = {TAG_RESIDUALS: 1, TAG_RESIDUALS_2: 2, TAG_RESIDUALS_3: 3}
_TAG_OF = {v: k for k, v in _TAGS.items()}
_P = struct.Struct("<dd")  # grid step, bound on each coordinate's error (files before v4)
#: the compact parameters: the step as float32 (the encoder's grid is that value) and, under
#: ``max_error`` with a sphere, its radius as float32 (the radius the encoder used)
_Q = struct.Struct("<f")
_QR = struct.Struct("<ff")
#: largest integer coordinate a file may hold (the kernel codes residuals below 2**42)
MAX_GRID = 1 << 40
#: radii, in grid steps, of the spheres of :meth:`PredictivePlan.for_max_error` (at least
#: sqrt(3) / 2, so that the rounded vertex is always inside)
SPHERE_RHO = (0.9, 1.0, 1.2)


class PredictivePlan:
    """Encoder state of the predictive codec: quantise at any step ``q``.

    ``sphere`` (None: rounding to the nearest grid point) lets each vertex take any grid point
    within distance ``sphere`` of the input, one near its prediction (set by
    :meth:`for_max_error`).
    """

    def __init__(self, X: np.ndarray, F: np.ndarray) -> None:
        self.X = X
        self.F = np.ascontiguousarray(F, dtype=np.int64)
        self.n = X.shape[0]
        self.sphere: float | None = None
        self._cache: tuple = (None, b"", None)

    def _bounds(self, q: float, sphere: float | None) -> np.ndarray:
        G = np.rint(self.X / q)
        reach = (sphere or 0.0) / q + 1.0
        if G.size and np.abs(G).max() + reach >= MAX_GRID:
            raise InvalidInputError("quantisation step too small for this mesh; use a larger one.")
        return G.astype(np.int64)

    def _encode(self, q: float) -> tuple[bytes, np.ndarray]:
        q = f32_below(float(q))
        key = (q, self.sphere, FORMAT)
        if self._cache[0] != key:
            self._cache = (key, *self._run(q, self.sphere))
        return self._cache[1], self._cache[2]

    def _run(self, q: float, sphere: float | None) -> tuple[bytes, np.ndarray]:
        """The residual stream and the grid coordinates at step ``q`` (float32) and ``sphere``."""
        from . import _predictive_kernel as kernel

        R = self._bounds(q, sphere)
        X = self.X / q if sphere else np.zeros((1, 3))
        rho = sphere / q if sphere else 0.0
        G = np.zeros_like(R)
        buf = np.zeros(self.n * 3 * 16 + 64, dtype=np.uint8)
        nb = kernel.run(True, self.F, self.n, G, buf, R, R, X, rho, FORMAT)
        if FORMAT >= 3:  # no vertex count; the coder's first byte (always 0: the
            # interval starts inside [0, 1)) and the trailing zero bytes are implied
            if buf[0] != 0:  # pragma: no cover - LZMA's coder never carries into it
                raise RuntimeError("predictive range coder wrote a nonzero first byte")
            return buf[1:nb].tobytes().rstrip(b"\0"), G
        return varint(self.n) + buf[:nb].tobytes(), G

    def params(self, q: float) -> bytes:
        q = f32_below(float(q))
        return _QR.pack(q, self.sphere) if self.sphere else _Q.pack(q)

    def chunks(self, q: float) -> list[tuple[int, bytes]]:
        return [(_TAG_OF[FORMAT], self._encode(q)[0])]

    def reconstruct(self, q: float | None) -> np.ndarray:
        return self.X.copy() if q is None else self._encode(q)[1] * f32_below(float(q))

    def levels(self) -> list[PredictivePlan]:
        return [self]

    def for_max_error(self, bound: float) -> float:
        """Grid step for a vertex error of at most ``bound``.

        Candidates: rounding to the grid of step ``2 bound / sqrt(3)`` (every coordinate within
        ``bound / sqrt(3)``), and on grids of step ``bound / rho`` (:data:`SPHERE_RHO`) the grid
        point within ``bound`` of the vertex near its prediction. Kept: the smallest
        ``bits + 3 n log2(D)``, ``D`` the candidate's largest vertex displacement (equal slope
        on the rate-error curve; docs/decisions.md#codec-sphere).
        """
        from .._threads import thread_map

        R = float(bound) * (1.0 - 1e-9)
        cands = [(None, 2.0 * R / math.sqrt(3.0))] + [(R, R / rho) for rho in SPHERE_RHO]
        # spheres and steps as stored (float32)
        cands = [
            (None if sphere is None else f32_below(sphere), f32_below(q))
            for sphere, q in cands
            if STEP_MIN <= q <= STEP_MAX
        ]
        if not cands:
            raise InvalidInputError(
                f"`max_error` = {bound:g} is below what 'predictive' reaches (its finest step "
                f"{STEP_MIN:g} bounds the error by {STEP_MIN * math.sqrt(3) / 2:.3g})."
            )
        best = None
        for (sphere, q), (data, G) in zip(
            cands, thread_map(lambda c: self._run(c[1], c[0]), cands)
        ):
            D = float(np.sqrt(((G * q - self.X) ** 2).sum(axis=1).max())) if self.n else 0.0
            score = 8 * len(data) + 3 * self.n * math.log2(max(D, 1e-300))
            if best is None or score < best[0]:
                best = (score, sphere, q, data, G)
        self.sphere = best[1]
        self._cache = ((best[2], best[1], FORMAT), best[3], best[4])
        return best[2]


def make_plan(X: np.ndarray, F: np.ndarray, method: str, options: dict) -> PredictivePlan:
    if options:
        raise InvalidInputError(
            f"unknown option(s) {sorted(options)} for method 'predictive'; it takes none."
        )
    return PredictivePlan(X, F)


def describe(params: bytes, method: str) -> dict:
    q, e = _step(params)
    return {"step": q, "max_vertex_error": e}


def _step(params: bytes) -> tuple[float, float]:
    """The grid step and the bound on each vertex's error."""
    if len(params) == _Q.size:
        (q,) = _Q.unpack(params)
        r = q / 2
    elif len(params) == _QR.size:
        q, radius = _QR.unpack(params)
        r = min(radius / math.sqrt(3.0), q) if math.isfinite(radius) and radius >= 0 else -1.0
    elif len(params) == _P.size:
        q, r = _P.unpack(params)
    else:
        raise InvalidInputError(".sgc predictive parameters are malformed.")
    if not (math.isfinite(q) and 0 < q <= STEP_MAX and math.isfinite(r) and 0 <= r <= q):
        raise InvalidInputError(".sgc predictive parameters are invalid (step).")
    return q, r * math.sqrt(3.0)


def decode(params: bytes, chunks, F: np.ndarray, n: int, method: str, *, complete: bool = True):
    """Normalised coordinates (n, 3) from the residual chunk."""
    from . import _predictive_kernel as kernel

    q = _step(params)[0]
    if len(chunks) != 1 or chunks[0][0] not in _TAGS:
        raise InvalidInputError(".sgc predictive stream lacks its residual chunk.")
    ver = _TAGS[chunks[0][0]]
    if ver >= 3:
        buf = np.frombuffer(b"\0" + chunks[0][1], dtype=np.uint8).copy()
    else:
        r = Reader(chunks[0][1], "predictive residuals")
        if r.varint() != n:
            raise InvalidInputError(".sgc predictive residuals do not match the vertex count.")
        buf = np.frombuffer(r.rest(), dtype=np.uint8).copy()
    G = np.zeros((n, 3), dtype=np.int64)
    F = np.ascontiguousarray(F, dtype=np.int64)
    none = np.zeros((0, 3), dtype=np.int64)
    if kernel.run(False, F, n, G, buf, none, none, np.zeros((1, 3)), 0.0, ver) < 0:
        raise InvalidInputError(".sgc predictive residuals are truncated or malformed.")
    if G.size and np.abs(G).max() >= MAX_GRID:
        raise InvalidInputError(".sgc predictive residuals are malformed (out of range).")
    return G * q
