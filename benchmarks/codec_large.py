"""The ``predictive`` codec on the full dragon (437k vertices): encode / decode time, size and
error next to Draco in the same run, each in a fresh process (templates of compress_large.py).

    python benchmarks/codec_large.py     # writes benchmarks/_out/codec_large.md (a few minutes)
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import machine_line, run_isolated, write_section  # noqa: E402
from compress_large import DRACO, OURS, _fmt  # noqa: E402
from spectrageo.datasets import data_dir  # noqa: E402

CASES = [
    ("predictive (default step)", {"method": "predictive"}),
    ("predictive --reorder", {"method": "predictive", "reorder": True}),
    ("predictive --reorder --max-error 1e-4", {"method": "predictive", "reorder": True,
                                               "max_error": 1e-4}),
    ("spectral --reorder (default step)", {"method": "spectral", "reorder": True}),
]  # fmt: skip
DRACO_CASES = [
    ("draco q=11 level 10 (reorders)", 11, 10, False),
    ("draco q=14 level 10", 14, 10, False),
]


def main() -> None:
    path = str(data_dir(required=True) / "meshes" / "dragon_vrip.ply.gz")
    rows = [
        (label, run_isolated(OURS.format(path=path, kw=repr(kw)), timeout=1800))
        for label, kw in CASES
    ]
    for label, bits, level, ordered in DRACO_CASES:
        code = DRACO.format(path=path, bits=bits, level=level, ordered=ordered)
        rows.append((label, run_isolated(code, timeout=1800)))
    lines = [
        "## The predictive codec on the 437k-vertex dragon",
        "",
        "`python benchmarks/codec_large.py` (validation mesh `meshes/dragon_vrip.ply.gz`); "
        "`bpv` the whole file, errors over the diagonal. Targets: encode <= 30 s, decode <= 15 s.",
        f"Machine: {machine_line()}.",
        "",
        "| codec | bpv | rms | hausdorff | encode (s) | decode (s) | peak RSS (GB) |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for label, r in rows:
        lines.append(
            f"| {label} | {r['bpv']:.2f} | {_fmt(r['rms'], '.2e')} | {r['hausdorff']:.2e} "
            f"| {r['encode_s']:.1f} | {r['decode_s']:.1f} | {r['peak_rss_mb'] / 1024:.2f} |"
        )
    write_section("codec_large", "\n".join(lines))


if __name__ == "__main__":
    main()
