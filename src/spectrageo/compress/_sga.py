"""Public entry points of the ``.sga`` animation codecs: encoding, decoding and streaming.

Dispatches between the eigen-trajectory methods (:mod:`._animation`) and the layered codec
(:mod:`._layered`); both write the stream format of :mod:`._sga_format`.
"""

from __future__ import annotations

import math

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_faces
from . import _animation, _container, _layered, _pca_pred
from ._animation import (
    DEFAULT_STEP,
    StreamState,
    _check_options,
    _laplacian,
    analyse_block,
    check_encode_args,
    choose_anchors,
    encode_at_rate,
    encode_block,
    make_encoder,
    read_header,
    reconstruct_block,
)
from ._layered import LayeredEncoder, LayeredState
from ._rate import bisect_step
from ._rate_animation import (
    QUANTISED,
    SLOPE_PRED_BPVF,
    _search,
    pred_rate_search,
    rate_search,
)
from ._sga_format import (
    KIND_INDEX,
    Params,
    block_segment,
    declared_frames,
    header_segment,
    index_segment,
    info_dict,
    is_animation,
    iter_segments,
    parse_block_params,
    segment_end,
)


def encode_animation(
    frames, F, *, method: str = "pca-pred", bpvf=None, error=None, step=None, **options
) -> bytes:
    """See :func:`spectrageo.compress.encode_animation`."""
    if method == "layered":
        if bpvf is not None and error is not None:
            raise InvalidInputError("give at most one of `bpvf` and `error`.")
        return _layered.encode(frames, F, step=step, bpvf=bpvf, error=error, **options)
    A, F = check_encode_args(frames, F, method, step, bpvf, error)
    if error is not None and not np.any(A != A[:, :1]):
        raise InvalidInputError(
            "`error` (KG) is undefined here: every frame has all its vertices at one point; "
            "give `bpvf` or `step` instead."
        )
    reorder = _pop_reorder(options, method)
    if reorder:
        from ._connectivity import reorder_coded

        _V, F, perm, _code = reorder_coded(A[0], F)
        A = A[:, perm]
    enc = make_encoder(A, F, method, options)
    if reorder:
        enc.reordered = True
    if method == "pca-pred":
        return pred_rate_search(enc, A, step, bpvf, error)[1]
    if method in QUANTISED and (bpvf is not None or error is not None):
        return rate_search(enc, A, bpvf, error)[1]
    return encode_at_rate(enc.build, A, method, step, bpvf, error)


def _pop_reorder(options: dict, method: str) -> bool:
    """The ``reorder`` option taken out of ``options``: a bool, True only with ``pca-pred``."""
    reorder = options.pop("reorder", False)
    if not isinstance(reorder, bool | np.bool_) or (reorder and method != "pca-pred"):
        raise InvalidInputError(
            f"`reorder` must be True or False and needs method 'pca-pred'; got {reorder!r}."
        )
    return bool(reorder)


def _check_header_memory(head: _container.Container, name: str) -> None:
    """Refuse a stream whose header declares counts beyond the memory cap (before decoding)."""
    frames = declared_frames(head)
    _container.check_memory(head.method, head.n_vertices, head.n_faces, name, max(frames, 1))


def check_memory(data: bytes, name: str) -> None:
    """:func:`._container.check_memory` for the counts an ``.sga`` header declares (nothing
    when ``data`` does not start with a complete animation header: decoding reports that)."""
    try:
        end = segment_end(data, 0) if is_animation(data) else None
        head = None if end is None else _container.parse(data[:end], fmt=".sga")
    except InvalidInputError:
        return
    if head is not None:
        _check_header_memory(head, name)


def _parse_stream(data, partial: bool):
    segs = iter_segments(data, partial)
    try:
        _p, _e, head = next(segs)
    except StopIteration:
        raise InvalidInputError(".sga data is empty.") from None
    _check_header_memory(head, ".sga header")
    if head.method == "layered":
        return LayeredState(head), segs
    st = read_header(head)
    return st, segs


def _sga_error(exc: InvalidInputError) -> InvalidInputError:
    """``exc`` naming the ``.sga`` format (the helpers shared with ``.sgc`` say ``.sgc``)."""
    text = str(exc)
    return type(exc)(".sga" + text[4:]) if text.startswith(".sgc ") else exc


