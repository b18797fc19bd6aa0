"""Viewer: time to serve and show a 500k-vertex mesh (server side, and in headless Chromium).

    python benchmarks/viewer.py            # writes benchmarks/_out/viewer.md

Steps measured on a synthetic 500,000-vertex, ~1M-face mesh (a bumpy 1000 x 500 grid, written as
binary PLY) and, when the shared data is present, the 437,645-vertex Stanford dragon:

* upload: POST of the file bytes, read by ``spectrageo.io.read`` (server),
* transfer: GET of positions (float32) and faces (uint32) as raw buffers,
* features: the feature-vertex job at patch 15 (Section 4.4 classification),
* proxy: the level-of-detail proxy drawn while the camera moves (vertex clustering, server side),
* browser: from choosing the file in the page to the first frame drawn with its features; redraw
  times of the full model and of the proxy; frame interval while dragging with the mouse, and the
  return to full detail on release (Chromium with SwiftShader, i.e. software WebGL on the CPU: a
  GPU browser draws far faster; the numbers are upper bounds).
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


# the viewer's per-session token (every API request carries it), set when the server starts
_HEADERS: dict[str, str] = {}


def _post(url, data, ctype="application/octet-stream"):
    req = urllib.request.Request(url, data=data, headers={**_HEADERS, "Content-Type": ctype})
    with urllib.request.urlopen(req, timeout=600) as r:
        return json.loads(r.read())


def _get(url, timeout=600):
    return urllib.request.urlopen(urllib.request.Request(url, headers=_HEADERS), timeout=timeout)


def _wait(base, job):
    while True:
        with _get(f"{base}api/job/{job}", timeout=60) as r:
            j = json.loads(r.read())
        if j["state"] != "running":
            return j
        time.sleep(0.02)


def server_side(path: Path) -> dict:
    srv = ViewerServer([], port=0).start()
    _HEADERS.clear()
    _HEADERS.update(srv.api_headers)
    try:
        data = path.read_bytes()
        t = time.perf_counter()
        info = _post(srv.url + f"api/upload?name={path.name}", data)["model"]
        t_up = time.perf_counter() - t
        t = time.perf_counter()
        nbytes = 0
        for what in ("positions", "faces"):
            with _get(f"{srv.url}api/model/{info['id']}/{what}") as r:
                nbytes += len(r.read())
        t_tr = time.perf_counter() - t
        t = time.perf_counter()
        job = _post(
            srv.url + f"api/model/{info['id']}/features", b'{"patch": 15}', "application/json"
        )
        j = _wait(srv.url, job["job"])
        t_feat = time.perf_counter() - t
        assert j["state"] == "done", j
        t = time.perf_counter()
        with _get(f"{srv.url}api/model/{info['id']}/lod") as r:
            lod = json.loads(r.read())
        t_lod = time.perf_counter() - t
        return {
            "n": info["n_vertices"],
            "m": info["n_faces"],
            "file_mb": len(data) / 2**20,
            "upload": t_up,
            "transfer": t_tr,
            "transfer_mb": nbytes / 2**20,
            "features": t_feat,
            "n_features": j["result"]["n_features"],
            "lod": t_lod,
            "lod_size": (lod["n_vertices"], lod["n_faces"]),
        }
    finally:
        srv.stop()


DRAG = """async ([n, full]) => {
  // n synchronous redraws at each detail (each waited for with a pixel read-back)
  const S = window.__spectrageo;
  return { proxy: S.timeRender('proxy', n), full: full ? S.timeRender('full', 2) : null };
}"""


def _drag(pg, steps: int = 8) -> dict:
    """Drag the camera with the mouse: frame interval while dragging, then time to full detail."""
    box = pg.locator("#canvas").bounding_box()
    x, y = box["x"] + box["width"] * 0.25, box["y"] + box["height"] / 2
    pg.mouse.move(x, y)
    t_down = pg.evaluate("performance.now()")
    pg.mouse.down()
    details = []
    for i in range(steps):
        r = pg.evaluate("window.__spectrageo.renders")
        pg.mouse.move(x + 12 * (i + 1), y + 3 * (i % 3))
        pg.wait_for_function("r => window.__spectrageo.renders > r", arg=r)
        details.append(pg.evaluate("window.__spectrageo.detail"))
    log = pg.evaluate(
        "t => window.__spectrageo.renderLog.filter(([s, d]) => s > t && d === 'proxy')", t_down
    )
    t_up = pg.evaluate("performance.now()")
    nf = pg.evaluate("window.__spectrageo.rendersFull")
    pg.mouse.up()
    pg.wait_for_function("n => window.__spectrageo.rendersFull > n", arg=nf)
    t_full = pg.evaluate("performance.now()") - t_up
    ts = [t for t, _ in log]
    return {
        "drag_frame_ms": (ts[-1] - ts[0]) / max(len(ts) - 1, 1),
        "drag_details": sorted(set(details)),
        "settle_full_ms": t_full,
    }


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
            pg.wait_for_function("window.__spectrageo.lod !== null")
            pg.wait_for_function("r => window.__spectrageo.renders > r", arg=0)
            t_all = time.perf_counter() - t
            lod = pg.evaluate("[window.__spectrageo.lod.nVertices, window.__spectrageo.lod.nFaces]")
            sync = pg.evaluate(DRAG, [5, True])
            drag = _drag(pg)
            renderer = pg.evaluate("window.__spectrageo.gl")
            pg.close()
            # the same model with multisampling forced on (the setting before level of detail)
            pg = b.new_page(viewport={"width": 1280, "height": 720})
            pg.set_default_timeout(600_000)
            pg.goto(srv.url + "?aa=1")
            pg.wait_for_selector("body[data-ready='1']")
            pg.wait_for_function("window.__spectrageo.lod !== null")
            msaa = pg.evaluate(DRAG, [3, True])
            b.close()
        return {
            "first_view": t_geom,
            "with_features": t_all,
            "proxy_size": lod,
            "full_ms": sync["full"],
            "proxy_ms": sync["proxy"],
            "full_msaa_ms": msaa["full"],
            "proxy_msaa_ms": msaa["proxy"],
            "renderer": renderer,
            **drag,
        }
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

    b0 = next((b for *_, b in rows if b), None)
    lines = [
        "## Viewer: serving a 500k-vertex mesh",
        "",
        f"Machine: {machine_line()}. Regenerate with `python benchmarks/viewer.py`.",
        "",
        "Server: HTTP upload (read with `spectrageo.io.read`), raw float32/uint32 transfer of",
        "positions and faces, feature vertices at patch 15, and the level-of-detail proxy (vertex",
        "clustering to at most 100,000 faces, `spectrageo.viewer._lod`).",
        "",
        "| model | vertices / faces | file (MB) | upload+read (s) | transfer (s, MB) "
        "| features (s) | proxy vertices / faces | proxy build (s) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for label, name, s, _ in rows:
        pv, pf = s["lod_size"]
        lines.append(
            f"| {label} ({name}) | {s['n']:,} / {s['m']:,} | {s['file_mb']:.1f} | {s['upload']:.2f} "
            f"| {s['transfer']:.2f} ({s['transfer_mb']:.1f}) | {s['features']:.2f} "
            f"| {pv:,} / {pf:,} | {s['lod']:.2f} |"
        )
    lines += [
        "",
        "Browser: headless Chromium, 1280 x 720 page, both panels drawn every frame. The WebGL",
        f"renderer here is `{b0['renderer']['renderer'] if b0 else 'n/a'}`: software rasterisation on",
        "the CPU (SwiftShader), shared with everything else on this 2-core machine, so every",
        "redraw time below is far above what a GPU browser needs and varies by tens of percent",
        "between runs. *First view*: from choosing the file to the first drawn frame; *with",
        "features*: until the feature colours and the proxy are in. *Redraw*: mean of synchronous",
        "redraws (each waited for with a pixel read-back) of the full model and of the proxy drawn",
        "while the camera moves. *Drag frame*: mean interval between frames while dragging with the",
        "mouse (proxy; includes input handling). *Full after release*: from releasing the mouse",
        "to the full-detail redraw being issued (250 ms settle delay included). Multisampling is",
        "off on software renderers (the default since level of detail; GPUs keep it); the last two",
        "columns force it on (`?aa=1`, the setting before).",
        "",
        "| model | first view (s) | with features (s) | redraw full (ms) | redraw proxy (ms) "
        "| drag frame (ms) | full after release (ms) | full, MSAA (ms) | proxy, MSAA (ms) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for label, name, _, b in rows:
        if not b:
            lines.append(f"| {label} ({name}) | n/a | n/a | n/a | n/a | n/a | n/a | n/a | n/a |")
            continue
        lines.append(
            f"| {label} ({name}) | {b['first_view']:.2f} | {b['with_features']:.2f} "
            f"| {b['full_ms']:.0f} | {b['proxy_ms']:.0f} | {b['drag_frame_ms']:.0f} "
            f"| {b['settle_full_ms']:.0f} | {b['full_msaa_ms']:.0f} | {b['proxy_msaa_ms']:.0f} |"
        )
    if not any(b for *_, b in rows):
        lines += ["", "Browser columns: n/a (Playwright or Chromium not installed)."]
    write_section("viewer", "\n".join(lines))


if __name__ == "__main__":
    main()
