"""Long fuzz run of the readers and codecs (the harness of ``tests/fuzz``): ``N`` mutants spread
over the formats, each read by ``spectrageo info`` and ``convert`` under a 4 GiB address-space
limit and a per-command timeout; prints the classes per format and keeps every failing file.

    python benchmarks/fuzz_long.py --n 6000 --seed 7 [--formats sgc,sga,3mf] [--metrics] [--out DIR]

Failing files are copied to ``DIR/seedS/failures`` (default ``DIR``: ``$TMPDIR/spectrageo_fuzz``) with
``failures.txt`` naming each one's mutation, command, class and message; the exit status is 1
when any case is an internal error, wrong, a hang, a memory blow-up or a signal death.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(_ROOT / "tests"))

from fuzz import harness, seeds  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=6000, help="number of cases (default 6000)")
    ap.add_argument("--seed", type=int, default=1, help="random seed of the mutations")
    ap.add_argument("--formats", default=",".join(seeds.FORMATS), help="comma-separated formats")
    ap.add_argument("--out", type=Path, default=Path(tempfile.gettempdir()) / "spectrageo_fuzz")
    ap.add_argument("--timeout", type=int, default=30, help="seconds per command (default 30)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument(
        "--metrics", action="store_true", help="also run `metrics F F` on the mesh formats"
    )
    a = ap.parse_args(argv)
    formats = [f.strip() for f in a.formats.split(",") if f.strip()]
    unknown = sorted(set(formats) - set(seeds.FORMATS))
    if unknown:
        ap.error(f"unknown formats {unknown}; known: {', '.join(seeds.FORMATS)}")
    work = a.out / f"seed{a.seed}"
    shutil.rmtree(work, ignore_errors=True)
    t0 = time.perf_counter()
    cases = harness.make_cases(a.n, a.seed, formats, work / "cases")
    commands = (*harness.COMMANDS, "metrics") if a.metrics else harness.COMMANDS
    harness.run_cases(cases, work / "run", workers=a.workers, limit=a.timeout, commands=commands)
    dt = time.perf_counter() - t0
    print(f"{len(cases)} cases, seed {a.seed}, {dt:.0f} s")
    print(harness.table(cases))
    bad = harness.failures(cases)
    fail_dir = work / "failures"
    fail_dir.mkdir(parents=True, exist_ok=True)
    for c in cases:
        if c.worst in harness.BAD:
            shutil.copy2(c.path, fail_dir / c.name)
    (fail_dir / "failures.txt").write_text("".join(line + "\n" for line in bad))
    if bad:
        print(f"\n{len(bad)} failing commands (files in {fail_dir}):")
        print("\n".join(bad))
    shutil.rmtree(work / "run", ignore_errors=True)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
