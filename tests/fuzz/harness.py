"""Make the fuzz cases, run them and classify the outcomes.

A case is one mutant of a seed file; it runs ``spectrageo info FILE --json`` and ``spectrageo
convert FILE OUT`` (``OUT`` is ``.npz`` for ``.sga`` animations). Commands run in batches inside
child processes limited to 4 GiB of address space (:mod:`.driver`), each command under a
per-command alarm; a batch that dies or stops answering has the job it was running rerun alone
through the real command line (:func:`_cli_limits.run_cli`), which names signals and native hangs.

Classes: ``ok``, ``clear`` (exit 2, one stderr line, no traceback), ``internal`` (exit 1, another
exception, a traceback or several stderr lines), ``wrong`` (exit 0 with an output that breaks an
invariant: invalid JSON, non-finite coordinates, face indices out of range, a checksummed codec
file decoded differently from its seed or read although it must be refused), ``hang`` (timeout),
``memory`` (MemoryError, bad_alloc) and ``signal`` (killed by a signal).
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from _cli_limits import Outcome, child_env, limit_resources, run_cli

from . import mutators, seeds

CLASSES = ("ok", "clear", "internal", "wrong", "hang", "memory", "signal")
BAD = ("internal", "wrong", "hang", "memory", "signal")
COMMANDS = ("info", "convert")
_DRIVER = Path(__file__).with_name("driver.py")
_MEMORY = ("MemoryError", "bad_alloc", "Cannot allocate memory", "out of memory")


@dataclass
class Case:
    """One mutant and the commands run on it."""

    name: str
    fmt: str
    path: Path
    desc: str
    expect: str
    seed_path: Path
    results: dict[str, tuple[str, str]] = field(default_factory=dict)  # command -> (class, why)
    seconds: dict[str, float] = field(default_factory=dict)  # command -> run time

    @property
    def worst(self) -> str:
        found = [c for c, _ in self.results.values()]
        for c in reversed(CLASSES):
            if c in found:
                return c
        return "ok"


def make_cases(n: int, seed: int, formats, folder: Path) -> list[Case]:
    """``n`` cases spread evenly over ``formats`` (format order kept), written under ``folder``;
    the same arguments give the same files."""
    folder.mkdir(parents=True, exist_ok=True)
    fmts = [f for f in formats if seeds.available(f)]
    per = [n // len(fmts) + (i < n % len(fmts)) for i in range(len(fmts))]
    cases = []
    for fmt, k in zip(fmts, per):
        seed_files = seeds.build_seeds(fmt, folder)
        seed_paths = []
        for j, (suffix, data) in enumerate(seed_files):
            p = folder / f"seed_{fmt}_{j}{suffix}"
            p.write_bytes(data)
            seed_paths.append(p)
        rng = np.random.default_rng([seed, seeds.FORMATS.index(fmt)])
        for i in range(k):
            j = int(rng.integers(len(seed_files)))
            suffix, data = seed_files[j]
            mutant, desc, expect = mutators.mutate(data, fmt, suffix, rng)
            p = folder / f"{fmt}_{i:04d}_s{j}{suffix}"
            p.write_bytes(mutant)
            cases.append(Case(p.name, fmt, p, f"seed {j}: {desc}", expect, seed_paths[j]))
    return cases


#: formats whose mutants ``metrics`` compares with themselves (``commands`` of :func:`run_cases`)
MESH_FORMATS = ("ply_ascii", "obj", "off", "stl", "gltf", "glb", "3mf", "sgc")


def _jobs(case: Case, out_dir: Path, commands) -> list[dict]:
    out = str(out_dir / (case.name + (".npz" if case.fmt == "sga" else ".ply")))
    check = {"out": out, "expect": case.expect}
    if case.fmt in seeds.CODEC_FORMATS:
        check["ref_seed"] = str(case.seed_path)
        check["ref_out"] = str(out_dir / ("ref_" + case.seed_path.name + Path(out).suffix))
    f = str(case.path)
    argv = {
        "info": ["info", f, "--json"],
        "convert": ["convert", f, out],
        "metrics": ["metrics", f, f, "--json", "-q"],
    }
    checks = {"convert": check, "metrics": {"self_metrics": True}}
    return [
        {"id": f"{case.name}|{c}", "argv": argv[c], "check": checks.get(c)}
        for c in commands
        if c != "metrics" or case.fmt in MESH_FORMATS
    ]


def classify(out: Outcome, wrong: str | None, json_expected: bool) -> tuple[str, str]:
    """``(class, reason)`` of one command's outcome."""
    text = " ".join(out.lines)
    code = out.code
    if code is None:
        return "hang", f"no answer within {out.seconds:.0f} s"
    if any(m in text for m in _MEMORY) or (isinstance(code, str) and "MemoryError" in code):
        return "memory", out.describe()
    if isinstance(code, int) and code < 0:
        return "signal", out.describe()
    if isinstance(code, str) or "Traceback" in text:
        return "internal", str(code) if isinstance(code, str) else out.describe()
    if code == 2:
        return ("clear", out.lines[0]) if len(out.lines) == 1 else ("internal", out.describe())
    if code != 0:
        return "internal", out.describe()
    if wrong:
        return "wrong", wrong
    if json_expected:
        try:
            json.loads(out.stdout)
        except ValueError:
            return "wrong", "exit 0 with invalid JSON"
    return "ok", ""


