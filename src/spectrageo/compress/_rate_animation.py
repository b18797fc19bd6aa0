"""Rate control of the animation codecs (Section 5.2.2): the step meeting a ``bpvf`` or KG target.

The quantised eigen-trajectory methods (``pca-q``, ``pca-qs``, ``pca-qp``, ``blocks``) search the
coefficient step ``s`` with trial quantisations that skip the entropy coder:

* error: the decoder's own arithmetic (:func:`._animation.dequantise_block`,
  :func:`._animation.solve_frames`) on the quantised symbols gives the decoded frames exactly, so
  the KG error of a trial is the KG error of the file coded at that step;
* size: the bits of every coded group under the quantised Laplace model the entropy coder fits
  (:mod:`._entropy`), ``-sum log2 p(q)`` plus the raw low bits and the model parameters, and the
  fixed part (headers, connectivity, index) measured once on the file of the coarsest step.

The first step comes from a closed form: for the error, white uniform noise ``s^2 / 12``
through Eq. 5.51 (:meth:`Trials.noise_step`); for the size, per-row Laplace entropies
(:meth:`Trials.model_bits`). Then secant steps on ``(x, log f)``, ``x`` the log step (error) or
the log of the modelled size (size), inverse quadratic interpolation once the target is
bracketed; the file is coded once from the last trial's symbols and its size checked (one
refinement with the model rescaled when it misses). Targets outside what the steps
``[STEP_MIN, STEP_MAX]`` reach raise :class:`~spectrageo.InvalidInputError` with the value there.
``pca`` (a kept-coefficient count), ``pca-spectral`` and ``layered`` keep the bisection of
full encodes (:func:`._animation.encode_at_rate`). See
docs/decisions.md#rate-animation-model-search.
"""

from __future__ import annotations

import math

import numpy as np

from .._errors import InvalidInputError
from .._progress import activity
from ._animation import (
    _Solver,
    dequantise_block,
    quantise_block,
    solve_frames,
)
from ._entropy import MAX_HIGH
from ._rate import AIM, RATE_TOLERANCE, STEP_MAX, STEP_MIN

#: most trial quantisations of one search (each a fraction of a full encode and decode)
MAX_TRIALS = 8
#: initial slope d log f / d log s of the search for a KG error ``f`` (uniform quantisation)
SLOPE_ERROR = 1.0
_HIGH_BITS = MAX_HIGH.bit_length()


