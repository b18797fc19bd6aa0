"""File names as data (cleaning, extensions, download headers) and the viewer's temporary files."""

from __future__ import annotations

import os
import re
import shutil
import stat
import tempfile
import time
import unicodedata
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from urllib.parse import quote

from ._limits import MAX_NAME

TMP_PREFIX = "spectrageo-view-"

_SPLIT_PATH = re.compile(r"[/\\]")
_EXT = re.compile(r"(\.[A-Za-z0-9]{1,10})?(\.[A-Za-z0-9]{1,10})$")
_ASCII_UNSAFE = re.compile(r"[^A-Za-z0-9._+-]+")


def clean_name(name, *, default: str = "upload", max_len: int = MAX_NAME) -> str:
    """A file name fit for display and JSON: NFC Unicode without control and format characters
    (``Cc``, ``Cf``, ``Cs``), line separators as spaces, no folders, and at most ``max_len``
    characters (cut in the stem with an ellipsis, so the extension that selects the reader stays).
    """
    s = unicodedata.normalize("NFC", str(name))
    s = "".join(
        " " if unicodedata.category(c) in ("Zl", "Zp") else c
        for c in s
        if unicodedata.category(c) not in ("Cc", "Cf", "Cs")
    )
    s = _SPLIT_PATH.split(s)[-1].strip()
    if s in ("", ".", ".."):
        return default
    if len(s) > max_len:
        ext = file_suffix(s)
        s = s[: max_len - len(ext) - 1].rstrip() + "\u2026" + ext
    return s


def file_suffix(name: str) -> str:
    """Lower-case extension that selects the reader: ``'.ply'``, ``'.ply.gz'``, or ``''``."""
    m = _EXT.search(name)
    if not m:
        return ""
    if m.group(2).lower() == ".gz" and m.group(1):
        return (m.group(1) + m.group(2)).lower()
    return m.group(2).lower()


def _stem(name: str) -> str:
    ext = file_suffix(name)
    return name[: len(name) - len(ext)] if ext and len(ext) < len(name) else name


def content_disposition(name: str) -> str:
    """``attachment`` header value for ``name`` (RFC 6266): ASCII fallback + UTF-8 ``filename*``."""
    name = clean_name(name, default="download")
    fallback = unicodedata.normalize("NFKD", name).encode("ascii", "ignore").decode("ascii")
    fallback = _ASCII_UNSAFE.sub("_", fallback).strip("_") or "download"
    if not fallback.lower().endswith(file_suffix(name)):
        fallback += file_suffix(name)
    return f"attachment; filename=\"{fallback}\"; filename*=UTF-8''{quote(name, safe='')}"


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # exists, belongs to someone else
    except OSError:
        return True
    return True


def remove_stale_temp_dirs(root: str | os.PathLike | None = None) -> list[Path]:
    """Remove this user's ``spectrageo-view-<PID>-*`` folders whose PID is gone (PID-less ones once
    untouched for an hour); returns the removed paths. Does nothing on Windows."""
    if os.name == "nt":
        return []
    root = Path(root if root is not None else tempfile.gettempdir())
    removed = []
    pat = re.compile(re.escape(TMP_PREFIX) + r"(\d+)-[A-Za-z0-9_]+")
    try:
        candidates = list(root.glob(TMP_PREFIX + "*"))
    except OSError:
        return []
    for p in candidates:
        try:
            st = os.lstat(p)
        except OSError:
            continue
        if not stat.S_ISDIR(st.st_mode) or st.st_uid != os.getuid():
            continue
        m = pat.fullmatch(p.name)
        if m:
            pid = int(m.group(1))
            if pid == os.getpid() or _pid_alive(pid):
                continue
        elif time.time() - st.st_mtime < 3600:
            continue
        shutil.rmtree(p, ignore_errors=True)
        if not p.exists():
            removed.append(p)
    return removed


def _make_temp_dir() -> Path:
    return Path(tempfile.mkdtemp(prefix=f"{TMP_PREFIX}{os.getpid()}-"))


@contextmanager
def scratch_file(tmp_dir: Path | None, prefix: str, suffix: str = "") -> Iterator[Path]:
    """A fresh path in ``tmp_dir`` (else in its own folder), removed with that folder on exit."""
    own = tmp_dir is None or not tmp_dir.is_dir()
    folder = _make_temp_dir() if own else tmp_dir
    p = folder / f"{prefix}-{uuid.uuid4().hex}{suffix}"
    try:
        yield p
    finally:
        p.unlink(missing_ok=True)
        if own:
            shutil.rmtree(folder, ignore_errors=True)