def _read_log(log: Path) -> tuple[dict[str, dict], str | None]:
    done, started = {}, None
    for line in log.read_text().splitlines() if log.exists() else []:
        rec = json.loads(line)
        if "start" in rec:
            started = rec["start"]
        else:
            done[rec["id"]] = rec
            started = None
    return done, started


def _run_batch(jobs: list[dict], work: Path, tag: str, limit: int) -> dict[str, tuple]:
    """``id -> (Outcome, wrong)`` of every job; dead batches continue in new processes."""
    results: dict[str, tuple] = {}
    todo = list(jobs)
    k = 0
    while todo:
        k += 1
        log, lst = work / f"{tag}-{k}.log", work / f"{tag}-{k}.json"
        lst.write_text(json.dumps(todo))
        cmd = [sys.executable, str(_DRIVER), str(log), str(lst), str(limit)]
        proc = subprocess.Popen(
            cmd,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            preexec_fn=limit_resources,
            env=child_env(),
        )
        last, seen = time.monotonic(), 0
        while proc.poll() is None:  # a job past its alarm by 15 s is a native hang
            time.sleep(0.2)
            size = log.stat().st_size if log.exists() else 0
            if size != seen:
                last, seen = time.monotonic(), size
            elif time.monotonic() - last > limit + 15 + (60 if k == 1 and not size else 0):
                proc.kill()
                proc.wait()
        done, started = _read_log(log)
        for jid, rec in done.items():
            out = Outcome(rec["code"], rec["lines"], rec["stdout"], rec["seconds"])
            out.lines += ["..."] * (rec["n_lines"] - len(rec["lines"]))
            results[jid] = (out, rec["wrong"])
        todo = [j for j in todo if j["id"] not in results]
        if todo:  # the batch died on (or before) this job: run it alone through the command line
            job = next((j for j in todo if j["id"] == started), todo[0])
            results[job["id"]] = (run_cli(job["argv"], timeout=limit + 5), None)
            todo = [j for j in todo if j["id"] != job["id"]]
    return results


def run_cases(
    cases: list[Case], work: Path, *, workers: int = 2, limit: int = 30, commands=COMMANDS
) -> None:
    """Run ``commands`` (of ``info``, ``convert``, ``metrics``) on every case (fills
    ``case.results``)."""
    out_dir = work / "out"
    out_dir.mkdir(parents=True, exist_ok=True)
    jobs = [j for c in cases for j in _jobs(c, out_dir, commands)]
    # interleave so that each worker gets every format
    chunks = [jobs[2 * w :: 2 * workers] + jobs[2 * w + 1 :: 2 * workers] for w in range(workers)]
    chunks = [sorted(ch, key=lambda j: jobs.index(j)) for ch in chunks]
    with ThreadPoolExecutor(workers) as pool:
        parts = list(
            pool.map(lambda a: _run_batch(a[1], work, f"w{a[0]}", limit), enumerate(chunks))
        )
    results = {k: v for part in parts for k, v in part.items()}
    for c in cases:
        for command in commands:
            if f"{c.name}|{command}" not in results:
                continue
            out, wrong = results[f"{c.name}|{command}"]
            c.results[command] = classify(out, wrong, json_expected=command != "convert")
            c.seconds[command] = out.seconds


def table(cases: list[Case]) -> str:
    """Counts of the worst class per case, one row per format."""
    fmts = list(dict.fromkeys(c.fmt for c in cases))
    rows = [f"{'format':<16}" + "".join(f"{k:>9}" for k in CLASSES) + f"{'cases':>8}"]
    for fmt in [*fmts, "all"]:
        sel = [c for c in cases if fmt in ("all", c.fmt)]
        counts = [sum(c.worst == k for c in sel) for k in CLASSES]
        rows.append(f"{fmt:<16}" + "".join(f"{v:>9}" for v in counts) + f"{len(sel):>8}")
    return "\n".join(rows)


def failures(cases: list[Case]) -> list[str]:
    """One line per failing command: file, mutation, command, class and reason."""
    out = []
    for c in cases:
        for command, (cls, why) in c.results.items():
            if cls in BAD:
                out.append(f"{c.name} [{c.desc}] {command}: {cls}: {why}")
    return out
