"""``spectrageo batch``: one Dask task per file, each running the single-file command unchanged.

A task runs the command's runner (:data:`~spectrageo.distributed._commands.COMMANDS`) on a
namespace built from its schema (defaults, then the caller's options), so the options, checks and
output of a batch file are those of ``spectrageo COMMAND IN OUT``. Per file the task returns a
record (status, time, metrics, the command's status lines, the error); an exception in one file
never stops the others.

Animations with ``denoise --method gft-rpca --block-size N`` are split further: the file's task
submits one task per block of ``N`` frames to the same cluster
(:func:`~spectrageo.distributed.gft_rpca_blocks`, via ``worker_client``, seceding while it waits),
then writes the output as ``spectrageo denoise`` does; the result equals the serial command's.
"""

from __future__ import annotations

import contextlib
import glob
import io as _stdio
import json
import os
import sys
import threading
import time
from pathlib import Path
from typing import Any

from .._errors import InvalidInputError
from ._cluster import open_client, require_dask, show_progress, thread_budget, thread_limits
from ._commands import COMMANDS
from ._schema import json_default

__all__ = ["BATCH_COMMANDS", "batch", "expand_inputs", "output_paths"]

#: Commands ``batch`` runs, with the attribute of the command's namespace that holds its output.
BATCH_COMMANDS: dict[str, str] = {name: schema.output for name, schema in COMMANDS.items()}
_GLOB_CHARS = set("*?[")
SUMMARY_NAME = "batch-summary.json"


def available_commands() -> list[str]:
    """Names of the commands ``batch`` runs."""
    return list(COMMANDS)


# ----------------------------------------------------------------------------- inputs and outputs
def _readable_suffixes() -> tuple[str, ...]:
    from ..io import supported_formats

    return tuple(s for s in supported_formats()["read"] if s.startswith("."))


def _split_name(p: Path) -> tuple[str, str]:
    """``("bunny", ".ply.gz")``: the name without and with its format suffix (and ``.gz``)."""
    name = p.name
    low = name.lower()
    if low.endswith(".gz"):
        stem, suf = _split_name(Path(name[:-3]))
        return stem, suf + name[-3:]
    dot = name.rfind(".")
    return (name[:dot], name[dot:]) if dot > 0 else (name, "")


def expand_inputs(inputs: Any) -> list[Path]:
    """Files named by ``inputs``: files, glob patterns (``**`` recursive) and folders (their
    geometry files, not recursive), in the given order, sorted within a glob or folder, duplicates
    dropped."""
    if isinstance(inputs, str | os.PathLike):
        inputs = [inputs]
    inputs = list(inputs)
    if not inputs:
        raise InvalidInputError("`inputs` is empty; give files, glob patterns or folders.")
    suffixes = _readable_suffixes()
    out: list[Path] = []
    for item in inputs:
        s = os.fspath(item)
        p = Path(s)
        if p.is_dir():
            found = sorted(
                q for q in p.iterdir() if q.is_file() and q.name.lower().endswith(suffixes)
            )
            if not found:
                raise InvalidInputError(f"`inputs`: folder {s} holds no geometry files.")
            out.extend(found)
        elif p.exists():
            out.append(p)
        elif _GLOB_CHARS & set(s):
            found = sorted(Path(q) for q in glob.glob(s, recursive=True) if Path(q).is_file())
            if not found:
                raise InvalidInputError(f"`inputs`: no file matches {s!r}.")
            out.extend(found)
        else:
            raise InvalidInputError(f"`inputs`: {s} does not exist.")
    seen: set[Path] = set()
    uniq = []
    for p in out:
        r = p.resolve()
        if r not in seen:
            seen.add(r)
            uniq.append(p)
    return uniq


def _output_suffix(command: str, in_suffix: str, suffix: str | None) -> str:
    if suffix is not None:
        return suffix if suffix.startswith(".") else "." + suffix
    if command == "convert":
        raise InvalidInputError("`suffix` is required for convert (the output format, e.g. .ply).")
    if command == "saliency":
        return ".npy"
    if command == "compress":
        return ".sga" if in_suffix.lower().startswith((".npz", ".sga")) else ".sgc"
    # a compressed input is written decoded: .sgc meshes as PLY, .sga animations as .npz (a
    # command writes geometry, which only `compress` turns into a rate-controlled file)
    if in_suffix.lower().startswith(".sgc"):
        return ".ply"
    if in_suffix.lower().startswith(".sga"):
        return ".npz"
    return in_suffix


