"""Free-space verification of identification poses (docs/decisions.md#identify-visibility).

A model point ``p`` placed in the scene by ``T`` violates free space when the sensor at ``e``
observed a scene point ``q`` on (nearly) the same ray farther away: ``|p - e| < |q - e| - tol``.
The object would have hidden ``q``, so the pose contradicts the scan.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ._common import WORKERS, apply_transform

#: scene points within this many sampling steps (as an angle at the model point's range) share a ray
RAY_STEPS = 1.0
#: neighbouring rays looked at; the nearest of their points counts (robust at silhouettes)
RAY_NEIGHBORS = 4
#: model points whose surface meets their ray at |cos| below this (seen nearly edge-on) are not
#: counted: such a surface covers almost no pixel, so its absence from the scan is no evidence
#: (docs/decisions.md#identify2-grazing)
GRAZE_COS = 0.2
#: a model point more than ``tol`` behind a plane of the scene (a support or a wall), with an
#: observed point of that plane within this many sampling steps of its projection, lies inside
#: the solid and counts as a violation (docs/decisions.md#identify3-planes)
PLANE_NEAR = 2.0


class SceneRays:
    """Directions and ranges of the scene points seen from ``viewpoint``.

    Parameters
    ----------
    points : (n, 3) array
        Observed scene points (all of them: planes and clutter carry free-space evidence).
    viewpoint : (3,) array
        Sensor position.
    step : float
        Sampling step of ``points``; sets the ray width and the range tolerance.
    planes : sequence of ((4,) array, (k, 3) array)
        Planes ``[n, c]`` (``n . x = c``) of the scene with their observed points; a model
        point behind one of them, where it was observed, violates (objects do not enter them).
    """

    def __init__(self, points: np.ndarray, viewpoint: np.ndarray, step: float, planes=()):
        self.e = np.asarray(viewpoint, dtype=np.float64)
        D = points - self.e
        r = np.linalg.norm(D, axis=1)
        ok = r > 0
        self.r = np.r_[r[ok], np.inf]  # index n (no neighbour) reads an infinite range
        self.tree = cKDTree(D[ok] / r[ok, None])
        self.step = float(step)
        self.planes = []
        for nc, Q in planes:
            n, c = np.asarray(nc[:3], dtype=np.float64), float(nc[3])
            sgn = 1.0 if n @ self.e >= c else -1.0  # the sensor's side is the front
            if len(Q):
                self.planes.append((sgn * n, sgn * c, cKDTree(Q)))

    def violations(
        self, P: np.ndarray, T: np.ndarray, tol_steps: float, normals: np.ndarray | None = None
    ) -> float:
        """Fraction of the moved model points ``T P`` (m, 3) with scene rays that violate free space.

        With (unoriented) model ``normals`` (m, 3), points whose surface meets the ray at
        ``|cos| < GRAZE_COS`` are left out. Points behind a plane of the scene where it was
        observed count as violating. Returns 0.0 when no model point has a scene point on
        its ray.
        """
        X = apply_transform(T, P)
        D = X - self.e
        rp = np.linalg.norm(D, axis=1)
        good = rp > 0
        if normals is not None:
            c = np.abs(np.einsum("ij,ij->i", normals @ T[:3, :3].T, D))
            good &= c >= GRAZE_COS * rp
        X, D, rp = X[good], D[good], rp[good]
        if rp.size == 0:
            return 0.0
        ang = RAY_STEPS * self.step / rp
        d, j = self.tree.query(D / rp[:, None], k=RAY_NEIGHBORS,
                               distance_upper_bound=float(ang.max()), workers=WORKERS)  # fmt: skip
        rq = np.where(d <= ang[:, None], self.r[j], np.inf).min(axis=1)
        seen = np.isfinite(rq)
        if not seen.any():
            return 0.0
        bad = seen & (rp < rq - tol_steps * self.step)
        for n, c, tree in self.planes:
            s = X @ n - c
            behind = np.flatnonzero(seen & ~bad & (s < -tol_steps * self.step))
            if behind.size:
                d, _ = tree.query(X[behind] - s[behind, None] * n, k=1,
                                  distance_upper_bound=PLANE_NEAR * self.step, workers=WORKERS)  # fmt: skip
                bad[behind[np.isfinite(d)]] = True
        return float(bad[seen].mean())


__all__ = ["SceneRays"]
