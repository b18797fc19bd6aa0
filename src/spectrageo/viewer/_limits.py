"""Resource limits of the viewer and the early refusal of compression bombs."""

from __future__ import annotations

import os
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import InvalidInputError

MAX_NAME = 200  # characters of a model name (longer ones are cut, keeping the extension)
MAX_JSON_BODY = 1 << 20  # bytes of a JSON request body
CHUNK = 1 << 20  # bytes per read while streaming an upload to disk
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
        models are unloaded, never the newest nor one a job is using.
    max_jobs, max_queued : int
        Computations running at once, and waiting for a worker (then 429).
    max_uploads : int
        Uploads received at once; further ones get 429 before their body is read.
    request_timeout : float
        Seconds to receive a request's headers and longest pause within a body.
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

    def to_json(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)} | {
            "max_upload_bytes": self.max_upload_bytes
        }


def _check_expansion(path: Path, name: str, cap: int) -> None:
    """Refuse a gzip or zip upload that expands beyond ``cap`` bytes (the models' memory budget).

    gzip is counted as a stream; for zip archives the central directory's sizes are summed.
    """
    import gzip
    import zipfile
    import zlib

    with open(path, "rb") as f:
        magic = f.read(4)
    too_big = f"{name} decompresses to more than {cap / 2**20:g} MB (the viewer's --max-memory)."
    try:
        if magic[:2] == b"\x1f\x8b":
            n = 0
            with gzip.open(path, "rb") as g:
                while chunk := g.read(CHUNK):
                    n += len(chunk)
                    if n > cap:
                        raise InvalidInputError(too_big)
        elif magic == b"PK\x03\x04":
            with zipfile.ZipFile(path) as z:
                if sum(i.file_size for i in z.infolist()) > cap:
                    raise InvalidInputError(too_big)
    except (OSError, EOFError, zlib.error, zipfile.BadZipFile) as exc:
        raise InvalidInputError(
            f"could not read {name}: corrupt compressed data ({exc})."
        ) from None
