"""Sequential kernels that cannot be vectorised with numpy."""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def propagate_signs(
    N: np.ndarray, child: np.ndarray, par: np.ndarray
) -> None:  # pragma: no cover - jitted
    """Flip ``N[child[t]]`` to agree with ``N[par[t]]``, in order (BFS order of a spanning tree)."""
    for t in range(child.shape[0]):
        c = child[t]
        p = par[t]
        d = N[c, 0] * N[p, 0] + N[c, 1] * N[p, 1] + N[c, 2] * N[p, 2]
        if d < 0:
            N[c, 0] = -N[c, 0]
            N[c, 1] = -N[c, 1]
            N[c, 2] = -N[c, 2]


@numba.njit(cache=True)
def vertex_update_kernel(V, F, N, inv_deg, n_iter):  # pragma: no cover - jitted
    """``n_iter`` in-place steps of Eq. (4.28) (one pass over the faces each); ``inv_deg`` 0 = fixed."""
    n = V.shape[0]
    m = F.shape[0]
    delta = np.empty((n, 3))
    for _ in range(n_iter):
        delta[:, :] = 0.0
        for j in range(m):
            a = F[j, 0]
            b = F[j, 1]
            c = F[j, 2]
            c0 = (V[a, 0] + V[b, 0] + V[c, 0]) / 3.0
            c1 = (V[a, 1] + V[b, 1] + V[c, 1]) / 3.0
            c2 = (V[a, 2] + V[b, 2] + V[c, 2]) / 3.0
            n0 = N[j, 0]
            n1 = N[j, 1]
            n2 = N[j, 2]
            for t in range(3):
                v = F[j, t]
                p = n0 * (c0 - V[v, 0]) + n1 * (c1 - V[v, 1]) + n2 * (c2 - V[v, 2])
                delta[v, 0] += p * n0
                delta[v, 1] += p * n1
                delta[v, 2] += p * n2
        for i in range(n):
            s = inv_deg[i]
            V[i, 0] += delta[i, 0] * s
            V[i, 1] += delta[i, 1] * s
            V[i, 2] += delta[i, 2] * s
    return V


@numba.njit(cache=True, nogil=True)
def jacobi3(a00, a11, a22, a01, a02, a12):  # pragma: no cover - compiled
    """``(A, V)``: cyclic Jacobi of a symmetric 3x3 matrix; eigenvalues on the diagonal of ``A``,
    unit eigenvectors in the columns of ``V``, unsorted.
    """
    A = np.empty((3, 3))
    A[0, 0], A[1, 1], A[2, 2] = a00, a11, a22
    A[0, 1] = A[1, 0] = a01
    A[0, 2] = A[2, 0] = a02
    A[1, 2] = A[2, 1] = a12
    V = np.eye(3)
    for _ in range(30):
        off = A[0, 1] ** 2 + A[0, 2] ** 2 + A[1, 2] ** 2
        diag = A[0, 0] ** 2 + A[1, 1] ** 2 + A[2, 2] ** 2
        if off == 0.0 or off <= 1e-30 * diag:
            break
        for p, q in ((0, 1), (0, 2), (1, 2)):
            apq = A[p, q]
            if apq == 0.0:
                continue
            theta = (A[q, q] - A[p, p]) / (2.0 * apq)
            t = 1.0 / (abs(theta) + np.sqrt(theta * theta + 1.0))
            if theta < 0.0:
                t = -t
            c = 1.0 / np.sqrt(t * t + 1.0)
            s = t * c
            A[p, p] -= t * apq
            A[q, q] += t * apq
            A[p, q] = A[q, p] = 0.0
            r = 3 - p - q
            arp, arq = A[r, p], A[r, q]
            A[r, p] = A[p, r] = c * arp - s * arq
            A[r, q] = A[q, r] = s * arp + c * arq
            for i in range(3):
                vip, viq = V[i, p], V[i, q]
                V[i, p] = c * vip - s * viq
                V[i, q] = s * vip + c * viq
    return A, V


@numba.njit(cache=True, nogil=True)
def min_eigvec3(a00, a11, a22, a01, a02, a12):  # pragma: no cover - compiled
    """``(lambda_min, x, y, z)`` of a symmetric 3x3 matrix (:func:`jacobi3`)."""
    A, V = jacobi3(a00, a11, a22, a01, a02, a12)
    j = 0
    if A[1, 1] < A[j, j]:
        j = 1
    if A[2, 2] < A[j, j]:
        j = 2
    return A[j, j], V[0, j], V[1, j], V[2, j]


