"""Computed-torque control of the platform pose with actuator force limits, and minimum-jerk references on the manifold.

The controller inverts the equations of motion of ``kinematics.dynamics`` (M(x) ẍ + c(x, ẋ) + G(x) = J_iᵀ τ):

    w = M(x) (ẍ_d + K_d (ẋ_d − ẋ) + K_p (x_d ⊖ x)) + c(x, ẋ) + G(x),   J_iᵀ τ = w,   τ ← clip(τ, −τ_max, τ_max),

with x_d ⊖ x the twist step from x to x_d (``pose_difference``: (p_d − p, δθ) with exp([δθ]×) R = R_d in {B} for
spatial poses) and every rate in the mechanism's twist convention. With the exact model and no saturation the
error e = x_d ⊖ x obeys ë + K_d ė + K_p e = 0 in each pose coordinate, so K_p [1/s²] and K_d [1/s] have the same
units for translations and rotations. The characteristic length ℓ_c only enters the size of an error, measured
as ‖(δp, ℓ_c δθ)‖ [m] (``ComputedTorqueCommand.error_norm``).

The reference ``MinimumJerkPath`` moves along the geodesics x_k ⊕ s(t) (x_{k+1} ⊖ x_k) of the pose space with the
quintic s = 10 τ³ − 15 τ⁴ + 6 τ⁵ (τ = t / T_k), at rest at every waypoint.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from kinematics._validation import as_float_array
from kinematics.dynamics import InertialParameters, RobotDynamics
from kinematics.family import DistanceConstraintMechanism

__all__ = [
    "ComputedTorqueCommand",
    "ComputedTorqueController",
    "MinimumJerkPath",
    "Reference",
    "TimeOptimalPath",
    "minimum_jerk",
]

FloatArray = NDArray[np.float64]


def _finite(name: str, arr: FloatArray) -> FloatArray:
    if not np.isfinite(arr).all():
        index = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])
        raise ValueError(f"{name} must be finite, got {float(arr[index])!r} at index {index}")
    return arr


def _vector(name: str, value: Any, size: int, what: str) -> FloatArray:
    """A finite batch of vectors of shape (..., size)."""
    arr = as_float_array(name, value)
    if arr.ndim == 0 or arr.shape[-1] != size:
        raise ValueError(f"{name} must have shape (..., {size}) holding {what}, got shape {arr.shape}")
    return _finite(name, arr)


def _per_coordinate(name: str, value: Any, size: int, unit: str, allow_inf: bool = False) -> FloatArray:
    """A positive number or shape (size,) array of them, as a read-only array of shape (size,)."""
    arr = as_float_array(name, value)
    if arr.shape not in ((), (size,)):
        raise ValueError(f"{name} must be a number or have shape ({size},) [{unit}], got shape {arr.shape}")
    bad = np.isnan(arr) | (arr <= 0) | (np.isinf(arr) & (not allow_inf))
    if bad.any():
        which = "> 0" + ("" if allow_inf else " and finite")
        raise ValueError(f"{name} must be {which} [{unit}], got {float(np.atleast_1d(arr)[np.atleast_1d(bad)][0])!r}")
    out = np.array(np.broadcast_to(arr, (size,)), dtype=np.float64)
    out.setflags(write=False)
    return out


class ComputedTorqueCommand(NamedTuple):
    """The controller's output for a batch of states.

    Attributes:
        tau: Actuator efforts after clipping to the force limits, shape (..., n) [N for legs and sliders, N·m
            for cranks].
        tau_model: The efforts the model asks for, before clipping, shape (..., n).
        saturated: Whether any actuator's effort was clipped, shape (...) (bool).
        pose_error: x_d ⊖ x, the twist step from the pose to the reference (δp [m], δθ [rad]), shape (..., m).
        velocity_error: ẋ_d − ẋ, shape (..., m).
        error_norm: ‖(δp, ℓ_c δθ)‖ [m], the pose error with rotations scaled by the characteristic length,
            shape (...).
    """

    tau: FloatArray
    tau_model: FloatArray
    saturated: NDArray[np.bool_]
    pose_error: FloatArray
    velocity_error: FloatArray
    error_norm: FloatArray


class ComputedTorqueController:
    """Computed-torque (inverse-dynamics) control of a distance-constraint robot's platform pose.

    τ solves J_iᵀ τ = M(x) (ẍ_d + K_d (ẋ_d − ẋ) + K_p (x_d ⊖ x)) + c(x, ẋ) + G(x) with the model
    ``RobotDynamics(mechanism, inertia)``, then is clipped to ±``force_limits`` (see the module docstring). J_iᵀ
    τ = w is solved as ``mechanism.actuator_forces`` does (τ = J_fᵀ w), so it needs J_x regular and raises
    ``SingularConfigurationError`` at a Type II singularity.

    Args:
        mechanism: The robot's kinematics.
        inertia: The model's inertial parameters; default ``default_inertia(mechanism)`` (presets only). A plant
            with other parameters is controlled with this model's errors.
        kp: K_p [1/s²], > 0, a number or one per pose coordinate, shape (m,).
        kd: K_d [1/s], > 0, a number or shape (m,). K_d = 2 √K_p damps each coordinate critically.
        force_limits: τ_max, > 0 (``inf`` for an unlimited actuator), a number or one per actuator, shape (n,)
            [N for legs and sliders, N·m for cranks]; default None: no clipping.

    Raises:
        TypeError: If ``mechanism`` is not a ``DistanceConstraintMechanism`` or a gain is not real.
        ValueError: On a gain or limit of the wrong shape, not > 0 or NaN (the message names it), or inertial
            parameters that do not fit the mechanism.
    """

    def __init__(
        self,
        mechanism: DistanceConstraintMechanism,
        inertia: InertialParameters | None = None,
        *,
        kp: Any,
        kd: Any,
        force_limits: Any = None,
    ) -> None:
        """Validate the gains and limits and build the model (see the class docstring)."""
        self.dynamics = RobotDynamics(mechanism, inertia)
        self.mechanism = mechanism
        m, n = mechanism.n_pose, mechanism.n_actuators
        self.kp = _per_coordinate("kp", kp, m, "1/s²")
        self.kd = _per_coordinate("kd", kd, m, "1/s")
        limits = np.inf if force_limits is None else force_limits
        self.force_limits = _per_coordinate("force_limits", limits, n, "N or N·m", allow_inf=True)
        self._length_scale = 1.0 / mechanism.pose_scale  # 1 for translations, ℓ_c for rotations

    @classmethod
    def critically_damped(
        cls,
        mechanism: DistanceConstraintMechanism,
        inertia: InertialParameters | None = None,
        *,
        bandwidth: float,
        force_limits: Any = None,
    ) -> ComputedTorqueController:
        """The controller with K_p = ω², K_d = 2 ω in every pose coordinate: the error decays as (1 + ω t) e^{−ω t}.

        Args:
            mechanism: The robot's kinematics.
            inertia: The model's inertial parameters (see the class docstring).
            bandwidth: ω [rad/s], finite and > 0.
            force_limits: As for the class.

        Raises:
            ValueError: If ``bandwidth`` is not a finite number > 0.
        """
        if isinstance(bandwidth, bool) or not isinstance(bandwidth, (int, float, np.integer, np.floating)):
            raise TypeError(f"bandwidth must be a real number [rad/s], got {type(bandwidth).__name__}")
        if not (math.isfinite(bandwidth) and bandwidth > 0):
            raise ValueError(f"bandwidth must be a finite number > 0 [rad/s], got {bandwidth!r}")
        omega = float(bandwidth)
        return cls(mechanism, inertia, kp=omega**2, kd=2.0 * omega, force_limits=force_limits)

    def compute(
        self,
        q: Any,
        x: Any,
        xdot: Any,
        target: Any,
        target_velocity: Any = None,
        target_acceleration: Any = None,
    ) -> ComputedTorqueCommand:
        """The actuator efforts that drive the state (q, x, ẋ) along the reference (x_d, ẋ_d, ẍ_d).

        Args:
            q: Actuator coordinates with Φ(q, x) = 0 (e.g. ``inverse_kinematics(x)``), shape (..., n).
            x: Platform pose of {P} in {B}, shape (..., m).
            xdot: Platform twist in the mechanism's convention (spatial: (v [m/s], ω [rad/s]) in {B}),
                shape (..., m).
            target: x_d, the reference pose, shape (..., m).
            target_velocity: ẋ_d, the reference twist, shape (..., m); default zero (a fixed target).
            target_acceleration: ẍ_d [m/s², rad/s²], shape (..., m); default zero.

        Returns:
            The clipped and unclipped efforts, the saturation flags and the errors, broadcast over the batch.

        Raises:
            ValueError: If an argument has the wrong shape or a non-finite entry (naming it), or the batch
                shapes do not broadcast.
            SingularConfigurationError: If J_x is singular at x (a Type II singularity).
        """
        mech = self.mechanism
        m, n = mech.n_pose, mech.n_actuators
        twist = "a platform twist"
        arrays = {
            "q": _vector("q", q, n, mech.q_description),
            "x": _vector("x", x, m, mech.x_description),
            "xdot": _vector("xdot", xdot, m, twist),
            "target": _vector("target", target, m, mech.x_description),
        }
        for name, value in (("target_velocity", target_velocity), ("target_acceleration", target_acceleration)):
            arrays[name] = np.zeros(m) if value is None else _vector(name, value, m, twist)
        try:
            batch = np.broadcast_shapes(*(arr.shape[:-1] for arr in arrays.values()))
        except ValueError:
            shapes = ", ".join(f"{name} {arr.shape}" for name, arr in arrays.items())
            raise ValueError(f"batch shapes do not broadcast: {shapes}") from None
        q, x, xdot, x_d, v_d, a_d = (np.broadcast_to(arr, batch + arr.shape[-1:]) for arr in arrays.values())
        error = mech.pose_difference(x_d, x, validate=False)
        velocity_error = v_d - xdot
        acceleration = a_d + self.kd * velocity_error + self.kp * error
        M = self.dynamics.mass_matrix(q, x)
        wrench = np.einsum("...mk,...k->...m", M, acceleration) + self.dynamics.bias_forces(q, x, xdot)
        tau_model = mech.actuator_forces(q, x, wrench)
        tau = np.clip(tau_model, -self.force_limits, self.force_limits)
        saturated = np.any(np.abs(tau_model) > self.force_limits, axis=-1)
        error_norm = np.linalg.norm(error * self._length_scale, axis=-1)
        return ComputedTorqueCommand(tau, tau_model, saturated, error, velocity_error, error_norm)


# -- references ---------------------------------------------------------------------------------------------


class Reference(NamedTuple):
    """A reference state of the platform.

    Attributes:
        x: Pose x_d, shape (..., m).
        xdot: Twist ẋ_d (the mechanism's convention), shape (..., m).
        xddot: Its rate ẍ_d, shape (..., m).
    """

    x: FloatArray
    xdot: FloatArray
    xddot: FloatArray


def minimum_jerk(phase: Any) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The rest-to-rest quintic s(τ) = 10 τ³ − 15 τ⁴ + 6 τ⁵ and its first two derivatives in τ.

    Args:
        phase: τ = t / T, any shape; clipped to [0, 1] (at rest before and after).

    Returns:
        (s, ds/dτ, d²s/dτ²), each the shape of ``phase``.
    """
    tau = np.clip(np.asarray(phase, dtype=np.float64), 0.0, 1.0)
    s = tau**3 * (10.0 + tau * (-15.0 + 6.0 * tau))
    ds = 30.0 * tau**2 * (1.0 - tau) ** 2
    dds = 60.0 * tau * (1.0 - tau) * (1.0 - 2.0 * tau)
    return s, ds, dds


class _Segments:
    """Consecutive segments of a reference: their start times ``times`` (K + 1,) and durations (K,)."""

    times: FloatArray
    durations: FloatArray

    @property
    def duration(self) -> float:
        """Total time [s] from the first waypoint to the last."""
        return float(self.times[-1])

    def _segment(self, t: float) -> int:
        """The segment k whose interval holds t [s] (the first before it, the last after it)."""
        if isinstance(t, bool) or not isinstance(t, (int, float, np.integer, np.floating)) or not math.isfinite(t):
            raise ValueError(f"t must be a finite number [s], got {t!r}")
        return int(np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, len(self.durations) - 1))


