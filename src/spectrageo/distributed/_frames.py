"""Mesh-animation denoising (Algorithm 3, ``gft-rpca``) with one Dask task per frame block.

Partition (``docs/scaling.md``, "Animation frame blocks"): the spatial setup of Algorithm 3 -- the
overlapped submeshes and the full eigenbasis of every submesh Laplacian, or the exact basis -- is
computed once where :func:`gft_rpca_blocks` is called (:func:`spectrageo.denoise.dynamic.
gft_rpca_setup`) and scattered to every worker once; the animation is cut into consecutive blocks
of ``block_size`` frames, each scattered to one worker, and one task per block runs lines 2-17 of
Algorithm 3 on it (:func:`~spectrageo.denoise.dynamic.gft_rpca_block`). The RPCA of every
(submesh, block) pair draws from its own generator derived from the seed, so the assembled result
equals the serial ``gft_rpca(frames, F, block_size=block_size, rng=rng)``.
"""

from __future__ import annotations

import dataclasses
import time
import uuid
from typing import Any

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_faces, as_frames
from ._cluster import open_client, require_dask, show_progress, thread_budget

__all__ = ["gft_rpca_blocks"]


# ``gft_options`` may hold the fields of :class:`~spectrageo.denoise.dynamic.GFTRPCAOptions`
def _gft_options() -> set[str]:
    from ..denoise.dynamic import GFTRPCAOptions

    return {f.name for f in dataclasses.fields(GFTRPCAOptions)}


def _block_task(setup, frames: np.ndarray, block_index: int, n_threads: int | None):
    """One Dask task: Algorithm 3 on one block of frames with the scattered setup."""
    from .. import _progress
    from ..denoise.dynamic import gft_rpca_block
    from ._cluster import thread_limits

    _progress.QUIET = True
    with thread_limits(n_threads):
        return gft_rpca_block(setup, frames, block_index)


def _prepare(frames, F, block_size, rng, gft_options):
    from ..denoise.dynamic import GFTRPCAOptions, _check_block_size, _faces_of, gft_rpca_setup

    unknown = sorted(set(gft_options) - _gft_options())
    if unknown:
        raise InvalidInputError(
            f"unknown option(s) for gft_rpca_blocks: {', '.join(unknown)}; "
            f"accepted: {', '.join(sorted(_gft_options()))}."
        )
    F = _faces_of(frames, F)
    A = as_frames(frames)
    T, n, _ = A.shape
    F = as_faces(F, n, "F")
    if block_size is None:
        raise InvalidInputError("`block_size` is required (frames per Dask task); got None.")
    bs = _check_block_size(block_size, T)
    setup = gft_rpca_setup(F, n, options=GFTRPCAOptions(**gft_options), rng=rng)
    return A, bs, setup


def _run_blocks(client, A: np.ndarray, bs: int, setup, progress: bool, n_threads: int | None):
    """Scatter ``setup`` to every worker and each block to one, run a task per block, assemble."""
    starts = list(range(0, A.shape[0], bs))
    setup_f = client.scatter(setup, broadcast=True)
    tag = uuid.uuid4().hex[:8]  # several animations may share one cluster (batch)
    futs = []
    for b, s in enumerate(starts):
        block_f = client.scatter(A[s : s + bs])
        futs.append(
            client.submit(
                _block_task,
                setup_f,
                block_f,
                b,
                n_threads,
                key=f"spectrageo-gft-rpca-{tag}-block-{b}",
                pure=False,
            )
        )
    show_progress(futs, progress)
    out = np.empty_like(A)
    n_high = np.zeros((setup.n_parts, len(starts)), dtype=np.int64)
    n_iter, converged, residual = 0, True, 0.0
    for b, (s, fut) in enumerate(zip(starts, futs)):
        r = fut.result()
        out[s : s + bs] = r.frames
        n_high[:, b] = r.n_high
        n_iter = max(n_iter, r.n_iter)
        converged = converged and r.converged
        residual = max(residual, r.residual)
    return out, n_high, n_iter, converged, residual