@numba.njit(cache=True, nogil=True)
def patch_covariance(P, row):  # pragma: no cover - jitted
    """Entries ``(cxx, cyy, czz, cxy, cxz, cyz)`` of the covariance of ``P[row]``."""
    k = row.shape[0]
    mx = 0.0
    my = 0.0
    mz = 0.0
    for q in range(k):
        j = row[q]
        mx += P[j, 0]
        my += P[j, 1]
        mz += P[j, 2]
    mx /= k
    my /= k
    mz /= k
    cxx = 0.0
    cyy = 0.0
    czz = 0.0
    cxy = 0.0
    cxz = 0.0
    cyz = 0.0
    for q in range(k):
        j = row[q]
        dx = P[j, 0] - mx
        dy = P[j, 1] - my
        dz = P[j, 2] - mz
        cxx += dx * dx
        cyy += dy * dy
        czz += dz * dz
        cxy += dx * dy
        cxz += dx * dz
        cyz += dy * dz
    return cxx / k, cyy / k, czz / k, cxy / k, cxz / k, cyz / k


@numba.njit(cache=True, parallel=True)
def patch_min_variance(P, idx, lam, dirs):  # pragma: no cover - jitted
    """Smallest covariance eigenvalue ``lam[i]`` and its direction ``dirs[i]`` of ``P[idx[i]]``."""
    for i in numba.prange(idx.shape[0]):
        cxx, cyy, czz, cxy, cxz, cyz = patch_covariance(P, idx[i])
        w, x, y, z = min_eigvec3(cxx, cyy, czz, cxy, cxz, cyz)
        lam[i] = w
        dirs[i, 0] = x
        dirs[i, 1] = y
        dirs[i, 2] = z


@numba.njit(cache=True, parallel=True)
def patch_quadric_residual(P, idx, dirs, res, spread):  # pragma: no cover - jitted
    """Residual variance ``RSS / (k - 6)`` of the quadric height field fitted to
    ``P[idx[i]]`` along ``dirs[i]`` (``inf`` below 7 points or for coincident points), and the
    tangent ``spread`` (docs/decisions.md#geometry-quadric-spread).
    """
    k = idx.shape[1]
    for i in numba.prange(idx.shape[0]):
        if k < 7:
            res[i] = np.inf
            spread[i] = 0.0
            continue
        nx, ny, nz = dirs[i, 0], dirs[i, 1], dirs[i, 2]
        # tangent frame: t1 orthogonal to n, t2 = n x t1
        if abs(nx) < 0.9:
            ax, ay, az = 1.0, 0.0, 0.0
        else:
            ax, ay, az = 0.0, 1.0, 0.0
        d = ax * nx + ay * ny + az * nz
        t1x, t1y, t1z = ax - d * nx, ay - d * ny, az - d * nz
        s = np.sqrt(t1x * t1x + t1y * t1y + t1z * t1z)
        t1x /= s
        t1y /= s
        t1z /= s
        t2x = ny * t1z - nz * t1y
        t2y = nz * t1x - nx * t1z
        t2z = nx * t1y - ny * t1x
        o = idx[i, 0]
        X = np.empty(k)
        Y = np.empty(k)
        Z = np.empty(k)
        scale = 0.0
        for q in range(k):
            j = idx[i, q]
            dx = P[j, 0] - P[o, 0]
            dy = P[j, 1] - P[o, 1]
            dz = P[j, 2] - P[o, 2]
            X[q] = dx * t1x + dy * t1y + dz * t1z
            Y[q] = dx * t2x + dy * t2y + dz * t2z
            Z[q] = dx * nx + dy * ny + dz * nz
            scale += X[q] * X[q] + Y[q] * Y[q]
        scale = np.sqrt(scale / k)
        if not scale > 0.0:
            res[i] = np.inf
            spread[i] = 0.0
            continue
        sxx = 0.0
        syy = 0.0
        sxy = 0.0
        for q in range(k):
            sxx += X[q] * X[q]
            syy += Y[q] * Y[q]
            sxy += X[q] * Y[q]
        half_tr = 0.5 * (sxx + syy)
        disc = np.sqrt(max(half_tr * half_tr - (sxx * syy - sxy * sxy), 0.0))
        spread[i] = (half_tr - disc) / (half_tr + disc) if half_tr + disc > 0 else 0.0
        A = np.empty((k, 6))
        for q in range(k):
            x = X[q] / scale
            y = Y[q] / scale
            A[q, 0] = x * x
            A[q, 1] = x * y
            A[q, 2] = y * y
            A[q, 3] = x
            A[q, 4] = y
            A[q, 5] = 1.0
        M = A.T @ A
        b = A.T @ Z
        tr = 0.0
        for r in range(6):
            tr += M[r, r]
        for r in range(6):
            M[r, r] += 1e-10 * tr
        coef = np.linalg.solve(M, b)
        rss = 0.0
        for q in range(k):
            e = Z[q]
            for r in range(6):
                e -= A[q, r] * coef[r]
            rss += e * e
        res[i] = rss / (k - 6)


