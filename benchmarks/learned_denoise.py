"""Learned denoisers (issue 20, thesis Sections 5.1.3-5.1.4) against TSGSP and BNF.

    python benchmarks/learned_denoise.py            # writes benchmarks/_out/learned_denoise.md/.csv
    python benchmarks/learned_denoise.py --quick    # pairs only
    python benchmarks/learned_denoise.py --repeat 1 # one timed run per case (default best of 3)

Parts (see :func:`spectrageo.learn.evaluate.evaluate_learned`): every shared benchmark pair of
``denoise/``; a slice of the denoising protocol's validation split at Gaussian noise 0.3 and 0.5;
the protocol's whole validation split (every corruption kind at 0.3, models up to 30k vertices);
the shared animations at Gaussian noise 0.3 (first 20 frames), ``dae`` trained on the first 8
frames against per-frame TSGSP. No case was used for training (see the weights' metadata).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import OUT, machine_line  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None, help="shared data folder (default: SPECTRAGEO_DATA)")
    ap.add_argument("--quick", action="store_true", help="benchmark pairs only")
    ap.add_argument("--out", default=str(OUT / "learned_denoise"))
    ap.add_argument("--repeat", type=int, default=3, help="static cases: best time of N runs")
    ap.add_argument(
        "--protocol-levels",
        default="0.3",
        help="also the denoising protocol's whole validation split at these levels ('' to skip)",
    )
    args = ap.parse_args(argv)
    from spectrageo.learn.evaluate import evaluate_learned, format_markdown, write

    t0 = time.perf_counter()
    levels = tuple(float(x) for x in args.protocol_levels.split(",") if x.strip())
    kw = {"validation": (), "animations": ()} if args.quick else {"protocol_levels": levels}
    rows = evaluate_learned(args.data, repeat=args.repeat, **kw)
    note = (
        f"Produced by `python benchmarks/learned_denoise.py`; {machine_line()}; whole run "
        f"{time.perf_counter() - t0:.0f} s; static times are the best of {args.repeat} runs. "
        "Weights trained on casting, cad, rocker-arm, spot "
        "and knot2 (none of the pairs or validation meshes)."
    )
    md, _ = write(rows, args.out, note=note)
    print(format_markdown(rows, note=note))
    print(f"wrote {md}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
