"""Progress reporting shown only on an interactive terminal (stderr is a TTY)."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable, Iterator
from typing import TypeVar

T = TypeVar("T")


def progress_enabled() -> bool:
    """True when progress bars should be drawn: stderr is a terminal and not disabled by env."""
    if os.environ.get("SPECTRAGEO_PROGRESS", "").lower() in {"0", "off", "false", "no"}:
        return False
    if os.environ.get("SPECTRAGEO_PROGRESS", "").lower() in {"1", "on", "true", "yes"}:
        return True
    return bool(getattr(sys.stderr, "isatty", lambda: False)())


def progress(iterable: Iterable[T], *, desc: str = "", total: int | None = None) -> Iterator[T]:
    """Wrap ``iterable`` in a tqdm bar on a terminal; otherwise yield from it unchanged."""
    if not progress_enabled():
        yield from iterable
        return
    from tqdm.auto import tqdm

    yield from tqdm(iterable, desc=desc, total=total, leave=False, file=sys.stderr)
