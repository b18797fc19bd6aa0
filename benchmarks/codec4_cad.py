"""``predictive`` residual formats 2 and 3 against Draco at equal Hausdorff, small CAD stand-ins.

    python benchmarks/codec4_cad.py     # writes _out/codec4_cad.md (tuning data only)

Meshes: the compress tuning split (fandisk, partLp, the two elephants), and, since that split
has no small CAD part, meshes derived from fandisk and partLp: quadric decimations (Open3D) to
800 and 2,000 faces, and "planar" decimations that stop at a quadric error of 1e-9 and 1e-7
times the squared diagonal (flat regions emptied of inner vertices, as CAD exporters do). Per
mesh: Draco (level 10) at 6-16 quantisation bits, and ``predictive --reorder`` at the
``max_error`` points of ``spectrageo evaluate compress`` in each residual format (the formats
alternate in one process); cells are our size interpolated (log-log) at each Draco point's exact
symmetric Hausdorff distance over Draco's size. Then the bits of the format-3 file at Draco
6 bits' distance: connectivity, geometry and the rest (container header, chunk heads).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _util import machine_line, write_section  # noqa: E402
from spectrageo import compress  # noqa: E402
from spectrageo.compress import _container, _predictive  # noqa: E402
from spectrageo.datasets import data_dir  # noqa: E402
from spectrageo.datasets.splits import cases  # noqa: E402
from spectrageo.evaluate import compress as ev  # noqa: E402
from spectrageo.evaluate._tables import rate_at_error  # noqa: E402
from spectrageo.io import read_mesh  # noqa: E402

FORMATS = (2, 3)


def _meshes():
    import open3d as o3d

    out = []
    for c in cases(task="compress", split="tuning"):
        m = read_mesh(data_dir(required=True) / c.file)
        V, F = m.vertices, np.asarray(m.faces, dtype=np.int64)
        name = Path(c.file).name.split(".")[0]
        out.append((name, V, F))
        if name not in ("fandisk", "partLp"):
            continue
        d2 = float(np.sum((V.max(0) - V.min(0)) ** 2))
        for label, target, err in (
            ("@800", 800, np.inf),
            ("@2000", 2000, np.inf),
            ("~1e-9", 1, 1e-9 * d2),
            ("~1e-7", 1, 1e-7 * d2),
        ):
            t = o3d.geometry.TriangleMesh(
                o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F)
            )
            t = t.simplify_quadric_decimation(target, maximum_error=err)
            t.remove_unreferenced_vertices()
            out.append((name + label, np.asarray(t.vertices), np.asarray(t.triangles, np.int64)))
    return out


def main() -> None:
    rows, breakdown, ratios = [], [], {f: [] for f in FORMATS}
    for name, V, F in _meshes():
        n = V.shape[0]
        draco = []
        for b in ev.DRACO_BITS:
            nb, V2, F2, *_ = ev._draco(V, F, b, False)
            draco.append((b, 8.0 * nb / n, ev._metrics(V, F, V2, F2, False)["hausdorff"]))
        curves = {f: [] for f in FORMATS}
        for e in ev.MAX_ERRORS:
            for f in FORMATS:
                _predictive.FORMAT = f
                try:
                    data = compress.encode(V, F, method="predictive", reorder=True, max_error=e)
                finally:
                    _predictive.FORMAT = FORMATS[-1]
                V2, F2 = compress.decode(data)
                curves[f].append(
                    (8.0 * len(data) / n, ev._metrics(V, F, V2, F2, False)["hausdorff"])
                )
        for f in FORMATS:
            cells = []
            for _b, bpv, h in draco:
                r = rate_at_error(curves[f], h) / bpv
                if np.isfinite(r):
                    ratios[f].append(r)
                cells.append(f"{r:.3f}")
            rows.append(f"| {name} | {n} | {f} | " + " | ".join(cells) + " |")
        data = compress.encode(V, F, method="predictive", reorder=True, max_error=draco[0][2])
        sizes = [len(p) for _t, p in _container.parse(data).chunks]
        rest = len(data) - sum(sizes)
        breakdown.append(
            f"| {name} | {draco[0][1]:.2f} | {8 * len(data) / n:.2f} | {8 * sizes[0] / n:.2f} | "
            f"{8 * sizes[1] / n:.2f} | {8 * rest / n:.2f} ({rest} B) |"
        )
        print(name, n, flush=True)
    head = " | ".join(f"q={b}" for b in ev.DRACO_BITS)
    lines = [
        "## predictive residual formats against Draco at equal Hausdorff (tuning data, CAD stand-ins)",
        "",
        machine_line(),
        "",
        "`python benchmarks/codec4_cad.py`: `predictive --reorder` size over Draco's (level 10) at "
        "each Draco point's exact symmetric Hausdorff distance, per residual format.",
        "",
        f"| mesh | vertices | format | {head} |",
        "|---|---|---|" + "---|" * len(ev.DRACO_BITS),
        *rows,
        "",
    ]
    for f in FORMATS:
        r = np.array(ratios[f])
        lines.append(
            f"Format {f}: geometric mean {np.exp(np.log(r).mean()):.4f}, largest {r.max():.3f}."
        )
    lines += [
        "",
        "Format 3 at Draco 6 bits' Hausdorff distance, bits per vertex:",
        "",
        "| mesh | Draco | ours | connectivity | geometry | rest |",
        "|---|---|---|---|---|---|",
        *breakdown,
    ]
    write_section("codec4_cad", "\n".join(lines))


if __name__ == "__main__":
    main()
