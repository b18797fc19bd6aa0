"""The ``.sga`` animation codec (Section 5.2.2) with one Dask task per frame block.

Partition (``docs/scaling.md``, "Animation codec frame blocks"): what the whole file shares --
the normalisation (bounding box of all frames), the Laplacian ``L = D - C`` (binary, unnormalised,
Eq. 4.1), the anchors (farthest-point samples of the first frame, Eq. 5.51) and the header
segment with the connectivity -- is computed once where :func:`encode_animation_blocks` is
called; ``L`` and the anchors are sent once to every worker, each block of frames to one worker.
One task per block runs Eq. (5.46)-(5.48) and the quantisation and entropy coding of that block
and returns its segment; the driver writes the segments in frame order after the header and
appends the frame index.

Cross-block dependence and the "overlap" it needs: a block segment decodes on its own, but with
``method="blocks"`` and ``basis="oi"`` (the default) the encoder finds a block's
eigen-trajectories by orthogonal iterations started from the *previous block's* basis (Section
5.2.2, "Speed-up Process using OI"), which was itself started from the one before: the basis of
block ``b`` depends on every earlier block, not on a fixed number of frames before it. What
crosses the block boundary is small, though: three ``k_f x k_f`` matrices. A chain of small
tasks (one per block, on the worker holding that block) computes these bases in frame order with
the serial code's own function (a ``k_f x k_f`` Gram matrix and ``n_iter`` QR steps each), and
each block's coding task receives the previous block's basis from the chain, so its output is
the serial segment byte for byte. ``basis="exact"`` and the one-block methods (``pca``,
``pca-q``, ``pca-qs``, ``pca-qp``: the whole sequence is one block, hence one task and no
parallelism) have no chain.

Rate control (``bpvf`` / ``error``) searches one quantisation step (or, for ``pca``, one kept
count) for the whole file, like the serial encoder. The quantised methods (``pca-q``, ``pca-qs``,
``pca-qp``, ``blocks``) take the step the serial model search of
:mod:`spectrageo.compress._rate_animation` finds (run here, on the driver) and code the blocks on
the cluster at that step once; for ``pca`` the analysed blocks stay on the workers, every probe
codes all blocks in parallel at the probed count, and the serial search routine picks the next
probe from the assembled file's size or the KG error of its decoding. Either way the result is
the serial file.

Refused: ``method="layered"`` (Section 5.2.4): its encoder is a closed loop, frame ``t`` is coded
against a prediction from the two previous *decoded* frames, and refresh frames correct the
decoder's state instead of resetting it, so the state at any frame depends on every earlier
frame; no bounded overlap reproduces it, and the encoder runs only serially.
"""

from __future__ import annotations

import uuid
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from .._errors import InvalidInputError
from ._cluster import open_client, require_dask, show_progress, thread_budget

__all__ = ["CODEC_BLOCK_METHODS", "encode_animation_blocks"]

#: methods of :func:`spectrageo.compress.encode_animation` that :func:`encode_animation_blocks` runs
CODEC_BLOCK_METHODS = ("pca", "pca-q", "pca-qs", "pca-qp", "blocks")


# ----------------------------------------------------------------------------- tasks
def _basis_task(Ab, origin, scale, prev_U, n_iter: int, n_threads: int | None):
    """One link of the OI chain: the eigen-trajectories (3 x (nf, nf)) of one block, started from
    the previous block's (``prev_U``; None for the first block), as the serial encoder finds them."""
    from ..compress._animation import eigen_trajectories
    from ._cluster import thread_limits

    X = (Ab - origin) / scale
    with thread_limits(n_threads):
        return [
            eigen_trajectories(
                np.ascontiguousarray(X[:, :, c]), None if prev_U is None else prev_U[c], n_iter
            )
            for c in range(3)
        ]


def _plan_task(Ab, origin, scale, L, anchors, t0: int, prev_U, n_iter, n_threads):
    """Eq. (5.46)-(5.48) for one block (the serial ``analyse_block`` call, same arguments)."""
    from ..compress._animation import analyse_block
    from ._cluster import thread_limits

    X = (Ab - origin) / scale
    prev = None if prev_U is None else SimpleNamespace(U=prev_U)
    with thread_limits(n_threads):
        return analyse_block(X, L, anchors, t0, prev, n_iter)


