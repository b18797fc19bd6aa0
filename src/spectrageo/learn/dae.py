"""Feature-aware, content-wise denoising autoencoders (thesis Section 5.1.3, Algorithm 4).

A face's row holds the guided normals (Section 4.2.1) of its ``k = 9`` nearest centroids within
two vertex rings, rotated so that its own is ``[1 0 0]``. RPCA of the rows minus the flat row
splits feature faces (``||s_i|| > ||e_i|| + e``, ``e = 0.7``) from flat ones; each class is
grouped by kappa-means and each group has one autoencoder (one hidden layer, tanh); a noisy row
takes the network of its class and nearest centre (lines 10-17), and the vertices follow by
Eq. (4.28). Static meshes use shipped weights; animations train at denoise time on their first
frames (Fig. 5.38) with Noise2Noise targets (docs/decisions.md#learn-dae-rows), turning other
frames' normals by their local motion when needed (docs/decisions.md#learn-motion).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_faces, as_frames, as_points, check_positive, options_with_legacy
from ..geometry import face_centroids, face_normals
from . import _features as fe
from ._nn import mlp_forward, train_mlp_numpy
from ._options import MOTIONS, FramesTrainOptions
from ._weights import default_weights, load_weights, model_loader, unrotate_unit

ARRAYS = ("centres", "W1", "b1", "W2", "b2")
#: RPCA feature threshold ``e`` of Section 5.1.3
FEATURE_THRESHOLD = 0.7


# --------------------------------------------------------------------------- rows and groups
def face_rows(V, F, k: int = fe.IMAGE_COLS):
    """Rows ``M_i`` (m, 3k) of the module notes, the rotations (m, 3, 3) and the kNN (m, k)."""
    N, idx, G, R = fe.mesh_inputs(V, F, k)
    return rows_of(G, idx, R), R, idx, N


def rows_of(P: np.ndarray, idx: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Rotated values ``P`` of the kNN rows, nearest first, flattened to (m, 3k)."""
    out = np.einsum("mij,mkj->mki", R, P[idx], optimize=True)
    return out.reshape(idx.shape[0], -1)


def feature_mask(rows: np.ndarray, *, threshold: float = FEATURE_THRESHOLD) -> np.ndarray:
    """RPCA feature identification of Section 5.1.3: True where ``||s_i|| > ||e_i|| + e``."""
    from ..linalg import rpca

    k = rows.shape[1] // 3
    M = rows - np.tile([1.0, 0.0, 0.0], k)
    if M.shape[0] < 2:
        return np.zeros(M.shape[0], dtype=bool)
    # The first pixel of every row is the face's own guided pixel, rotated to [1 0 0]: its three
    # columns of M are zero up to rounding. Zero columns are zero in both RPCA parts, but they
    # make the solver's Gram matrix singular (it then falls back to a QR per chunk, twice the
    # time), so they are left out; the parts of the other columns are unchanged.
    keep = np.abs(M).max(axis=0) > 1e-9 * max(float(np.abs(M).max()), 1e-300)
    if not keep.any():
        return np.zeros(M.shape[0], dtype=bool)
    res = rpca(
        np.ascontiguousarray(M[:, keep]), method="ialm", on_nonconvergence="ignore", max_iter=200
    )
    s = np.linalg.norm(res.sparse, axis=1)
    e = np.linalg.norm(res.low_rank, axis=1)
    return s > e + threshold


def model_index(rows: np.ndarray, centres: np.ndarray, threshold: float) -> np.ndarray:
    """Model of every row: ``class * n_groups + nearest group centre`` (Algorithm 4, l. 10-17)."""
    feat = feature_mask(rows, threshold=threshold).astype(np.int64)
    G = centres.shape[1]
    out = np.empty(rows.shape[0], dtype=np.int64)
    for c in (0, 1):
        sel = np.flatnonzero(feat == c)
        if sel.size:
            out[sel] = c * G + fe.assign_classes(rows[sel], centres[c])
    return out


