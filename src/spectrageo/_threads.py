"""Threads for compiled kernels: the worker count, an ordered map, numba's thread limit."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
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


@contextlib.contextmanager
def numba_threads(workers: int | None) -> Iterator[None]:
    """Numba's thread-local limit set to ``workers`` threads inside (-1 or None: all)."""
    import numba

    if workers is None or workers < 0:
        yield
        return
    old = numba.get_num_threads()
    numba.set_num_threads(max(1, min(int(workers), numba.config.NUMBA_NUM_THREADS)))
    try:
        yield
    finally:
        numba.set_num_threads(old)
