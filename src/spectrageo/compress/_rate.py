"""Rate control of the codecs: log-bisection of the quantisation step for a target rate or error."""

from __future__ import annotations

import math

from .._errors import InvalidInputError
from .._progress import activity

#: relative tolerance of the rate control (the issue's contract is 5 %)
RATE_TOLERANCE = 0.05
AIM = 0.03  # the bisection stops within 3 % to stay inside 5 % after rounding
STEP_MIN, STEP_MAX = 1e-7, 4.0


def error_step(measure, target: float, method: str) -> float:
    """The quantisation step whose RMS error (``measure(step)``) is within 3 % of ``target``."""
    floor = measure(None)
    if floor > (1 - AIM) * target:
        raise InvalidInputError(
            f"`error` = {target:g} is below what method {method!r} reaches with these options "
            f"(about {floor:.3g} at the finest step); "
            + (
                "raise `k` or `submesh_size`."
                if method == "spectral"
                else "send more deltas (`feature_fraction`, `class_keep`) or give `ratio` >= 1."
            )
        )
    s, _ = bisect_step(lambda s: (measure(s), None), target, increasing=True, what="error")
    return s


def _unreachable(what: str, target: float, side: str, value: float, other=None) -> str:
    """The message for a target outside what the steps ``[STEP_MIN, STEP_MAX]`` reach."""
    text = f"`{what}` = {target:g} cannot be reached: the {side} value this method gives here is "
    text += f"{value:.4g}"
    if other is not None:
        lo, hi = sorted((value, other))
        text += f" (it reaches {lo:.4g} to {hi:.4g})"
    if what == "bpv" and side == "smallest":
        text += "; the connectivity and header alone take most of it"
    return text + "."


def check_connectivity_floor(bpv: float, conn_bytes: int, n: int, reorder: bool) -> None:
    """Refuse at once a ``bpv`` below the connectivity's share (``8 conn_bytes / n``), the bound
    every file of the mesh exceeds, before any geometry is analysed or coded
    (docs/decisions.md#rate-unreachable-at-once).

    Raises
    ------
    InvalidInputError
        ``bpv < (1 - RATE_TOLERANCE) * 8 conn_bytes / n``; the message names ``reorder`` when
        the order is kept (its connectivity is the expensive one).
    """
    floor = 8.0 * conn_bytes / max(n, 1)
    if bpv >= floor * (1 - RATE_TOLERANCE):
        return
    text = (
        f"`bpv` = {bpv:g} cannot be reached: the connectivity and header alone take more than "
        f"{floor:.2f} bpv here"
    )
    if not reorder:
        text += (
            " with the vertex and face order kept; give reorder=True (--reorder) to let the codec "
            "renumber them (a much smaller connectivity), or a larger `bpv`."
        )
    else:
        text += "; give a larger `bpv`."
    raise InvalidInputError(text)


def bisect_step(measure, target: float, *, increasing: bool, what: str):
    """Log-bisection on the quantisation step until ``measure(step)`` is within 3 % of target.

    ``increasing``: the measure grows with the step (error) or falls with it (bpv).
    """
    with activity(f"compress: searching the step for `{what}`"):
        return _bisect(measure, target, increasing, what)


def _bisect(measure, target: float, increasing: bool, what: str):
    lo, hi = math.log(STEP_MIN), math.log(STEP_MAX)
    best = None
    # the coarsest step first: it is the cheap end, and it alone answers a target below the
    # smallest rate (or above the largest error) before the finest step is coded
    f_hi, d_hi = measure(math.exp(hi))
    if abs(f_hi - target) <= AIM * target:
        return math.exp(hi), d_hi
    if not increasing and target < f_hi * (1 - RATE_TOLERANCE):
        raise InvalidInputError(_unreachable(what, target, "smallest", f_hi))
    if increasing and target > f_hi * (1 + RATE_TOLERANCE):
        raise InvalidInputError(_unreachable(what, target, "largest", f_hi))
    f_lo, d_lo = measure(math.exp(lo))
    if abs(f_lo - target) <= AIM * target:
        return math.exp(lo), d_lo
    small, large = (f_lo, f_hi) if increasing else (f_hi, f_lo)
    if target < small * (1 - RATE_TOLERANCE):
        raise InvalidInputError(_unreachable(what, target, "smallest", small, large))
    if target > large * (1 + RATE_TOLERANCE):
        raise InvalidInputError(_unreachable(what, target, "largest", large, small))
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        f, d = measure(math.exp(mid))
        err = abs(f - target) / target
        if best is None or err < best[0]:
            best = (err, mid, d)
        if err <= AIM:
            break
        if (f < target) == increasing:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-6:
            break
    err, s, d = best
    if err > RATE_TOLERANCE:
        raise InvalidInputError(
            f"`{what}` = {target:g} could not be met within 5 % (closest: {err:.1%} away); the "
            "rate of this mesh jumps at that point."
        )
    return math.exp(s), d
