"""Scalable layered coding of mesh animations for low-latency streaming (Section 5.2.4,
Algorithm 11), method ``"layered"`` of the ``.sga`` container.

Frame 0 is sent whole; frame ``t`` sends layer ``l_t`` (:mod:`._layered_reconstruct`): the
vertices of ``M_{l_t}`` as residuals against a constant-velocity prediction from the two
previous decoded frames (closed loop), quantised with the step ``s`` (a fraction of twice the
first frame's diagonal) and entropy coded; the decoder turns them into the motion vectors of
Eq. (5.64). With ``bpvf`` each frame's layer is the largest that fits the budget (Algorithm 11
line 5); :func:`encode` bisects the per-frame budget (``bpvf``) or the layer (``error``), or the
step with every vertex sent beyond that range. Every ``refresh`` frames a refresh frame also
sends the other vertices' residuals. Segments: a header (kind 0: frame count, step, refresh,
fine; connectivity and temporal levels), one per frame (kind 1) and the frame index (kind 2);
decoding is sequential. See docs/decisions.md#compress-layered.
"""

from __future__ import annotations

import math
import struct

import numpy as np

from .._errors import InvalidInputError
from .._validation import as_faces, as_frames
from . import _connectivity, _container
from ._container import Reader, varint
from ._entropy import decode_groups, encode_groups
from ._layered_reconstruct import CT_LEVELS, Reconstructor, motion_levels, order_from_levels
from ._sga_format import (
    KIND_BLOCK,
    KIND_HEADER,
    KIND_INDEX,
    MAX_FRAMES,
    TAG_CONNECTIVITY,
    index_segment,
    info_dict,
    iter_segments,
    segment_end,
)

METHOD = "layered"
#: default quantisation step of positions and motion vectors (fraction of twice the first
#: frame's diagonal); chosen on the tuning split, see docs/decisions.md#compress-layered
DEFAULT_STEP = 1e-3
#: smallest step the ``error=`` rate control tries (same unit as ``DEFAULT_STEP``)
_STEP_MIN = 1e-7
#: the rate controls stop within 3 % so that the 5 % contract holds
_AIM = 0.03
#: default layer (fraction of the vertices sent per frame) without a rate target
DEFAULT_LAYER = 0.1
DEFAULT_REFRESH = 16

# segment kinds and the connectivity tag are those of the other .sga streams (a frame is a block
# of one frame), so the shared parser (:func:`._sga_format.iter_segments`) reads both
KIND_FRAME = KIND_BLOCK
TAG_ORDER = 2  # the temporal levels from which the layer order is computed
TAG_FRAME = 7
_HEAD = struct.Struct("<BIdIB")  # kind, frame count, step, refresh, fine
_FRAME = struct.Struct("<BIIId")  # kind, frame number, frame number, 1, step (block layout)


# ----------------------------------------------------------------------------- segments
def _segment(n, m, origin, scale, params: bytes, chunks) -> bytes:
    return _container.Container(METHOD, n, m, origin, scale, params, False, chunks).to_bytes()


def _quantise(x: np.ndarray, step: float) -> np.ndarray:
    q = np.rint(x / step)
    if q.size and np.abs(q).max() > 2**39:
        raise InvalidInputError("motion too large for the quantisation step; use a larger step.")
    return q.astype(np.int64)


def _code_ints(q: np.ndarray) -> bytes:
    """(k, 3) ints: one Laplace group per coordinate."""
    if q.size == 0:
        return b""
    g = np.broadcast_to(np.arange(3), q.shape).ravel()
    return encode_groups(q.ravel(), g, 3)


def _decode_ints(buf: bytes, k: int, what: str) -> np.ndarray:
    if k == 0:
        return np.zeros((0, 3), dtype=np.int64)
    g = np.broadcast_to(np.arange(3), (k, 3)).ravel()
    return decode_groups(buf, g, 3, what).reshape(k, 3)


def _frame_payload(layer: int, q_known: np.ndarray, q_res: np.ndarray | None) -> bytes:
    a = _code_ints(q_known)
    body = varint(layer) + varint(len(a)) + a
    if q_res is not None:
        body += b"\x01" + _code_ints(q_res)
    else:
        body += b"\x00"
    return body