def _segment_task(plan, b: int, head: dict, step, n_threads: int | None) -> bytes:
    """Quantisation + entropy coding of one analysed block into its ``.sga`` segment."""
    from ..compress._animation import block_segment, encode_block
    from ._cluster import thread_limits

    with thread_limits(n_threads):
        chunks = encode_block(plan, head["method"], step, head["ratio"], head["rd"])
    return block_segment(
        head["method"], head["n"], head["m"], head["origin"], head["scale"],
        b, plan.t0, plan.nf, step, chunks,
    )  # fmt: skip


# ----------------------------------------------------------------------------- checks
def _check_call(frames, F, method, step, bpvf, error, options):
    """The argument checks of the serial :func:`~spectrageo.compress.encode_animation`."""
    from ..compress import _animation as an

    if method == "layered":
        raise InvalidInputError(
            "method 'layered' cannot be split into frame blocks: its encoder predicts every frame "
            "from the two previous decoded frames (a closed loop whose state depends on all "
            "earlier frames); use spectrageo.compress.encode_animation, or one of "
            f"{list(CODEC_BLOCK_METHODS)}."
        )
    if method not in CODEC_BLOCK_METHODS:
        raise InvalidInputError(
            f"`method` must be one of {list(CODEC_BLOCK_METHODS)}; got {method!r}."
        )
    A, F = an.check_encode_args(frames, F, method, step, bpvf, error)
    o = an._check_options(method, options)
    return A, F, o


# ----------------------------------------------------------------------------- driver
class _BlockEncoder:
    """The shared part of :class:`~spectrageo.compress._animation.AnimationEncoder` computed here;
    the blocks analysed on the cluster and kept there (futures) for every probe of a rate search."""

    def __init__(self, client, A, F, method, o, progress, n_threads):
        from ..compress import _animation as an

        self.client, self.method, self.n_threads = client, method, n_threads
        self.T, self.n = A.shape[:2]
        self.F = F
        self.origin, self.scale = an.frame_box(A)
        L = an._laplacian(F, self.n)
        if an._anchored(method):
            X0 = (A[0] - self.origin) / self.scale
            self.anchors = an.choose_anchors(X0, L, float(o["anchors"]))
        else:
            self.anchors = an._component_anchors(L)
        self.blk = int(o["block"]) if method == "blocks" else self.T
        self.basis = 1 if o["basis"] == "oi" else 0
        self.o = o
        n_iter = int(o["n_iter"]) if self.basis else 0
        self.head = {
            "method": method,
            "n": self.n,
            "m": F.shape[0],
            "origin": tuple(self.origin),
            "scale": self.scale,
            "ratio": float(o["anchor_ratio"]),
            "rd": float(o["rd"]),
        }
        self.tag = uuid.uuid4().hex[:8]
        starts = list(range(0, self.T, self.blk))
        shared = client.scatter([L, self.anchors, self.origin], broadcast=True)
        L_f, anchors_f, origin_f = shared
        self.plans = []
        prev_U = None
        for b, t0 in enumerate(starts):
            Ab = client.scatter(A[t0 : t0 + self.blk])
            self.plans.append(
                client.submit(
                    _plan_task, Ab, origin_f, self.scale, L_f, anchors_f, t0, prev_U, n_iter,
                    n_threads, key=f"spectrageo-sga-{self.tag}-plan-{b}", pure=False,
                )
            )  # fmt: skip
            if n_iter and b + 1 < len(starts):  # OI: the next block starts from this basis
                prev_U = client.submit(
                    _basis_task, Ab, origin_f, self.scale, prev_U, n_iter, n_threads,
                    key=f"spectrageo-sga-{self.tag}-basis-{b}", pure=False,
                )  # fmt: skip
        self.progress = progress
        self.n_probe = 0

    def build(self, step) -> bytes:
        from ..compress._animation import Params, header_segment, index_segment

        self.n_probe += 1
        futs = [
            self.client.submit(
                _segment_task, plan, b, self.head, step, self.n_threads,
                key=f"spectrageo-sga-{self.tag}-segment-{self.n_probe}-{b}", pure=False,
            )
            for b, plan in enumerate(self.plans)
        ]  # fmt: skip
        show_progress(futs, self.progress and self.n_probe == 1)
        segs = self.client.gather(futs)
        o, h = self.o, self.head
        p = Params(
            self.method, self.T, self.blk, int(self.anchors.size), float(step),
            h["ratio"], float(o["weight"]), self.basis, int(o["n_iter"]),
        )  # fmt: skip
        head = header_segment(
            self.method, self.n, h["m"], h["origin"], self.scale, p, self.F, self.anchors
        )
        entries, off = [], len(head)
        for b, seg in enumerate(segs):
            t0 = b * self.blk
            entries.append((t0, min(self.blk, self.T - t0), off, len(seg)))
            off += len(seg)
        index = index_segment(self.method, self.n, h["m"], h["origin"], self.scale, entries)
        return b"".join([head, *segs, index])


