"""Download the files of the sealed test split (``manifest.csv``) and check their SHA-256.

    python benchmarks/test_split/fetch.py [--dest DIR] [--manifest FILE]

Each file comes from ``https://raw.githubusercontent.com/<repo>/<commit>/<path>`` (the commit is
pinned in the manifest) and is saved as ``<DIR>/<file>``; ``DIR`` is ``--dest``, else the
environment variable ``SPECTRAGEO_TEST_DATA``, else ``../test_split_data`` (beside the
repository when run from its root). A file already there with the right hash is not fetched
again; a hash mismatch is an error and leaves no file behind. Nothing here is run by the tests.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import os
import sys
import urllib.request
from pathlib import Path

HERE = Path(__file__).resolve().parent
RAW = "https://raw.githubusercontent.com/{repo}/{commit}/{path}"


def files(manifest: Path) -> dict[str, tuple[str, str]]:
    """``{local file: (url, sha256)}`` over the manifest, the clean file of each pair included."""
    out: dict[str, tuple[str, str]] = {}
    with manifest.open(newline="", encoding="utf-8") as f:
        for row in csv.DictReader(f):
            for file, path, sha in (
                (row["file"], row["path"], row["sha256"]),
                (row["clean_file"], row["clean_path"], row["clean_sha256"]),
            ):
                if file:
                    url = RAW.format(repo=row["repo"], commit=row["commit"], path=path)
                    out[file] = (url, sha)
    return out


def sha256(path: Path) -> str:
    h = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def fetch(dest: Path, manifest: Path) -> int:
    """Fetch every missing file; return the number of failures."""
    failures = 0
    for file, (url, expected) in sorted(files(manifest).items()):
        target = dest / file
        if target.is_file() and sha256(target) == expected:
            print(f"ok       {file}")
            continue
        target.parent.mkdir(parents=True, exist_ok=True)
        tmp = target.with_name(target.name + ".part")
        try:
            with urllib.request.urlopen(url, timeout=120) as r, tmp.open("wb") as f:
                while block := r.read(1 << 20):
                    f.write(block)
            got = sha256(tmp)
            if got != expected:
                raise ValueError(f"SHA-256 {got} differs from the manifest's {expected}")
            tmp.replace(target)
            print(f"fetched  {file}")
        except Exception as exc:  # noqa: BLE001 - reported per file, the others still run
            tmp.unlink(missing_ok=True)
            print(f"FAILED   {file}: {exc} ({url})", file=sys.stderr)
            failures += 1
    return failures


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    default = os.environ.get("SPECTRAGEO_TEST_DATA", "../test_split_data")
    ap.add_argument("--dest", default=default, help=f"target folder (default {default})")
    ap.add_argument("--manifest", default=str(HERE / "manifest.csv"))
    a = ap.parse_args()
    n = fetch(Path(a.dest), Path(a.manifest))
    sys.exit(1 if n else 0)


if __name__ == "__main__":
    main()