@numba.njit(cache=True)
def neighbour_median_residual(indptr, indices, r, s):  # pragma: no cover - jitted
    """``s[i] = r[i] - median(r[N(i)])`` over a CSR adjacency (0 when isolated)."""
    n = r.shape[0]
    for i in range(n):
        a, b = indptr[i], indptr[i + 1]
        if b == a:
            s[i] = 0.0
            continue
        vals = np.empty(b - a)
        for t in range(a, b):
            vals[t - a] = r[indices[t]]
        s[i] = r[i] - np.median(vals)


@numba.njit(cache=True)
def isolated_spikes(indptr, indices, s, thr, iso, flag):  # pragma: no cover - jitted
    """Flag vertices whose ``|s[i]| > thr`` dominates their neighbours (Eq. N7 of
    :mod:`spectrageo.denoise._guard`); returns the count.
    """
    n = s.shape[0]
    cnt = 0
    for i in range(n):
        a = abs(s[i])
        ok = a > thr and indptr[i + 1] > indptr[i]
        if ok:
            for t in range(indptr[i], indptr[i + 1]):
                b = s[indices[t]]
                if abs(b) >= a or (b * s[i] > 0 and abs(b) >= iso * a):
                    ok = False
                    break
        flag[i] = ok
        if ok:
            cnt += 1
    return cnt


@numba.njit(cache=True)
def few_face_planes(vf_ptr, vf_idx, FN, sel, cos_tol, max_planes, out):  # pragma: no cover - jitted
    """``out[t]``: the faces around ``sel[t]`` have at most ``max_planes`` distinct normals
    (cosine above ``cos_tol``) while being more: a vertex on a crease of planar parts.
    """
    reps = np.empty((max_planes + 1, 3))
    for t in range(sel.shape[0]):
        i = sel[t]
        a, b = vf_ptr[i], vf_ptr[i + 1]
        if b - a <= max_planes:
            out[t] = False
            continue
        nr = 0
        for q in range(a, b):
            f = vf_idx[q]
            found = False
            for c in range(nr):
                if FN[f, 0] * reps[c, 0] + FN[f, 1] * reps[c, 1] + FN[f, 2] * reps[c, 2] > cos_tol:
                    found = True
                    break
            if not found:
                if nr == max_planes:
                    nr += 1
                    break
                reps[nr, 0] = FN[f, 0]
                reps[nr, 1] = FN[f, 1]
                reps[nr, 2] = FN[f, 2]
                nr += 1
        out[t] = nr <= max_planes


@numba.njit(cache=True)
def jacobi_rotate(app, aqq, apq, arp, arq):  # pragma: no cover - jitted
    """One Jacobi rotation zeroing ``a_pq`` of a symmetric 3x3 matrix (``r`` the third index)."""
    tau = (aqq - app) / (2.0 * apq)
    if abs(tau) > 1e150:
        t = 0.5 / tau
    else:
        t = 1.0 / (abs(tau) + np.sqrt(1.0 + tau * tau))
        if tau < 0:
            t = -t
    c = 1.0 / np.sqrt(1.0 + t * t)
    s = t * c
    return app - t * apq, aqq + t * apq, c * arp - s * arq, s * arp + c * arq


@numba.njit(cache=True)
def max_sq_distance(N, i, members, j):  # pragma: no cover - jitted
    """``max_q ||N[i] - N[members[j, q]]||^2``, the spread of a normal patch (Eq. 4.10 / 5.17)."""
    best = 0.0
    for q in range(members.shape[1]):
        g = members[j, q]
        d0 = N[i, 0] - N[g, 0]
        d1 = N[i, 1] - N[g, 1]
        d2 = N[i, 2] - N[g, 2]
        d = d0 * d0 + d1 * d1 + d2 * d2
        if d > best:
            best = d
    return best


