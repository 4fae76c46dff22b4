"""N robots' equations of motion in one call: M(x), c + G and ẍ (``envs.kernels.dynamics``, one entry per row path).

What the tests check the compiled equations with against ``kinematics.dynamics.RobotDynamics``; the step calls
``envs.kernels.dynamics``' operations robot by robot instead.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from envs.kernels import paths
from envs.kernels.cache import drop_stale_caches
from envs.kernels.dynamics import _dynamics_work, equations, solve_acceleration
from envs.kernels.dynamics_layout import C_INERTIA_SIZE, D_ACC, I_N
from envs.kernels.layout import C_N, C_SIZE
from envs.kernels.packing import ROW_PATHS, read_only, row_path
from envs.kernels.setup import jit

__all__ = ["bias_batch", "forward_dynamics_batch", "mass_matrix_batch", "path_kernels"]

drop_stale_caches(__file__)


class DynamicsKernels(NamedTuple):
    """The entry kernel of one row path (``_path_kernels``)."""

    dynamics: Any


def _path_kernels(path: int) -> DynamicsKernels:
    """The entry kernel of the row path ``path`` (a compile-time constant): (M, c + G, ẍ) of N robots."""

    def dynamics(c, ci, q, x, xdot, tau):
        n, m = x.shape
        o_M, o_bias, o_acc = np.empty((n, m, m)), np.empty((n, m)), np.empty((n, m))
        wd = _dynamics_work()
        for i in range(n):
            qi, xi = paths.vector(path, q[i]), paths.vector(path, x[i])
            vi, ti = paths.vector(path, xdot[i]), paths.vector(path, tau[i])
            M, bias, force = equations(path, c, ci, qi, xi, vi, ti, wd)
            acc = solve_acceleration(path, M, bias, force, wd, wd[D_ACC])
            for j in range(m):
                o_bias[i, j] = bias[j]
                o_acc[i, j] = acc[j]
                row = M[j]
                for k in range(m):
                    o_M[i, j, k] = row[k]
        return o_M, o_bias, o_acc

    # One qualified name per path: Numba's on-disk cache keeps one index per name (see ``step._path_kernels``).
    dynamics.__qualname__ = dynamics.__name__ = f"dynamics_path{path}"
    return DynamicsKernels(jit(dynamics))


_PATH_KERNELS = {path: _path_kernels(path) for path in ROW_PATHS}


def path_kernels(c) -> DynamicsKernels:
    """The entry kernel of the robot of packed constants ``c`` (its ``row_path``'s)."""
    return _PATH_KERNELS[row_path(c)]


def _state(name: str, value: Any, n: int, width: int, what: str) -> np.ndarray:
    """``value`` as a C-ordered, writable float64 array of shape (n, width), or a ValueError naming it."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (n, width):
        raise ValueError(f"{name} must have shape ({n}, {width}) holding {what}, got shape {arr.shape}")
    return np.require(arr, np.float64, ("C", "W"))


def _arguments(c: Any, ci: Any, q: Any, x: Any, xdot: Any, tau: Any) -> tuple[np.ndarray, ...]:
    """Validated arguments of the batches (see ``forward_dynamics_batch``); zero ẋ and τ where None."""
    c, ci = np.asarray(c, dtype=np.float64), np.asarray(ci, dtype=np.float64)
    if c.shape != (C_SIZE,):
        raise ValueError(f"c (packed constants, pack_family) must have shape ({C_SIZE},), got shape {c.shape}")
    if ci.shape != (C_INERTIA_SIZE,):
        raise ValueError(f"ci (packed inertia, pack_inertia) must have shape ({C_INERTIA_SIZE},), got shape {ci.shape}")
    m = int(c[C_N])
    if ci[I_N] != m:
        raise ValueError(f"ci packs the inertia of {ci[I_N]:g} legs, but c is a robot with {m} legs")
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[0] if x.ndim == 2 else -1
    x = _state("x", x, n, m, "platform poses")
    q = _state("q", q, n, m, "actuator coordinates")
    xdot = _state("xdot", np.zeros((n, m)) if xdot is None else xdot, n, m, "platform twists")
    tau = _state("tau", np.zeros((n, m)) if tau is None else tau, n, m, "actuator efforts")
    return read_only(c), read_only(ci), q, x, xdot, tau


def mass_matrix_batch(c, ci, q, x) -> np.ndarray:
    """M(x) of N robots of one geometry, (N, m, m) (``RobotDynamics.mass_matrix``; as ``forward_dynamics_batch``)."""
    c, ci, q, x, xdot, tau = _arguments(c, ci, q, x, None, None)
    return path_kernels(c).dynamics(c, ci, q, x, xdot, tau)[0]


def bias_batch(c, ci, q, x, xdot) -> np.ndarray:
    """c(x, ẋ) + G(x) of N robots, (N, m) (``RobotDynamics.bias_forces``; as ``forward_dynamics_batch``)."""
    c, ci, q, x, xdot, tau = _arguments(c, ci, q, x, xdot, None)
    return path_kernels(c).dynamics(c, ci, q, x, xdot, tau)[1]


def forward_dynamics_batch(c, ci, q, x, xdot, tau) -> np.ndarray:
    """The twist rates ẍ = M⁻¹ (J_iᵀ τ − c − G) of N robots, shape (N, m) (``forward_dynamics``).

    Args:
        c: Packed constants, shape (C_SIZE,).
        ci: Packed inertia, shape (C_INERTIA_SIZE,).
        q: Actuator coordinates with Φ(q, x) = 0, shape (N, n).
        x: Platform poses, shape (N, m).
        xdot: Platform twists, shape (N, m).
        tau: Actuator efforts [N for legs and sliders, N·m for cranks], shape (N, n).

    Returns:
        ẍ (planar: m/s², m/s², rad/s²; spatial: v̇ [m/s²], ω̇ [rad/s²] in {B}), shape (N, m); NaN where M is
        exactly singular.

    Raises:
        ValueError: On an array of the wrong shape, naming it.
    """
    c, ci, q, x, xdot, tau = _arguments(c, ci, q, x, xdot, tau)
    return path_kernels(c).dynamics(c, ci, q, x, xdot, tau)[2]