def _parse_payload(buf: bytes, n: int):
    r = Reader(buf, "layered frame")
    layer = r.varint()
    if not 0 <= layer <= n:
        raise InvalidInputError(".sga layered frame has an invalid layer.")
    la = r.varint()
    a = r.take(la)
    flag = r.take(1)[0]
    if flag not in (0, 1):
        raise InvalidInputError(".sga layered frame is malformed.")
    q_known = _decode_ints(a, layer, "layered motion vectors")
    q_res = _decode_ints(r.rest(), n - layer, "layered residuals") if flag else None
    return layer, q_known, q_res


# ----------------------------------------------------------------------------- encoder
class LayeredEncoder:
    """Online encoder: :meth:`push` one frame at a time (``StreamEncoder(method="layered")``)."""

    def __init__(
        self,
        F,
        *,
        step: float | None = None,
        bpvf: float | None = None,
        layer: float | None = None,
        refresh: int = DEFAULT_REFRESH,
        fine: bool = False,
        motion_frames=None,
        n_frames: int = 0,
    ) -> None:
        self.F_in = F
        self.step = DEFAULT_STEP if step is None else float(step)
        if not (math.isfinite(self.step) and 1e-7 <= self.step <= 1.0):
            raise InvalidInputError(f"`step` must be in [1e-7, 1]; got {step!r}.")
        self.bpvf = None if bpvf is None else float(bpvf)
        if self.bpvf is not None and not (math.isfinite(self.bpvf) and self.bpvf > 0):
            raise InvalidInputError(f"`bpvf` must be a positive number; got {bpvf!r}.")
        if layer is not None and (
            isinstance(layer, bool) or not isinstance(layer, int | float) or not 0 < layer <= 1
        ):
            raise InvalidInputError(f"`layer` must be a fraction in (0, 1]; got {layer!r}.")
        self.layer = DEFAULT_LAYER if layer is None else float(layer)
        if isinstance(refresh, bool) or not isinstance(refresh, int | np.integer) or refresh < 0:
            raise InvalidInputError(f"`refresh` must be a non-negative integer; got {refresh!r}.")
        self.refresh = int(refresh)
        self.fine = bool(fine)
        self.motion_frames = motion_frames
        self.n_frames = int(n_frames)
        self.t = 0
        self.offset = 0
        self.entries: list[tuple[int, int, int, int]] = []
        self.started = False
        self.closed = False
        self.layers: list[int] = []

    def _start(self, V0: np.ndarray) -> bytes:
        n = V0.shape[0]
        self.n = n
        self.F = as_faces(self.F_in, n, "F")
        if n > _container.MAX_COUNT or self.F.shape[0] > _container.MAX_COUNT:
            raise InvalidInputError("the animation is too large for the .sga format.")
        lo, hi = V0.min(axis=0), V0.max(axis=0)
        self.origin = 0.5 * (lo + hi)
        diag = float(np.linalg.norm(hi - lo))
        self.scale = 2.0 * diag if diag > 0 else 1.0  # room for motion beyond the first frame
        mf = V0[None] if self.motion_frames is None else np.asarray(self.motion_frames)
        levels = motion_levels(mf)
        self.order = order_from_levels(self.F, n, levels)
        self.rec = Reconstructor(self.F, n, self.order, fine=self.fine)
        head = _HEAD.pack(KIND_HEADER, self.n_frames, self.step, self.refresh, int(self.fine))
        chunks = [
            (TAG_CONNECTIVITY, _connectivity.encode_faces(self.F)),
            (TAG_ORDER, encode_groups(levels, np.zeros(n, dtype=np.int64), 1)),
        ]
        seg = _segment(n, self.F.shape[0], tuple(self.origin), self.scale, head, chunks)
        self.started = True
        self.offset = len(seg)
        return seg

    def _frame_segment(self, body: bytes) -> bytes:
        params = _FRAME.pack(KIND_FRAME, self.t, self.t, 1, self.step)
        return _segment(
            self.n, self.F.shape[0], tuple(self.origin), self.scale, params, [(TAG_FRAME, body)]
        )

    def push(self, frame) -> bytes:
        """Add one frame (n, 3); returns its bytes (the header too, with the first frame)."""
        if self.closed:
            raise InvalidInputError("the stream is closed.")
        V = np.asarray(frame, dtype=np.float64)
        if V.ndim != 2 or V.shape[1] != 3 or (self.started and V.shape[0] != self.n):
            raise InvalidInputError(f"`frame` must have shape (n, 3); got {V.shape}.")
        if not np.isfinite(V).all():
            raise InvalidInputError("`frame` contains NaN or inf coordinates.")
        out = b"" if self.started else self._start(V)
        X = (V - self.origin) / self.scale
        s = self.step
        if self.t == 0:  # the whole first frame (decodable from the first packet)
            q = _quantise(X[self.order], s)
            P0 = np.empty((self.n, 3))
            P0[self.order] = q * s
            self.rec.first(P0)
            body = _frame_payload(self.n, q, None)
            layer = self.n
        else:
            refresh = self.refresh > 0 and self.t % self.refresh == 0
            layer, body = self._choose_layer(X, refresh)
        seg = self._frame_segment(body)
        self.layers.append(layer)
        self.entries.append((self.t, 1, self.offset, len(seg)))
        self.offset += len(seg)
        self.t += 1
        return out + seg

    def _choose_layer(self, X: np.ndarray, refresh: bool) -> tuple[int, bytes]:
        n, s = self.n, self.step
        if self.bpvf is None:
            layer = max(1, int(round(self.layer * n)))
        else:  # Algorithm 11 line 5: the largest layer whose motion vectors fit the budget
            budget = self.bpvf * n / 8.0
            lo, hi = 1, n

            pred = self.rec.predict(self.order)

            def size(k):
                return len(_code_ints(_quantise(X[self.order[:k]] - pred[:k], s))) + 8

            if size(hi) <= budget:
                lo = hi
            while hi - lo > max(1, n // 200):
                mid = (lo + hi) // 2
                if size(mid) <= budget:
                    lo = mid
                else:
                    hi = mid
            layer = lo
        known = self.order[:layer]
        pk = self.rec.predict(known)
        q = _quantise(X[known] - pk, s)  # closed loop: against the decoder's prediction
        Xr = self.rec.step(known, pk + q * s - self.rec.prev[known])
        q_res = None
        if refresh:
            rest = self.order[layer:]
            q_res = _quantise(X[rest] - Xr[rest], s)
            res = np.zeros((n, 3))
            res[rest] = q_res * s
            self.rec.correct(res)
        return layer, _frame_payload(layer, q, q_res)

    def close(self) -> bytes:
        """The frame index; returns the final bytes."""
        if self.closed:
            return b""
        self.closed = True
        if not self.started:
            raise InvalidInputError("the stream has no frame.")
        return index_segment(
            METHOD, self.n, self.F.shape[0], tuple(self.origin), self.scale, self.entries
        )


def encode(frames, F, *, step=None, bpvf=None, error=None, **options) -> bytes:
    """Layered coding of a whole animation (the layer decomposition uses all its frames)."""
    A = as_frames(frames, "frames")
    F = as_faces(F, A.shape[1], "F")
    T = A.shape[0]
    if T > MAX_FRAMES:
        raise InvalidInputError("the animation is too large for the .sga format.")
    bad = sorted(set(options) - {"layer", "refresh", "fine"})
    if bad:
        raise InvalidInputError(
            f"unknown option(s) {bad} for method 'layered'; use ['fine', 'layer', 'refresh']."
        )

    def build(step=step, **kw):
        enc = LayeredEncoder(F, motion_frames=A, n_frames=T, step=step, **options, **kw)
        return b"".join(enc.push(A[t]) for t in range(T)) + enc.close()

    if bpvf is not None:
        return _whole_file_rate(
            build, float(bpvf), A.shape[1] * T, "layer" in options, step_given=step is not None
        )
    if error is None:
        return build()
    if "layer" in options:
        raise InvalidInputError("`layer` cannot be combined with `error`.")
    from ..metrics import kg_error

    target = float(error)
    best = None
    if step is None:
        full = build(layer=1.0)
        e_full = kg_error(decode(full)[0], A)
        best = (abs(e_full - target) / target, full)  # a candidate for the layer search too
        if e_full > target * (1 + _AIM):
            # even sending every vertex of every frame, the default step's rounding is above
            # the request: every vertex is sent and the step is bisected instead
            return _error_by_step(build, A, target, best)
    # the KG error falls as the layer grows: bisection on the layer fraction, within 5 %
    return _bisect_log(
        lambda f: build(layer=f),
        lambda data: -kg_error(decode(data)[0], A),
        -target,
        1e-3,
        1.0,
        best,
        "error",
        iters=14,
        hint="; the step bounds the error from below, try a smaller `step`",
    )


def _bisect_log(make, measure, target, lo, hi, best, what, *, iters=40, hint=""):
    """Bisection (log scale) of a knob in ``[lo, hi]`` until ``measure(make(knob))`` is within 3 %
    of ``target`` (5 % is the contract). ``measure`` must grow with the knob (pass the negatives
    of a measure that falls, and of its target). ``best`` is ``None`` or the (relative gap,
    data) to beat; ``what`` names the request in the error raised when 5 % is not met."""
    for _ in range(iters):
        mid = math.sqrt(lo * hi)
        data = make(mid)
        value = measure(data)
        gap = abs(value - target) / abs(target)
        if best is None or gap < best[0]:
            best = (gap, data)
        if gap <= _AIM:
            break
        if value > target:
            hi = mid
        else:
            lo = mid
        if hi / lo < 1.0001:
            break
    if best[0] > 0.05:
        raise InvalidInputError(
            f"`{what}` = {abs(target):g} could not be met within 5 % with 'layered' (closest: "
            f"{best[0]:.1%} away){hint}."
        )
    return best[1]


def _error_by_step(build, A, target: float, best) -> bytes:
    """``error=`` below what the default step gives with every vertex sent: the step is
    bisected at layer 1, within 5 % of the KG error ``target``; ``best`` is the (relative gap,
    data) of the default step."""
    from ..metrics import kg_error

    return _bisect_log(
        lambda s: build(step=s, layer=1.0),
        lambda data: kg_error(decode(data)[0], A),
        target,
        _STEP_MIN,
        DEFAULT_STEP,
        best,
        "error",
    )


def _rate_by_step(build, target: float, nvf: int, budget: float, best) -> bytes:
    """``bpvf`` above what the default step gives with every vertex sent (a per-frame
    ``budget`` that sends them all): the step is bisected, within 5 %."""
    finest = build(step=_STEP_MIN, bpvf=budget)
    r_top = 8.0 * len(finest) / nvf
    if r_top < target * 0.95:
        raise InvalidInputError(
            f"`bpvf` = {target:g} cannot be reached with 'layered': every vertex of every frame "
            f"at the smallest step ({_STEP_MIN:g}) gives {r_top:.3g} bpvf here."
        )
    return _bisect_log(
        lambda s: build(step=s, bpvf=budget),
        lambda data: -8.0 * len(data) / nvf,  # the rate falls as the step grows
        -target,
        _STEP_MIN,
        DEFAULT_STEP,
        best,
        "bpvf",
    )


def _whole_file_rate(
    build, target: float, nvf: int, fixed_layer: bool, *, step_given: bool = True
) -> bytes:
    """``bpvf`` for a whole file: bisection on the per-frame budget of the rate adaptation so
    that the file -- header and whole first frame included -- is within 5 % of ``target``. A
    target above what every vertex of every frame gives at the default step (``step`` not
    given) is met by bisecting the step with every vertex sent."""
    if fixed_layer:
        raise InvalidInputError("`layer` cannot be combined with `bpvf`.")

    def rate(b):
        data = build(bpvf=b)
        return 8.0 * len(data) / nvf, data

    lo, hi = 1e-3 * target, 64.0 * target
    r_lo, d_lo = rate(lo)
    if r_lo > target * 1.05:
        raise InvalidInputError(
            f"`bpvf` = {target:g} cannot be reached with 'layered': the header and the whole "
            f"first frame alone give {r_lo:.3g} bpvf here (more frames amortise them)."
        )
    r_hi, d_hi = rate(hi)
    if r_hi < target * 0.95 and not step_given:
        return _rate_by_step(build, target, nvf, hi, (abs(r_hi - target) / target, d_hi))
    if r_hi < target * 0.95:
        raise InvalidInputError(
            f"`bpvf` = {target:g} cannot be reached with 'layered': sending every vertex of "
            f"every frame gives {r_hi:.3g} bpvf here (use a smaller `step`)."
        )
    best = min((abs(r_lo - target) / target, d_lo), (abs(r_hi - target) / target, d_hi))
    return _bisect_log(
        lambda b: build(bpvf=b),
        lambda data: 8.0 * len(data) / nvf,
        target,
        lo,
        hi,
        best,
        "bpvf",
        iters=30,
    )


# ----------------------------------------------------------------------------- decoder
class LayeredState:
    """What the decoder knows after the header segment, and its running state."""

    def __init__(self, c: _container.Container) -> None:
        if len(c.params) != _HEAD.size or c.params[0] != KIND_HEADER:
            raise InvalidInputError(".sga layered stream header is malformed.")
        _k, T, step, refresh, fine = _HEAD.unpack(c.params)
        if not (math.isfinite(step) and step > 0 and T <= MAX_FRAMES and fine in (0, 1)):
            raise InvalidInputError(".sga layered stream header has invalid parameters.")
        if [t for t, _ in c.chunks] != [TAG_CONNECTIVITY, TAG_ORDER]:
            raise InvalidInputError(".sga layered stream header lacks connectivity or order.")
        n, m = c.n_vertices, c.n_faces
        self.method = METHOD
        self.n, self.m = n, m
        self.n_frames = T
        self.step = step
        self.refresh = refresh
        self.origin = np.asarray(c.origin)
        self.scale = c.scale
        self.F = _connectivity.decode_faces(c.chunks[0][1], n, m)
        levels = decode_groups(c.chunks[1][1], np.zeros(n, dtype=np.int64), 1, "layer levels")
        if levels.size and (levels.min() < 0 or levels.max() > CT_LEVELS):
            raise InvalidInputError(".sga layer levels are malformed.")
        self.order = order_from_levels(self.F, n, levels)
        self.rec = Reconstructor(self.F, n, self.order, fine=bool(fine))
        self.expect = 0

    def frame(self, c: _container.Container) -> np.ndarray:
        if len(c.params) != _FRAME.size or c.params[0] != KIND_FRAME:
            raise InvalidInputError(".sga layered frame segment header is malformed.")
        _k, t0, _t, nf, step = _FRAME.unpack(c.params)
        if c.method != METHOD or c.n_vertices != self.n or c.n_faces != self.m or nf != 1:
            raise InvalidInputError(".sga layered frame does not belong to this stream.")
        if t0 != self.expect:
            raise InvalidInputError(
                f".sga frames are out of order (frame {t0}, expected {self.expect})."
            )
        if step != self.step or [t for t, _ in c.chunks] != [TAG_FRAME]:
            raise InvalidInputError(".sga layered frame segment is malformed.")
        layer, q, q_res = _parse_payload(c.chunks[0][1], self.n)
        s = self.step
        if t0 == 0:
            if layer != self.n:
                raise InvalidInputError(".sga layered stream must start with a whole frame.")
            P0 = np.empty((self.n, 3))
            P0[self.order] = q * s
            X = self.rec.first(P0)
        else:
            known = self.order[:layer]
            pk = self.rec.predict(known)
            X = self.rec.step(known, pk + q * s - self.rec.prev[known])
            if q_res is not None:
                res = np.zeros((self.n, 3))
                res[self.order[layer:]] = q_res * s
                X = self.rec.correct(res)
        if not np.isfinite(X).all():
            raise InvalidInputError(".sga data decodes to non-finite coordinates (corrupted).")
        self.expect += 1
        return X * self.scale + self.origin


def decode(data) -> tuple[np.ndarray, np.ndarray]:
    """Frames and faces of a complete layered ``.sga`` byte string."""
    segs = iter_segments(bytes(data), False)
    st = LayeredState(next(segs)[2])
    parts = [X for _t, X in iter_frames(st, segs, False)]
    return np.concatenate(parts, axis=0), st.F


def iter_frames(st: LayeredState, segs, partial: bool):
    """Yield ``(t, frame[None])`` for the frame segments ``segs`` that follow the header ``st``."""
    seen_index = False
    for _pos, _end, c in segs:
        if seen_index:
            raise InvalidInputError(".sga data continues after its frame index.")
        if c.params[:1] == bytes([KIND_INDEX]):
            seen_index = True
            continue
        t = st.expect
        yield t, st.frame(c)[None]
    if st.n_frames and st.expect != st.n_frames and not partial:
        raise InvalidInputError(
            f".sga data is truncated: {st.expect} of {st.n_frames} frames present."
        )


def info(data: bytes, st: LayeredState, segs) -> dict:
    """Header summary of a layered ``.sga`` byte string (see :func:`._sga.info_animation`)."""
    conn = len(_container.parse(data[: segment_end(data, 0)]).chunks[0][1])
    layers = []
    has_index = False
    for _p, _e, c in segs:
        if c.params[:1] == bytes([KIND_INDEX]):
            has_index = True
            continue
        if not c.chunks:
            raise InvalidInputError(".sga layered frame segment is malformed.")
        layers.append(_parse_payload(c.chunks[0][1], st.n)[0])
    frames = len(layers)
    parameters = {
        "step": st.step,
        "refresh": st.refresh,
        "mean_layer": float(np.mean(layers[1:])) / st.n if frames > 1 else 1.0,
    }
    return info_dict(data, st, frames, conn, frames, has_index, parameters)