def output_paths(
    command: str, inputs: list[Path], out_dir: Path, suffix: str | None = None
) -> list[Path]:
    """Output of every input in ``out_dir``: its name with the output suffix; when two inputs share
    a name (``a/Noisy.obj``, ``b/Noisy.obj``) their paths relative to the inputs' common folder
    are kept (``out/a/Noisy.obj``, ``out/b/Noisy.obj``)."""
    parts = [_split_name(p) for p in inputs]
    names = [stem + _output_suffix(command, suf, suffix) for stem, suf in parts]
    if len(set(names)) == len(names):
        outs = [out_dir / n for n in names]
    else:
        absolute = [p.resolve() for p in inputs]
        common = Path(os.path.commonpath([str(a.parent) for a in absolute]))
        outs = [out_dir / a.parent.relative_to(common) / n for a, n in zip(absolute, names)]
        if len({str(o) for o in outs}) != len(outs):
            dup = sorted({n for n in names if names.count(n) > 1})
            raise InvalidInputError(
                f"inputs map to the same output name ({', '.join(dup)}); pass them in separate "
                "batches or give each a distinct name."
            )
    ins = {p.resolve() for p in inputs}
    for o in outs:
        if o.resolve() in ins:
            raise InvalidInputError(
                f"output {o} would overwrite its input; choose another `out_dir` or `suffix`."
            )
    return outs


# ----------------------------------------------------------------------------- the per-file task
def command_namespace(command: str, options: dict[str, Any]):
    """The namespace ``spectrageo COMMAND IN OUT`` would get, with ``options`` (Python names,
    e.g. ``method="bilateral"``) in place of the defaults."""
    if command not in COMMANDS:
        raise InvalidInputError(f"`command` must be one of {', '.join(COMMANDS)}; got {command!r}.")
    return COMMANDS[command].namespace(options)


class _ThreadStderr:
    """``sys.stderr`` stand-in: threads that registered a buffer write there, others through."""

    def __init__(self, real):
        self.real = real
        self.local = threading.local()

    def write(self, s):
        buf = getattr(self.local, "buf", None)
        return (buf if buf is not None else self.real).write(s)

    def flush(self):
        buf = getattr(self.local, "buf", None)
        (buf if buf is not None else self.real).flush()

    def isatty(self):
        return False

    def __getattr__(self, name):
        return getattr(self.real, name)


_STDERR_LOCK = threading.Lock()


@contextlib.contextmanager
def _capture_stderr():
    with _STDERR_LOCK:
        if not isinstance(sys.stderr, _ThreadStderr):
            sys.stderr = _ThreadStderr(sys.stderr)
        proxy = sys.stderr
    buf = _stdio.StringIO()
    proxy.local.buf = buf
    try:
        yield buf
    finally:
        proxy.local.buf = None


def run_file(
    command: str, src: str, dst: str, options: dict[str, Any], n_threads: int | None = None
) -> dict:
    """Run ``spectrageo COMMAND src dst [options]`` here; a record, never an exception."""
    from .. import _progress

    _progress.QUIET = True  # no tqdm bars from inside a task
    rec: dict[str, Any] = {"input": src, "output": dst, "status": "failed"}
    t0 = time.perf_counter()
    with _capture_stderr() as log:
        try:
            ns = command_namespace(command, options)
            schema = COMMANDS[command]
            ns.input = src
            setattr(ns, schema.output, dst)
            Path(dst).parent.mkdir(parents=True, exist_ok=True)
            mask = None
            if schema.keep_mask is not None:
                mask = Path(dst).with_name(f".{Path(dst).name}.keep.npy")
                setattr(ns, schema.keep_mask, str(mask))
            if command == "denoise" and getattr(ns, "block_size", None) is not None:
                # an animation's frame blocks run as tasks of this cluster (None off a worker)
                from ._frames import gft_rpca_blocks_in_task

                ns.frame_blocks = gft_rpca_blocks_in_task(n_threads)
            with thread_limits(n_threads):
                rc = int(schema.run(ns) or 0)
            if rc != 0:
                raise RuntimeError(f"{command} exited with status {rc}")
            p = Path(dst)
            info = {"output_bytes": p.stat().st_size if p.is_file() else None}
            info.update(schema.result(p, mask))
            rec["info"] = info
            rec["status"] = "ok"
        except Exception as exc:  # noqa: BLE001 - a batch reports every file's failure and goes on
            rec["error"] = f"{type(exc).__name__}: {exc}"
    rec["time_s"] = round(time.perf_counter() - t0, 4)
    lines = [ln for ln in log.getvalue().splitlines() if ln.strip()]
    if lines:
        rec["log"] = lines
    return rec