@numba.njit(cache=True)
def patch_moments(N, nb_sorted):  # pragma: no cover - jitted
    """Entries [xx, yy, zz, xy, xz, yz] of ``R_i = N_i^T N_i / k`` per patch, float64, summed
    in the order of ``nb_sorted``.
    """
    m, k = nb_sorted.shape
    out = np.zeros((m, 6))
    for i in range(m):
        a0 = 0.0
        a1 = 0.0
        a2 = 0.0
        a3 = 0.0
        a4 = 0.0
        a5 = 0.0
        for q in range(k):
            g = nb_sorted[i, q]
            x = np.float64(N[g, 0])
            y = np.float64(N[g, 1])
            z = np.float64(N[g, 2])
            a0 += x * x
            a1 += y * y
            a2 += z * z
            a3 += x * y
            a4 += x * z
            a5 += y * z
        out[i, 0] = a0 / k
        out[i, 1] = a1 / k
        out[i, 2] = a2 / k
        out[i, 3] = a3 / k
        out[i, 4] = a4 / k
        out[i, 5] = a5 / k
    return out


@numba.njit(cache=True, parallel=True)
def patch_bimodality(N, nb, S):  # pragma: no cover - jitted
    """Sarle's bimodality coefficient ``(g^2 + 1) / kappa`` of each patch projected on the
    middle eigenvector of its moments ``S[i]`` (1 two-valued, 5/9 uniform, 1/3 Gaussian, 0 constant).
    """
    m, k = nb.shape
    out = np.zeros(m)
    for i in numba.prange(m):
        A, V = jacobi3(S[i, 0], S[i, 1], S[i, 2], S[i, 3], S[i, 4], S[i, 5])
        lo = 0
        hi = 0
        for j in range(1, 3):
            if A[j, j] < A[lo, lo]:
                lo = j
            if A[j, j] >= A[hi, hi]:
                hi = j
        mid = 3 - lo - hi if lo != hi else 1
        ex, ey, ez = V[0, mid], V[1, mid], V[2, mid]
        mean = 0.0
        for q in range(k):
            g = nb[i, q]
            mean += N[g, 0] * ex + N[g, 1] * ey + N[g, 2] * ez
        mean /= k
        m2 = 0.0
        m3 = 0.0
        m4 = 0.0
        for q in range(k):
            g = nb[i, q]
            d = N[g, 0] * ex + N[g, 1] * ey + N[g, 2] * ez - mean
            d2 = d * d
            m2 += d2
            m3 += d2 * d
            m4 += d2 * d2
        m2 /= k
        m3 /= k
        m4 /= k
        if m2 > 1e-24 and m4 > 0.0:
            out[i] = (m3 * m3 + m2 * m2 * m2) / (m4 * m2)
    return out


@numba.njit(cache=True, parallel=True)
def sym3_eigenvalues(S):  # pragma: no cover - jitted
    """Ascending eigenvalues of (m, 6) symmetric 3x3 matrices by cyclic Jacobi, backward
    stable also for the repeated eigenvalues of flat patches.
    """
    m = S.shape[0]
    out = np.empty((m, 3))
    for i in numba.prange(m):
        a00 = S[i, 0]
        a11 = S[i, 1]
        a22 = S[i, 2]
        a01 = S[i, 3]
        a02 = S[i, 4]
        a12 = S[i, 5]
        for _ in range(30):
            off = a01 * a01 + a02 * a02 + a12 * a12
            diag = a00 * a00 + a11 * a11 + a22 * a22
            if off == 0.0 or off <= 1e-36 * diag:
                break
            if a01 != 0.0:  # (p, q, r) = (0, 1, 2)
                a00, a11, a02, a12 = jacobi_rotate(a00, a11, a01, a02, a12)
                a01 = 0.0
            if a02 != 0.0:  # (0, 2, 1)
                a00, a22, a01, a12 = jacobi_rotate(a00, a22, a02, a01, a12)
                a02 = 0.0
            if a12 != 0.0:  # (1, 2, 0)
                a11, a22, a01, a02 = jacobi_rotate(a11, a22, a12, a01, a02)
                a12 = 0.0
        lo = min(a00, min(a11, a22))
        hi = max(a00, max(a11, a22))
        out[i, 0] = lo
        out[i, 1] = max(min(a00, a11), min(max(a00, a11), a22))
        out[i, 2] = hi
    return out
