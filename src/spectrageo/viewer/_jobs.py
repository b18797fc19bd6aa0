"""Background computations of the viewer: jobs polled by the browser and a bounded worker pool."""

from __future__ import annotations

import queue
import threading
import time
import uuid

from .._errors import SpectrageoError


class Job:
    """A background computation polled by the browser: ``state`` is ``"running"`` (``queued`` while
    it waits for a worker), then ``"done"`` or ``"error"``."""

    def __init__(self, desc: str):
        self.id = uuid.uuid4().hex[:12]
        self.desc = desc
        self.state = "running"
        self.queued = True
        self.progress: float | None = None
        self.message = f"{desc}: waiting for a free worker"
        self.result: dict | None = None
        self.error: str | None = None
        self.started = time.perf_counter()
        self.finished: float | None = None
        self.cancelled = False

    def cancel(self) -> None:
        """Ask the job to stop: it ends with an error at its next :meth:`update` (or before it
        starts, when still queued)."""
        self.cancelled = True

    def update(self, progress: float | None = None, message: str | None = None) -> None:
        if self.cancelled:
            raise JobCancelled(f"{self.desc}: cancelled, the viewer is stopping.")
        if progress is not None:
            self.progress = float(min(max(progress, 0.0), 1.0))
        if message is not None:
            self.message = message

    def to_json(self) -> dict:
        end = self.finished if self.finished is not None else time.perf_counter()
        d = {
            "id": self.id,
            "state": self.state,
            "queued": self.queued,
            "progress": self.progress,
            "message": self.message,
            "elapsed": round(end - self.started, 3),
        }
        if self.result is not None:
            d["result"] = self.result
        if self.error is not None:
            d["error"] = self.error
        return d


class ViewerBusyError(SpectrageoError):
    """The job queue is full (HTTP 429); viewer-internal, the library never raises it."""


class JobCancelled(SpectrageoError):
    """A job stopped by :meth:`Job.cancel`; viewer-internal."""


class _JobPool:
    """``workers`` daemon threads and at most ``queued`` waiting jobs (submit fails beyond)."""

    def __init__(self, workers: int, queued: int):
        self.workers = workers
        self._q: queue.SimpleQueue = queue.SimpleQueue()
        self._slots = threading.BoundedSemaphore(workers + queued)
        self._threads: list[threading.Thread] = []
        self._lock = threading.Lock()
        self._closed = False

    def submit(self, fn) -> bool:
        with self._lock:
            if self._closed or not self._slots.acquire(blocking=False):
                return False
            if len(self._threads) < self.workers:
                t = threading.Thread(
                    target=self._loop,
                    daemon=True,
                    name=f"spectrageo-view-worker-{len(self._threads)}",
                )
                self._threads.append(t)
                t.start()
        self._q.put(fn)
        return True

    def _loop(self) -> None:
        while True:
            fn = self._q.get()
            if fn is None:
                return
            try:
                fn()
            finally:
                self._slots.release()

    def close(self, timeout: float = 0.0) -> bool:
        """Refuse new work, let the workers end after the queued jobs, and wait up to ``timeout``
        seconds for them; whether they all ended."""
        with self._lock:
            if not self._closed:
                self._closed = True
                for _ in self._threads:
                    self._q.put(None)
            threads = list(self._threads)
        end = time.monotonic() + timeout
        for t in threads:
            if t is not threading.current_thread():
                t.join(max(end - time.monotonic(), 0.0))
        return not any(t.is_alive() for t in threads if t is not threading.current_thread())


def _error_text(exc: BaseException) -> str:
    if isinstance(exc, (SpectrageoError, ValueError)):
        return str(exc)
    return f"internal error: {type(exc).__name__}: {exc}"
