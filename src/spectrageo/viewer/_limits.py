"""Resource limits of the viewer and the early refusal of compression bombs."""

from __future__ import annotations

import os
import zlib
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import InvalidInputError

MAX_NAME = 200  # characters of a model name (longer ones are cut, keeping the extension)
MAX_JSON_BODY = 1 << 20  # bytes of a JSON request body
CHUNK = 1 << 20  # bytes per read while streaming an upload to disk
MIN_BODY_RATE = 256 << 10  # bytes per second a body must average (beyond request_timeout)
ENV_PREFIX = "SPECTRAGEO_VIEW_"


@dataclass(frozen=True)
class ViewerLimits:
    """Resource limits of one viewer server; each field can also be set as an environment variable
    ``SPECTRAGEO_VIEW_<FIELD>`` (e.g. ``SPECTRAGEO_VIEW_MAX_UPLOAD_MB``); arguments win.

    Parameters
    ----------
    max_upload_mb : float
        Largest upload body in MiB (``--max-upload``); refused from its ``Content-Length`` (413).
    max_models : int
        Models kept loaded; beyond it the least recently used is unloaded (``--max-models``).
    max_memory_mb : float
        Budget of the models' arrays in MiB (``--max-memory``); beyond it least recently used
        models are unloaded, never the newest nor one a job is using. An upload may decompress
        to, and its reader allocate, at most a quarter of it (:attr:`max_read_bytes`).
    max_jobs, max_queued : int
        Computations running at once, and waiting for a worker (then 429).
    max_uploads : int
        Uploads received at once; further ones get 429 before their body is read.
    request_timeout : float
        Seconds to receive a request's headers and longest pause within a body; a whole body
        must arrive within it plus one second per ``MIN_BODY_RATE`` bytes (else 408).
    max_connections : int
        Open connections at once; further ones get 503 and are closed.
    """

    max_upload_mb: float = 256.0
    max_models: int = 32
    max_memory_mb: float = 2048.0
    max_jobs: int = 2
    max_queued: int = 8
    max_uploads: int = 2
    request_timeout: float = 30.0
    max_connections: int = 64

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if f.type == "int":
                ok = isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 1
                want = "an integer >= 1"
            else:
                ok = isinstance(v, (int, float, np.number)) and not isinstance(v, bool) and v > 0
                ok = ok and np.isfinite(v)
                want = "a number > 0"
            if not ok:
                raise InvalidInputError(f"`{f.name}` must be {want}; got {v!r}.")

    @classmethod
    def from_env(cls, environ=None, **overrides) -> ViewerLimits:
        """Defaults, then ``SPECTRAGEO_VIEW_*`` environment variables, then ``overrides``."""
        env = os.environ if environ is None else environ
        values: dict[str, Any] = {}
        for f in fields(cls):
            raw = env.get(ENV_PREFIX + f.name.upper())
            if raw is None or raw.strip() == "":
                continue
            try:
                values[f.name] = int(raw) if f.type == "int" else float(raw)
            except ValueError:
                raise InvalidInputError(
                    f"`{ENV_PREFIX}{f.name.upper()}` must be a number; got {raw!r}."
                ) from None
        values.update({k: v for k, v in overrides.items() if v is not None})
        unknown = set(values) - {f.name for f in fields(cls)}
        if unknown:
            raise InvalidInputError(f"unknown viewer limit(s): {', '.join(sorted(unknown))}.")
        return cls(**values)

    @property
    def max_upload_bytes(self) -> int:
        return int(self.max_upload_mb * 2**20)

    @property
    def max_memory_bytes(self) -> int:
        return int(self.max_memory_mb * 2**20)

    @property
    def max_read_bytes(self) -> int:
        """What one upload may decompress to and its reader allocate at once: a quarter of the
        memory budget (reading holds the inflated bytes and the arrays decoded from them)."""
        return self.max_memory_bytes // 4

    def to_json(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)} | {
            "max_upload_bytes": self.max_upload_bytes
        }


def _mb(n: int) -> str:
    return f"{n / 2**20:g} MB"


def _gzip_size(path: Path, stop: int) -> int:
    """Bytes that the gzip members of ``path`` inflate to, counted in a stream (no output kept)
    until the end or beyond ``stop``; NUL padding between members is skipped."""
    total, d, fresh = 0, zlib.decompressobj(16 + zlib.MAX_WBITS), True
    with open(path, "rb") as f:
        while raw := f.read(CHUNK):
            while raw:
                if fresh:
                    raw = raw.lstrip(b"\0")
                    if not raw:
                        break
                    fresh = False
                total += len(d.decompress(raw, 16 * CHUNK))
                if total > stop:
                    return total
                raw = d.unconsumed_tail
                if d.eof:
                    raw, d, fresh = d.unused_data, zlib.decompressobj(16 + zlib.MAX_WBITS), True
    return total if fresh else total + len(d.flush(1 << 16))


def _check_expansion(path: Path, name: str, limits: ViewerLimits) -> None:
    """Refuse a gzip or zip upload that expands beyond the memory budget, or beyond what one
    upload may decompress to (:attr:`ViewerLimits.max_read_bytes`), before it is read.

    gzip is counted as a stream (no output kept); for zip archives the central directory's sizes
    are summed.
    """
    import zipfile

    cap, read_cap = limits.max_memory_bytes, limits.max_read_bytes
    with open(path, "rb") as f:
        magic = f.read(4)
    try:
        if magic[:2] == b"\x1f\x8b":
            n = _gzip_size(path, cap)
        elif magic == b"PK\x03\x04":
            with zipfile.ZipFile(path) as z:
                n = sum(i.file_size for i in z.infolist())
        else:
            return
    except (OSError, EOFError, zlib.error, zipfile.BadZipFile) as exc:
        raise InvalidInputError(
            f"could not read {name}: corrupt compressed data ({exc})."
        ) from None
    if n > cap:
        raise InvalidInputError(
            f"{name} decompresses to more than {_mb(cap)} (the viewer's --max-memory)."
        )
    if n > read_cap:
        raise InvalidInputError(
            f"{name} decompresses to more than {_mb(read_cap)}, a quarter of the viewer's "
            f"--max-memory of {_mb(cap)} (the most one upload may decompress to)."
        )
