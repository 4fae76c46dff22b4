"""Rate control in the compiled step: the strokes move at the commanded rates, the pose follows onto Φ = 0.

The step's first integrator (``envs.kernels.force.advance`` chooses it when the step has no ``Dynamics`` record):
``advance_rate`` predicts the pose by Euler or RK4 on ẋ = J_f q̇ and corrects it by Newton's method, in substeps.
"""

from __future__ import annotations

import math

import numpy as np

from envs.kernels import paths
from envs.kernels.cache import drop_stale_caches
from envs.kernels.layout import (
    C_DT,
    C_MAX_SUBSTEP,
    C_MAX_SUBSTEPS,
    C_NEWTON_IT,
    C_NEWTON_TOL,
    C_RK4,
    W_ACT,
    W_K1,
    W_K2,
    W_K3,
    W_KQ,
    W_KX,
    W_NQ,
    W_PRED,
    W_QM,
    W_QR,
    W_T,
    W_V,
    W_XM,
)
from envs.kernels.pose import _all_finite
from envs.kernels.setup import jit_inline

__all__ = ["advance_rate", "substeps"]

drop_stale_caches(__file__)


@jit_inline
def substeps(c, motion):
    """Substeps of a period whose predicted motion is ``motion`` [m]: each moves at most ``max_substep``."""
    count = np.ceil(motion * c[C_DT] / c[C_MAX_SUBSTEP])
    cap = c[C_MAX_SUBSTEPS]
    if not math.isfinite(count):
        return int(cap)
    return int(min(max(count, 1.0), cap))


@jit_inline
def advance_rate(path, c, q0, x0, action, residual, w):
    """Predict and correct: move one robot through one control period (``envs.physics.transition``).

    The strokes move at the commanded rates; each of the substeps predicts the pose by Euler or RK4 on
    ẋ = J_f q̇ and corrects it onto Φ = 0 by Newton's method at the substep's strokes. If a prediction is not
    finite or a correction fails, the robot stays where it was.

    Args:
        path: The row path, a compile-time constant (``envs.kernels.paths``).
        c: The robot's packed constants.
        q0: Its strokes (n,), a vector of the path.
        x0: Its pose (m,), a vector of the path.
        action: Its normalised stroke rates (n,).
        residual: The constraint residual at (q0, x0) [m²].
        w: Its work array (``constraints._work``).

    Returns:
        (q, x, anchors, rows, applied action, stroke rates, residual, jump [m], failed): the strokes and the pose
        at the end of the period and the anchors and rows there (``envs.kernels.paths``).
    """
    dt = c[C_DT]
    a, nq, qr = paths.commanded(path, c, q0, action, w[W_ACT], w[W_NQ], w[W_QR])
    kq = paths.keep(path, q0, w[W_KQ])
    kx = paths.keep(path, x0, w[W_KX])
    start_anchors = paths.anchors_at(path, c, kq)
    start_rows = paths.rows_at(path, c, kq, start_anchors, kx, w)
    anchors, rows = start_anchors, start_rows
    v = paths.pose_rate(path, c, kq, rows, qr, w, w[W_V])
    count = substeps(c, paths.metric(path, c, v))
    h = dt / count
    rk4 = c[C_RK4] != 0.0
    tolerance, iterations = c[C_NEWTON_TOL], int(c[C_NEWTON_IT])
    res = residual
    jump = 0.0
    failed = False
    for s in range(count):
        if s > 0:  # at the pose Newton's method just returned, whose rows it left
            v = paths.pose_rate(path, c, kq, rows, qr, w, w[W_V])
        if rk4:
            qm = paths.axpy(path, kq, 0.5 * h, qr, w[W_QM])
            mid = paths.anchors_at(path, c, qm)
            xm = paths.retract(path, c, kx, v, 0.5 * h, w[W_XM])
            k1 = paths.pose_rate(path, c, qm, paths.rows_at(path, c, qm, mid, xm, w), qr, w, w[W_K1])
            xm = paths.retract(path, c, kx, k1, 0.5 * h, w[W_XM])
            k2 = paths.pose_rate(path, c, qm, paths.rows_at(path, c, qm, mid, xm, w), qr, w, w[W_K2])
            qm = paths.axpy(path, kq, h, qr, w[W_QM])
            end = paths.anchors_at(path, c, qm)
            xm = paths.retract(path, c, kx, k2, h, w[W_XM])
            k3 = paths.pose_rate(path, c, qm, paths.rows_at(path, c, qm, end, xm, w), qr, w, w[W_K3])
            pred = paths.retract(path, c, kx, paths.rk4_mean(path, v, k1, k2, k3, w[W_K3]), h, w[W_PRED])
        else:
            pred = paths.retract(path, c, kx, v, h, w[W_PRED])
        if not _all_finite(pred, len(pred)):
            failed = True
            break
        t = paths.lerp(path, q0, nq, (s + 1) / count, w[W_T])
        anchors = paths.anchors_at(path, c, t)
        y, fres, rows = paths.newton(path, c, t, anchors, pred, w, tolerance, iterations)
        if not fres <= tolerance:
            failed = True
            break
        jump = max(jump, paths.jump(path, c, y, pred, w))
        kq = paths.keep(path, t, w[W_KQ])
        kx = paths.keep(path, y, w[W_KX])
        res = fres
    if failed:  # back at the start (rare)
        kq = paths.keep(path, q0, w[W_KQ])
        kx = paths.keep(path, x0, w[W_KX])
        res = residual
        anchors = start_anchors  # the strokes are q0 again
        rows = paths.rows_at(path, c, kq, anchors, kx, w)
    return kq, kx, anchors, rows, a, qr, res, jump, failed