def _indexed(segs, seen: list[bool]):
    """``segs``, recording in ``seen[0]`` whether the frame index segment was among them."""
    for item in segs:
        if item[2].params[:1] == bytes([KIND_INDEX]):
            seen[0] = True
        yield item


def iter_decode(data, *, partial: bool = False, serial: bool | None = None, _state=None):
    """Yield ``(t0, frames_block)`` for every block of an ``.sga`` byte string, in order.

    A file ends with its frame index; without it the file was cut short, an error unless
    ``partial``. ``_state``: a dict that receives the stream state under ``"st"``.
    """
    if isinstance(data, memoryview | bytearray):
        data = bytes(data)
    if not isinstance(data, bytes):
        raise InvalidInputError(f"`data` must be bytes; got {type(data).__name__}.")
    if not is_animation(data):
        raise InvalidInputError("not a spectrageo compressed animation (.sga).")
    try:
        st, segs = _parse_stream(data, partial)
        if _state is not None:
            _state["st"] = st
        seen = [False]
        segs = _indexed(segs, seen)
        if st.method == "layered":
            yield from _layered.iter_frames(st, segs, partial)
        else:
            yield from _animation.iter_blocks(st, segs, partial, serial)
        if not seen[0] and not partial:
            raise InvalidInputError(
                ".sga data is truncated: its trailing frame index segment is missing "
                "(`spectrageo decompress --partial` decodes the complete blocks)."
            )
    except InvalidInputError as exc:
        raise _sga_error(exc) from exc