class MinimumJerkPath(_Segments):
    """Rest-to-rest minimum-jerk segments along the pose space's geodesics through waypoints.

    Segment k goes from waypoint x_k to x_{k+1} in T_k seconds along x_k ⊕ s(τ) Δ_k, Δ_k = x_{k+1} ⊖ x_k
    (``retract`` and ``pose_difference``; spatial: R(t) = exp([s Δθ_k]×) R_k, the shortest rotation), so the
    twist is ṡ Δ_k and its rate s̈ Δ_k exactly. The platform stops at every waypoint; before t = 0 the path
    rests at the first waypoint and after the last segment at the last one. A certified detour start →
    waypoint → target is three waypoints.

    Args:
        mechanism: The robot whose pose space the path lies in.
        waypoints: x_0, ..., x_K, shape (..., K + 1, m) with K ≥ 1 (a leading batch of paths with common
            timing).
        durations: T_k [s], finite and > 0, a number (every segment) or shape (K,).

    Raises:
        ValueError: On waypoints of the wrong shape or not finite, or durations of the wrong shape or not > 0.
    """

    def __init__(self, mechanism: DistanceConstraintMechanism, waypoints: Any, durations: Any) -> None:
        """Validate the waypoints and durations and take the segments' steps (see the class docstring)."""
        m = mechanism.n_pose
        points = _vector("waypoints", waypoints, m, mechanism.x_description)
        if points.ndim < 2 or points.shape[-2] < 2:
            raise ValueError(f"waypoints must have shape (..., K + 1, {m}) with K ≥ 1, got shape {points.shape}")
        count = points.shape[-2] - 1
        self.mechanism = mechanism
        self.durations = _per_coordinate("durations", durations, count, "s")
        self.waypoints = np.array(points)
        self.steps = mechanism.pose_difference(points[..., 1:, :], points[..., :-1, :], validate=False)
        self.times = np.concatenate([[0.0], np.cumsum(self.durations)])

    @classmethod
    def point_to_point(cls, mechanism: DistanceConstraintMechanism, start: Any, end: Any, duration: float) -> Any:
        """One segment from ``start`` to ``end`` (each shape (..., m)) in ``duration`` [s]."""
        m = mechanism.n_pose
        start = _vector("start", start, m, mechanism.x_description)
        end = _vector("end", end, m, mechanism.x_description)
        try:
            batch = np.broadcast_shapes(start.shape, end.shape)
        except ValueError:
            raise ValueError(f"start {start.shape} and end {end.shape} do not broadcast") from None
        return cls(mechanism, np.stack([np.broadcast_to(start, batch), np.broadcast_to(end, batch)], axis=-2), duration)

    def __call__(self, t: float) -> Reference:
        """The reference (x_d, ẋ_d, ẍ_d) at time t [s] (a finite number), each shape (..., m)."""
        k = self._segment(t)
        T = self.durations[k]
        s, ds, dds = minimum_jerk((t - self.times[k]) / T)
        step = self.steps[..., k, :]
        x = self.mechanism.retract(self.waypoints[..., k, :], s * step, validate=False)
        return Reference(x, (ds / T) * step, (dds / T**2) * step)


