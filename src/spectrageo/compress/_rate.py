"""Rate control of the codecs: log-bisection of the quantisation step for a target rate or error."""

from __future__ import annotations

import math

from .._errors import InvalidInputError

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


def bisect_step(measure, target: float, *, increasing: bool, what: str):
    """Log-bisection on the quantisation step until ``measure(step)`` is within 3 % of target.

    ``increasing``: the measure grows with the step (error) or falls with it (bpv).
    """
    lo, hi = math.log(STEP_MIN), math.log(STEP_MAX)
    f_lo, d_lo = measure(math.exp(lo))
    f_hi, d_hi = measure(math.exp(hi))
    best = None
    for f, s, d in ((f_lo, lo, d_lo), (f_hi, hi, d_hi)):
        if abs(f - target) <= AIM * target:
            return math.exp(s), d
    small, large = (f_lo, f_hi) if increasing else (f_hi, f_lo)
    if target < small * (1 - RATE_TOLERANCE):
        raise InvalidInputError(
            f"`{what}` = {target:g} cannot be reached: the smallest value this method gives here "
            f"is {small:.4g}" + (" (the connectivity and header alone)." if what == "bpv" else ".")
        )
    if target > large * (1 + RATE_TOLERANCE):
        raise InvalidInputError(
            f"`{what}` = {target:g} cannot be reached: the largest value this method gives here "
            f"is {large:.4g}."
        )
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
