"""Shared helpers of the outlier evaluations: scores of removed points, peers, oracle cuts."""

from __future__ import annotations

import numpy as np

#: ``pcl-sor``: the statistical filter at the setting of PCL's outlier-removal tutorial
#: (``setMeanK(50)``, ``setStddevMulThresh(1.0)``; the algorithm of our ``sor``, exactly).
PCL_MEAN_K = 50


def _prf(removed: np.ndarray, labels: np.ndarray) -> tuple[float, float, float]:
    tp = int(np.count_nonzero(removed & labels))
    p = tp / max(int(np.count_nonzero(removed)), 1)
    r = tp / max(int(np.count_nonzero(labels)), 1)
    return p, r, (2 * p * r / (p + r) if p + r > 0 else 0.0)


def _open3d_sor(P: np.ndarray, k: int, std_ratio: float) -> np.ndarray:
    import open3d as o3d

    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(P))
    _, ind = pc.remove_statistical_outlier(nb_neighbors=k, std_ratio=std_ratio)
    keep = np.zeros(P.shape[0], dtype=bool)
    keep[np.asarray(ind, dtype=np.int64)] = True
    return keep


def _have_open3d() -> bool:
    try:
        import open3d  # noqa: F401
    except Exception:  # noqa: BLE001 - missing shared libraries raise OSError, not ImportError
        return False
    return True


def _oracle_threshold(scores: np.ndarray, labels: np.ndarray) -> float:
    """The threshold ``tau`` (remove ``score >= tau``) of best F1, chosen with the labels."""
    o = np.argsort(-scores, kind="stable")
    s = scores[o]
    tp = np.cumsum(labels[o])
    f1 = 2.0 * tp / (np.arange(1, s.size + 1) + max(int(np.count_nonzero(labels)), 1))
    # only cut between distinct scores: removing the top i+1 points must be a threshold
    valid = np.append(s[1:] < s[:-1], True)
    i = int(np.argmax(np.where(valid, f1, -1.0)))
    return float(s[i])


def _row(base: dict, method: str, params: str, removed, labels, dt: float) -> dict:
    removed = np.asarray(removed, bool)
    p, r, f = _prf(removed, labels)
    extra = {"flagged": round(float(removed.mean()), 4)} if base.get("kind") == "clean" else {}
    return {
        **base,
        **extra,
        "method": method,
        "params": params,
        "precision": round(p, 4),
        "recall": round(r, 4),
        "f1": round(f, 4),
        "time_s": round(dt, 3),
    }
