"""Viewer: time to serve and show a 500k-vertex mesh (server side, and in headless Chromium).

    python benchmarks/viewer.py            # writes benchmarks/_out/viewer.md

Steps measured on a synthetic 500,000-vertex, ~1M-face mesh (a bumpy 1000 x 500 grid, written as
binary PLY) and, when the shared data is present, the 437,645-vertex Stanford dragon:

* upload: POST of the file bytes, read by ``spectrageo.io.read`` (server),
* transfer: GET of positions (float32) and faces (uint32) as raw buffers,
* features: the feature-vertex job at patch 15 (Section 4.4 classification),
* browser: from choosing the file in the page to the first frame drawn with its features, and the
  mean time of 5 redraws while the camera orbits (Chromium with SwiftShader, i.e. software WebGL on
  the CPU: a GPU browser draws far faster; the number is an upper bound).
"""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _util import machine_line, write_section  # noqa: E402
from spectrageo import io  # noqa: E402
from spectrageo.geometry import Mesh  # noqa: E402
from spectrageo.viewer import ViewerServer  # noqa: E402


def bumpy_grid(nx: int, ny: int) -> Mesh:
    x, y = np.meshgrid(np.linspace(0, 2, nx), np.linspace(0, 1, ny), indexing="ij")
    z = 0.05 * np.sin(8 * x) * np.cos(6 * y) + 0.1 * (x > 1)
    V = np.c_[x.ravel(), y.ravel(), z.ravel()]
    idx = np.arange(nx * ny).reshape(nx, ny)
    a, b, c, d = (
        idx[:-1, :-1].ravel(),
        idx[1:, :-1].ravel(),
        idx[1:, 1:].ravel(),
        idx[:-1, 1:].ravel(),
    )
    return Mesh(V, np.r_[np.c_[a, b, c], np.c_[a, c, d]])


def _post(url, data, ctype="application/octet-stream"):
    req = urllib.request.Request(url, data=data, headers={"Content-Type": ctype})
    with urllib.request.urlopen(req, timeout=600) as r:
        return json.loads(r.read())


def _wait(base, job):
    while True:
        with urllib.request.urlopen(f"{base}api/job/{job}", timeout=60) as r:
            j = json.loads(r.read())
        if j["state"] != "running":
            return j
        time.sleep(0.02)


def server_side(path: Path) -> dict:
    srv = ViewerServer([], port=0).start()
    try:
        data = path.read_bytes()
        t = time.perf_counter()
        info = _post(srv.url + f"api/upload?name={path.name}", data)["model"]
        t_up = time.perf_counter() - t
        t = time.perf_counter()
        nbytes = 0
        for what in ("positions", "faces"):
            with urllib.request.urlopen(f"{srv.url}api/model/{info['id']}/{what}") as r:
                nbytes += len(r.read())
        t_tr = time.perf_counter() - t
        t = time.perf_counter()
        job = _post(
            srv.url + f"api/model/{info['id']}/features", b'{"patch": 15}', "application/json"
        )
        j = _wait(srv.url, job["job"])
        t_feat = time.perf_counter() - t
        assert j["state"] == "done", j
        return {
            "n": info["n_vertices"],
            "m": info["n_faces"],
            "file_mb": len(data) / 2**20,
            "upload": t_up,
            "transfer": t_tr,
            "transfer_mb": nbytes / 2**20,
            "features": t_feat,
            "n_features": j["result"]["n_features"],
        }
    finally:
        srv.stop()


def browser_side(path: Path) -> dict | None:
    chromium = shutil.which("chromium") or "/usr/bin/chromium"
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        return None
    if not Path(chromium).exists():
        return None
    srv = ViewerServer([], port=0).start()
    args = ["--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--no-sandbox"]
    try:
        with sync_playwright() as p:
            b = p.chromium.launch(executable_path=chromium, args=args)
            pg = b.new_page(viewport={"width": 1280, "height": 720})
            pg.set_default_timeout(600_000)
            pg.goto(srv.url)
            pg.wait_for_selector("body[data-ready='1']")
            t = time.perf_counter()
            pg.set_input_files("#file-input", str(path))
            pg.wait_for_function(
                "n => document.getElementById('info-name').textContent === n", arg=path.name
            )
            t_geom = time.perf_counter() - t
            pg.wait_for_function(
                "document.body.dataset.busy === '0' && "
                "document.getElementById('info-features').textContent !== '…'"
            )
            pg.wait_for_function("r => window.__spectrageo.renders > r", arg=0)
            t_all = time.perf_counter() - t
            redraw = pg.evaluate(
                """async () => {
                  const S = window.__spectrageo;
                  const t0 = performance.now();
                  for (let i = 0; i < 5; i++) {
                    const r = S.renders;
                    const c = document.getElementById('canvas');
                    const box = c.getBoundingClientRect();
                    c.dispatchEvent(new WheelEvent('wheel', {deltaY: i % 2 ? 40 : -40,
                      clientX: box.left + 100, clientY: box.top + 100, bubbles: true}));
                    while (S.renders === r) await new Promise(requestAnimationFrame);
                  }
                  return (performance.now() - t0) / 5;
                }"""
            )
            b.close()
        return {"first_view": t_geom, "with_features": t_all, "redraw_ms": redraw}
    finally:
        srv.stop()


def main() -> None:
    rows = []
    tmp = Path(tempfile.mkdtemp(prefix="spectrageo-bench-viewer-"))
    try:
        p = tmp / "grid500k.ply"
        io.write(p, bumpy_grid(1000, 500))
        cases = [("synthetic bumpy grid", p)]
        from spectrageo.datasets import data_dir

        d = data_dir()
        if d is not None and (Path(d) / "meshes" / "dragon_vrip.ply.gz").exists():
            cases.append(("Stanford dragon", Path(d) / "meshes" / "dragon_vrip.ply.gz"))
        for label, path in cases:
            s = server_side(path)
            b = browser_side(path)
            rows.append((label, path.name, s, b))
            print(label, s, b, file=sys.stderr)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

    lines = [
        "## Viewer: serving a 500k-vertex mesh",
        "",
        f"Machine: {machine_line()}. Regenerate with `python benchmarks/viewer.py`.",
        "Server: HTTP upload (read with `spectrageo.io.read`), raw float32/uint32 transfer of",
        "positions and faces, feature vertices at patch 15. Browser: headless Chromium with",
        "SwiftShader (software WebGL on the CPU, so redraw times are an upper bound), from choosing the",
        "file to the first drawn frame, then with the feature colours, and the mean redraw while",
        "zooming.",
        "",
        "| model | vertices / faces | file (MB) | upload+read (s) | transfer (s, MB) "
        "| features (s) | browser: first view (s) | with features (s) | redraw (ms) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for label, name, s, b in rows:
        bcols = (
            f"{b['first_view']:.2f} | {b['with_features']:.2f} | {b['redraw_ms']:.0f}"
            if b
            else "n/a | n/a | n/a"
        )
        lines.append(
            f"| {label} ({name}) | {s['n']:,} / {s['m']:,} | {s['file_mb']:.1f} | {s['upload']:.2f} "
            f"| {s['transfer']:.2f} ({s['transfer_mb']:.1f}) | {s['features']:.2f} | {bcols} |"
        )
    if not any(b for *_, b in rows):
        lines += ["", "Browser columns: n/a (Playwright or Chromium not installed)."]
    write_section("viewer", "\n".join(lines))


if __name__ == "__main__":
    main()
