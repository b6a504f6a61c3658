"""The gravity torque on each joint of a serial chain of point masses: one formula, shared by
the twin (``twin.ticks``: the realistic world's joint compliance deflects its joints by
it) and the calibration's compliance parameters (``planecal.model.gravity``). Plain numpy
loops that numba compiles where a caller compiles (``register_jitable``: the
interpreter runs the same code as the reference)."""
from __future__ import annotations

import numpy as np
from numba.extending import register_jitable


@register_jitable
def gravity_torque(theta, W, tau):
    """Gravity torque on each joint [N m] (into ``tau``) at joint angles ``theta`` (the
    twin's qpos): the chain of ``W``'s body poses (``base``, then per joint its pose
    before the hinge), turned about local z by theta, and point masses on the bodies."""
    base, P, mbody, mcom, mkg, g = W[1], W[2], W[3], W[4], W[5], W[6]
    n = P.shape[0]
    R = np.empty((n + 1, 3, 3))
    p = np.empty((n + 1, 3))
    R[0] = base[:3, :3]
    p[0] = base[:3, 3]
    for i in range(n):
        c, s = np.cos(theta[i]), np.sin(theta[i])
        for r in range(3):
            a0 = R[i, r, 0] * P[i, 0, 0] + R[i, r, 1] * P[i, 1, 0] + R[i, r, 2] * P[i, 2, 0]
            a1 = R[i, r, 0] * P[i, 0, 1] + R[i, r, 1] * P[i, 1, 1] + R[i, r, 2] * P[i, 2, 1]
            a2 = R[i, r, 0] * P[i, 0, 2] + R[i, r, 1] * P[i, 1, 2] + R[i, r, 2] * P[i, 2, 2]
            p[i + 1, r] = (R[i, r, 0] * P[i, 0, 3] + R[i, r, 1] * P[i, 1, 3]
                           + R[i, r, 2] * P[i, 2, 3] + p[i, r])
            R[i + 1, r, 0] = a0 * c + a1 * s
            R[i + 1, r, 1] = a1 * c - a0 * s
            R[i + 1, r, 2] = a2
    for j in range(n):
        tau[j] = 0.0
    for k in range(mbody.shape[0]):
        b = mbody[k]
        cx = R[b, 0, 0] * mcom[k, 0] + R[b, 0, 1] * mcom[k, 1] + R[b, 0, 2] * mcom[k, 2] + p[b, 0]
        cy = R[b, 1, 0] * mcom[k, 0] + R[b, 1, 1] * mcom[k, 1] + R[b, 1, 2] * mcom[k, 2] + p[b, 1]
        cz = R[b, 2, 0] * mcom[k, 0] + R[b, 2, 1] * mcom[k, 1] + R[b, 2, 2] * mcom[k, 2] + p[b, 2]
        fx, fy, fz = mkg[k] * g[0], mkg[k] * g[1], mkg[k] * g[2]
        for j in range(1, b + 1):  # joints 1..b carry body b (joint j's axis: z of frame j)
            rx, ry, rz = cx - p[j, 0], cy - p[j, 1], cz - p[j, 2]
            tau[j - 1] += (R[j, 0, 2] * (ry * fz - rz * fy) + R[j, 1, 2] * (rz * fx - rx * fz)
                           + R[j, 2, 2] * (rx * fy - ry * fx))