def fit_groups(rows: np.ndarray, feat: np.ndarray, n_groups: int, rng=0) -> np.ndarray:
    """kappa-means centres (2, n_groups, 3k) of the flat (0) and feature (1) rows."""
    gen = np.random.default_rng(rng)
    out = np.zeros((2, n_groups, rows.shape[1]))
    for c in (0, 1):
        X = rows[feat == c]
        if X.shape[0] == 0:
            X = rows
        if X.shape[0] > 50000:
            X = X[gen.choice(X.shape[0], 50000, replace=False)]
        cc = fe.kmeans(X, n_groups, rng=gen)
        out[c, : cc.shape[0]] = cc
        if cc.shape[0] < n_groups:
            out[c, cc.shape[0] :] = cc[-1]
    return out


# --------------------------------------------------------------------------- model
class DAEModel:
    """Content-wise DAEs: ``centres`` (2, G, d) and per model ``W1``, ``b1``, ``W2``, ``b2`` (``2 G`` models)."""

    def __init__(self, arrays: dict[str, np.ndarray], meta: dict):
        missing = [k for k in ARRAYS if k not in arrays]
        if missing:
            raise InvalidInputError(f"dae weights lack arrays: {', '.join(missing)}.")
        self.arrays = {k: np.asarray(arrays[k], dtype=np.float64) for k in ARRAYS}
        self.meta = dict(meta)
        self.k = int(meta.get("image_cols", fe.IMAGE_COLS))
        self.activation = str(meta.get("activation", "tanh"))
        self.threshold = float(meta.get("feature_threshold", FEATURE_THRESHOLD))

    @classmethod
    def load(cls, path=None) -> DAEModel:
        path = default_weights("dae") if path is None else Path(path)
        return cls(*load_weights(path, "dae"))

    def predict_rows(self, rows: np.ndarray) -> np.ndarray:
        """Denoised rows (m, d) (Algorithm 4, lines 10-17)."""
        a = self.arrays
        mid = model_index(rows, a["centres"], self.threshold)
        out = np.empty((rows.shape[0], a["W2"].shape[-1]))
        for j in range(a["W1"].shape[0]):
            sel = np.flatnonzero(mid == j)
            if sel.size:
                out[sel] = mlp_forward(
                    rows[sel], a["W1"][j], a["b1"][j], a["W2"][j], a["b2"][j], self.activation
                )
        return out

    def filter_normals(self, V, F) -> np.ndarray:
        """Denoised unit face normals ``n_bar_c`` (m, 3)."""
        rows, R, _, _ = face_rows(V, F, self.k)
        centre = self.predict_rows(rows)[:, :3]  # nearest first: the face itself
        return unrotate_unit(R, centre)


load_model = model_loader(DAEModel, "dae")


def _update(V, F, model: DAEModel, n_iter: int, vertex_iter: int) -> np.ndarray:
    from ..denoise._normals import fast_update_vertices

    X = V.copy()
    for _ in range(n_iter):
        X = fast_update_vertices(X, F, model.filter_normals(X, F), vertex_iter)
    return X


def dae(
    V, F, *, weights=None, n_iter: int | None = None, vertex_iter: int | None = None
) -> np.ndarray:
    """Denoise a static mesh with content-wise DAEs (Section 5.1.3, Algorithm 4).

    ``weights``: a path or :class:`DAEModel` (default: the shipped weights); ``n_iter`` passes
    (default from the metadata, else 1), each followed by ``vertex_iter`` iterations of Eq. (4.28)
    (default 20). Returns the (n, 3) float64 denoised positions.
    """
    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F")
    model = load_model(weights)
    n_iter = int(model.meta.get("n_iter", 1)) if n_iter is None else n_iter
    vertex_iter = int(model.meta.get("vertex_iter", 20)) if vertex_iter is None else vertex_iter
    check_positive(n_iter, "n_iter", integer=True)
    check_positive(vertex_iter, "vertex_iter", integer=True)
    return _update(V, F, model, n_iter, vertex_iter)


# --------------------------------------------------------------------------- animations
#: ``motion="auto"`` compensates when the median local rotation between training frames
#: ``r + 1`` apart exceeds this many degrees (docs/decisions.md#learn-motion)
AUTO_MOTION_DEG = 35.0
#: faces whose centroids fix the local rotation between two frames (``motion="rigid"``)
MOTION_PATCH = 30


