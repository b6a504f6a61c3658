"""The compiled kernels of the kinematic chain (``planecal.model.kinematics``) and of the
laser distance and its Jacobian (``planecal.model.measurement``), compiled by numba and
cached on disk. Plain loops over samples and joints with scalar locals; the chain is
passed packed: ``K`` (n, 11) alpha, a, beta, theta, d, cos alpha, sin alpha, cos beta,
sin beta, cos theta, sin theta per joint (``Kinematics.packed``: the fixed angles' sines
are taken once, not per sample), ``B`` the base and ``F`` the flange frame (4x4). The
joint variables come as their cosines and sines (``trig``), and cos(theta + q) is formed by
the angle sum: a fit evaluates the model at the same joints every iteration, so it takes
the sines once (``distance``), which is most of a sample's cost.

One joint, from frame j-1 (axes x, y, z, origin p, in the cell frame):
    Rx(alpha): y, z <- ca y + sa z, ca z - sa y       (x stays)
    Tx(a):     c = p + a x                             (the point on joint j's axis)
    Ry(beta):  x, z <- cb x - sb z, sb x + cb z        (y' = y: the beta axis)
    Rz(theta + q): x, y <- ct x + st y, ct y - st x    (z: joint j's axis)
    Tz(d):     p <- c + d z
``_walk`` does it for one row of joint angles (their cosines c and sines s) and keeps, per joint, in ``S[j]`` (15): x
and p of frame j-1, the beta axis y', the point c and the axis z.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from planecal.base.paths import numba_cache

numba_cache()  # in planecal's cache folder, not beside this file in site-packages

JIT = dict(cache=True, error_model="numpy")


@njit(inline="always", **JIT)
def _walk(K, B, c, s, S):
    """The chain at joint angles q (n,), given as c = cos q and s = sin q, from the base B;
    per joint its terms into S (n, 15); returns the last frame's axes and origin (12
    scalars)."""
    x0, x1, x2 = B[0, 0], B[1, 0], B[2, 0]
    y0, y1, y2 = B[0, 1], B[1, 1], B[2, 1]
    z0, z1, z2 = B[0, 2], B[1, 2], B[2, 2]
    p0, p1, p2 = B[0, 3], B[1, 3], B[2, 3]
    for j in range(K.shape[0]):
        a, d = K[j, 1], K[j, 4]
        ca, sa, cb, sb = K[j, 5], K[j, 6], K[j, 7], K[j, 8]
        S[j, 0], S[j, 1], S[j, 2] = x0, x1, x2
        S[j, 3], S[j, 4], S[j, 5] = p0, p1, p2
        y0, z0 = ca * y0 + sa * z0, ca * z0 - sa * y0
        y1, z1 = ca * y1 + sa * z1, ca * z1 - sa * y1
        y2, z2 = ca * y2 + sa * z2, ca * z2 - sa * y2
        p0, p1, p2 = p0 + a * x0, p1 + a * x1, p2 + a * x2
        S[j, 6], S[j, 7], S[j, 8] = y0, y1, y2
        S[j, 9], S[j, 10], S[j, 11] = p0, p1, p2
        x0, z0 = cb * x0 - sb * z0, sb * x0 + cb * z0
        x1, z1 = cb * x1 - sb * z1, sb * x1 + cb * z1
        x2, z2 = cb * x2 - sb * z2, sb * x2 + cb * z2
        ct = c[j] * K[j, 9] - s[j] * K[j, 10]  # cos(theta + q), sin(theta + q)
        st = s[j] * K[j, 9] + c[j] * K[j, 10]
        x0, y0 = ct * x0 + st * y0, ct * y0 - st * x0
        x1, y1 = ct * x1 + st * y1, ct * y1 - st * x1
        x2, y2 = ct * x2 + st * y2, ct * y2 - st * x2
        p0, p1, p2 = p0 + d * z0, p1 + d * z1, p2 + d * z2
        S[j, 12], S[j, 13], S[j, 14] = z0, z1, z2
    return x0, x1, x2, y0, y1, y2, z0, z1, z2, p0, p1, p2


@njit(inline="always", **JIT)
def _row_trig(Q, i, c, s):
    """c, s = cos, sin of row i of Q."""
    for j in range(Q.shape[1]):
        c[j] = np.cos(Q[i, j])
        s[j] = np.sin(Q[i, j])


@njit(**JIT)
def trig(Q, C, Sn):
    """C, Sn = cos Q, sin Q (N, n): the joint variables as ``distance`` takes them."""
    for i in range(Q.shape[0]):
        for j in range(Q.shape[1]):
            C[i, j] = np.cos(Q[i, j])
            Sn[i, j] = np.sin(Q[i, j])


@njit(inline="always", **JIT)
def _times(f, X, R, p):
    """Frame f (12 scalars: x, y, z axes, p) times the 4x4 X into R (3, 3), p (3,)."""
    for r in range(3):
        ax, ay, az = f[r], f[3 + r], f[6 + r]
        for c in range(3):
            R[r, c] = ax * X[0, c] + ay * X[1, c] + az * X[2, c]
        p[r] = f[9 + r] + ax * X[0, 3] + ay * X[1, 3] + az * X[2, 3]


@njit(**JIT)
def frames(K, B, Q):
    """Frames 0..n for each row of Q (N, n): rotation matrices (N, n+1, 3, 3), origins
    (N, n+1, 3)."""
    N, n = Q.shape
    Rs = np.empty((N, n + 1, 3, 3))
    ps = np.empty((N, n + 1, 3))
    S = np.empty((n, 15))
    c, s = np.empty(n), np.empty(n)
    for i in range(N):
        _row_trig(Q, i, c, s)
        f = _walk(K, B, c, s, S)
        for j in range(n + 1):
            if j < n:  # frame j: x and p kept at joint j+1's start; z from joint j
                for r in range(3):
                    Rs[i, j, r, 0] = S[j, r]
                    ps[i, j, r] = S[j, 3 + r]
            else:
                for r in range(3):
                    Rs[i, j, r, 0] = f[r]
                    Rs[i, j, r, 1] = f[3 + r]
                    Rs[i, j, r, 2] = f[6 + r]
                    ps[i, j, r] = f[9 + r]
        for j in range(n):  # z of frame j (j >= 1) is joint j's axis; frame 0's is B's
            for r in range(3):
                Rs[i, j, r, 2] = S[j - 1, 12 + r] if j > 0 else B[r, 2]
            # y = z x x
            Rs[i, j, 0, 1] = Rs[i, j, 1, 2] * Rs[i, j, 2, 0] - Rs[i, j, 2, 2] * Rs[i, j, 1, 0]
            Rs[i, j, 1, 1] = Rs[i, j, 2, 2] * Rs[i, j, 0, 0] - Rs[i, j, 0, 2] * Rs[i, j, 2, 0]
            Rs[i, j, 2, 1] = Rs[i, j, 0, 2] * Rs[i, j, 1, 0] - Rs[i, j, 1, 2] * Rs[i, j, 0, 0]
    return Rs, ps


@njit(**JIT)
def link_frames(K, B, F, Q):
    """Each link's frame (``kinematics.link_frames``): frame j times the next joint's
    Rx(alpha) Tx(a), the flange last: (N, n+1, 3, 3), (N, n+1, 3)."""
    N, n = Q.shape
    Rf, pf = frames(K, B, Q)
    Rs = np.empty((N, n + 1, 3, 3))
    ps = np.empty((N, n + 1, 3))
    for i in range(N):
        for j in range(n + 1):
            if j < n:
                ca, sa, a = K[j, 5], K[j, 6], K[j, 1]
                for r in range(3):
                    x, y, z = Rf[i, j, r, 0], Rf[i, j, r, 1], Rf[i, j, r, 2]
                    Rs[i, j, r, 0] = x
                    Rs[i, j, r, 1] = ca * y + sa * z
                    Rs[i, j, r, 2] = ca * z - sa * y
                    ps[i, j, r] = pf[i, j, r] + a * x
            else:
                for r in range(3):
                    for c in range(3):
                        Rs[i, j, r, c] = (Rf[i, j, r, 0] * F[0, c] + Rf[i, j, r, 1] * F[1, c]
                                          + Rf[i, j, r, 2] * F[2, c])
                    ps[i, j, r] = (pf[i, j, r] + Rf[i, j, r, 0] * F[0, 3]
                                   + Rf[i, j, r, 1] * F[1, 3] + Rf[i, j, r, 2] * F[2, 3])
    return Rs, ps


@njit(inline="always", **JIT)
def _store(T, i, R, p):
    """T[i] = [[R, p], [0, 1]]."""
    for r in range(3):
        for c in range(3):
            T[i, r, c] = R[r, c]
        T[i, r, 3] = p[r]
        T[i, 3, r] = 0.0
    T[i, 3, 3] = 1.0


@njit(**JIT)
def flange_jacobian(K, B, F, Q, T, J):
    """The flange pose (T, (N, 4, 4)) and, unless J has no rows, its geometric Jacobian (J,
    (N, 6, n), rows v about the flange origin, then w) of each row of Q."""
    N, n = Q.shape
    S = np.empty((n, 15))
    R = np.empty((3, 3))
    p = np.empty(3)
    c, s = np.empty(n), np.empty(n)
    for i in range(N):
        _row_trig(Q, i, c, s)
        _times(_walk(K, B, c, s, S), F, R, p)
        _store(T, i, R, p)
        if J.shape[0] == 0:
            continue
        for j in range(n):
            z0, z1, z2 = S[j, 12], S[j, 13], S[j, 14]
            r0, r1, r2 = p[0] - S[j, 9], p[1] - S[j, 10], p[2] - S[j, 11]
            J[i, 0, j] = z1 * r2 - z2 * r1
            J[i, 1, j] = z2 * r0 - z0 * r2
            J[i, 2, j] = z0 * r1 - z1 * r0
            J[i, 3, j] = z0
            J[i, 4, j] = z1
            J[i, 5, j] = z2


@njit(inline="always", **JIT)
def _turn(n0, n1, n2, w0, w1, w2, c0, c1, c2, m0, m1, m2, inv):
    """dd for a rotation about the axis w through c: -(p_m - c) . (n x w) / s."""
    return -((m0 - c0) * (n1 * w2 - n2 * w1) + (m1 - c1) * (n2 * w0 - n0 * w2)
             + (m2 - c2) * (n0 * w1 - n1 * w0)) * inv


@njit(**JIT)
def distance(K, B, F, C, Sn, o, zf, dzf, planes, pidx, base_axes, base_point, out_d, out_hit,
             J, cols_joint, cols_base, cols_origin, cols_angles, cols_plane, extra_joint,
             extra_col, extra_factor):
    """For each sample (joint angles q as C[i] = cos q and Sn[i] = sin q (``trig``),
    gravity deflection included; plane pidx[i]): the distance along the beam to the plane n~ . p = 1 (``out_d``) and the hit point
    (``out_hit``); with J of more than 0 columns, the distance's derivatives into J's
    columns as the maps say (-1: not wanted): ``cols_joint`` (n, 5) alpha, a, beta, theta,
    d of each joint; ``cols_base`` (6) the base frame error's x, y, z (translations along
    the cell's axes) and rx, ry, rz (rotations about ``base_axes`` rows through
    ``base_point``); ``cols_origin`` (3) and ``cols_angles`` (2) the sensor origin o and
    beam angles (``dzf`` (3, 2): d z_f / d phi) in the flange frame; ``cols_plane`` (k, 3)
    each plate's n~; and ``extra_col`` (m) columns that are joint ``extra_joint``'s theta
    column times ``extra_factor[i, m]`` (compliance: the gravity torque). A rotation about
    an axis w through c: dd = -(p_m - c) . (n~ x w) / s; a translation t: -n~ . t / s;
    s = n~ . z_b, p_m the hit point."""
    N, n = C.shape
    S = np.empty((n, 15))
    R = np.empty((3, 3))
    fp = np.empty(3)
    dtheta = np.empty(n)
    ob = np.empty(3)
    zb = np.empty(3)
    derivatives = J.shape[1] > 0
    for i in range(N):
        _times(_walk(K, B, C[i], Sn[i], S), F, R, fp)
        for r in range(3):
            ob[r] = fp[r] + R[r, 0] * o[0] + R[r, 1] * o[1] + R[r, 2] * o[2]
            zb[r] = R[r, 0] * zf[0] + R[r, 1] * zf[1] + R[r, 2] * zf[2]
        k = pidx[i]
        n0, n1, n2 = planes[k, 0], planes[k, 1], planes[k, 2]
        s = n0 * zb[0] + n1 * zb[1] + n2 * zb[2]
        dist = (1.0 - (n0 * ob[0] + n1 * ob[1] + n2 * ob[2])) / s
        out_d[i] = dist
        m0, m1, m2 = ob[0] + dist * zb[0], ob[1] + dist * zb[1], ob[2] + dist * zb[2]
        out_hit[i, 0], out_hit[i, 1], out_hit[i, 2] = m0, m1, m2
        if not derivatives:
            continue
        _derivatives(J, i, S, R, n0, n1, n2, m0, m1, m2, s, dist, dzf, base_axes, base_point,
                     cols_joint, cols_base, cols_origin, cols_angles, cols_plane, k,
                     extra_joint, extra_col, extra_factor, dtheta)


@njit(inline="always", **JIT)
def _derivatives(J, i, S, R, n0, n1, n2, m0, m1, m2, s, dist, dzf, base_axes, base_point,
                 cols_joint, cols_base, cols_origin, cols_angles, cols_plane, k, extra_joint,
                 extra_col, extra_factor, dtheta):
    """Row i of J: the distance's derivatives by the mapped parameters (``distance``), for
    the chain's terms S, the flange rotation R, the plate's n~ (n0, n1, n2), the hit point
    (m0, m1, m2), s = n~ . z_b and the distance."""
    n = S.shape[0]
    inv = 1.0 / s
    for j in range(n):
        dtheta[j] = _turn(n0, n1, n2, S[j, 12], S[j, 13], S[j, 14], S[j, 9], S[j, 10],
                          S[j, 11], m0, m1, m2, inv)
        c = cols_joint[j, 3]
        if c >= 0:
            J[i, c] = dtheta[j]
        c = cols_joint[j, 0]
        if c >= 0:
            J[i, c] = _turn(n0, n1, n2, S[j, 0], S[j, 1], S[j, 2], S[j, 3], S[j, 4],
                            S[j, 5], m0, m1, m2, inv)
        c = cols_joint[j, 1]
        if c >= 0:
            J[i, c] = -(n0 * S[j, 0] + n1 * S[j, 1] + n2 * S[j, 2]) * inv
        c = cols_joint[j, 2]
        if c >= 0:
            J[i, c] = _turn(n0, n1, n2, S[j, 6], S[j, 7], S[j, 8], S[j, 9], S[j, 10],
                            S[j, 11], m0, m1, m2, inv)
        c = cols_joint[j, 4]
        if c >= 0:
            J[i, c] = -(n0 * S[j, 12] + n1 * S[j, 13] + n2 * S[j, 14]) * inv
    for e in range(extra_col.shape[0]):
        J[i, extra_col[e]] = dtheta[extra_joint[e]] * extra_factor[i, e]
    for r in range(3):
        if cols_base[r] >= 0:
            J[i, cols_base[r]] = -(n0 if r == 0 else n1 if r == 1 else n2) * inv
        if cols_base[3 + r] >= 0:
            J[i, cols_base[3 + r]] = _turn(n0, n1, n2, base_axes[r, 0], base_axes[r, 1],
                                           base_axes[r, 2], base_point[0], base_point[1],
                                           base_point[2], m0, m1, m2, inv)
    # R^T n~: the plate's normal in the flange frame
    f0 = R[0, 0] * n0 + R[1, 0] * n1 + R[2, 0] * n2
    f1 = R[0, 1] * n0 + R[1, 1] * n1 + R[2, 1] * n2
    f2 = R[0, 2] * n0 + R[1, 2] * n1 + R[2, 2] * n2
    if cols_origin[0] >= 0:
        J[i, cols_origin[0]] = -f0 * inv
    if cols_origin[1] >= 0:
        J[i, cols_origin[1]] = -f1 * inv
    if cols_origin[2] >= 0:
        J[i, cols_origin[2]] = -f2 * inv
    for a in range(2):
        if cols_angles[a] >= 0:
            J[i, cols_angles[a]] = -dist * inv * (f0 * dzf[0, a] + f1 * dzf[1, a]
                                                  + f2 * dzf[2, a])
    if cols_plane.shape[0] > k:
        for r in range(3):
            if cols_plane[k, r] >= 0:
                J[i, cols_plane[k, r]] = -(m0 if r == 0 else m1 if r == 1 else m2) * inv
