"""Synthetic single-view scans of cluttered tabletop scenes with ground truth (Section 6.2.8).

Models at random poses on the plane ``z = 0`` with clutter are sampled by area, kept by a depth
buffer of a pinhole camera (pixels far behind their 3 x 3 neighbourhood dropped) and moved along
their rays by range noise; ``occlusion = 1 - visible fraction`` as in the UWA data set.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.ndimage import minimum_filter

from .._errors import InvalidInputError

CLUTTER_LABEL = -2
PLANE_LABEL = -1


@dataclass(frozen=True)
class Scene:
    """A generated scan: ``points``, ``labels`` (object, -1 plane, -2 clutter), ``model_index``,
    ``names``, model-to-scene ``poses``, ``visible_fraction``, ``occlusion``, ``viewpoint`` and
    ``pixel_size``.
    """

    points: np.ndarray
    labels: np.ndarray
    model_index: np.ndarray
    names: tuple
    poses: np.ndarray
    visible_fraction: np.ndarray
    occlusion: np.ndarray
    viewpoint: np.ndarray
    pixel_size: float

    @property
    def n_objects(self) -> int:
        return int(self.poses.shape[0])


def _load_mesh(m, i: int):
    """``(name, V, F)`` of a model given as a path, a Mesh, a trimesh or a ``(V, F)`` pair."""
    from .. import io
    from .._validation import as_faces, as_points

    if isinstance(m, str | Path):
        p = Path(m)
        if not p.is_file():
            raise InvalidInputError(f"`models[{i}]`: file not found: {m}")
        g = io.read(p)
        V, F = getattr(g, "vertices", None), getattr(g, "faces", None)
        if F is None or len(F) == 0:
            raise InvalidInputError(f"`models[{i}]`: {p.name} has no faces; a mesh is needed.")
        name = p.name.split(".")[0]
    elif hasattr(m, "vertices") and hasattr(m, "faces"):
        V, F, name = m.vertices, m.faces, f"model{i}"
    elif isinstance(m, tuple) and len(m) == 2:
        V, F, name = m[0], m[1], f"model{i}"
    else:
        raise InvalidInputError(
            f"`models[{i}]` must be a mesh path, a Mesh or a (V, F) pair; got {type(m).__name__}."
        )
    V = as_points(V, f"models[{i}] vertices")
    F = as_faces(F, V.shape[0], f"models[{i}] faces")
    if F.shape[0] == 0:
        raise InvalidInputError(f"`models[{i}]` has no faces.")
    return name, V, F


def random_rotation(rng) -> np.ndarray:
    """A uniformly distributed rotation (3, 3) (normalised Gaussian quaternion)."""
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _sample_surface(V, F, count: int, rng) -> np.ndarray:
    """``count`` points uniform by area on the triangles (V, F)."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    cdf = np.cumsum(area)
    f = np.searchsorted(cdf, rng.random(count) * cdf[-1], side="right")
    f = np.minimum(f, F.shape[0] - 1)
    r1, r2 = rng.random(count), rng.random(count)
    s = np.sqrt(r1)
    u, v = 1 - s, s * (1 - r2)
    return u[:, None] * a[f] + v[:, None] * b[f] + (1 - u - v)[:, None] * c[f]


def _clutter_mesh(kind: int, size: float, rng):
    import trimesh

    if kind == 0:
        m = trimesh.creation.box(extents=size * rng.uniform(0.3, 0.9, 3))
    elif kind == 1:
        m = trimesh.creation.cylinder(radius=size * rng.uniform(0.15, 0.35), height=size * rng.uniform(0.3, 0.9), sections=24)  # fmt: skip
    else:
        m = trimesh.creation.icosphere(subdivisions=2, radius=size * rng.uniform(0.15, 0.35))
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


def _occlusion_range(occlusion) -> tuple[float, float]:
    if isinstance(occlusion, int | float | np.floating) and not isinstance(occlusion, bool):
        t = float(occlusion)
        lo, hi = t - 0.1, t + 0.1
    else:
        try:
            lo, hi = (float(x) for x in occlusion)
        except (TypeError, ValueError):
            raise InvalidInputError(
                f"`occlusion` must be a number or a (low, high) pair; got {occlusion!r}."
            ) from None
    if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi and hi >= 0 and lo <= 1):
        raise InvalidInputError(f"`occlusion` must give 0 <= low <= high <= 1; got {occlusion!r}.")
    return max(lo, 0.0), min(hi, 1.0)


