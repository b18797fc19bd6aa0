"""Canonical-order connectivity bytes under the counted adaptive models' rates (tuning split).

    python benchmarks/codec_conn_rates.py     # writes _out/codec_conn_rates.md

For each ``(RATE0, RATE_MAX)`` of ``spectrageo.compress._rangecoder``, in a fresh process (the
constants are compiled in): the canonical-order connectivity size (first byte 0x43 since
docs/decisions.md#codec-conn-inline, 0x42 before) of the compress tuning meshes
in their ``--reorder`` order, and of 800- and 2,000-face quadric decimations (Open3D) of fandisk
and partLp, the small meshes the tuning split lacks.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _util import machine_line, run_isolated, write_section  # noqa: E402

RATES = ((2, 32), (3, 32), (2, 16), (2, 24), (2, 48), (2, 64))

_CODE = """
import numpy as np, open3d as o3d
from spectrageo.compress import _rangecoder as R
R.RATE0, R.RATE_MAX = {r0}, {rmax}
from spectrageo.compress import _conn_traverse as T
from spectrageo.compress._connectivity import reorder_coded
from spectrageo.datasets import data_dir
from spectrageo.datasets.splits import cases
from spectrageo.io import read
out = {{}}
for c in cases(task="compress", split="tuning"):
    g = read(data_dir(required=True) / c.file)
    V, F = np.asarray(g.vertices), np.asarray(g.faces, dtype=np.int64)
    todo = [(c.file, V, F)]
    if "fandisk" in c.file or "partLp" in c.file:
        for t in (800, 2000):
            m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F))
            m = m.simplify_quadric_decimation(t)
            m.remove_unreferenced_vertices()
            todo.append((f"{{c.file}}@{{t}}", np.asarray(m.vertices), np.asarray(m.triangles, np.int64)))
    for name, V, F in todo:
        G = reorder_coded(V, F)[1]
        out[name] = len(T.encode(G))
RESULT = out
"""


def main() -> None:
    rows = {}
    for r0, rmax in RATES:
        with tempfile.TemporaryDirectory() as cache:
            code = f"import os; os.environ['NUMBA_CACHE_DIR'] = {cache!r}\n"
            r = run_isolated(code + _CODE.format(r0=r0, rmax=rmax))
        r.pop("peak_rss_mb")
        rows[(r0, rmax)] = r
    names = list(next(iter(rows.values())))
    lines = [
        "## Canonical connectivity bytes by adaptation rate (tuning split)",
        "",
        machine_line(),
        "",
        "| RATE0, RATE_MAX | total | " + " | ".join(names) + " |",
        "|---|---|" + "---|" * len(names),
    ]
    for key, r in rows.items():
        cells = " | ".join(str(r[n]) for n in names)
        lines.append(f"| {key[0]}, {key[1]} | {sum(r.values())} | {cells} |")
    write_section("codec_conn_rates", "\n".join(lines))


if __name__ == "__main__":
    main()
