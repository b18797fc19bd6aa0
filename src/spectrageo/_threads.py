"""Threads for compiled kernels that release the GIL: the worker count and an ordered map."""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor


def default_workers() -> int:
    """Threads used by default: the CPUs this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def thread_map(fn, items, workers: int | None = None) -> list:
    """``[fn(x) for x in items]`` on ``workers`` threads (default :func:`default_workers`)."""
    items = list(items)
    w = default_workers() if workers is None else max(1, int(workers))
    if w == 1 or len(items) <= 1:
        return [fn(x) for x in items]
    with ThreadPoolExecutor(min(w, len(items))) as ex:
        return list(ex.map(fn, items))
