"""Dask clusters for :mod:`spectrageo.distributed`: a local one by default, any scheduler by address.

Dask is an optional dependency (``pip install "spectrageo[dist]"``); nothing here imports it at
module import time, and :func:`require_dask` turns its absence into one clear error.
"""

from __future__ import annotations

import contextlib
import importlib.util
import logging
import os
import sys
from collections.abc import Iterator
from typing import Any

from .._errors import SpectrageoError
from .._validation import check_positive

__all__ = ["DaskMissingError", "open_client", "require_dask"]


class DaskMissingError(SpectrageoError, ImportError):
    """Dask (``dask[array]`` and ``distributed``) is not installed."""


def require_dask() -> Any:
    """Import and return :mod:`distributed`, or raise :class:`DaskMissingError` saying how to get it."""
    missing = [m for m in ("dask", "distributed") if importlib.util.find_spec(m) is None]
    if missing:
        raise DaskMissingError(
            f"{' and '.join(missing)} not installed; spectrageo's batch and tiled processing run "
            'on Dask: pip install "spectrageo[dist]" (or pip install "dask[array,distributed]").'
        )
    import distributed

    return distributed


def default_workers(n_tasks: int) -> int:
    """Local workers when none is asked for: one per core, no more than tasks."""
    return max(1, min(os.cpu_count() or 1, n_tasks))


@contextlib.contextmanager
def open_client(
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    processes: bool = True,
    n_tasks: int | None = None,
    verbose: bool = False,
) -> Iterator[Any]:
    """A :class:`distributed.Client`, closed (with its local cluster) on exit.

    Parameters
    ----------
    workers : int, optional
        Local cluster: worker processes, one thread each (default: one per core, at most
        ``n_tasks``). Not allowed with ``scheduler`` (a remote cluster has its own workers).
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``); workers must have spectrageo
        installed and see the input and output paths (a shared file system).
    processes : bool
        Local cluster: worker processes (True, real parallelism) or threads of this process.
    verbose : bool
        Print the dashboard link (or why there is none) on stderr.
    """
    distributed = require_dask()
    if workers is not None:
        check_positive(workers, "workers", integer=True)
    if scheduler is not None:
        if workers is not None:
            raise SpectrageoError(
                "`workers` sizes the local cluster; with `scheduler` the remote cluster's own "
                "workers run the tasks (start more with `dask worker ADDRESS`)."
            )
        try:
            client = distributed.Client(scheduler, timeout="20s")
        except OSError as exc:
            raise SpectrageoError(
                f"cannot reach the Dask scheduler at {scheduler!r}: {exc}"
            ) from exc
        try:
            _say_dashboard(client, verbose)
            yield client
        finally:
            client.close()
        return
    n = workers if workers is not None else default_workers(n_tasks or (os.cpu_count() or 1))
    cluster = distributed.LocalCluster(
        n_workers=int(n),
        threads_per_worker=1,
        processes=processes,
        dashboard_address=":0" if _has_bokeh() else None,
        silence_logs=logging.ERROR,
    )
    try:
        client = distributed.Client(cluster)
        try:
            _say_dashboard(client, verbose)
            yield client
        finally:
            client.close()
    finally:
        cluster.close()


def _has_bokeh() -> bool:
    return importlib.util.find_spec("bokeh") is not None


def _say_dashboard(client: Any, verbose: bool) -> None:
    if not verbose:
        return
    n = len(client.scheduler_info().get("workers", {}))
    if _has_bokeh() or client.scheduler_info().get("services", {}).get("dashboard"):
        print(f"dask: {n} workers, dashboard {client.dashboard_link}", file=sys.stderr, flush=True)
    else:
        print(
            f"dask: {n} workers (no dashboard: pip install bokeh to get one)",
            file=sys.stderr,
            flush=True,
        )


def thread_budget(workers: int | None, scheduler: str | None) -> int | None:
    """Numba/BLAS threads per single-threaded local worker (cores shared out); None: leave as is."""
    if scheduler is not None or workers is None:
        return None
    return max(1, (os.cpu_count() or 1) // int(workers))


def show_progress(futures: list, enabled: bool) -> None:
    """Dask's progress bar over ``futures`` on a terminal (returns when all are done)."""
    if not enabled or not futures:
        return
    distributed = require_dask()
    distributed.progress(futures, notebook=False)
    print(file=sys.stderr, flush=True)


@contextlib.contextmanager
def thread_limits(n: int | None):
    """BLAS/OpenMP (threadpoolctl) and numba threads limited to ``n`` inside the block."""
    if n is None:
        yield
        return
    from threadpoolctl import threadpool_limits

    try:
        import numba

        old = numba.get_num_threads()
        numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))
    except ImportError:  # pragma: no cover - numba is a dependency
        numba = None
    try:
        with threadpool_limits(n):
            yield
    finally:
        if numba is not None:
            numba.set_num_threads(old)
