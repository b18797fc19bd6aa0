"""The generated blocks of BENCHMARKS.md and README.md (``benchmarks/summary.py``)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))

import run_all  # noqa: E402
import summary  # noqa: E402


@pytest.fixture(scope="module")
def rows():
    return summary.read_headlines()


def test_slug_follows_github():
    assert summary.slug("Size at Draco's error") == "size-at-dracos-error"
    assert summary.slug("Completion (Section 5.3)") == "completion-section-53"
    assert (
        summary.slug("Fine step after unfolding (TSGSP's `unfold_fine`)")
        == "fine-step-after-unfolding-tsgsps-unfold_fine"
    )
    assert summary.slug("Outlier removal at 10,000,000 points") == (
        "outlier-removal-at-10000000-points"
    )


def test_repeated_headings_get_numbered_anchors():
    text = "# T\n\n## A\n\n### Summary\n\n## B\n\n### Summary\n\n```\n## not a heading\n```\n"
    assert [a for _, _, a in summary.headings(text)] == ["t", "a", "summary", "b", "summary-1"]


def test_every_headline_anchor_is_a_section(rows):
    text = (ROOT / "BENCHMARKS.md").read_text(encoding="utf-8")
    assert rows, "benchmarks/headlines.csv has no rows"
    assert summary.missing_anchors(text, rows) == []
    for r in rows:
        for field in ("task", "metric", "ours", "peer", "data", "split", "source"):
            assert r[field].strip(), f"{r['task']}: empty {field}"


def test_update_is_idempotent(rows):
    bench = (ROOT / "BENCHMARKS.md").read_text(encoding="utf-8")
    once = summary.update_benchmarks(bench, rows)
    assert summary.update_benchmarks(once, rows) == once
    assert once.count(summary.START) == 1 and once.count(summary.END) == 1
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    once = summary.update_readme(readme, rows)
    assert summary.update_readme(once, rows) == once


def test_first_build_inserts_after_the_introduction(rows):
    bench = (ROOT / "BENCHMARKS.md").read_text(encoding="utf-8")
    a = bench.index(summary.START)
    b = bench.index(summary.END) + len(summary.END)
    bare = bench[:a].rstrip("\n") + bench[b:]
    rebuilt = summary.update_benchmarks(bare, rows)
    assert summary.update_benchmarks(rebuilt, rows) == rebuilt
    assert rebuilt.index(summary.START) < rebuilt.index("\n## ", rebuilt.index(summary.END))


def test_contents_lists_every_section_once():
    bench = (ROOT / "BENCHMARKS.md").read_text(encoding="utf-8")
    block = bench[bench.index(summary.START) : bench.index(summary.END)]
    body = bench[bench.index(summary.END) :]
    for level, _, anchor in summary.headings(body):
        if level >= 2:
            assert block.count(f"](#{anchor})") >= 1, anchor


def test_committed_files_are_current():
    """BENCHMARKS.md is what ``run_all.py --assemble-only`` builds from ``benchmarks/_out``, and
    both generated blocks match ``headlines.csv`` (``python benchmarks/summary.py`` rebuilds)."""
    assert summary.main(["--check"]) == 0
    assert run_all.assemble() == (ROOT / "BENCHMARKS.md").read_text(encoding="utf-8")