def make_scene(
    models,
    *,
    n_objects: int = 4,
    occlusion=(0.5, 0.9),
    clutter: int = 2,
    noise: float = 0.3,
    image_size: tuple[int, int] = (640, 480),
    oversample: float = 8.0,
    max_tries: int = 8,
    rng=0,
) -> Scene:
    """Single-view scan of ``n_objects`` distinct ``models`` on a plane with ``clutter`` primitives.

    ``occlusion`` (low, high) or ``t`` (``t +- 0.1``) is the wanted range; up to ``max_tries``
    layouts are drawn and the first in range (else the best) kept. ``noise`` is the range noise in
    pixel footprints, ``image_size`` (width, height), ``oversample`` samples per pixel. Returns a
    :class:`Scene`.
    """
    if isinstance(models, dict):
        items = [(str(k), v) for k, v in models.items()]
    elif isinstance(models, list | tuple):
        items = [(None, v) for v in models]
    else:
        raise InvalidInputError(f"`models` must be a list or a dict; got {type(models).__name__}.")
    if not items:
        raise InvalidInputError("`models` is empty.")
    if isinstance(n_objects, bool) or not isinstance(n_objects, int | np.integer):
        raise InvalidInputError(f"`n_objects` must be an integer; got {n_objects!r}.")
    if not 1 <= n_objects <= len(items):
        raise InvalidInputError(
            f"`n_objects` must be in [1, {len(items)}] (the number of models); got {n_objects}."
        )
    if isinstance(clutter, bool) or not isinstance(clutter, int | np.integer) or clutter < 0:
        raise InvalidInputError(f"`clutter` must be a non-negative integer; got {clutter!r}.")
    if not (isinstance(noise, int | float) and np.isfinite(noise) and noise >= 0):
        raise InvalidInputError(f"`noise` must be a finite number >= 0; got {noise!r}.")
    try:
        W, H = (int(x) for x in image_size)
    except (TypeError, ValueError):
        raise InvalidInputError(
            f"`image_size` must be (width, height); got {image_size!r}."
        ) from None
    if not (16 <= W <= 4096 and 16 <= H <= 4096):
        raise InvalidInputError(
            f"`image_size` must lie in [16, 4096] per side; got {image_size!r}."
        )
    lo, hi = _occlusion_range(occlusion)
    meshes = []
    for i, (key, m) in enumerate(items):
        name, V, F = _load_mesh(m, i)
        meshes.append((key or name, V, F))
    g = np.random.default_rng(rng)
    best, best_score = None, -1
    for _ in range(max(1, int(max_tries))):
        sc = _one_scene(meshes, n_objects, clutter, float(noise), W, H, float(oversample), g)
        score = int(((sc.occlusion >= lo) & (sc.occlusion <= hi)).sum())
        if score > best_score:
            best, best_score = sc, score
        if score == n_objects:
            break
    return best


