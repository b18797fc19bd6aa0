"""The fine step after unfolding (``unfold_fine`` of :func:`spectrageo.denoise.tsgsp.tsgsp`):
on meshes whose noise flipped triangles (Eq. N10 of :mod:`spectrageo.denoise._guard`), TSGSP
smooths with Taubin's lambda|mu blocks until the folds are gone; with ``unfold_fine`` it then
runs its fine step (:func:`~spectrageo.denoise.tsgsp.fine`, default preset) on the unfolded mesh
when the fold share is below ``FOLD_STOP``.

    python benchmarks/unfold_fine.py [--data DIR] [--out FILE.md]    # about 1 minute

Tuning: every folded case of ``benchmarks/fold_rule.py`` (the protocol's tuning split, trimesh's
seven CAD test models, the synthetic shapes; five kinds at 0.1 / 0.3 / 0.5, seed 1), on which the
rule was chosen. Validation, measured afterwards with the rule fixed: every folded case of the
protocol's validation split (``spectrageo evaluate denoise``'s cases, seeds included) at levels
0.3 and 0.5, up to 30,000 vertices.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import data_out_args, machine_line, write_section  # noqa: E402
from fold_rule import cases  # noqa: E402
from spectrageo.denoise import _guard  # noqa: E402
from spectrageo.denoise.tsgsp import GateMeasures, tsgsp  # noqa: E402
from spectrageo.evaluate.denoise import _load_clean, protocol_cases  # noqa: E402
from spectrageo.metrics import theta_deg  # noqa: E402
from spectrageo.noise.generator import generate  # noqa: E402

MAX_VERTICES = 30000


def _row(split: str, name: str, V0, F, Vn) -> dict:
    U, fs = _guard.unfold(Vn, F, return_share=True)
    a = theta_deg(U, V0, F)
    # the shipped folded path (unfold_fine)
    b = theta_deg(tsgsp(Vn, F, measured=GateMeasures(folded=True)), V0, F)
    return {"split": split, "case": name, "input": theta_deg(Vn, V0, F), "unfold": a, "new": b,
            "fold_share": fs}  # fmt: skip


def tuning_rows(data: Path) -> list[dict]:
    return [
        _row("tuning", name, V, F, Vn) for name, V, F, Vn in cases(data) if _guard.is_folded(Vn, F)
    ]


def validation_rows(data: Path) -> list[dict]:
    out = []
    for case in protocol_cases("validation", levels=(0.3, 0.5)):
        _vin, V0, F = _load_clean(data, case)
        if V0.shape[0] > MAX_VERTICES:
            continue
        Vn = generate(V0, F, kind=case.corruption, level=case.level, rng=case.seed).vertices
        if _guard.is_folded(Vn, F):
            out.append(_row("validation", case.name, V0, F, Vn))
    return out


def _summary(rows: list[dict], label: str) -> str:
    a = np.array([r["unfold"] for r in rows])
    b = np.array([r["new"] for r in rows])
    changed = int(np.sum(a != b))
    return (
        f"| {label} | {len(rows)} | {changed} | {np.mean([r['input'] for r in rows]):.2f} | "
        f"{a.mean():.2f} | {b.mean():.2f} | {int(np.sum(b < a))} | {int(np.sum(b > a))} | "
        f"{np.max(b - a):+.2f} |"
    )


def markdown(tun: list[dict], val: list[dict]) -> str:
    lines = [
        "## Fine step after unfolding (TSGSP's `unfold_fine`)",
        "",
        f"`python benchmarks/unfold_fine.py`. Machine: {machine_line()}. Folded cases (Eq. N10): "
        "mean face-normal angle to the clean mesh (degrees) after the unfold alone (the rule as it "
        "was) and with the fine step run on the unfolded mesh when its fold share is below "
        "`FOLD_STOP` (otherwise the two are the same). Chosen on the tuning rows; the validation "
        "rows were measured afterwards, with the rule fixed.",
        "",
        "| cases | folded | fine step ran | input | unfold | unfold + fine | better | worse | "
        "largest loss |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
        _summary(tun, "tuning (fold_rule cases, 0.1-0.5)"),
    ]
    for lv in (0.3, 0.5):
        sub = [r for r in val if r["case"].endswith(f"@{lv}")]
        if sub:
            lines.append(_summary(sub, f"validation at {lv}"))
    lines += [
        "",
        "Cases where the fine step ran:",
        "",
        "| split | case | input | unfold | unfold + fine | fold share after unfold |",
        "|---|---|---:|---:|---:|---:|",
    ]
    for r in tun + val:
        if r["new"] != r["unfold"]:
            lines.append(
                f"| {r['split']} | {r['case']} | {r['input']:.2f} | {r['unfold']:.2f} | "
                f"{r['new']:.2f} | {r['fold_share']:.4f} |"
            )
    return "\n".join(lines) + "\n"


def main() -> None:
    a = data_out_args()
    data = Path(a.data)
    tun = tuning_rows(data)
    print(_summary(tun, "tuning"), file=sys.stderr, flush=True)
    val = validation_rows(data)
    md = markdown(tun, val)
    if a.out:
        Path(a.out).write_text(md)
    else:
        write_section("unfold_fine", md)
    print(md)


if __name__ == "__main__":
    main()