def decode_animation(data, *, partial: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """See :func:`spectrageo.compress.decode_animation`."""
    state: dict = {}
    parts = [X for _t0, X in iter_decode(data, partial=partial, _state=state)]
    if not parts:
        raise InvalidInputError(".sga data holds no complete frame.")
    return np.concatenate(parts, axis=0), state["st"].F


def info_animation(data) -> dict:
    """Header summary of ``.sga`` bytes without decoding the geometry."""
    if isinstance(data, memoryview | bytearray):
        data = bytes(data)
    try:
        return _info_animation(data)
    except InvalidInputError as exc:
        raise _sga_error(exc) from exc


def _info_animation(data: bytes) -> dict:
    st, segs = _parse_stream(data, False)
    if st.method == "layered":
        return _layered.info(data, st, segs)
    n_blocks = 0
    frames = 0
    head = _container.parse(data[: segment_end(data, 0)], fmt=".sga")
    conn = len(head.chunks[0][1])
    has_index = False
    for _p, _e, c in segs:
        if c.params[:1] == bytes([KIND_INDEX]):
            has_index = True
            continue
        _b, _t0, nf, _s = parse_block_params(c, st)
        n_blocks += 1
        frames += nf
    p = st.params
    parameters = {
        ("kept_coefficients" if p.method == "pca" else "step"): p.step,
        "block": p.block,
        "n_anchors": p.n_anchors,
        "anchor_ratio": p.anchor_ratio,
        "basis": "oi" if p.basis else "exact",
    }
    return info_dict(data, st, frames, conn, n_blocks, has_index, parameters, head.reordered)


class StreamEncoder:
    """See :class:`spectrageo.compress.StreamEncoder`."""

    def __init__(self, F, *, method="pca-pred", step=None, bpvf=None, **options) -> None:
        self._lay = None
        if method == "layered":
            bad = sorted(set(options) - {"layer", "refresh", "fine"})
            if bad:
                raise InvalidInputError(
                    f"unknown option(s) {bad} for method 'layered'; use ['fine', 'layer', "
                    "'refresh']."
                )
            self._lay = LayeredEncoder(F, step=step, bpvf=bpvf, **options)
            return
        if method not in ("blocks", "pca-pred"):
            raise InvalidInputError(
                f"streaming supports methods 'blocks', 'pca-pred' and 'layered' (the others "
                f"need the whole sequence); got {method!r}."
            )
        self.reorder = _pop_reorder(options, method)
        if step is not None and bpvf is not None:
            raise InvalidInputError("give at most one of `step` and `bpvf`.")
        for name, v in (("step", step), ("bpvf", bpvf)):
            ok = not isinstance(v, bool) and isinstance(v, int | float | np.integer | np.floating)
            if v is not None and not (ok and math.isfinite(float(v)) and float(v) > 0):
                raise InvalidInputError(f"`{name}` must be a positive number; got {v!r}.")
        self.o = _check_options(method, options)
        self.F_in = F
        default = _pca_pred.PRED_STEP if method == "pca-pred" else DEFAULT_STEP
        self.step = default if step is None else float(step)
        self.bpvf = None if bpvf is None else float(bpvf)
        self.method = method
        self.buf: list[np.ndarray] = []
        self.prev = None
        self.t = 0
        self.b = 0
        self.offset = 0
        self.entries: list[tuple[int, int, int, int]] = []
        self.started = False
        self.closed = False
        self.block_steps: list[float] = []

    def _start(self, V0: np.ndarray) -> bytes:
        n = V0.shape[0]
        self.F = as_faces(self.F_in, n, "F")
        self.n = n
        lo, hi = V0.min(axis=0), V0.max(axis=0)
        self.origin = 0.5 * (lo + hi)
        diag = float(np.linalg.norm(hi - lo))
        self.scale = 2.0 * diag if diag > 0 else 1.0  # room for motion beyond the first frame
        self.perm = None
        if self.method == "pca-pred":
            return self._start_pred(V0)
        self.L = _laplacian(self.F, n)
        X0 = (V0 - self.origin) / self.scale
        self.anchors = choose_anchors(X0, self.L, float(self.o["anchors"]))
        self.p = Params(
            self.method,
            0,
            int(self.o["block"]),
            int(self.anchors.size),
            self.step,
            float(self.o["anchor_ratio"]),
            float(self.o["weight"]),
            1 if self.o["basis"] == "oi" else 0,
            int(self.o["n_iter"]),
        )
        # the header carries the nominal step; blocks coded at another step (rate adaptation)
        # carry theirs in their own segment parameters
        head = header_segment(
            self.method,
            n,
            self.F.shape[0],
            tuple(self.origin),
            self.scale,
            self.p,
            self.F,
            self.anchors,
        )
        self.started = True
        self.offset = len(head)
        return head

    def _start_pred(self, V0: np.ndarray) -> bytes:
        if self.reorder:
            from ._connectivity import reorder_coded

            _V, self.F, self.perm, _code = reorder_coded(V0, self.F)
        self.plan = _pca_pred.make_plan(self.F, self.n)
        self.p = Params(
            "pca-pred", 0, int(self.o["block"]), 0, self.step, 1.0, 1.0, 0, _pca_pred.CODER
        )
        head = header_segment(
            "pca-pred",
            self.n,
            self.F.shape[0],
            tuple(self.origin),
            self.scale,
            self.p,
            self.F,
            np.zeros(0, np.int64),
            bool(self.reorder),
        )
        self.started = True
        self.offset = len(head)
        return head

    def push(self, frame) -> bytes:
        """Add one frame (n, 3); returns the bytes ready to send (possibly empty)."""
        if self._lay is not None:
            return self._lay.push(frame)
        if self.closed:
            raise InvalidInputError("the stream is closed.")
        V = np.asarray(frame, dtype=np.float64)
        if V.ndim != 2 or V.shape[1] != 3 or (self.started and V.shape[0] != self.n):
            raise InvalidInputError(f"`frame` must have shape (n, 3); got {V.shape}.")
        if not np.isfinite(V).all():
            raise InvalidInputError("`frame` contains NaN or inf coordinates.")
        out = b"" if self.started else self._start(V)
        if self.perm is not None:
            V = V[self.perm]
        self.buf.append((V - self.origin) / self.scale)
        if len(self.buf) == self.p.block:
            out += self._flush()
        return out

    def _flush(self) -> bytes:
        if not self.buf:
            return b""
        X = np.stack(self.buf)
        self.buf = []
        if self.method == "pca-pred":
            return self._emit(X.shape[0], self._pred_segment(X))
        o = self.o
        plan = analyse_block(
            X,
            self.L,
            self.anchors,
            self.t,
            self.prev,
            int(o["n_iter"]) if o["basis"] == "oi" else 0,
        )
        self.prev = plan
        m = self.F.shape[0]

        def seg(s):
            chunks = encode_block(plan, self.method, s, float(o["anchor_ratio"]), float(o["rd"]))
            return block_segment(
                self.method,
                self.n,
                m,
                tuple(self.origin),
                self.scale,
                self.b,
                self.t,
                plan.nf,
                s,
                chunks,
            )

        if self.bpvf is None:
            s, data = self.step, seg(self.step)
        else:  # per-block rate adaptation: the block alone meets the target
            nvf = float(self.n * plan.nf)
            s, data = bisect_step(
                lambda s: (8.0 * len(seg(s)) / nvf, seg(s)),
                self.bpvf,
                increasing=False,
                what="bpvf",
            )
        self.block_steps.append(s)
        return self._emit(plan.nf, data)

    def _pred_segment(self, X: np.ndarray) -> bytes:
        """The ``pca-pred`` segment of the normalised block ``X`` (nf, n, 3)."""
        enc = _pca_pred.PcaPredEncoder(X, self.F, plan=self.plan)
        nf, m = X.shape[0], self.F.shape[0]

        def seg(s):
            chunks = enc.chunks(s)
            o = tuple(self.origin)
            return block_segment(
                "pca-pred", self.n, m, o, self.scale, self.b, self.t, nf, s, chunks
            )

        if self.bpvf is None:
            s = self.step
        else:  # per-block rate adaptation: secant steps from the previous block's step
            nvf = float(self.n * nf)
            x0 = math.log(self.block_steps[-1] if self.block_steps else self.step)
            s = _search(lambda s: 8.0 * len(seg(s)) / nvf, self.bpvf, x0, SLOPE_PRED_BPVF, "bpvf")
        self.block_steps.append(s)
        return seg(s)

    def _emit(self, nf: int, data: bytes) -> bytes:
        self.entries.append((self.t, nf, self.offset, len(data)))
        self.offset += len(data)
        self.t += nf
        self.b += 1
        return data

    def close(self) -> bytes:
        """Flush the last (short) block and append the frame index; returns the final bytes."""
        if self._lay is not None:
            return self._lay.close()
        if self.closed:
            return b""
        self.closed = True
        if not self.started:
            raise InvalidInputError("the stream has no frame.")
        out = self._flush()
        return out + index_segment(
            self.method, self.n, self.F.shape[0], tuple(self.origin), self.scale, self.entries
        )


class StreamDecoder:
    """See :class:`spectrageo.compress.StreamDecoder`."""

    def __init__(self) -> None:
        self.buf = b""
        self.state: StreamState | None = None
        self.expect = 0
        self.done = False
        self.F: np.ndarray | None = None

    def feed(self, data) -> list[np.ndarray]:
        """Add received bytes; returns the frames (n, 3) completed by them, in order."""
        if self.done and data:
            raise InvalidInputError(".sga stream continues after its frame index.")
        self.buf += bytes(data)
        try:
            return self._segments()
        except InvalidInputError as exc:
            raise _sga_error(exc) from exc

    def _segments(self) -> list[np.ndarray]:
        out: list[np.ndarray] = []
        while self.buf:
            end = segment_end(self.buf, 0)
            if end is None:
                break
            c = _container.parse(self.buf[:end], fmt=".sga")
            self.buf = self.buf[end:]
            if self.state is None:
                _check_header_memory(c, ".sga header")
                if c.method == "layered":
                    self.state = LayeredState(c)
                else:
                    self.state = read_header(c)
                self.F = self.state.F
                continue
            if c.params[:1] == bytes([KIND_INDEX]):
                self.done = True
                continue
            if self.state.method == "layered":
                out.append(self.state.frame(c))
                self.expect += 1
                continue
            out.extend(self._block(c))
        return out

    def _block(self, c) -> list[np.ndarray]:
        _b, t0, nf, step = parse_block_params(c, self.state)
        if t0 != self.expect:
            raise InvalidInputError(
                f".sga blocks are out of order (frame {t0}, expected {self.expect})."
            )
        X = reconstruct_block(self.state, c.chunks, nf, step, serial=False)
        self.expect += nf
        return list(X)

    @property
    def n_frames(self) -> int:
        """Frames decoded so far."""
        return self.expect

    @property
    def pending_bytes(self) -> int:
        """Bytes received that do not yet form a complete segment (a cut stream's remainder)."""
        return len(self.buf)