def local_rotations(Cs: np.ndarray, Ct: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Kabsch rotations (m, 3, 3) mapping the centred points ``Cs[idx[i]]`` onto ``Ct[idx[i]]``."""
    P = Cs[idx]
    Q = Ct[idx]
    P = P - P.mean(axis=1, keepdims=True)
    Q = Q - Q.mean(axis=1, keepdims=True)
    U, _, Vt = np.linalg.svd(np.einsum("mki,mkj->mij", P, Q))
    d = np.sign(np.linalg.det(U @ Vt))
    d[d == 0] = 1.0
    D = np.ones((idx.shape[0], 3))
    D[:, 2] = d
    return np.einsum("mji,mj,mkj->mik", Vt, D, U)  # V diag(1, 1, d) U^T


def rotation_angles(Q: np.ndarray) -> np.ndarray:
    """Angles (degrees) of rotations (m, 3, 3)."""
    cos = np.clip((np.trace(Q, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    return np.degrees(np.arccos(cos))


class _FrameData:
    """Per-frame normals, guided normals, kNN rows and rotations of an animation."""

    def __init__(self, A: np.ndarray, F: np.ndarray, k: int, motion: str = "none"):
        self.A, self.F, self.k = A, F, k
        self.motion = motion
        self.cache: dict[int, tuple] = {}
        self._centroids: dict[int, np.ndarray] = {}
        self._patches: dict[int, np.ndarray] = {}

    def _clamp(self, t: int) -> int:
        return int(min(max(t, 0), self.A.shape[0] - 1))

    def get(self, t: int):
        t = self._clamp(t)
        if t not in self.cache:
            N, idx, G, R = fe.mesh_inputs(self.A[t], self.F, self.k)
            self.cache[t] = (N, idx, G, R)
        return self.cache[t]

    def centroids(self, t: int) -> np.ndarray:
        t = self._clamp(t)
        if t not in self._centroids:
            self._centroids[t] = face_centroids(self.A[t], self.F)
        return self._centroids[t]

    def rotation(self, t: int, s: int) -> np.ndarray:
        """Rotation of frame ``s``'s normals into frame ``t``'s rows: ``R_t``, times the local motion with ``"rigid"``."""
        R = self.get(t)[3]
        if self.motion == "none" or self._clamp(s) == self._clamp(t):
            return R
        return R @ local_rotations(self.centroids(s), self.centroids(t), self.motion_patches(t))

    def local_motion(self, t: int, s: int) -> float:
        """Median angle (degrees) of the local rotations from frame ``s`` to frame ``t``."""
        Q = local_rotations(self.centroids(s), self.centroids(t), self.motion_patches(t))
        return float(np.median(rotation_angles(Q)))

    def motion_patches(self, t: int) -> np.ndarray:
        """The :data:`MOTION_PATCH` faces around every face of frame ``t`` (Kabsch patches)."""
        t = self._clamp(t)
        if t not in self._patches:
            self._patches[t] = fe.centroid_knn(self.centroids(t), MOTION_PATCH, self.F)
        return self._patches[t]

    def rows(self, t: int, radius: int) -> tuple[np.ndarray, np.ndarray]:
        """Temporal rows of frame ``t`` (frames ``t - radius .. t + radius``, frame ``t`` first) and ``R_t``."""
        _, idx, _, R = self.get(t)
        parts = [
            rows_of(self.get(t + d)[2], idx, self.rotation(t, t + d))
            for d in range(-radius, radius + 1)
        ]
        order = sorted(range(len(parts)), key=lambda j: abs(j - radius))  # frame t first
        return np.concatenate([parts[j] for j in order], axis=1), R


def train_frames_model(
    frames,
    F,
    options: FramesTrainOptions | None = None,
    *,
    train_frames: int,
    clean=None,
    inputs=None,
    rng=0,
    **legacy,
) -> tuple[DAEModel, list[float]]:
    """Train content-wise DAEs on the first ``train_frames`` frames of an animation (numpy).

    Frame ``t``'s rows hold frames ``t - r .. t + r`` (``r = options.temporal``); targets are the
    ``clean`` frames when given, else the mean of the noisy normals of frames ``t - r - 1`` and
    ``t + r + 1`` (docs/decisions.md#learn-dae-rows), so ``train_frames >= 2 r + 3``.

    Parameters
    ----------
    frames : (T, n, 3) float
    F : (m, 3) int
    options : FramesTrainOptions, optional
    train_frames : int
    clean, inputs : (T, n, 3) float, optional
        Clean target frames; frames the rows come from (default ``frames``).
    rng : int or numpy.random.Generator
    **legacy
        Deprecated: the fields of :class:`FramesTrainOptions` as keyword arguments.

    Returns
    -------
    tuple
        The :class:`DAEModel` and the final training loss of each autoencoder.
    """
    o = options_with_legacy(options, legacy, FramesTrainOptions, "train_frames_model")
    k, n_groups, hidden, epochs, activation = o.k, o.n_groups, o.hidden, o.epochs, o.activation
    A = as_frames(frames)
    F = as_faces(F, A.shape[1], "F")
    Ain = A if inputs is None else as_frames(inputs, "inputs")
    check_positive(train_frames, "train_frames", integer=True)
    if train_frames > A.shape[0]:
        raise InvalidInputError(
            f"`train_frames` must be <= the number of frames ({A.shape[0]}); got {train_frames}."
        )
    gen = np.random.default_rng(rng)
    r = int(o.temporal)
    motion = o.motion
    data = _FrameData(Ain, F, k, "none" if motion == "auto" else motion)
    if motion == "auto":  # one training frame (clean targets) shows no motion: "none"
        gap = min(r + 1, train_frames - 1)
        angles = [data.local_motion(t, t + gap) for t in range(0, train_frames - gap, max(gap, 1))]
        data.motion = "rigid" if gap > 0 and np.median(angles) > AUTO_MOTION_DEG else "none"
    X, Y = [], []
    if clean is not None:
        Cl = as_frames(clean, "clean")
        if Cl.shape[0] < train_frames or Cl.shape[1:] != A.shape[1:]:
            raise InvalidInputError(
                f"`clean` must hold at least {train_frames} frames of shape {A.shape[1:]}; "
                f"got {Cl.shape}."
            )
        ts = range(train_frames)
    else:
        if train_frames < 2 * r + 3:
            raise InvalidInputError(
                f"`train_frames` must be >= {2 * r + 3} without clean frames (frame t is fitted "
                f"to the noisy normals of frames t-{r + 1} and t+{r + 1}); got {train_frames}."
            )
        ts = range(r + 1, train_frames - r - 1)
    per = max(1, o.max_rows // len(ts))
    for t in ts:
        rows, R = data.rows(t, r)
        idx = data.get(t)[1]
        if clean is not None:
            tgt = rows_of(face_normals(Cl[t], F), idx, R)
        else:
            tgt = 0.5 * sum(
                rows_of(face_normals(A[s], F), idx, data.rotation(t, s))
                for s in (t - r - 1, t + r + 1)
            )
        sel = np.arange(rows.shape[0])
        if sel.size > per:
            sel = np.sort(gen.choice(sel.size, per, replace=False))
        X.append(rows[sel])
        Y.append(tgt[sel])
    X = np.concatenate(X)
    Y = np.concatenate(Y)
    feat = feature_mask(X)
    centres = fit_groups(X, feat, n_groups, rng=gen)
    mid = feat.astype(np.int64) * n_groups
    for c in (0, 1):
        sel = np.flatnonzero(feat == c)
        if sel.size:
            mid[sel] = c * n_groups + fe.assign_classes(X[sel], centres[c])
    d_in, d = X.shape[1], Y.shape[1]
    Ms = 2 * n_groups
    W1 = np.zeros((Ms, d_in, hidden))
    b1 = np.zeros((Ms, hidden))
    W2 = np.zeros((Ms, hidden, d))
    b2 = np.zeros((Ms, d))
    losses = []
    wts = np.ones(d)
    wts[:3] = 4.0  # the centre normal is what is used: weigh it more
    for j in range(Ms):
        sel = np.flatnonzero(mid == j)
        if sel.size < 2 * hidden:  # too few rows for a model of its own: fit it on all rows
            sel = np.arange(X.shape[0])
        p, ls = train_mlp_numpy(
            X[sel], Y[sel], hidden=hidden, activation=activation, epochs=epochs, weight=wts, rng=gen
        )
        W1[j], b1[j], W2[j], b2[j] = p["W1"], p["b1"], p["W2"], p["b2"]
        losses.append(float(ls[-1]))
    meta = {
        "model": "dae",
        "architecture": (
            f"content-wise DAE: 2 classes x {n_groups} groups, {d_in}-{hidden}-{d} {activation}"
        ),
        "activation": activation,
        "image_cols": k,
        "temporal": r,
        "motion": data.motion,
        "feature_threshold": FEATURE_THRESHOLD,
        "training": "clean first frames" if clean is not None else "noise2noise",
        "train_frames": int(train_frames),
        "epochs": int(epochs),
    }
    arrays = {"centres": centres, "W1": W1, "b1": b1, "W2": W2, "b2": b2}
    return DAEModel(arrays, meta), losses


def _denoise_frames(A: np.ndarray, F, model: DAEModel, vertex_iter: int) -> np.ndarray:
    """One pass of a (temporal) DAE model over every frame, then the vertex update."""
    from ..denoise._normals import fast_update_vertices

    r = int(model.meta.get("temporal", 0))
    data = _FrameData(A, F, model.k, str(model.meta.get("motion", "none")))
    out = np.empty_like(A)
    for t in range(A.shape[0]):
        rows, R = data.rows(t, r)
        centre = model.predict_rows(rows)[:, :3]
        out[t] = fast_update_vertices(A[t], F, unrotate_unit(R, centre), vertex_iter)
        data.cache.pop(t - r - 1, None)  # frames no longer needed
    return out


def dae_animation(
    frames,
    F=None,
    *,
    train_frames: int | None = None,
    weights=None,
    clean=None,
    temporal: int = 2,
    motion: str = "auto",
    k: int = fe.IMAGE_COLS,
    n_stages: int = 1,
    vertex_iter: int = 20,
    epochs: int = 10,
    rng=0,
) -> np.ndarray:
    """Denoise a mesh animation with content-wise DAEs (Section 5.1.3, Fig. 5.38).

    With ``train_frames`` the DAEs are trained on this animation's first frames
    (:func:`train_frames_model`) and denoise every frame; ``n_stages`` > 1 cascades, each stage
    trained on the previous output. Without it the static ``weights`` denoise each frame.
    Returns the (T, n, 3) float64 frames.
    """
    if F is None:
        F = getattr(frames, "faces", None)
        if F is None:
            raise InvalidInputError("`F` is required (the faces shared by all frames).")
    A = as_frames(frames)
    F = as_faces(F, A.shape[1], "F")
    check_positive(n_stages, "n_stages", integer=True)
    check_positive(vertex_iter, "vertex_iter", integer=True)
    gen = np.random.default_rng(rng)
    if train_frames is None:
        model = load_model(weights)
        return np.stack([_update(A[t], F, model, n_stages, vertex_iter) for t in range(A.shape[0])])
    if weights is not None:
        raise InvalidInputError("pass either `train_frames` or `weights`, not both.")
    options = FramesTrainOptions(temporal=temporal, motion=motion, k=k, epochs=epochs)
    out = A.copy()
    for _ in range(n_stages):
        model, _ = train_frames_model(
            A, F, options, train_frames=train_frames, clean=clean, inputs=out, rng=gen
        )
        out = _denoise_frames(out, F, model, vertex_iter)
    return out


__all__ = [
    "MOTIONS",
    "DAEModel",
    "FramesTrainOptions",
    "dae",
    "dae_animation",
    "face_rows",
    "feature_mask",
    "load_model",
    "train_frames_model",
]
