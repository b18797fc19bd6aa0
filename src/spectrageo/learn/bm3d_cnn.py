"""Image-based mesh denoising with a block-matching 3D CNN (thesis Section 5.1.4, Algorithm 5).

Per face: guided pixels (Eqs. 5.38-5.39, line 3) form the image of Fig. 5.40, rotated so that the
pixel of interest is ``[1 0 0]`` (Fig. 5.43, line 4); kappa-means (kappa = 3) on the eigenvalues
of the first row's covariance picks the flat / edge / corner network (line 6); the shrinkage
network of Eqs. (5.40)-(5.41) predicts the centre pixel (line 7), rotated back into a normal
(line 8); the vertices follow by Eq. (4.28) (line 9). Image size, extra channels and the cascade
of stages: docs/decisions.md#learn-bm3d-images; neighbours within two rings:
docs/decisions.md#learn-ring-neighbours.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_faces, as_points, check_positive
from . import _features as fe
from ._nn import RBFTable, cnn_centre
from ._weights import default_weights, load_weights, model_loader, unrotate_unit

#: faces imaged and filtered at a time (bounded memory on large meshes)
IMAGE_CHUNK = 131072
#: arrays of a bm3d-cnn weight file (leading axes: stage, class)
ARRAYS = ("class_centres", "W1", "b1", "rw", "mu", "W2", "b2")


class BM3DCNNModel:
    """A loaded bm3d-cnn model: ``arrays`` (:data:`ARRAYS`, a leading stage axis) and ``meta``."""

    def __init__(self, arrays: dict[str, np.ndarray], meta: dict):
        missing = [k for k in ARRAYS if k not in arrays]
        if missing:
            raise InvalidInputError(f"bm3d-cnn weights lack arrays: {', '.join(missing)}.")
        self.arrays = {k: np.asarray(arrays[k], dtype=np.float64) for k in ARRAYS}
        self.meta = dict(meta)
        self.sigma = float(np.asarray(arrays.get("s", meta.get("rbf_sigma", 0.5))))
        self.k = int(meta.get("image_cols", fe.IMAGE_COLS))
        self.channels = int(self.arrays["W1"].shape[3])
        self._rbf: dict[int, list[RBFTable]] = {}

    @property
    def n_stages(self) -> int:
        return int(self.arrays["W1"].shape[0])

    @property
    def kernel(self) -> int:
        return int(self.arrays["W1"].shape[-1])

    @classmethod
    def load(cls, path=None) -> BM3DCNNModel:
        path = default_weights("bm3d-cnn") if path is None else Path(path)
        arrays, meta = load_weights(path, "bm3d-cnn")
        arrays["s"] = np.asarray(meta.get("rbf_sigma", 0.5))
        return cls(arrays, meta)

    def stage(self, s: int) -> dict[str, np.ndarray]:
        s = min(s, self.n_stages - 1)
        return {k: v[s] for k, v in self.arrays.items() if k != "mu"} | {"mu": self.arrays["mu"]}

    def images(self, V, F):
        """(images (m, ch, ks, k) float32, rotations (m, 3, 3)) of the mesh (steps 1-3)."""
        return fe.build_images(V, F, k=self.k, rows=self.kernel, channels=self.channels)

    def classes(self, img: np.ndarray, s: int) -> np.ndarray:
        lam = fe.row_eigenvalues(img[:, :3, 0, :])
        return fe.assign_classes(lam, self.stage(s)["class_centres"])

    def _tables(self, s: int) -> list[RBFTable]:
        s = min(s, self.n_stages - 1)
        if s not in self._rbf:
            w = self.stage(s)
            self._rbf[s] = [
                RBFTable(w["rw"][c], w["mu"], self.sigma) for c in range(w["rw"].shape[0])
            ]
        return self._rbf[s]

    def predict(self, img: np.ndarray, s: int) -> np.ndarray:
        """Denoised centre pixels (m, 3), in the rotated frame, of stage ``s`` (step 5)."""
        w = self.stage(s)
        cls = self.classes(img, s)
        out = np.empty((img.shape[0], 3))
        tables = self._tables(s)
        for c in range(w["W1"].shape[0]):
            sel = np.flatnonzero(cls == c)
            if sel.size:
                out[sel] = cnn_centre(
                    img,
                    w["W1"][c],
                    w["b1"][c],
                    w["rw"][c],
                    w["mu"],
                    self.sigma,
                    w["W2"][c],
                    w["b2"][c],
                    table=tables[c],
                    index=sel,
                )
        return out

    def filter_normals(self, V, F, s: int = 0, *, chunk: int = IMAGE_CHUNK) -> np.ndarray:
        """Filtered unit face normals (m, 3) of stage ``s``, ``chunk`` faces at a time (the result does not depend on it)."""
        idx, R, parts = fe.image_parts(V, F, k=self.k, channels=self.channels)
        m = idx.shape[0]
        step = max(1, int(chunk))
        p = np.empty((m, 3))
        for a in range(0, m, step):
            faces = np.arange(a, min(m, a + step))
            img = fe.images_of(idx, R, parts, rows=self.kernel, faces=faces)
            p[faces] = self.predict(img, s)
        return unrotate_unit(R, p)


load_model = model_loader(BM3DCNNModel, "bm3d-cnn")


def bm3d_cnn(
    V,
    F,
    *,
    weights=None,
    n_iter: int | None = None,
    vertex_iter: int | None = None,
) -> np.ndarray:
    """Denoise a mesh ``(V, F)`` with the block-matching 3D CNN of Section 5.1.4 (Algorithm 5).

    ``weights``: a path or :class:`BM3DCNNModel` (default: the shipped weights); ``n_iter`` filtering
    passes (default: the trained stages), each followed by ``vertex_iter`` iterations of Eq. (4.28)
    (default from the metadata, else 20). Returns the (n, 3) float64 denoised positions.
    """
    from ..denoise._normals import fast_update_vertices

    V = as_points(V, "V")
    F = as_faces(F, V.shape[0], "F")
    model = load_model(weights)
    n_iter = int(model.meta.get("n_iter", model.n_stages)) if n_iter is None else n_iter
    vertex_iter = int(model.meta.get("vertex_iter", 20)) if vertex_iter is None else vertex_iter
    check_positive(n_iter, "n_iter", integer=True)
    check_positive(vertex_iter, "vertex_iter", integer=True)
    if F.shape[0] < 2:
        raise InvalidInputError(f"`F` must have at least 2 faces; got {F.shape[0]}.")
    X = V.copy()
    for s in range(n_iter):
        N = model.filter_normals(X, F, s)
        X = fast_update_vertices(X, F, N, vertex_iter)
    return X


__all__ = ["ARRAYS", "BM3DCNNModel", "bm3d_cnn", "load_model"]
