"""Tuning data of the denoising gate's planar-tessellation rule (Eq. N9 of
:mod:`spectrageo.denoise._guard`): the share of coplanar face pairs (``planar_share``) of every
tuning case, and the impulse repair's keep / refuse decision on planar tessellations.

    python benchmarks/planar_rule.py [--data DIR] [--out FILE.md]

Tuning cases: the shared denoising pairs (noisy and original), the tuning meshes of
``spectrageo evaluate denoise`` (rocker-arm, knot2, spot, casting) and seven trimesh test models
(``tests/data/trimesh``), each clean and with the five generated kinds at levels 0.1, 0.3 and
0.5, and synthetic CAD-like shapes (cylinders and tubes sampled on their rims only, a cone, a
capsule) at level 0.3, and quadric-decimated versions (Open3D ``simplify_quadric_decimation``)
of the CAD models (trimesh models and casting) at 1,000 and 2,000 faces, clean and noisy at the
three levels; the decimated clean versions are listed apart with the default ``denoise``'s
verdict on them (they do not enter the midpoint). ``PLANAR_SHARE`` is the geometric midpoint between the largest share of a
noisy case that needs the filter (dense kinds and the pairs) and the smallest share of a clean
CAD tessellation.
"""

from __future__ import annotations

import argparse
import os
import warnings
from pathlib import Path

import numpy as np

from spectrageo import io
from spectrageo.denoise import denoise
from spectrageo.denoise._guard import PLANAR_SHARE, SPIKE_SHARE, despike, planar_share
from spectrageo.evaluate.denoise import TUNING_MESHES, TUNING_PAIRS
from spectrageo.metrics import theta_deg
from spectrageo.noise.generator import GENERATOR_KINDS, generate

TRIMESH = Path(__file__).resolve().parent.parent / "tests" / "data" / "trimesh"
TRIMESH_TUNING = (
    "20mm-xyz-cube.stl",
    "box.STL",
    "idler_riser.STL",
    "cylinder.stl",
    "round.stl",
    "1002_tray_bottom.STL",
    "torus.STL",
)
LEVELS = (0.1, 0.3, 0.5)
#: pairs whose original is not a CAD tessellation (a scan; a sphere with carved features)
ORGANIC_PAIRS = ("Bunny", "SharpSphere")
#: face counts of the decimated versions of the clean CAD models
DECIMATED_FACES = (1000, 2000)


def synthetic():
    import trimesh

    c = trimesh.creation
    shapes = {
        "cylinder-64": c.cylinder(radius=1, height=3, sections=64),
        "tube-64": c.annulus(r_min=0.6, r_max=1.0, height=0.5, sections=64),
        "capsule": c.capsule(height=2, radius=0.5, count=[32, 32]),
        "cone-48": c.cone(radius=1, height=2, sections=48),
        "cylinder-128": c.cylinder(radius=1, height=1, sections=128),
        "tube-96": c.annulus(r_min=0.3, r_max=1.0, height=1.5, sections=96),
    }
    for k, m in shapes.items():
        yield f"synthetic/{k}", np.asarray(m.vertices, float), np.asarray(m.faces)


def decimated(name: str, V, F):
    """Quadric-decimated versions of a clean CAD model at ``DECIMATED_FACES`` faces (those below
    its own face count)."""
    import open3d as o3d

    for faces in DECIMATED_FACES:
        if faces >= F.shape[0]:
            continue
        m = o3d.geometry.TriangleMesh(
            o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(np.asarray(F, np.int32))
        )
        d = m.simplify_quadric_decimation(target_number_of_triangles=faces)
        d.remove_unreferenced_vertices()
        Vd, Fd = np.asarray(d.vertices, float), np.asarray(d.triangles, np.int64)
        if Fd.shape[0]:
            yield f"{name}@quadric{faces}", Vd, Fd, True


