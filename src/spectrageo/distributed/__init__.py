"""Batch and out-of-core processing on Dask (optional: ``pip install "spectrageo[dist]"``).

* :func:`batch` -- a single-file command (``denoise``, ``outliers``, ``saliency``, ``compress``,
  ``complete``, ``convert``) over many files, one Dask task per file, with a JSON summary.
* :func:`remove_outliers_tiled` -- outlier removal of a cloud streamed from PLY/NPY/LAS/LAZ (or
  an (n, 3) numpy / ``dask.array``) in spatial tiles with halos, one Dask task per tile, written
  streaming (see ``docs/scaling.md``); with ``method="rpca"`` and ``tile >= block_size`` it equals
  :func:`spectrageo.outliers.remove_outliers`.
* :func:`saliency_tiled`, :func:`robot_denoise_tiled` -- point-cloud saliency and the robot
  pipeline's outlier removal + bilateral filtering, tiled the same way.
* :func:`gft_rpca_blocks` -- mesh-animation denoising (Algorithm 3) in online mode, one Dask task
  per block of frames, equal to the serial ``gft_rpca(..., block_size=...)``.
* :func:`encode_animation_blocks` -- the ``.sga`` animation codec (Section 5.2.2), one Dask task
  per frame block, the same bytes as the serial ``compress.encode_animation``.
* :data:`COMMANDS` -- the :class:`CommandSchema` of every batch command (runner, options, result
  description), from which the command line builds its options.

Dask is imported only when a function runs; without it they raise :class:`DaskMissingError`.
"""

from ._batch import BATCH_COMMANDS, batch, expand_inputs, output_paths
from ._cluster import DaskMissingError, open_client, require_dask
from ._codec import CODEC_BLOCK_METHODS, encode_animation_blocks
from ._commands import COMMANDS
from ._frames import gft_rpca_blocks
from ._schema import CommandSchema, Option, describe, json_default

#: names of :mod:`._tiled`, imported on first use (it pulls in the outlier kernels, which every
#: other command, and ``spectrageo --help``, would otherwise pay for at start-up)
_TILED = (
    "TileOptions",
    "TiledResult",
    "TiledRobotResult",
    "TiledSaliencyResult",
    "remove_outliers_tiled",
    "robot_denoise_tiled",
    "saliency_tiled",
)


def __getattr__(name: str):
    if name in _TILED:
        from . import _tiled

        return getattr(_tiled, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "BATCH_COMMANDS",
    "CODEC_BLOCK_METHODS",
    "COMMANDS",
    "CommandSchema",
    "DaskMissingError",
    "Option",
    "TileOptions",
    "TiledResult",
    "TiledRobotResult",
    "TiledSaliencyResult",
    "batch",
    "describe",
    "encode_animation_blocks",
    "expand_inputs",
    "gft_rpca_blocks",
    "json_default",
    "open_client",
    "output_paths",
    "remove_outliers_tiled",
    "require_dask",
    "robot_denoise_tiled",
    "saliency_tiled",
]