# ----------------------------------------------------------------------------- the driver
def batch(
    command: str,
    inputs: Any,
    out_dir: str | os.PathLike,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    resume: bool = False,
    suffix: str | None = None,
    summary: str | os.PathLike | None = None,
    processes: bool = True,
    progress: bool | None = None,
    **options: Any,
) -> list[dict]:
    """Run one single-file command over many files on Dask, one task per file.

    Parameters
    ----------
    command : {"denoise", "outliers", "saliency", "compress", "complete", "convert"}
    inputs : path, glob pattern, folder, or a list of them
        See :func:`expand_inputs`.
    out_dir : path
        Outputs are named after the inputs (:func:`output_paths`); created if absent.
    workers : int, optional
        Local cluster size (processes of one thread; default one per core).
    scheduler : str, optional
        Address of a running Dask scheduler instead of a local cluster.
    resume : bool
        Skip inputs whose output exists (outputs are written atomically, so an existing output is
        a finished one).
    suffix : str, optional
        Output format (``".ply"``); default the input's (``.ply`` / ``.npz`` for compressed
        ``.sgc`` / ``.sga`` inputs, ``.npy`` for saliency, ``.sgc``/``.sga``
        for compress; required for convert).
    summary : path, optional
        JSON summary (default ``out_dir/batch-summary.json``).
    processes : bool
        Local cluster of processes (default) or of threads in this process.
    progress : bool, optional
        Dask's progress bar and the dashboard link on stderr (default: when stderr is a terminal).
    **options
        The command's options under their Python names (``method="bilateral"``, ``k=12``).

    Returns
    -------
    list of dict
        One record per input, input order: ``input``, ``output``, ``status`` (``"ok"``,
        ``"failed"``, ``"skipped"``), ``time_s``, ``info`` (the command's metrics), ``log`` (its
        status lines), ``error`` (failed only).
    """
    files = expand_inputs(inputs)
    command_namespace(command, options)  # bad command or option: fail before any cluster starts
    out_dir = Path(out_dir)
    outs = output_paths(command, files, out_dir, suffix)
    out_dir.mkdir(parents=True, exist_ok=True)
    summary_path = Path(summary) if summary is not None else out_dir / SUMMARY_NAME
    previous = _previous_records(summary_path) if resume else {}
    records: list[dict | None] = [None] * len(files)
    todo = []
    for i, (src, dst) in enumerate(zip(files, outs)):
        if resume and dst.exists():
            prev = previous.get(str(src), {})
            rec = {"input": str(src), "output": str(dst), "status": "skipped", "time_s": 0.0}
            if "info" in prev:
                rec["info"] = prev["info"]
            records[i] = rec
        else:
            todo.append(i)
    if progress is None:
        from .. import _progress

        progress = _progress.progress_enabled()
    t0 = time.perf_counter()
    n_workers = None
    if todo:
        require_dask()
        with open_client(
            workers=workers,
            scheduler=scheduler,
            processes=processes,
            n_tasks=len(todo),
            verbose=progress,
        ) as client:
            n_workers = len(client.scheduler_info().get("workers", {}))
            budget = thread_budget(n_workers, scheduler)
            # largest inputs first (longest-processing-time-first list scheduling: a big file
            # started last would leave the other workers idle at the end); records keep input
            # order
            rank = {i: r for r, i in enumerate(sorted(todo, key=lambda i: _size(files[i])))}
            futs = [
                client.submit(
                    run_file,
                    command,
                    str(files[i]),
                    str(outs[i]),
                    options,
                    budget,
                    key=f"spectrageo-{command}-{i}-{files[i].name}",
                    pure=False,
                    priority=rank[i],
                )
                for i in todo
            ]
            show_progress(futs, progress)
            for i, fut in zip(todo, futs):
                try:
                    records[i] = fut.result()
                except Exception as exc:  # noqa: BLE001 - a worker lost mid-task (killed, OOM)
                    records[i] = {
                        "input": str(files[i]),
                        "output": str(outs[i]),
                        "status": "failed",
                        "error": f"{type(exc).__name__}: {exc}",
                    }
    done = [r for r in records if r is not None]
    _write_summary(summary_path, command, options, done, n_workers, scheduler, t0)
    return done


def _size(path: Path) -> int:
    """Bytes of an input file (a frame folder: of its files), the cost proxy of the task order."""
    try:
        if path.is_dir():
            return sum(p.stat().st_size for p in path.iterdir() if p.is_file())
        return path.stat().st_size
    except OSError:
        return 0


def _previous_records(path: Path) -> dict[str, dict]:
    try:
        d = json.loads(path.read_text())
        return {r["input"]: r for r in d.get("files", []) if isinstance(r, dict) and "input" in r}
    except (OSError, ValueError, AttributeError):
        return {}


def _write_summary(path, command, options, records, n_workers, scheduler, t0) -> None:
    from ..io import atomic_write

    counts = {s: sum(r["status"] == s for r in records) for s in ("ok", "failed", "skipped")}
    doc = {
        "command": command,
        "options": options,
        "workers": n_workers,
        "scheduler": scheduler or "local",
        "wall_time_s": round(time.perf_counter() - t0, 4),
        "n_files": len(records),
        **{f"n_{k}": v for k, v in counts.items()},
        "files": records,
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(path) as tmp:
        Path(tmp).write_text(json.dumps(doc, indent=2, default=json_default) + "\n")
