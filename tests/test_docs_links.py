"""Every ``docs/decisions.md#anchor`` cited in the package, the benchmarks or the README exists."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_CITE = re.compile(r"decisions\.md#([A-Za-z0-9_-]+)")


def _anchors() -> set[str]:
    text = (ROOT / "docs" / "decisions.md").read_text(encoding="utf-8")
    return set(re.findall(r'<a id="([^"]+)"></a>', text))


def test_every_cited_decision_anchor_exists():
    anchors = _anchors()
    files = [*(ROOT / "src").rglob("*.py"), *(ROOT / "benchmarks").glob("*.py"), ROOT / "README.md"]
    files += [ROOT / "BENCHMARKS.md", ROOT / "CHANGELOG.md", ROOT / "docs" / "decisions.md"]
    missing = {
        f"{f.relative_to(ROOT)}: {a}"
        for f in files
        for a in _CITE.findall(f.read_text(encoding="utf-8"))
        if a not in anchors and a != "anchor"  # the how-to of decisions.md names the form
    }
    assert not missing, sorted(missing)


def test_anchors_are_unique():
    text = (ROOT / "docs" / "decisions.md").read_text(encoding="utf-8")
    ids = re.findall(r'<a id="([^"]+)"></a>', text)
    assert len(ids) == len(set(ids))
