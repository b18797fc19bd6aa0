"""Regenerate BENCHMARKS.md: run every benchmark script (sequentially, so timings do not compete)
and assemble their sections.

    python benchmarks/run_all.py                 # run all, then assemble
    python benchmarks/run_all.py --assemble-only # only assemble benchmarks/_out/*.md
    python benchmarks/run_all.py --only core,lowpass

The headline table and the table of contents at the top come from ``benchmarks/summary.py``.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

import summary  # noqa: E402


def _script(name: str) -> list[str]:
    return [sys.executable, str(HERE / f"{name}.py")]


def _evaluate(what: str, stem: str) -> list[str]:
    out = str(HERE / "_out" / stem)
    return [sys.executable, "-m", "spectrageo.cli.main", "evaluate", what, "--out", out]


# order of sections in BENCHMARKS.md: (section file stem, command producing it)
SECTIONS = [
    ("noisy_inputs", _script("noisy_inputs")),
    ("core", _script("core")),
    ("lowpass", _script("lowpass")),
    ("rpca_large", _script("rpca_large")),
    ("denoise", _evaluate("denoise", "denoise")),
    ("denoise_generality", _script("denoise_generality")),
    (
        "denoise_validation",
        [
            *_evaluate("denoise", "denoise_validation"),
            "--split",
            "both",
            "--levels",
            "0.3",
            "--max-vertices",
            "30000",
            "--repeat",
            "3",
            "--cli-timing",
        ],
    ),
    (
        "denoise_levels",
        [*_script("denoise_levels"), "--out", str(HERE / "_out" / "denoise_levels.md")],
    ),
    (
        "clean_inputs",
        [
            *_script("clean_inputs"),
            "--max-vertices",
            "500000",
            "--out",
            str(HERE / "_out" / "clean_inputs.md"),
        ],
    ),
    (
        "lowpoly/clean_coarse_validation_after",
        [*_script("lowpoly/clean_coarse"), "--split", "validation", "--tag", "validation_after"],
    ),
    ("clean_resolutions", _script("clean_resolutions")),
    ("planar_rule", [*_script("planar_rule"), "--out", str(HERE / "_out" / "planar_rule.md")]),
    ("fold_rule", [*_script("fold_rule"), "--out", str(HERE / "_out" / "fold_rule.md")]),
    ("unfold_fine", _script("unfold_fine")),
    (
        "curved_finish",
        [*_script("curved_finish"), "--out", str(HERE / "_out" / "curved_finish.md")],
    ),
    (
        "quiet_impulses",
        [*_script("quiet_impulses"), "--out", str(HERE / "_out" / "quiet_impulses.md")],
    ),
    ("denoise_large", _script("denoise_large")),
    ("denoise_dynamic", [*_script("denoise_dynamic"), "--max-frames", "40"]),
    ("outliers", _evaluate("outliers", "outliers")),
    ("retune_outliers/retune_outliers", _script("retune_outliers")),
    ("retune_outliers/validation_new", [*_script("retune_outliers"), "--validation", "new"]),
    ("outliers_large", _script("outliers_large")),
    ("bench_outliers_speed", [*_script("bench_outliers_speed"), "--repeat", "3", "--large"]),
    (
        "outliers_scantypes",
        [*_evaluate("outliers", "outliers_scantypes"), "--methods", "scan-types"],
    ),
    ("saliency", _script("saliency")),
    ("retune_saliency/tuning", _script("retune_saliency")),
    ("retune_saliency/validation_patch", [*_script("retune_saliency"), "--validation"]),
    ("compress", _evaluate("compress", "compress")),
    ("compress_large", _script("compress_large")),
    ("doi_codec", _script("doi_codec")),
    ("connectivity", _script("connectivity")),
    ("codec_predictive_validation", [*_script("codec_predictive"), "--split", "validation"]),
    ("codec_auto_tuning", [*_script("codec_auto"), "--split", "tuning"]),
    (
        "codec_auto_reorder_validation",
        [*_script("codec_predictive"), "--split", "validation", "--methods", "auto-reorder"],
    ),
    ("compress_animation", _evaluate("compress-animation", "compress_animation")),
    ("rate_animation", _script("rate_animation")),
    ("anim_pca_pred_validation", [*_script("anim_pca_pred"), "--split", "validation"]),
    ("animation_rank", _script("animation_rank")),
    ("animation_stream", _script("animation_stream")),
    ("complete", _evaluate("complete", "complete")),
    ("complete_large", _script("complete_large")),
    ("register", _evaluate("register", "register")),
    ("register_speed", [*_script("register_speed"), "--split", "validation"]),
    ("register_cli_startup", [*_script("register_cli_startup"), "--repeats", "7"]),
    ("narrow_phase", _script("narrow_phase")),
    ("identify", _evaluate("identify", "identify")),
    ("identify_speed", _script("identify_speed")),
    ("learned_denoise", _script("learned_denoise")),
    ("learned_refine", _script("learned_refine")),
    ("viewer", _script("viewer")),
    # the sealed test split: run once at the end of a change, to report (never to choose)
    (
        "test_split/denoise",
        [*_script("test_split/run"), "--final", "--task", "denoise", "--no-oracle"],
    ),
    (
        "test_split/outliers",
        [*_script("test_split/run"), "--final", "--task", "outliers", "--no-oracle"],
    ),
]

HEADER = """# Benchmarks

Every table below is produced by a command (named in its section) and assembled by
`python benchmarks/run_all.py`. Figures come from one run on the machine named in each section;
speed comparisons are ratios measured in the same run.
"""


def assemble() -> str:
    """BENCHMARKS.md from the section files in ``benchmarks/_out``, with the headline table and
    the table of contents at the top (benchmarks/summary.py)."""
    parts = [HEADER]
    for name, cmd in SECTIONS:
        f = HERE / "_out" / f"{name}.md"
        if f.exists():
            parts.append(f.read_text().rstrip() + "\n")
        else:
            run = " ".join(Path(c).name if c == sys.executable else c for c in cmd)
            parts.append(f"## {name}\n\nNot measured yet: `{run}`.\n")
    return summary.update_benchmarks("\n".join(parts))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--assemble-only", action="store_true")
    ap.add_argument("--only", default=None)
    args = ap.parse_args()
    only = set(args.only.split(",")) if args.only else None
    if not args.assemble_only:
        for name, cmd in SECTIONS:
            if only and name not in only:
                continue
            print(f"== {name}: {' '.join(cmd[1:])}", file=sys.stderr, flush=True)
            subprocess.run(cmd, check=True, cwd=ROOT)
    text = assemble()
    tmp = ROOT / "BENCHMARKS.md.tmp"
    tmp.write_text(text)
    tmp.replace(ROOT / "BENCHMARKS.md")
    print(f"wrote {ROOT / 'BENCHMARKS.md'}", file=sys.stderr)


if __name__ == "__main__":
    main()