def encode_animation_blocks(
    frames,
    F,
    path: str | Path | None = None,
    *,
    method: str = "blocks",
    step: float | None = None,
    bpvf: float | None = None,
    error: float | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    processes: bool = True,
    progress: bool | None = None,
    **options: Any,
) -> bytes:
    """:func:`spectrageo.compress.encode_animation` with one Dask task per frame block.

    Returns (and, with ``path``, writes atomically) the same ``.sga`` bytes as
    ``encode_animation(frames, F, method=method, step=step, bpvf=bpvf, error=error, **options)``
    (Section 5.2.2, Eq. 5.46-5.52; tested byte for byte). The header (normalisation, anchors,
    connectivity) is computed here, each block of frames is sent to one worker and coded there,
    and the segments are assembled in frame order with the frame index. With ``basis="oi"`` a
    chain of small tasks carries each block's eigen-trajectories to the next block (the OI warm
    start of the serial encoder). ``bpvf`` / ``error`` search one step for the whole file as the
    serial encoder does, each probe coding all blocks on the cluster.

    Parameters
    ----------
    frames : (T, n, 3) float or MeshAnimation
    F : (m, 3) int
        Shared faces.
    path : str or Path, optional
        Output ``.sga`` file, written atomically (temporary file + rename).
    method : {"blocks", "pca", "pca-q", "pca-qs", "pca-qp"}
        ``blocks`` (``block`` frames per task, default 16) is the one that parallelises; the other
        four code the whole sequence as one block (one task). ``layered`` is refused
        (:class:`~spectrageo.InvalidInputError`): its closed-loop encoder is sequential.
    step, bpvf, error
        As in :func:`~spectrageo.compress.encode_animation`.
    scheduler : str, optional
        Address of a running Dask scheduler (workers need spectrageo installed).
    workers : int, optional
        Local cluster size (processes of one thread; default one per core, at most one per block).
    processes : bool
        Local cluster of processes (default) or of threads in this process.
    progress : bool, optional
        Dask's progress bar and the dashboard link on stderr (default: when stderr is a terminal).
    **options
        As in :func:`~spectrageo.compress.encode_animation`.

    Returns
    -------
    bytes
        The ``.sga`` file content.
    """
    from ..compress import _animation as an
    from ..compress._rate_animation import QUANTISED, rate_search

    require_dask()
    A, F, o = _check_call(frames, F, method, step, bpvf, error, options)
    if path is not None and not Path(path).expanduser().resolve().parent.is_dir():
        raise InvalidInputError(f"`path`: the folder of {str(path)!r} does not exist.")
    if progress is None:
        from .. import _progress

        progress = _progress.progress_enabled()
    blk = int(o["block"]) if method == "blocks" else A.shape[0]
    n_tasks = -(-A.shape[0] // blk)
    with open_client(
        workers=workers, scheduler=scheduler, processes=processes, n_tasks=n_tasks, verbose=progress
    ) as client:
        n_workers = len(client.scheduler_info().get("workers", {}))
        budget = thread_budget(n_workers, scheduler)
        enc = _BlockEncoder(client, A, F, method, o, progress, budget)
        if method in QUANTISED and (bpvf is not None or error is not None):
            # the serial model search picks the step (the serial file's), the cluster codes it
            data = enc.build(rate_search(an.make_encoder(A, F, method, o), A, bpvf, error)[0])
        else:
            data = an.encode_at_rate(enc.build, A, method, step, bpvf, error)
        del enc
    if path is not None:
        from ..io import atomic_write

        with atomic_write(path) as tmp:
            Path(tmp).write_bytes(data)
    return data
