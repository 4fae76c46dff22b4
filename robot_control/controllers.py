"""Classical controllers: resolved-rate, singularity-aware resolved-rate, the planner and computed torque (NumPy).

They read only the observation (as a policy does) and are batched: observations (N, D) → actions (N, n), for
any robot of the family.
They use the kinematics library for J_i and the inverse condition number; nothing is re-derived here.
``CONTROLLERS`` names them for the evaluation (``training.evaluate --controller``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from envs.kernels.force import actions_of_efforts
from envs.kernels.packing import observation_layout
from envs.params import FamilyParams
from envs.physics import wrap_angle
from robot_control.planner import PathFollower

__all__ = [
    "CONTROLLERS",
    "DAMPING_FLOOR",
    "ComputedTorqueAgent",
    "PlannerController",
    "ResolvedRateController",
    "SingularityAwareController",
    "damping_factor",
    "decode_observation",
    "pose_error",
]

#: The least speed factor of the planner's damping near a Type II band (``damping_factor``).
DAMPING_FLOOR = 0.05


def damping_factor(k: np.ndarray, threshold: float) -> np.ndarray:
    """The speed factor f = clip((k / k_d)², ``DAMPING_FLOOR``, 1) of ``PlannerController``'s damping.

    Args:
        k: Inverse condition numbers of J_x, any shape, in [0, 1].
        threshold: k_d, the k below which the factor falls below 1, in (0, 1].

    Returns:
        f, the shape of ``k``, float64.
    """
    return np.clip((np.asarray(k, dtype=np.float64) / threshold) ** 2, DAMPING_FLOOR, 1.0)


def decode_observation(params: FamilyParams, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pose, exact error and target velocity from observations (the layout of ``envs.FamilyReachEnv``'s docstring).

    Args:
        params: Environment constants.
        obs: Observations, shape (N, D).

    Returns:
        (pose (N, m); error (N, m): (p* − p, δθ) with δθ the rotation vector of R* Rᵀ in {B}, planar
        (x* − x, y* − y, wrap(φ* − φ)), translational p* − p; target velocity (N, m), zeros for Reach).
    """
    robot = params.robot
    layout = observation_layout(robot.pose_space.name, robot.n_actuators, True, force=params.control == "force")
    obs = np.asarray(obs, dtype=np.float64)
    pose = _decode_pose(robot.pose_space.name, obs[:, layout["pose"]])
    error = obs[:, layout["error"]]
    velocity_slice = layout["target_velocity"]
    codes = 2 * robot.base.shape[1] ** 2 if params.geometry_variation else 0  # a known geometry's codes end it
    with_velocity = obs.shape[1] - codes >= velocity_slice.stop
    velocity = obs[:, velocity_slice] if with_velocity else np.zeros_like(pose)
    return pose, error, velocity