def _varint_len(v: int) -> int:
    return max(1, -(-max(int(v), 1).bit_length() // 7))


def _group_bits(v: np.ndarray) -> float:
    """Coded bits of one group of integers under the entropy coder's model (:mod:`._entropy`):
    a quantised Laplace law of scale ``mean |high part|`` on ``[-R, R]``, raw low bits."""
    head = 8.0 * 3
    if v.size == 0:
        return head + 8.0
    R = int(np.abs(v).max())
    shift = max(0, R.bit_length() - _HIGH_BITS)
    hi = v >> shift
    Rh = int(np.abs(hi).max())
    if Rh > MAX_HIGH:
        shift += 1
        hi = v >> shift
        Rh = int(np.abs(hi).max())
    bits = head + 8.0 * _varint_len(Rh) + shift * v.size
    if Rh == 0:
        return bits
    b = float(np.float16(max(float(np.abs(hi).mean()), 0.05)))
    k = np.arange(-Rh, Rh + 2) - 0.5
    cdf = np.where(
        k < 0, 0.5 * np.exp(np.minimum(k, 0) / b), 1 - 0.5 * np.exp(-np.maximum(k, 0) / b)
    )
    p = np.diff(cdf)
    p = np.maximum(p / p.sum(), 2.0**-24)
    cnt = np.bincount(hi + Rh, minlength=2 * Rh + 1)
    used = cnt > 0
    return bits - float(np.sum(cnt[used] * np.log2(p[used])))


def block_bits(sym) -> float:
    """Estimated coded bits of one block's :class:`._animation.BlockSymbols`."""
    bits = 0.0
    for c in range(3):
        k = sym.rows[c].size
        bits += 8.0 * (_varint_len(k) + 8 * k)
        bits += sum(_group_bits(sym.qU[c][:, j]) for j in range(k))
        bits += sum(_group_bits(sym.q[c][j]) for j in range(k))
    d = np.diff(sym.qa, axis=0, prepend=np.zeros((1,) + sym.qa.shape[1:], np.int64))
    for c in range(3):
        bits += _group_bits(d[:1, :, c].ravel()) + _group_bits(d[1:, :, c].ravel())
    return bits


def laplace_entropy(a: np.ndarray) -> np.ndarray:
    """Entropy (bits) of a Laplace variable of scale ``b`` quantised to the nearest multiple of
    ``s``, for ``a = s / b``: ``p_0 = 1 - e^{-a/2}``, ``p_{+-k} = e^{-a(k - 1/2)} (1 - e^{-a}) / 2``.
    """
    a = np.minimum(np.asarray(a, dtype=np.float64), 700.0)
    e = np.exp(-0.5 * a)
    p0 = -np.expm1(-0.5 * a)
    q = -np.expm1(-a)
    with np.errstate(divide="ignore", invalid="ignore"):
        h = -p0 * np.log2(np.where(p0 > 0, p0, 1.0)) - e * np.log2(np.where(q > 0, q / 2, 1.0))
        h += a / math.log(2) * e * (1.0 / np.where(q > 0, q, 1.0) - 0.5)
    return np.where(q > 0, h, 0.0)


class Trials:
    """Trial quantisations of an :class:`._animation.AnimationEncoder` at any step, cached."""

    def __init__(self, enc, frames: np.ndarray) -> None:
        self.enc = enc
        self.A = frames
        self.nvf = float(enc.n * enc.T)
        self._solver = None
        self._syms: dict[float, list] = {}
        self.count = 0
        self.errors: dict[float, float] = {}
        self._rows = None

    def symbols(self, s: float) -> list:
        if s not in self._syms:
            e = self.enc
            self._syms = {s: [quantise_block(p, e.method, s, e.ratio, e.rd) for p in e.plans]}
            self.count += 1
        return self._syms[s]

    def model_bits(self, s: float) -> float:
        """Bits of the coefficients at step ``s`` if every row of ``U^T delta^T`` (Eq. 5.48) were
        Laplace with its mean magnitude ``b``: ``n H(s / b)``, ``H`` the entropy of the
        uniformly quantised Laplace law (closed form, :func:`laplace_entropy`)."""
        if self._rows is None:
            P = [p.P[c] for p in self.enc.plans for c in range(3)]
            self._rows = np.concatenate([np.abs(x).mean(axis=1) for x in P])
        b = np.maximum(self._rows, 1e-300)
        return float(self.enc.n * laplace_entropy(s / b).sum())

    def bits(self, s: float) -> float:
        """Estimated bits of the blocks at step ``s`` (headers and index excluded)."""
        return sum(block_bits(sym) for sym in self.symbols(s))

    def _init(self):
        """The encoder, with the reconstruction's factorisation and the KG denominator ready."""
        if self._solver is None:
            e = self.enc
            self._solver = _Solver(e.L, e.anchors, e.weight)
            self._den = float(np.linalg.norm(self.A - self.A.mean(axis=1, keepdims=True)))
        return self.enc

    def error(self, s: float) -> float:
        """KG error (percent, :func:`spectrageo.metrics.kg_error`) of the frames the decoder
        gives for the file at step ``s``."""
        e = self._init()
        sq = 0.0
        for sym, p in zip(self.symbols(s), e.plans):
            deltas, apos = dequantise_block(sym, e.method, s, e.ratio)
            X = solve_frames(self._solver, deltas, apos, False) * e.scale + e.origin
            sq += float(np.sum((X - self.A[p.t0 : p.t0 + p.nf]) ** 2))
        self.errors[s] = 100.0 * math.sqrt(sq) / self._den
        return self.errors[s]

    def noise_step(self, kg: float) -> float:
        """The step whose uniform quantisation noise (variance ``s^2 / 12`` on every delta
        coordinate and, times ``anchor_ratio``, anchor) gives the KG error ``kg`` through Eq. 5.51:
        ``E ||M e||^2 = sigma^2 ||M||_F^2``, ``||M||_F^2`` from 16 random sign probes."""
        e = self._init()
        rng = np.random.default_rng(0)
        n, na, k = e.n, e.anchors.size, 16
        Z = rng.choice([-1.0, 1.0], size=(n, k))
        fd = float(np.sum(self._solver.solve(Z, np.zeros((na, k))) ** 2)) / k
        Za = rng.choice([-1.0, 1.0], size=(na, k))
        fa = float(np.sum(self._solver.solve(np.zeros((n, k)), Za) ** 2)) / k
        per_s2 = 3.0 * e.T * (fd + e.ratio**2 * fa) / 12.0  # squared error / s^2
        return kg * self._den / (100.0 * e.scale * math.sqrt(per_s2))

    def build(self, s: float) -> bytes:
        return self.enc.build(s, self.symbols(s))


def _search(
    f, target: float, x: float, slope0: float, what: str, to_step=math.exp, bounds=None, aim=AIM
):
    """The step ``s = to_step(x)`` with ``f(s)`` within ``aim`` (default :data:`AIM`) of ``target``, ``log f``
    monotone in ``x`` (increasing when ``slope0 > 0``), starting at ``x``: secant steps on
    ``(x, log f)`` (initial slope ``slope0``), inverse quadratic interpolation once the target is
    bracketed, ``x`` clamped to ``bounds`` (default ``log`` of ``[STEP_MIN, STEP_MAX]``)."""
    lo_x, hi_x = bounds or (math.log(STEP_MIN), math.log(STEP_MAX))
    yt = math.log(target)
    pts: list[tuple[float, float]] = []
    best = None
    for _ in range(MAX_TRIALS):
        v = f(to_step(x))
        err = abs(v / target - 1.0)
        if best is None or err < best[0]:
            best = (err, x)
        if err <= aim:
            return to_step(x)
        y = math.log(max(v, 1e-300))
        pts.append((x, y))
        small = [p for p in pts if (p[1] < yt) == (slope0 > 0)]  # x below the answer
        large = [p for p in pts if (p[1] < yt) != (slope0 > 0)]
        if small and large:
            (x0, y0), (x1, y1) = max(small), min(large)
            if x1 - x0 < 1e-9:
                break
            t = (yt - y0) / (y1 - y0) if y1 != y0 else 0.5
            x = x0 + min(max(t, 0.02), 0.98) * (x1 - x0)
            near = sorted(pts, key=lambda p: abs(p[1] - yt))[:3]
            ys = [p[1] for p in near]
            if len(set(ys)) == 3:  # inverse quadratic interpolation
                xq = sum(
                    near[i][0]
                    * math.prod((yt - ys[j]) / (ys[i] - ys[j]) for j in range(3) if j != i)
                    for i in range(3)
                )
                if x0 + 0.02 * (x1 - x0) < xq < x1 - 0.02 * (x1 - x0):
                    x = xq
            continue
        slope = slope0
        if len(pts) > 1:
            (xa, ya), (xb, yb) = pts[-2], pts[-1]
            sl = (yb - ya) / (xb - xa) if xb != xa else 0.0
            if sl * slope0 > 0 and 0.2 <= sl / slope0 <= 5.0:
                slope = sl
        nx = min(max(x + (yt - y) / slope, lo_x), hi_x)
        if nx == x:  # at a bound and still short of the target
            if err <= RATE_TOLERANCE:
                return to_step(x)
            side = "smallest" if y > yt else "largest"  # stuck above the target: its floor
            raise InvalidInputError(
                f"`{what}` = {target:g} cannot be reached: the {side} value this method gives "
                f"here is {v:.4g}" + _unit(what)
            )
        x = nx
    err, x = best
    if err > RATE_TOLERANCE:
        raise InvalidInputError(
            f"`{what}` = {target:g} could not be met within 5 % (closest: {err:.1%} away): the "
            "rate-distortion test keeps or drops a whole eigen-trajectory near that step."
        )
    return to_step(x)


def _unit(what: str) -> str:
    return " (KG error, percent)." if what == "error" else " bpvf."


def rate_search(enc, frames: np.ndarray, bpvf, error) -> tuple[float, bytes]:
    """``(step, file)``: the file of ``enc`` meeting ``bpvf`` (whole file) or KG ``error``
    within 5 %, and the step it is coded at.

    Raises
    ------
    InvalidInputError
        The target is outside what the steps reach (the smallest file is known before any
        search), or no step meets it within 5 %.
    """
    tr = Trials(enc, frames)
    with activity(f"compress: choosing the step for {'bpvf' if bpvf else 'error'}"):
        if error is not None:
            x0 = math.log(min(max(tr.noise_step(float(error)), STEP_MIN), STEP_MAX))
            s = _search(tr.error, float(error), x0, SLOPE_ERROR, "error")
            return s, tr.build(s)
        floor = tr.build(STEP_MAX)
        fixed = 8.0 * len(floor) - tr.bits(STEP_MAX)
        lo = 8.0 * len(floor) / tr.nvf
        target = float(bpvf)
        if target < lo * (1 - RATE_TOLERANCE):
            raise InvalidInputError(
                f"`bpvf` = {target:g} cannot be reached: the smallest file of this method is "
                f"{lo:.4g} bpvf (the connectivity, {enc.anchors.size} anchor trajectories and "
                "headers at the coarsest step); give a larger `bpvf`."
            )
        gain = 1.0
        for _ in range(2):  # the model, then once rescaled by the measured size

            def bpvf_at(s, g=gain):
                return (fixed + g * tr.bits(s)) / tr.nvf

            def modelled(s):  # the closed-form model of the same
                return (fixed + tr.model_bits(s)) / tr.nvf

            def to_step(x):  # the step where the closed-form model gives exp(x) bpvf
                a, b = math.log(STEP_MIN), math.log(STEP_MAX)
                for _i in range(50):
                    m = 0.5 * (a + b)
                    a, b = (m, b) if modelled(math.exp(m)) > math.exp(x) else (a, m)
                return math.exp(0.5 * (a + b))

            bounds = (math.log(modelled(STEP_MAX)), math.log(modelled(STEP_MIN)))
            x = min(max(math.log(target), bounds[0]), bounds[1])
            s = _search(bpvf_at, target, x, 1.0, "bpvf", to_step, bounds)
            data = tr.build(s)
            got = 8.0 * len(data) / tr.nvf
            if abs(got - target) <= AIM * target:
                return s, data
            gain = (8.0 * len(data) - fixed) / max(tr.bits(s), 1.0)
        if abs(got - target) > RATE_TOLERANCE * target:
            raise InvalidInputError(
                f"`bpvf` = {target:g} could not be met within 5 % (closest: {got:.4g})."
            )
        return s, data


QUANTISED = ("pca-q", "pca-qs", "pca-qp", "blocks")

__all__ = [
    "QUANTISED",
    "Trials",
    "block_bits",
    "pred_error_search",
    "pred_rate_search",
    "rate_search",
]


#: initial slope d log bpvf / d log s of the ``pca-pred`` size search
SLOPE_PRED_BPVF = -0.45
#: decoded KG error over the closed form's at the same step (``pca-pred``: dropped components,
#: basis quantisation, the encoder's rounding choices)
PRED_ERROR_GUESS = 1.22
#: decoded KG error over that of the coefficients rounded to the nearest step (``pca-pred``: the
#: coder's rate-distortion rounding), before the first coded trial measures it
PRED_RDO_RATIO = 1.085
#: coded trials of a ``pca-pred`` ``error=`` search guided by the rounded coefficients' error,
#: before the search on coded trials alone (at most :data:`MAX_TRIALS` more)
PRED_CODED_TRIALS = 2
#: aim of the steps on the rounded coefficients' error (times the ratio), and their number
PRED_ROUNDED_AIM = 0.02
PRED_ROUNDED_STEPS = 2
#: aim of the coded trials (each a decoded file's error, not a model)
PRED_ERROR_AIM = 0.04


def _pred_first_step(enc, den: float, error: float) -> float:
    """The log step where the closed form, a coefficient ``c`` costing ``min(c^2, s^2 / 12)``
    (every 7th vertex, sorted) plus the dropped energy, times :data:`PRED_ERROR_GUESS`, gives the
    KG ``error``."""
    parts = [(p, p.Yc[::7] @ p.V[:, : p.significant()]) for _t, p in enc.parts]
    C2 = np.sort(np.concatenate([(c * c).ravel() for _p, c in parts]))
    cum = np.r_[0.0, np.cumsum(C2)]
    tail = sum(float(p.energy[c.shape[1] :].sum()) for p, c in parts)
    goal = ((error / PRED_ERROR_GUESS * den / (100.0 * enc.scale)) ** 2 - tail) / 7
    a, b = math.log(STEP_MIN), math.log(STEP_MAX)
    for _i in range(40):
        m = 0.5 * (a + b)
        d = math.exp(2 * m) / 12.0
        i = int(np.searchsorted(C2, d))
        e2 = float(cum[i]) + (C2.size - i) * d
        a, b = (m, b) if e2 < goal else (a, m)
    return 0.5 * (a + b)


def pred_error_search(enc, frames: np.ndarray, error: float) -> tuple[float, dict]:
    """``(step, trials)``: the ``pca-pred`` step whose decoded file has the KG ``error`` within
    :data:`PRED_ERROR_AIM` (at worst :data:`~._rate.RATE_TOLERANCE`), and the number of trials
    (``coded``: quantised and coded, at most ``PRED_CODED_TRIALS + MAX_TRIALS``; ``rounded``).

    A coded trial's error is ``r`` times the error ``g(s)`` of the coefficients rounded to the
    nearest step (projection only, no coder), ``r`` = :data:`PRED_RDO_RATIO` until a coded trial
    measures it: each coded trial is at the step where ``r g(s)`` meets the target (at most
    :data:`PRED_ROUNDED_STEPS` steps ``log s += log(target / (r g(s)))`` from
    :func:`_pred_first_step`); then, if none met it, the secant search on coded trials alone.
    See docs/decisions.md#anim-speed3-rounded-guide.
    """
    den = float(np.linalg.norm(frames - frames.mean(axis=1, keepdims=True)))
    n = {"coded": 0, "rounded": 0}
    rounded: dict[float, float] = {}

    def kg(s):
        n["coded"] += 1
        return 100.0 * math.sqrt(enc.sq_error(s)) / den

    def kg_rounded(s):
        if s not in rounded:
            n["rounded"] += 1
            rounded[s] = 100.0 * math.sqrt(enc.sq_error(s, rounded=True)) / den
        return rounded[s]

    lo, hi = math.log(STEP_MIN), math.log(STEP_MAX)
    x = _pred_first_step(enc, den, error)
    ratio = PRED_RDO_RATIO
    for _ in range(PRED_CODED_TRIALS):
        for _i in range(PRED_ROUNDED_STEPS):  # fixed-point steps at slope 1 on r g(s)
            y = ratio * kg_rounded(math.exp(x))
            if abs(y / error - 1.0) <= PRED_ROUNDED_AIM:
                break
            x = min(max(x + math.log(error / y), lo), hi)
        v = kg(math.exp(x))
        if abs(v / error - 1.0) <= PRED_ERROR_AIM:
            return math.exp(x), n
        ratio = v / kg_rounded(math.exp(x))
    return _search(kg, error, x, SLOPE_ERROR, "error", aim=PRED_ERROR_AIM), n


def pred_rate_search(enc, frames: np.ndarray, step, bpvf, error) -> tuple[float, bytes]:
    """``(step, file)`` of a ``pca-pred`` encoder (:class:`._pca_pred.PcaPredFileEncoder`): the
    fixed ``step`` (default :data:`._pca_pred.PRED_STEP`), or the step meeting ``bpvf`` (whole
    file, each trial coded: the coder is a small part of the analysis) or the KG ``error``
    (:func:`pred_error_search`), within 5 %.

    Raises
    ------
    InvalidInputError
        The target is outside what the steps reach, or no step meets it within 5 %.
    """
    from ._pca_pred import PRED_STEP

    if bpvf is None and error is None:
        s = PRED_STEP if step is None else float(step)
        return s, enc.build(s)
    nvf = float(enc.n * enc.T)
    cache: dict[float, bytes] = {}
    with activity(f"compress: choosing the step for {'bpvf' if bpvf else 'error'}"):
        if error is not None:
            s = pred_error_search(enc, frames, float(error))[0]
            return s, enc.build(s)

        def rate(s):
            if s not in cache:
                cache.clear()
                cache[s] = enc.build(s)
            return 8.0 * len(cache[s]) / nvf

        x0 = math.log(PRED_STEP) + (math.log(float(bpvf)) - math.log(4.0)) / SLOPE_PRED_BPVF
        x0 = min(max(x0, math.log(STEP_MIN)), math.log(STEP_MAX))
        s = _search(rate, float(bpvf), x0, SLOPE_PRED_BPVF, "bpvf")
        rate(s)
        return s, cache[s]
