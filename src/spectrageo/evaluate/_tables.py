"""Output helpers shared by the evaluation harnesses: CSV text and atomic ``.md`` + ``.csv`` files."""

from __future__ import annotations

import csv
import io as _io
from collections.abc import Iterable, Sequence
from pathlib import Path


def rows_to_csv(rows: Iterable[dict], columns: Sequence[str]) -> str:
    """CSV text of ``rows`` restricted to ``columns`` (full precision; missing keys left empty)."""
    buf = _io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(columns), lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({c: r.get(c) for c in columns})
    return buf.getvalue()


def write_md_csv(out, markdown: str, csv_text: str) -> tuple[Path, Path]:
    """Write ``<out>.md`` and ``<out>.csv`` atomically (``out`` may end in .md or .csv).

    Creates the parent folder; returns both paths.
    """
    from ..io import atomic_write

    out = Path(out)
    if out.suffix in (".md", ".csv"):
        out = out.with_suffix("")
    out.parent.mkdir(parents=True, exist_ok=True)
    md, cs = out.with_name(out.name + ".md"), out.with_name(out.name + ".csv")
    with atomic_write(md) as tmp:
        Path(tmp).write_text(markdown.rstrip() + "\n", encoding="utf-8")
    with atomic_write(cs) as tmp:
        Path(tmp).write_text(csv_text, encoding="utf-8")
    return md, cs