def pose_error(params: FamilyParams, pose: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """The twist error from ``pose`` to ``goal`` (each (N, m), the env's pose coordinates), shape (N, m).

    As the observation's error block: the kinematics library's ``pose_difference`` (spatial (δp, δθ) with δθ the
    rotation vector of R_goal Rᵀ in {B}, translational δp), with planar δφ wrapped to (−π, π].
    """
    error = params.robot.pose_difference(np.asarray(goal, dtype=float), np.asarray(pose, dtype=float), validate=False)
    if params.robot.pose_space.name == "planar":
        error[..., 2] = wrap_angle(error[..., 2])
    return error


class ResolvedRateController:
    """q̇ = J_i(x) v, v = ẋ* + K e: a straight geodesic toward the target, for any robot of the family.

    e is the exact twist error of the observation (``decode_observation``); the feedback K e is capped at
    ``max_speed`` in (δp, ℓ_c δθ) (the reference's own rate ẋ* is fed forward uncapped). An actuator at a hard
    stop is not driven into it (the platform velocity is projected, in (p, ℓ_c θ), off that actuator's row of
    J_i), and q̇ is scaled down as a whole when an actuator would exceed ``max_rate``, so the platform keeps its
    direction. J_i comes from the kinematics library.

    Args:
        params: Environment constants (``envs.params.FamilyParams``).
        gain: K [1/s].
        max_speed: Cap on the scaled feedback speed [m/s].
    """

    name = "resolved-rate"

    def __init__(self, params: FamilyParams, gain: float = 2.0, max_speed: float = 0.25) -> None:
        if params.control != "rate":
            raise ValueError(f"{self.name} commands stroke rates (control='rate'); use computed-torque under force")
        self.params = params
        self.gain = float(gain)
        self.max_speed = float(max_speed)

    def desired_velocity(self, pose: np.ndarray, error: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        """Pose velocity the controller asks for, shape (N, m): ẋ* + K e with K e capped."""
        return velocity + self._cap(self.gain * error)

    def _cap(self, v: np.ndarray) -> np.ndarray:
        speed = np.linalg.norm(v * self.params.pose_metric, axis=-1, keepdims=True)
        return v / np.maximum(speed / self.max_speed, 1.0)

    def _respect_stroke_limits(self, q: np.ndarray, J_i: np.ndarray, x_dot: np.ndarray) -> np.ndarray:
        """q̇ = J_i ẋ, with ẋ projected (in (p, ℓ_c θ)) so that no actuator at a hard stop is driven into it."""
        lo, hi = self.params.stroke_limits
        scale = self.params.pose_metric
        vz = x_dot * scale
        rows = J_i / scale  # q̇_i = rows_i · v_z
        for i in range(q.shape[-1]):
            rate = np.sum(rows[:, i] * vz, axis=-1)
            blocked = ((q[:, i] <= lo + 1e-3) & (rate < 0)) | ((q[:, i] >= hi - 1e-3) & (rate > 0))
            r = rows[:, i]
            vz = np.where(blocked[:, None], vz - (rate / np.sum(r * r, axis=-1))[:, None] * r, vz)
        return np.einsum("nij,nj->ni", J_i, vz / scale)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """Normalised actuator rates in [−1, 1] for a batch of observations (N, D): shape (N, n), float32."""
        return self.act(*decode_observation(self.params, obs))

    def act(self, pose: np.ndarray, error: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        """Actions from ``pose`` along the twist error ``error`` with feed-forward ``velocity`` (each (N, m))."""
        robot = self.params.robot
        q = robot.inverse_kinematics(pose, validate=False)
        x_dot = self.desired_velocity(pose, error, velocity)
        J_i = robot.inverse_jacobian(q, pose, validate=False)
        q_dot = self._commanded_rates(pose, q, J_i, self._respect_stroke_limits(q, J_i, x_dot))
        a = q_dot / self.params.max_rate
        a /= np.maximum(np.max(np.abs(a), axis=-1, keepdims=True), 1.0)
        return a.astype(np.float32)

    def _commanded_rates(self, pose: np.ndarray, q: np.ndarray, J_i: np.ndarray, q_dot: np.ndarray) -> np.ndarray:
        """The actuator rates (N, n) sent for the resolved rates ``q_dot`` = J_i ẋ at (``pose``, ``q``): themselves."""
        return q_dot


class SingularityAwareController(ResolvedRateController):
    """Resolved-rate with a damped detour around the ill-conditioned zone.

    In the scaled pose space z = (p, ℓ_c θ), where the inverse condition number k falls below
    ``margin`` · k_safe the component of the desired velocity that would lower k is removed (the robot
    slides along the level set of k) and a push up the gradient of k is added, growing as k falls:

        v ← max(k/k_m, f_min) (v − min(0, v·n) n + β ((k_m − k)/k_m)₊ n),
        n = ∇_z k / ‖∇_z k‖,  k_m = margin · k_safe.

    The gradient comes from central differences of the kinematics library's inverse condition number.

    Args:
        params: Environment constants.
        gain: K [1/s].
        max_speed: Cap on the scaled platform speed [m/s].
        margin: Multiple of the safe threshold where the detour starts.
        push: β [m/s], speed of the push at k = 0.
        min_speed_fraction: Smallest fraction of the speed kept near the zone (the speed is scaled by
            k / k_m, the damping of the detour).
        step: Finite-difference step in z [m].
    """

    name = "singularity-aware"

    def __init__(
        self,
        params: FamilyParams,
        gain: float = 2.0,
        max_speed: float = 0.25,
        margin: float = 2.0,
        push: float = 0.3,
        min_speed_fraction: float = 0.2,
        step: float = 1e-4,
    ) -> None:
        super().__init__(params, gain, max_speed)
        self.margin, self.push, self.step = float(margin), float(push), float(step)
        self.min_speed_fraction = float(min_speed_fraction)

    def _k(self, pose: np.ndarray) -> np.ndarray:
        """The inverse condition number k at poses (N, m); NaN where a crank or slider cannot reach the pose."""
        robot = self.params.robot
        q = robot.inverse_kinematics(pose, validate=False)
        if all(kind == "leg" for kind in robot.actuator_kinds):
            q = np.maximum(q, 1e-9)
        k = np.full(len(pose), np.nan)
        reached = np.all(np.isfinite(q), axis=-1)
        if reached.any():
            k[reached] = robot.inverse_condition_number(q[reached], pose[reached], validate=False)
        return k

    def desired_velocity(self, pose: np.ndarray, error: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        """Resolved-rate velocity with the detour term, shape (N, m)."""
        v = self._cap(super().desired_velocity(pose, error, velocity))
        scale = self.params.pose_metric
        k = self._k(pose)
        k_m = self.margin * self.params.safe_threshold
        near = k < k_m
        if not np.any(near):
            return v
        p = pose[near]
        grad = np.empty_like(p)
        for j in range(p.shape[-1]):
            dz = np.zeros(p.shape[-1])
            dz[j] = self.step / scale[j]
            grad[:, j] = (self._k(p + dz) - self._k(p - dz)) / (2.0 * self.step)
        grad = np.nan_to_num(grad)  # out of reach on one side: no push along that coordinate
        n = grad / np.maximum(np.linalg.norm(grad, axis=-1, keepdims=True), 1e-12)
        vz = v[near] * scale
        into = np.minimum(np.sum(vz * n, axis=-1, keepdims=True), 0.0)
        strength = np.clip((k_m - k[near]) / k_m, 0.0, 1.0)[:, None]
        vz = vz - into * n + self.push * strength * n
        # Damping: slow down as k falls, so one step cannot carry the robot across the fold.
        slow = np.clip(k[near] / k_m, self.min_speed_fraction, 1.0)[:, None]
        v[near] = slow * vz / scale
        return v


class PlannerController(ResolvedRateController):
    """Follow a planned safe path (``robot_control.planner``) with resolved-rate control: the ceiling on hard targets.

    At the first observation of an episode (a new target, or a pose jump no control period can make) it
    plans a certified path from the pose to the target (``robot_control.planner.SafeGraph``). Then it steers, with
    ``ResolvedRateController``'s law, speed cap and stroke-limit handling, toward the carrot of
    ``robot_control.planner.PathFollower``: ``lookahead`` ahead of the platform's closest point on the path, and the
    target once the carrot reaches it. Where no certified path exists it drives straight, as resolved-rate.
    Near a thin Type II band a step at full speed leaves a certified line by millimetres where k falls by a
    third (the 3-RRR): with ``damping`` the action a is slowed by f = clip((k / k_d)², 0.05, 1) (``damping_factor``),
    k the observed one and k_d the ``damping_threshold`` (default the env's k_safe): with ``damping_kind``
    "scale" a ← f a (the gain falls too, to f K at an ill-conditioned target), with "cap" a ← a · min(1, f / ‖a‖∞)
    (the largest actuator rate is capped at f of its range; small corrections near the target keep the full gain K),
    and with ``cross_track`` a one-segment plan is followed as any other (``robot_control.planner.PathFollower``).
    With ``exact_step`` the rates are the secant ones, (IK(x ⊕ ẋ dt) − q) / dt with ẋ the platform twist of the
    (scaled) resolved rates, instead of J_i ẋ: a step at full rate then lands on the pose it aims at, where the
    first-order step is off by its second-order term (at full crank rate the 3-RRR's platform can turn several
    times the commanded angle in one period, 3.7 times on the first step of the hard episode of reset seed 1032,
    and drift off a certified path into the Type II band).

    Args:
        params: Environment constants.
        gain: K [1/s].
        max_speed: Cap on the scaled platform speed [m/s].
        lookahead: Distance of the carrot ahead of the closest point of the path, in z [m].
        follower: A ``robot_control.planner.PathFollower`` to share (its own lookahead and planner then apply);
            default a new one.
        planner: The follower's planner: "auto" (the certified grid's graph where there is one, else OMPL),
            "ompl" or "grid".
        cross_track: The follower's ``cross_track``: steer along one-segment plans too (``robot_control.planner``).
        damping: Slow down as the observed k falls below k_d (see above).
        damping_threshold: k_d, the k below which the damping slows down, in (0, 1]; None: ``params.safe_threshold``.
        damping_kind: "scale" or "cap" (see above).
        replan_distance: The follower's ``replan_distance`` [m]: plan afresh whenever the platform is farther than
            this from its path; None: once per episode (with a ``follower`` given, the follower's own applies).
        exact_step: Command the secant rates to the pose one period on (see above); False: J_i ẋ.

    Raises:
        ValueError: If ``damping_threshold`` is not in (0, 1], ``damping_kind`` is unknown or ``replan_distance``
            is not a positive distance.
    """

    name = "planner"

    def __init__(
        self,
        params: FamilyParams,
        gain: float = 2.0,
        max_speed: float = 0.25,
        lookahead: float = 0.1,
        follower=None,
        planner: str = "auto",
        cross_track: bool = True,
        damping: bool = True,
        damping_threshold: float | None = None,
        damping_kind: str = "scale",
        replan_distance: float | None = None,
        exact_step: bool = True,
    ) -> None:
        super().__init__(params, gain, max_speed)
        self.damping = bool(damping)
        self.exact_step = bool(exact_step)
        if damping_threshold is None:
            damping_threshold = params.safe_threshold
        if not 0.0 < damping_threshold <= 1.0:
            raise ValueError(f"damping_threshold must be in (0, 1], got {damping_threshold}")
        self.damping_threshold = float(damping_threshold)
        if damping_kind not in ("scale", "cap"):
            raise ValueError(f"damping_kind must be 'scale' or 'cap', got {damping_kind!r}")
        self.damping_kind = damping_kind
        layout = observation_layout(params.robot.pose_space.name, params.robot.n_actuators, False)
        self._k_column = layout["k"].start
        if follower is None:
            follower = PathFollower(params, lookahead, planner, replan_distance, cross_track=cross_track)
        self.follower = follower

    @property
    def log(self) -> Sequence:
        """The plans made, in order (the last ``robot_control.planner.LOG_LENGTH``)."""
        return self.follower.log

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """Actions for a batch of observations (row i is followed along its own plan), shape (N, n), float32."""
        pose, error, velocity = decode_observation(self.params, obs)
        target = self._target(pose, error)
        carrot = np.stack([self.follower.carrot(i, pose[i], target[i]) for i in range(len(pose))])
        action = self.steer(pose, carrot, velocity)
        if self.damping:
            k = np.asarray(obs, dtype=np.float64)[:, self._k_column]
            factor = damping_factor(k, self.damping_threshold)[:, None]
            if self.damping_kind == "cap":
                largest = np.max(np.abs(action), axis=-1, keepdims=True)
                factor = np.minimum(1.0, factor / np.maximum(largest, 1e-12))
            action = action * factor.astype(np.float32)
        return action

    def _target(self, pose: np.ndarray, error: np.ndarray) -> np.ndarray:
        """The target pose from the pose and the observation's error block (each (N, m))."""
        return _target_pose(self.params, pose, error)

    def steer(self, pose: np.ndarray, carrot: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        """Resolved-rate actions from ``pose`` toward ``carrot`` (each (N, m)) with feed-forward ``velocity``."""
        return self.act(pose, pose_error(self.params, pose, carrot), velocity)

    def _commanded_rates(self, pose: np.ndarray, q: np.ndarray, J_i: np.ndarray, q_dot: np.ndarray) -> np.ndarray:
        """With ``exact_step``, the secant rates to the pose the resolved rates (scaled to the rate limit) aim at."""
        if not self.exact_step:
            return q_dot
        robot, dt = self.params.robot, self.params.dt
        q_dot = q_dot / np.maximum(np.max(np.abs(q_dot), axis=-1, keepdims=True) / self.params.max_rate, 1.0)
        twist = np.einsum("nij,nj->ni", np.linalg.pinv(J_i), q_dot)  # the platform twist of these rates
        secant = (robot.inverse_kinematics(robot.retract(pose, twist * dt, validate=False), validate=False) - q) / dt
        return np.where(np.all(np.isfinite(secant), axis=-1, keepdims=True), secant, q_dot)

    def episode_metrics(self, row: int | None = None) -> dict[str, float] | None:
        """The last plan's figures (path found, planned / straight length, min k, planning time), or None.

        Args:
            row: The batch row whose current plan to describe; None: the last plan made.
        """
        return self.follower.last_plan_metrics(row)


def _target_pose(params: FamilyParams, pose: np.ndarray, error: np.ndarray) -> np.ndarray:
    """The target pose from the pose and the observation's error block (each (N, m))."""
    if params.robot.pose_space.name != "spatial":
        return pose + error
    return params.robot.retract(pose, error, validate=False)


def _decode_pose(space: str, code: np.ndarray) -> np.ndarray:
    """Poses (N, m) from the observation's pose codes (N, ·): spatial (p, quaternion), planar (x, y, cos, sin)."""
    from scipy.spatial.transform import Rotation

    if space == "spatial":
        quat = code[:, [4, 5, 6, 3]]  # SciPy's (x, y, z, w)
        return np.concatenate([code[:, :3], Rotation.from_quat(quat).as_rotvec()], axis=-1)
    if space == "translational":
        return code.copy()
    return np.stack([code[:, 0], code[:, 1], np.arctan2(code[:, 3], code[:, 2])], axis=-1)


class ComputedTorqueAgent:
    """Computed torque (``robot_control.computed_torque``) on a force-control env, from its observations alone.

    The pose, the target, the twist ẋ and (Track) the target's velocity are read from the observation; the
    efforts are those of ``ComputedTorqueController`` with the env's model and drive limits,
    K_p = ω², K_d = 2 ω, and the action is their offset from the holding forces in units of the limits,
    a = (τ − τ_h) / τ_max, clipped to [−1, 1]. The reference acceleration is zero (a fixed target, or the Track
    target's velocity fed forward).

    Args:
        params: Environment constants of a force-control env.
        bandwidth: ω [rad/s] of the error dynamics.
    """

    name = "computed-torque"

    def __init__(self, params: FamilyParams, bandwidth: float = 4.0) -> None:
        from robot_control.computed_torque import ComputedTorqueController

        if params.control != "force":
            raise ValueError("computed-torque commands efforts (control='force'), not stroke rates")
        self.params = params
        self.controller = ComputedTorqueController.critically_damped(
            params.robot, params.dynamics.inertia, bandwidth=bandwidth, force_limits=params.force_limits
        )
        robot = params.robot
        self._layout = observation_layout(robot.pose_space.name, robot.n_actuators, True, force=True)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """Normalised efforts in [−1, 1] for a batch of observations (N, D): shape (N, n), float32."""
        params, robot = self.params, self.params.robot
        obs = np.asarray(obs, dtype=np.float64)
        pose, error, velocity = decode_observation(params, obs)
        target, velocity = self._reference(obs, pose, error, velocity)
        q = robot.inverse_kinematics(pose, validate=False)
        twist = obs[:, self._layout["twist"]]
        command = self.controller.compute(q, pose, twist, target, velocity, self._acceleration(obs))
        hold = params.dynamics.holding_forces(q, pose)
        return actions_of_efforts(hold, command.tau, params.force_limit_array).astype(np.float32)

    def _reference(self, obs, pose, error, velocity) -> tuple[np.ndarray, np.ndarray]:
        """(x_d, ẋ_d) of each row (N, m): the observed target and its velocity."""
        return _decode_pose(self.params.robot.pose_space.name, obs[:, self._layout["target"]]), velocity

    def _acceleration(self, obs: np.ndarray) -> np.ndarray | None:
        """ẍ_d of each row (N, m) fed forward, or None: zero (the observation holds no acceleration)."""
        return None


class PlannerComputedTorqueAgent(ComputedTorqueAgent):
    """Computed torque toward the carrot of the planner's certified path (``PathFollower``): hard targets.

    As ``ComputedTorqueAgent`` with the reference pose the carrot, ``lookahead`` ahead of the platform's closest
    point on the path planned at the episode's first observation (``PlannerController``'s follower, with
    ``cross_track``), and the target once the carrot reaches it; the reference velocity is zero.

    Args:
        params: Environment constants of a force-control env.
        bandwidth: ω [rad/s] of the error dynamics.
        lookahead: The carrot's distance ahead on the path, in z [m].
        planner: "auto", "ompl" or "grid" (``PathFollower``).
        replan_distance: The follower's ``replan_distance`` [m]: plan afresh whenever the platform is farther than
            this from its path; None: once per episode.
    """

    name = "planner-computed-torque"

    def __init__(
        self,
        params: FamilyParams,
        bandwidth: float = 4.0,
        lookahead: float = 0.1,
        planner: str = "auto",
        replan_distance: float | None = None,
    ) -> None:
        super().__init__(params, bandwidth)
        self.follower = PathFollower(params, lookahead, planner, replan_distance, cross_track=True)

    @property
    def log(self) -> Sequence:
        """The plans made, in order (the last ``robot_control.planner.LOG_LENGTH``)."""
        return self.follower.log

    def _reference(self, obs, pose, error, velocity) -> tuple[np.ndarray, np.ndarray]:
        """(x_d, ẋ_d) of each row (N, m): the carrot of its planned path, at rest."""
        target = _target_pose(self.params, pose, error)
        carrot = np.stack([self.follower.carrot(i, pose[i], target[i]) for i in range(len(pose))])
        return carrot, np.zeros_like(carrot)

    def episode_metrics(self, row: int | None = None) -> dict[str, float] | None:
        """The last plan's figures (``PlannerController.episode_metrics``)."""
        return self.follower.last_plan_metrics(row)


#: Controllers by command-line name.
CONTROLLERS = {
    cls.name: cls
    for cls in (
        ResolvedRateController,
        SingularityAwareController,
        PlannerController,
        ComputedTorqueAgent,
        PlannerComputedTorqueAgent,
    )
}