def models(data: Path):
    """(name, clean V, F, is_cad) of every tuning model with generated noise."""
    for rel in TUNING_MESHES:
        m = io.read(data / rel)
        cad = rel.startswith("saliency/casting")
        yield rel, m.vertices, m.faces, cad
        if cad:
            yield from decimated(rel, m.vertices, m.faces)
    for name in TRIMESH_TUNING:
        m = io.read(TRIMESH / name)
        yield f"trimesh/{name}", m.vertices, m.faces, True
        yield from decimated(f"trimesh/{name}", m.vertices, m.faces)
    for name, V, F in synthetic():
        yield name, V, F, True


def main() -> None:
    from spectrageo.datasets import denoise_pairs

    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default=os.environ.get("SPECTRAGEO_DATA", "../shared/data"))
    ap.add_argument("--out", default=None)
    a = ap.parse_args()
    data = Path(a.data)
    warnings.simplefilter("ignore")
    noisy_need: list[tuple[float, str]] = []  # noisy cases the filter must see
    clean_cad: list[tuple[float, str]] = []
    clean_other: list[tuple[float, str]] = []
    repair: list[str] = []
    pairs = {p[0]: p for p in denoise_pairs(data)}
    for name in TUNING_PAIRS:
        _, noisy, orig = pairs[name]
        Vn, m0 = io.read(noisy).vertices, io.read(orig)
        noisy_need.append((planar_share(Vn, m0.faces), name))
        cad = not name.startswith(ORGANIC_PAIRS)
        (clean_cad if cad else clean_other).append(
            (planar_share(m0.vertices, m0.faces), f"{name} (original)")
        )
    decimated_rows: list[str] = []
    for name, V, F, cad in models(data):
        if "@quadric" in name:
            out = denoise(V, F)
            verdict = "unchanged" if np.array_equal(out, V) else "changed"
            decimated_rows.append(f"{name} {planar_share(V, F):.3f} ({verdict})")
        else:
            (clean_cad if cad else clean_other).append((planar_share(V, F), name))
        synth = name.startswith("synthetic/")
        for i, kind in enumerate(GENERATOR_KINDS):
            for j, lv in enumerate((0.3,) if synth else LEVELS):
                Vn = generate(V, F, kind=kind, level=lv, rng=1000 + 10 * i + j).vertices
                p = planar_share(Vn, F)
                case = f"{name}:{kind}@{lv:g}"
                if kind != "impulsive":
                    noisy_need.append((p, case))
                elif p >= PLANAR_SHARE:
                    rep = despike(Vn, F)
                    if rep.share >= SPIKE_SHARE:
                        p1 = planar_share(rep.vertices, F)
                        t0, t1 = theta_deg(Vn, V, F), theta_deg(rep.vertices, V, F)
                        keep = "kept" if p1 > p else "refused"
                        repair.append(
                            f"| {case} | {p:.3f} | {p1:.3f} | {keep} | {t0:.2f} | {t1:.2f} |"
                        )
    hi, lo = max(noisy_need), min(clean_cad)
    lines = [
        "## Planar-tessellation rule of the denoising gate (Eq. N9)",
        "",
        "`python benchmarks/planar_rule.py` (tuning data only; see the script's docstring).",
        "",
        f"- largest share of a noisy case that needs the filter: {hi[0]:.3f} ({hi[1]})",
        f"- smallest share of a clean CAD tessellation: {lo[0]:.3f} ({lo[1]})",
        f"- geometric midpoint: {np.sqrt(hi[0] * lo[0]):.3f}; `PLANAR_SHARE` = {PLANAR_SHARE}",
        "- clean CAD tessellations: " + ", ".join(f"{n} {p:.3f}" for p, n in sorted(clean_cad)),
        "- other clean tuning meshes: " + ", ".join(f"{n} {p:.3f}" for p, n in sorted(clean_other)),
        "- decimated clean CAD models (share, default `denoise`): " + ", ".join(decimated_rows),
        "",
        "Impulse repair on planar tessellations (first pass flags >= 1 % of the vertices): kept "
        "when the share of coplanar pairs rises. theta = mean normal error in degrees.",
        "",
        "| case | share in | share repaired | repair | theta in | theta repaired |",
        "|---|---:|---:|---|---:|---:|",
        *repair,
        "",
    ]
    text = "\n".join(lines)
    print(text)
    if a.out:
        Path(a.out).write_text(text)


if __name__ == "__main__":
    main()