class TimeOptimalPath(_Segments):
    """Rest-to-rest time-optimal motion along the geodesics through waypoints under actuator force limits (TOPP-RA).

    Segment k follows x_k ⊕ s Δ_k (s from 0 to 1, Δ_k = x_{k+1} ⊖ x_k, as ``MinimumJerkPath``), so the twist is ṡ Δ_k
    and its rate s̈ Δ_k, and the efforts τ(s, ṡ, s̈) of the inverse dynamics J_iᵀ τ = M ẍ + c + G are those of the
    model ``dynamics``. Each segment is parametrised time-optimally from rest to rest with every |τ_i| ≤ τ_max,i
    by TOPP-RA (``toppra``, the ``planner`` extra; H. Pham and Q.-C. Pham, "A new approach to time-optimal path
    parameterization based on reachability analysis", IEEE T-RO 34(3), 2018) on ``grid`` + 1 points per segment,
    with constant s̈ between them (the limits hold exactly at the grid points, to ~1e-5 between them). The
    platform stops at every waypoint.

    Args:
        dynamics: The model (``kinematics.dynamics.RobotDynamics``).
        waypoints: x_0, ..., x_K, shape (K + 1, m) with K ≥ 1, consecutive ones distinct.
        force_limits: τ_max > 0, a number or one per actuator, shape (n,) [N for legs and sliders, N·m for cranks].
        grid: Intervals of the path grid per segment (≥ 10).

    Raises:
        ValueError: On waypoints of the wrong shape, not finite or repeated, limits not > 0, a grid < 10, or a
            segment TOPP-RA finds no feasible motion along (e.g. the holding forces exceed the limits).
    """

    def __init__(self, dynamics: RobotDynamics, waypoints: Any, force_limits: Any, grid: int = 100) -> None:
        """Parametrise every segment (see the class docstring)."""
        mech = dynamics.mechanism
        m, n = mech.n_pose, mech.n_actuators
        points = _vector("waypoints", waypoints, m, mech.x_description)
        if points.ndim != 2 or points.shape[0] < 2:
            raise ValueError(f"waypoints must have shape (K + 1, {m}) with K ≥ 1, got shape {points.shape}")
        if isinstance(grid, bool) or not isinstance(grid, (int, np.integer)) or grid < 10:
            raise ValueError(f"grid must be an integer ≥ 10, got {grid!r}")
        self.mechanism, self.dynamics = mech, dynamics
        self.force_limits = _per_coordinate("force_limits", force_limits, n, "N or N·m")
        self.waypoints = np.array(points)
        self.steps = mech.pose_difference(points[1:], points[:-1], validate=False)
        if (np.linalg.norm(self.steps, axis=-1) == 0).any():
            raise ValueError("consecutive waypoints must differ")
        self.segments = [self._parametrise(k, int(grid)) for k in range(len(self.steps))]
        self.durations = np.array([float(seg.duration) for seg in self.segments])
        self.times = np.concatenate([[0.0], np.cumsum(self.durations)])

    def _efforts(self, k: int, xi: FloatArray, v: FloatArray, a: FloatArray) -> FloatArray:
        """τ at local coordinates ξ = s Δ_k of segment k, twist v and twist rate a (each shape (m,))."""
        mech, dyn = self.mechanism, self.dynamics
        x = mech.retract(self.waypoints[k], xi, validate=False)
        q = mech.inverse_kinematics(x, validate=False)
        wrench = dyn.mass_matrix(q, x) @ a + dyn.bias_forces(q, x, v)
        return mech.actuator_forces(q, x, wrench)

    def _parametrise(self, k: int, grid: int) -> Any:
        import toppra
        from toppra import algorithm, constraint

        toppra.setup_logging("WARNING")
        path = toppra.SplineInterpolator([0.0, 1.0], np.stack([np.zeros_like(self.steps[k]), self.steps[k]]))
        limits = np.stack([-self.force_limits, self.force_limits], axis=1)
        torque = constraint.JointTorqueConstraint(
            lambda xi, v, a: self._efforts(k, np.asarray(xi), np.asarray(v), np.asarray(a)),
            limits,
            np.zeros(len(self.force_limits)),
            discretization_scheme=constraint.DiscretizationType.Interpolation,
        )
        solver = algorithm.TOPPRA([torque], path, gridpoints=np.linspace(0.0, 1.0, grid + 1),
                                  parametrizer="ParametrizeConstAccel")  # fmt: skip
        trajectory = solver.compute_trajectory(0.0, 0.0)
        if trajectory is None:
            raise ValueError(f"segment {k} has no motion within the force limits (TOPP-RA found none)")
        return trajectory

    def __call__(self, t: float) -> Reference:
        """The reference (x_d, ẋ_d, ẍ_d) at time t [s] (a finite number), each shape (m,); at rest outside [0, T]."""
        k = self._segment(t)
        local = float(np.clip(t - self.times[k], 0.0, self.durations[k]))
        seg = self.segments[k]
        xi = np.asarray(seg(local), dtype=np.float64)
        moving = 0.0 <= t <= self.duration
        v = np.asarray(seg(local, 1), dtype=np.float64) * moving
        a = np.asarray(seg(local, 2), dtype=np.float64) * moving
        return Reference(self.mechanism.retract(self.waypoints[k], xi, validate=False), v, a)
