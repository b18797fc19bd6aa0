"""Weight files of the learned denoisers: ``.npz`` arrays and a JSON ``__meta__`` (model,
architecture, format_version, training data, seed, version); written atomically.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import numpy as np

from .._errors import InvalidInputError

FORMAT_VERSION = 1
WEIGHTS_DIR = Path(__file__).parent / "weights"
DEFAULT_WEIGHTS = {"bm3d-cnn": WEIGHTS_DIR / "bm3d_cnn.npz", "dae": WEIGHTS_DIR / "dae.npz"}


def save_weights(path, arrays: dict[str, np.ndarray], meta: dict) -> Path:
    """Write ``arrays`` and ``meta`` to ``path`` (``.npz``) atomically; returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = {"format_version": FORMAT_VERSION, **meta}
    payload = {k: np.asarray(v) for k, v in arrays.items()}
    payload["__meta__"] = np.array(json.dumps(meta, sort_keys=True))
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez_compressed(fh, **payload)
        os.chmod(tmp, 0o644)  # mkstemp creates 0600; weights are meant to be shared
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def load_weights(path, model: str | None = None) -> tuple[dict[str, np.ndarray], dict]:
    """Read a weight file; returns ``(arrays, meta)``. ``model`` checks the stored model name."""
    path = Path(path)
    if not path.is_file():
        raise InvalidInputError(f"`weights` file not found: {path}.")
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError) as exc:
        raise InvalidInputError(f"`weights` {path} is not a readable .npz file ({exc}).") from exc
    if "__meta__" not in arrays:
        raise InvalidInputError(f"`weights` {path} has no metadata (not a spectrageo weight file).")
    meta = json.loads(str(arrays.pop("__meta__")))
    if model is not None and meta.get("model") != model:
        raise InvalidInputError(
            f"`weights` {path} holds a {meta.get('model')!r} model; expected {model!r}."
        )
    if int(meta.get("format_version", 0)) > FORMAT_VERSION:
        raise InvalidInputError(
            f"`weights` {path} has format version {meta['format_version']}; this spectrageo "
            f"reads up to {FORMAT_VERSION}."
        )
    return arrays, meta


def default_weights(model: str) -> Path:
    """Path of the shipped weights of ``model`` (``"bm3d-cnn"`` or ``"dae"``)."""
    if model not in DEFAULT_WEIGHTS:
        raise InvalidInputError(
            f"`model` must be one of {', '.join(DEFAULT_WEIGHTS)}; got {model!r}."
        )
    return DEFAULT_WEIGHTS[model]


def package_version() -> str:
    try:
        from importlib.metadata import version

        return version("spectrageo")
    except Exception:  # noqa: BLE001 - metadata absent in a source checkout
        return "unknown"


def unrotate_unit(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``R_i^T p_i`` for (m, 3, 3) rotations and (m, 3) predictions, as unit rows (zero rows stay
    zero): a normal predicted in the patch frame brought back to the mesh frame."""
    n = np.einsum("mji,mj->mi", R, p)
    nrm = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, nrm, out=np.zeros_like(n), where=nrm > 0)


def model_loader(model_cls, method: str):
    """``load_model(weights=None)`` for ``model_cls``: a loaded model passes through, a path is
    loaded once per (path, modification time), None loads the shipped weights of ``method``."""
    from functools import lru_cache

    @lru_cache(maxsize=8)
    def cached(path: str, mtime: float):
        return model_cls.load(path)

    def load_model(weights=None):
        if isinstance(weights, model_cls):
            return weights
        path = default_weights(method) if weights is None else Path(weights)
        if not path.is_file():
            raise InvalidInputError(f"`weights` file not found: {path}.")
        return cached(str(path.resolve()), path.stat().st_mtime)

    load_model.__doc__ = (
        f"The {method} model of ``weights`` (a path, a loaded model, or None: the shipped weights)."
    )
    return load_model