def _one_scene(meshes, n_objects, n_clutter, noise, W, H, oversample, g) -> Scene:
    chosen = np.sort(g.choice(len(meshes), n_objects, replace=False))
    objs = []  # (V_world, F, label, pose or None)
    sizes = []
    for j, mi in enumerate(chosen):
        _, V, F = meshes[mi]
        R = random_rotation(g)
        c = 0.5 * (V.min(0) + V.max(0))
        Vr = (V - c) @ R.T
        objs.append([Vr, F, j, R, c])
        sizes.append(float(np.linalg.norm(np.ptp(V, axis=0))))
    mean_size = float(np.mean(sizes))
    for _ in range(n_clutter):
        Vc, Fc = _clutter_mesh(int(g.integers(3)), mean_size, g)
        Vr = Vc @ random_rotation(g).T
        objs.append([Vr, Fc, CLUTTER_LABEL, None, None])
    # layout: footprint circles, placed one by one in a disc that grows when crowded
    radii = np.array(
        [np.linalg.norm(o[0][:, :2] - o[0][:, :2].mean(0), axis=1).max() for o in objs]
    )
    R_disc = 0.9 * np.sqrt((radii**2).sum())
    centers = []
    for r in radii:
        for attempt in range(400):
            rr = R_disc * (1 + 0.02 * (attempt // 50)) * np.sqrt(g.random())
            th = 2 * np.pi * g.random()
            p = np.array([rr * np.cos(th), rr * np.sin(th)])
            if all(np.linalg.norm(p - q) >= 0.95 * (r + rq) for q, rq in zip(centers, radii)):
                break
        centers.append(p)
    scene_r = float(max(np.linalg.norm(c) + r for c, r in zip(centers, radii)))
    poses = np.zeros((n_objects, 4, 4))
    for o, p in zip(objs, centers):
        shift = np.r_[p - o[0][:, :2].mean(0), -o[0][:, 2].min()]
        o[0] = o[0] + shift
        if o[3] is not None:
            T = np.eye(4)
            T[:3, :3] = o[3]
            T[:3, 3] = shift - o[3] @ o[4]
            poses[o[2]] = T
    height = float(max(o[0][:, 2].max() for o in objs))
    # camera: random azimuth, elevation 30-55 degrees, looking at the scene centre
    az, el = 2 * np.pi * g.random(), np.deg2rad(g.uniform(30, 55))
    target = np.array([0.0, 0.0, 0.3 * height])
    dist = 2.2 * scene_r + height
    eye = target + dist * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    fwd = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    Rc = np.stack([right, -up, fwd])  # world -> camera (x right, y down, z forward)
    half = 0.95 * scene_r
    f = 0.5 * min(W, H) / (half / dist)
    cx, cy = 0.5 * W, 0.5 * H
    pix_at = 1.0 / f  # footprint per unit depth

    def project(X):
        Xc = (X - eye) @ Rc.T
        z = Xc[:, 2]
        ok = z > 1e-9
        u = np.floor(f * Xc[:, 0] / np.where(ok, z, 1) + cx).astype(np.int64)
        v = np.floor(f * Xc[:, 1] / np.where(ok, z, 1) + cy).astype(np.int64)
        ok &= (u >= 0) & (u < W) & (v >= 0) & (v < H)
        return v * W + u, np.linalg.norm(X - eye, axis=1), ok

    samples, owner, sobj = [], [], []
    for k, o in enumerate(objs):
        V, F = o[0], o[1]
        a = V[F]
        area = 0.5 * np.linalg.norm(np.cross(a[:, 1] - a[:, 0], a[:, 2] - a[:, 0]), axis=1).sum()
        zc = np.linalg.norm(V.mean(0) - eye)
        count = int(min(1_500_000, max(2000, oversample * area / (zc * pix_at) ** 2)))
        samples.append(_sample_surface(V, F, count, g))
        owner.append(np.full(count, o[2], dtype=np.int64))
        sobj.append(np.full(count, k, dtype=np.int64))
    S = np.concatenate(samples)
    lab = np.concatenate(owner)
    obj_of = np.concatenate(sobj)
    pix, depth, ok = project(S)
    # plane z = 0 (square around the layout), intersected exactly with every pixel ray
    uu, vv = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
    dirs_c = np.stack([(uu - cx) / f, (vv - cy) / f, np.ones_like(uu)], -1).reshape(-1, 3)
    dirs = dirs_c @ Rc
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        tpl = -eye[2] / dirs[:, 2]
    Xp = eye + tpl[:, None] * dirs
    side = 1.15 * scene_r
    on_plane = (tpl > 0) & (np.abs(Xp[:, 0]) <= side) & (np.abs(Xp[:, 1]) <= side)
    D = np.full(W * H, np.inf)
    D[on_plane] = tpl[on_plane]
    win = np.full(W * H, -1, dtype=np.int64)  # -1: plane (or empty when D is inf)
    # depth buffer: nearest sample per pixel
    idx = np.flatnonzero(ok)
    order = np.lexsort((depth[idx], pix[idx]))
    idx = idx[order]
    first = np.r_[True, pix[idx][1:] != pix[idx][:-1]]
    cand = idx[first]
    closer = depth[cand] < D[pix[cand]]
    D[pix[cand[closer]]] = depth[cand[closer]]
    win[pix[cand[closer]]] = cand[closer]
    # drop see-through pixels: far behind the nearest depth of their 3 x 3 neighbourhood
    Dimg = D.reshape(H, W)
    Dmin = minimum_filter(np.where(np.isfinite(Dimg), Dimg, 1e300), size=3, mode="nearest")
    gap = 0.03 * mean_size
    valid = np.isfinite(Dimg) & (Dimg <= Dmin + gap)
    valid = valid.ravel()
    pv = np.flatnonzero(valid)
    w = win[pv]
    pts = np.where((w >= 0)[:, None], S[np.maximum(w, 0)], Xp[pv])
    labels = np.where(w >= 0, lab[np.maximum(w, 0)], PLANE_LABEL)
    ray = pts - eye
    rng_d = np.linalg.norm(ray, axis=1)
    ray /= rng_d[:, None]
    if noise > 0:
        pts = pts + ray * (g.normal(size=rng_d.size) * noise * rng_d * pix_at)[:, None]
    # visible area fraction: samples within a footprint-scaled tolerance of the kept depth
    Dv = np.where(valid, D, -np.inf)
    vis = ok & (depth <= Dv[np.where(ok, pix, 0)] + 3.0 * depth * pix_at)
    vis &= np.where(ok, win[np.where(ok, pix, 0)] >= 0, False)
    vis &= obj_of == obj_of[np.maximum(win[np.where(ok, pix, 0)], 0)]
    visible = np.zeros(n_objects)
    for j in range(n_objects):
        m = lab == j
        visible[j] = float(vis[m].mean()) if m.any() else 0.0
    names = tuple(meshes[mi][0] for mi in chosen)
    return Scene(
        points=np.ascontiguousarray(pts),
        labels=labels.astype(np.int64),
        model_index=chosen.astype(np.int64),
        names=names,
        poses=poses,
        visible_fraction=visible,
        occlusion=1.0 - visible,
        viewpoint=eye,
        pixel_size=float(dist * pix_at),
    )


__all__ = ["Scene", "make_scene", "random_rotation"]
