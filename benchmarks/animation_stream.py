"""Time and memory of the ``blocks`` animation codec against the frame count (issue 17: "175
frames of a 10k-vertex animation compress in <= 5 s, with memory bounded by the block size, not
the frame count").

    python benchmarks/animation_stream.py    # about 2 minutes

The shared crane (175 frames, 10,002 vertices) is coded with the default settings, once whole
(:func:`spectrageo.compress.encode_animation`) and once through
:class:`spectrageo.compress.StreamEncoder`, one frame pushed at a time; the stream is then
repeated forwards and backwards to 700 and 1,400 frames (the 175 read frames stay in memory; the
repeats are handed over one at a time, never copied into a longer array). Each run is a fresh process; peak RSS is the whole process (interpreter, libraries
and the input file read included), so growth with the frame count is what the target is about.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import machine_line, run_isolated, write_section  # noqa: E402

DATA = os.environ.get("SPECTRAGEO_DATA", "../shared/data")

WHOLE = """
import time, numpy as np
from spectrageo import compress, io
a = io.read({path!r})
A, F = np.asarray(a.frames, dtype=np.float64), a.faces
t = time.perf_counter()
data = compress.encode_animation(A, F, method="blocks")
dt = time.perf_counter() - t
RESULT = {{"frames": int(A.shape[0]), "seconds": dt, "bytes": len(data),
          "bpvf": 8 * len(data) / (A.shape[0] * A.shape[1])}}
"""

STREAM = """
import time, numpy as np
from spectrageo import compress, io
a = io.read({path!r})
A, F = np.asarray(a.frames, dtype=np.float64), a.faces
T = A.shape[0]
del a
def frames(total):
    k = 0
    while k < total:
        for t in (range(T) if (k // T) % 2 == 0 else range(T - 1, -1, -1)):
            if k == total:
                return
            yield A[t]
            k += 1
enc = compress.StreamEncoder(F, method="blocks")
t = time.perf_counter()
nbytes = 0
for X in frames({total}):
    nbytes += len(enc.push(X))
nbytes += len(enc.close())
dt = time.perf_counter() - t
RESULT = {{"frames": {total}, "seconds": dt, "bytes": nbytes,
          "bpvf": 8 * nbytes / ({total} * A.shape[1])}}
"""


def main() -> None:
    path = str(Path(DATA) / "animations" / "crane.npz")
    rows = [("whole (encode_animation)", run_isolated(WHOLE.format(path=path)))]
    for total in (175, 700, 1400):
        rows.append(("stream (StreamEncoder)", run_isolated(STREAM.format(path=path, total=total))))
    lines = [
        "## Animation codec against the frame count (`blocks`, crane)",
        "",
        f"`python benchmarks/animation_stream.py`. Machine: {machine_line()}. Default settings; "
        "700 and 1,400 frames repeat crane's 175 forwards and backwards, generated one at a time; "
        "peak RSS of a fresh process (input file and libraries included).",
        "",
        "| run | frames | encode s | s per frame | bpvf | peak RSS MB |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for name, r in rows:
        lines.append(
            f"| {name} | {r['frames']} | {r['seconds']:.2f} | {r['seconds'] / r['frames']:.4f} | "
            f"{r['bpvf']:.2f} | {r['peak_rss_mb']:.0f} |"
        )
    md = "\n".join(lines) + "\n"
    write_section("animation_stream", md)
    print(md)


if __name__ == "__main__":
    main()
