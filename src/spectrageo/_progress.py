"""Progress reporting shown only on an interactive terminal (stderr is a TTY)."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable, Iterator
from typing import TypeVar

T = TypeVar("T")


#: Set by the command line's ``--quiet`` for the current command.
QUIET = False


def progress_enabled() -> bool:
    """True when stderr is a terminal and neither ``SPECTRAGEO_PROGRESS=0`` nor ``--quiet``."""
    if QUIET:
        return False
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


class activity:  # noqa: N801 - used as a context manager, like tqdm
    """Show ``desc: 12.3 s`` on a terminal while a block without a natural loop runs (erased at
    the end; nothing when :func:`progress_enabled` is False).
    """

    def __init__(self, desc: str, *, interval: float = 0.5, delay: float = 1.0) -> None:
        self.desc = desc
        self.interval = interval
        self.delay = delay
        self._thread = None
        self._stop = None

    def __enter__(self) -> activity:
        if not progress_enabled():
            return self
        import threading
        import time

        self._stop = threading.Event()
        t0 = time.perf_counter()

        def run() -> None:
            if self._stop.wait(self.delay):
                return
            while True:
                sys.stderr.write(f"\r{self.desc}: {time.perf_counter() - t0:.1f} s ")
                sys.stderr.flush()
                if self._stop.wait(self.interval):
                    break
            sys.stderr.write("\r" + " " * (len(self.desc) + 16) + "\r")
            sys.stderr.flush()

        self._thread = threading.Thread(target=run, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        if self._thread is not None:
            self._stop.set()
            self._thread.join()