def gft_rpca_blocks(
    frames,
    F=None,
    *,
    block_size: int,
    scheduler: str | None = None,
    workers: int | None = None,
    rng=None,
    processes: bool = True,
    progress: bool | None = None,
    **gft_options: Any,
):
    """:func:`spectrageo.denoise.dynamic.gft_rpca` in online mode, one Dask task per frame block.

    Equals ``gft_rpca(frames, F, block_size=block_size, rng=rng, **gft_options)`` (the same
    per-block computation with the same per-block random generators; with ``single_thread=False``
    multi-threaded BLAS may change the last bits). The setup -- submeshes and their eigenbases,
    ``sum_i n_i^2`` doubles, or the exact basis -- is computed here, before the cluster starts,
    and sent once to every worker; each task receives only its block of frames (``block_size x n
    x 3`` doubles) and returns its denoised frames.

    Parameters
    ----------
    frames : (T, n, 3) array_like or MeshAnimation
        Noisy animation with shared connectivity.
    F : (m, 3) int, optional
        Shared faces (taken from ``frames.faces`` for a MeshAnimation).
    block_size : int
        Frames per block and per task (the last block may be shorter).
    scheduler : str, optional
        Address of a running Dask scheduler (workers need spectrageo installed).
    workers : int, optional
        Local cluster size (processes of one thread; default one per core, at most one per block).
    rng : int, Generator or None
        As in :func:`~spectrageo.denoise.dynamic.gft_rpca`.
    processes : bool
        Local cluster of processes (default) or of threads in this process.
    progress : bool, optional
        Dask's progress bar and the dashboard link on stderr (default: when stderr is a terminal).
    **gft_options
        The other options of :func:`~spectrageo.denoise.dynamic.gft_rpca` (``energy``, ``rank``,
        ``lam``, ``basis``, ``submesh_size``, ``overlap``, ``submesh_solver``, ``max_iter``,
        ``tol``, ``single_thread``).

    Returns
    -------
    GFTRPCAResult
        ``seconds`` includes the setup and the cluster's start.
    """
    from ..denoise.dynamic import GFTRPCAResult

    t0 = time.perf_counter()
    require_dask()
    A, bs, setup = _prepare(frames, F, block_size, rng, gft_options)
    if progress is None:
        from .. import _progress

        progress = _progress.progress_enabled()
    n_tasks = -(-A.shape[0] // bs)
    with open_client(
        workers=workers, scheduler=scheduler, processes=processes, n_tasks=n_tasks, verbose=progress
    ) as client:
        n_workers = len(client.scheduler_info().get("workers", {}))
        budget = thread_budget(n_workers, scheduler)
        out, n_high, n_iter, converged, residual = _run_blocks(
            client, A, bs, setup, progress, budget
        )
    return GFTRPCAResult(
        out, n_high, setup.basis, setup.n_parts, n_iter, converged, residual,
        time.perf_counter() - t0,
    )  # fmt: skip


def gft_rpca_blocks_in_task(n_threads: int | None = None):
    """For a task already running on a Dask worker (``spectrageo batch``): a function
    ``(frames, F, block_size=..., **options) -> frames`` that runs :func:`gft_rpca_blocks`'s
    block tasks on the same cluster (the calling task secedes from the worker's thread pool while
    it waits, so it holds no worker slot), or None outside a worker."""
    try:
        from distributed import get_worker

        get_worker()
    except (ImportError, ValueError):
        return None

    def run(frames, F=None, *, block_size, rng=None, **gft_options) -> np.ndarray:
        from distributed import worker_client

        A, bs, setup = _prepare(frames, F, block_size, rng, gft_options)
        with worker_client() as client:
            return _run_blocks(client, A, bs, setup, False, n_threads)[0]

    return run
