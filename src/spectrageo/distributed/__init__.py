"""Batch and out-of-core processing on Dask (optional: ``pip install "spectrageo[dist]"``).

* :func:`batch` -- a single-file command (``denoise``, ``outliers``, ``saliency``, ``compress``,
  ``complete``, ``convert``) over many files, one Dask task per file, with a JSON summary.
* :func:`remove_outliers_tiled` -- outlier removal of a cloud streamed from PLY/NPY/LAS/LAZ in
  spatial tiles with halos, one Dask task per tile, written streaming (see ``docs/scaling.md``).

Dask is imported only when a function runs; without it they raise :class:`DaskMissingError`.
"""

from ._batch import BATCH_COMMANDS, batch, expand_inputs, output_paths
from ._cluster import DaskMissingError, open_client, require_dask
from ._tiled import TiledResult, remove_outliers_tiled

__all__ = [
    "BATCH_COMMANDS",
    "DaskMissingError",
    "TiledResult",
    "batch",
    "expand_inputs",
    "open_client",
    "output_paths",
    "remove_outliers_tiled",
    "require_dask",
]
