"""The Gymnasium environments Planar3RPRReach-v0 and Planar3RPRTrack-v0 (single robot)."""

from __future__ import annotations

import inspect
import math
from collections import deque
from collections.abc import Sequence
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from envs import core, kernels
from envs.core import EnvParams, Reference, State
from envs.rendering import HumanWindow, render_frame
from envs.tasks import is_safe, sample_reach, sample_track
from envs.workspace import WorkspaceMap, WorkspaceSpec, certify_workspace
from kinematics import Planar3RPR

__all__ = ["Planar3RPREnvBase", "Planar3RPRReachEnv", "Planar3RPRTrackEnv", "build_params"]

_TARGET_MODES = ("standard", "hard", "mixed")
_INTEGRATORS = ("euler", "rk4")
#: Platform positions kept for the rendered trail.
TRAIL_LENGTH = 200


def _number(name: str, value: Any, *, positive: bool = True, allow_zero: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__} {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if positive and (value < 0 or (value == 0 and not allow_zero)):
        bound = "≥ 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be {bound}, got {value!r}")
    return value


def _pair(name: str, value: Any, size: int) -> tuple[float, ...]:
    arr = np.asarray(value, dtype=object)
    if arr.shape != (size,):
        raise ValueError(f"{name} must be a sequence of {size} numbers, got {value!r}")
    return tuple(_number(f"{name}[{i}]", v, positive=False) for i, v in enumerate(arr))


def build_params(
    *,
    base: Any = None,
    platform: Any = None,
    characteristic_length: float | None = None,
    stroke_limits: tuple[float, float] = EnvParams.stroke_limits,
    pose_low: tuple[float, float, float] = EnvParams.pose_low,
    pose_high: tuple[float, float, float] = EnvParams.pose_high,
    dt: float = EnvParams.dt,
    max_rate: float = EnvParams.max_rate,
    integrator: str = EnvParams.integrator,
    safe_threshold: float = EnvParams.safe_threshold,
    hard_threshold: float = EnvParams.hard_threshold,
    position_weight: float = EnvParams.position_weight,
    orientation_weight: float = EnvParams.orientation_weight,
    singularity_weight: float = EnvParams.singularity_weight,
    action_weight: float = EnvParams.action_weight,
    termination_penalty: float = EnvParams.termination_penalty,
    success_position_tolerance: float = EnvParams.success_position_tolerance,
    success_orientation_tolerance: float = EnvParams.success_orientation_tolerance,
    jump_tolerance: float = EnvParams.jump_tolerance,
    newton_max_iterations: int = EnvParams.newton_max_iterations,
    track_period: float = EnvParams.track_period,
) -> EnvParams:
    """Validate constructor arguments and gather them into ``EnvParams`` (see the env docstrings).

    Returns:
        The validated, frozen parameters.

    Raises:
        TypeError: On an argument of the wrong type.
        ValueError: On an argument out of its range, naming the expected and the actual value.
    """
    robot = Planar3RPR(base=base, platform=platform, characteristic_length=characteristic_length)
    lo, hi = _pair("stroke_limits", stroke_limits, 2)
    if not 0 < lo < hi:
        raise ValueError(f"stroke_limits must satisfy 0 < L_min < L_max, got {(lo, hi)}")
    low, high = _pair("pose_low", pose_low, 3), _pair("pose_high", pose_high, 3)
    if not all(a < b for a, b in zip(low, high)):
        raise ValueError(f"pose_low must be < pose_high componentwise, got {low} and {high}")
    if not (-np.pi <= low[2] and high[2] <= np.pi):
        raise ValueError(f"the φ bounds must lie in [−π, π], got ({low[2]}, {high[2]})")
    if integrator not in _INTEGRATORS:
        raise ValueError(f"integrator must be one of {_INTEGRATORS}, got {integrator!r}")
    safe = _number("safe_threshold", safe_threshold)
    hard = _number("hard_threshold", hard_threshold)
    if not 0 < hard < safe < 1:
        raise ValueError(f"thresholds must satisfy 0 < hard_threshold < safe_threshold < 1, got {hard} and {safe}")
    if isinstance(newton_max_iterations, bool) or not isinstance(newton_max_iterations, (int, np.integer)):
        raise TypeError(f"newton_max_iterations must be an int, got {newton_max_iterations!r}")
    if newton_max_iterations < 1:
        raise ValueError(f"newton_max_iterations must be ≥ 1, got {newton_max_iterations}")
    return EnvParams(
        robot=robot,
        stroke_limits=(lo, hi),
        dt=_number("dt", dt),
        max_rate=_number("max_rate", max_rate),
        integrator=integrator,
        pose_low=low,
        pose_high=high,
        safe_threshold=safe,
        hard_threshold=hard,
        position_weight=_number("position_weight", position_weight, allow_zero=True),
        orientation_weight=_number("orientation_weight", orientation_weight, allow_zero=True),
        singularity_weight=_number("singularity_weight", singularity_weight, allow_zero=True),
        action_weight=_number("action_weight", action_weight, allow_zero=True),
        termination_penalty=_number("termination_penalty", termination_penalty, allow_zero=True),
        success_position_tolerance=_number("success_position_tolerance", success_position_tolerance),
        success_orientation_tolerance=_number("success_orientation_tolerance", success_orientation_tolerance),
        jump_tolerance=_number("jump_tolerance", jump_tolerance),
        newton_max_iterations=int(newton_max_iterations),
        track_period=_number("track_period", track_period),
    )


def _build_params_arguments(arguments: dict[str, Any]) -> dict[str, Any]:
    """The constructor arguments that ``build_params`` takes, picked from an ``__init__``'s ``locals()``."""
    return {name: arguments[name] for name in inspect.signature(build_params).parameters if name in arguments}


def workspace_for(params: EnvParams) -> WorkspaceMap:
    """The certified workspace of an environment's geometry, limits and safe threshold (cached).

    Args:
        params: Environment constants.

    Returns:
        The ``WorkspaceMap``.
    """
    return certify_workspace(
        WorkspaceSpec(
            robot=params.robot,
            stroke_limits=params.stroke_limits,
            pose_low=params.pose_low,
            pose_high=params.pose_high,
            safe_threshold=params.safe_threshold,
        )
    )


def initial_state(params: EnvParams, start: np.ndarray, reference: Reference) -> State:
    """State of N robots at rest at ``start``, strokes from the inverse kinematics.

    Args:
        params: Environment constants.
        start: Starting poses, shape (N, 3).
        reference: Target trajectories of the N robots.

    Returns:
        The state at t = 0.
    """
    start = np.ascontiguousarray(start, dtype=np.float64)
    q, k, det_sign, residual = kernels.initial_batch(params.packed, start)
    return State(
        q=q,
        x=start.copy(),
        t=np.zeros(len(start), dtype=np.int64),
        det_sign=det_sign,
        inverse_condition=k,
        residual=residual,
        reference=reference,
    )


def step_info(
    state: Any, evaluation: np.ndarray, reason: np.ndarray, rows: dict[str, Any] | None = None
) -> dict[str, np.ndarray]:
    """Per-robot diagnostics of a state (batched): reward terms, errors, conditioning, success, cost.

    Args:
        state: The robots' state after the step (kept for a uniform signature).
        evaluation: ``core.evaluate`` / ``core.step`` output for that state, shape (E, N).
        reason: Termination reason codes, shape (N,).
        rows: The evaluation's row layout; default ``core.EVALUATION_ROWS`` (the family core passes its own).

    Returns:
        Fresh arrays with a leading dimension N, in the order of the single env's ``info``.
    """
    rows = core.EVALUATION_ROWS if rows is None else rows
    info = {name: evaluation[rows[name]].copy() for name in INFO_KEYS[:8]}
    info["is_success"] = evaluation[rows["is_success"]] != 0.0
    info["cost"] = evaluation[rows["cost"]].copy()
    info["termination_reason"] = _REASON_NAMES[reason]
    info["pose"] = evaluation[rows["pose"]].T.copy()
    info["target"] = evaluation[rows["target"]].T.copy()
    return info


#: Termination reason names as an object array (indexed by reason codes).
_REASON_NAMES = np.asarray(core.TERMINATION_REASONS, dtype=object)
#: The keys of an env's ``info``, in order.
INFO_KEYS = (
    "reward_tracking",
    "reward_singularity",
    "reward_action",
    "reward_termination",
    "position_error",
    "orientation_error",
    "inverse_condition_number",
    "constraint_residual",
    "is_success",
    "cost",
    "termination_reason",
    "pose",
    "target",
)
# Evaluation rows the single env reads (module constants: the step reads them without lookups).
_E_TRACKING, _E_SINGULARITY, _E_ACTION, _E_TERMINATION = (core.EVALUATION_ROWS[k] for k in INFO_KEYS[:4])
_E_POSITION_ERROR, _E_ORIENTATION_ERROR = kernels.E_POSITION_ERROR, kernels.E_ORIENTATION_ERROR
_E_K, _E_RESIDUAL, _E_SUCCESS, _E_COST = kernels.E_K, kernels.E_RESIDUAL, kernels.E_SUCCESS, kernels.E_COST
_E_REWARD = kernels.E_REWARD
_E_POSE = slice(kernels.E_POSE, kernels.E_POSE + 3)
_E_TARGET = slice(kernels.E_TARGET, kernels.E_TARGET + 3)
_E_XY = slice(kernels.E_POSE, kernels.E_POSE + 2)


class Planar3RPREnvBase(gym.Env[np.ndarray, np.ndarray]):
    """Shared machinery of the single-robot 3-RPR environments; see the concrete classes for the documentation."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["human", "rgb_array"], "render_fps": 20}
    #: Whether the observation ends with the target velocity (Track).
    with_velocity = False
    #: The keys ``reset(options=...)`` accepts.
    reset_options: tuple[str, ...] = ()
    #: The pure functions of this env's physics (the shield and the HER goal view call them).
    physics = core

    def _setup(self, render_mode: str | None, params: EnvParams) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        self.render_mode = render_mode
        self.params = params
        self.metadata = {**type(self).metadata, "render_fps": 1.0 / params.dt}
        self.workspace = workspace_for(params)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)
        low, high = core.observation_bounds(params, self.with_velocity)
        self.observation_space = spaces.Box(low.copy(), high.copy(), dtype=np.float32)
        self._state: State | None = None
        # Two sets of step outputs, used in turn: a step never writes over the state it starts from.
        self._buffers = (core.StepBuffers(1, self.with_velocity), core.StepBuffers(1, self.with_velocity))
        self._next = 0
        self._terminated = False
        self._trail: deque[np.ndarray] = deque(maxlen=TRAIL_LENGTH)
        self._window: HumanWindow | None = None

    # -- the Gymnasium API ----------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start a new episode (see the class docstring, Starting State)."""
        super().reset(seed=seed)
        options = {} if options is None else options
        if not isinstance(options, dict):
            raise TypeError(f"options must be a dict or None, got {type(options).__name__}")
        unknown = set(options) - set(self.reset_options)
        if unknown:
            raise ValueError(f"unknown reset option(s) {sorted(unknown)}; valid options are {list(self.reset_options)}")
        start, reference = self.sample_task(options)
        self._state = initial_state(self.params, start, reference)
        self._terminated = False
        self._trail.clear()
        self._trail.append(self._state.x[0, :2].copy())
        reason = np.zeros(1, dtype=np.int64)
        evaluation, observations = core.evaluate(self.params, self._state, np.zeros((1, 3)), reason, self.with_velocity)
        info = self._info(evaluation[:, 0], 0)
        if self.render_mode == "human":
            self.render()
        return observations[0], info

    def step(self, action: Any):
        """Apply normalised stroke rates for one period dt (see the class docstring)."""
        if self._state is None:
            raise gym.error.ResetNeeded("Cannot call step() before reset()")
        if self._terminated:
            raise gym.error.ResetNeeded("The episode has terminated; call reset() before step()")
        a = self._check_action(action)
        out = self._buffers[self._next]  # not the one holding self._state
        state, outcome, evaluation, observations = core.step(self.params, self._state, a, self.with_velocity, out)
        self._next ^= 1
        self._state = state
        reason = int(outcome.reason[0])
        terminated = reason != 0
        self._terminated = terminated
        row = evaluation[:, 0]
        info = self._info(row, reason)
        self._trail.append(info["pose"][:2])
        if self.render_mode == "human":
            self.render()
        return observations[0].copy(), float(row[_E_REWARD]), terminated, False, info

    def render(self):
        """An RGB frame (``rgb_array``), or a window update (``human``); None without a render mode."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array' or 'human'")
            return None
        if self._state is None:
            raise gym.error.ResetNeeded("Cannot call render() before reset()")
        frame = render_frame(
            self.params,
            self._state.q[0],
            self._state.x[0],
            self._reference()[0][0],
            float(self._state.inverse_condition[0]),
            trail=list(self._trail),
            step=int(self._state.t[0]),
        )
        if self.render_mode == "rgb_array":
            return frame
        if self._window is None:
            self._window = HumanWindow(self.metadata["render_fps"])
        self._window.show(frame)
        return None

    def close(self) -> None:
        """Close the human window if one is open."""
        if self._window is not None:
            self._window.close()
            self._window = None

    # -- helpers ----------------------------------------------------------------------------------

    @property
    def state(self) -> State | None:
        """A copy of the current batched state (N = 1), or None before the first reset.

        The environment reuses its own arrays from step to step; the copy is yours to keep.
        """
        state = self._state
        return None if state is None else core.copy_state(state)

    def _reference(self) -> tuple[np.ndarray, np.ndarray]:
        return core.reference_pose(self.params, self._state.reference, self._state.t)

    def _info(self, row: np.ndarray, reason: int) -> dict[str, Any]:
        """The single env's ``info`` from its evaluation row (same keys and values as ``step_info``)."""
        v = row.tolist()
        return {
            "reward_tracking": v[_E_TRACKING],
            "reward_singularity": v[_E_SINGULARITY],
            "reward_action": v[_E_ACTION],
            "reward_termination": v[_E_TERMINATION],
            "position_error": v[_E_POSITION_ERROR],
            "orientation_error": v[_E_ORIENTATION_ERROR],
            "inverse_condition_number": v[_E_K],
            "constraint_residual": v[_E_RESIDUAL],
            "is_success": v[_E_SUCCESS] != 0.0,
            "cost": v[_E_COST],
            "termination_reason": core.TERMINATION_REASONS[reason],
            "pose": row[_E_POSE].copy(),
            "target": row[_E_TARGET].copy(),
        }

    @staticmethod
    def _check_action(action: Any) -> np.ndarray:
        """``action`` as a float64 array of shape (1, 3), or a clear error (wrong shape, not numbers).

        Finiteness is checked by ``core.step`` (in the compiled pass), which raises a ValueError.
        """
        try:
            a = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"action must be an array of 3 real numbers, got {action!r}") from exc
        if a.shape != (3,):
            raise ValueError(f"action must have shape (3,), got shape {a.shape}")
        return a.reshape(1, 3)

    def _check_pose(self, name: str, value: Any) -> np.ndarray:
        try:
            pose = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"options[{name!r}] must be a pose (x, y, φ), got {value!r}") from exc
        if pose.shape != (3,) or not np.all(np.isfinite(pose)):
            raise ValueError(f"options[{name!r}] must be a finite pose of shape (3,), got {value!r}")
        if not is_safe(self.params, self.workspace, pose[None])[0]:
            raise ValueError(
                f"options[{name!r}] = {pose.tolist()} is not in the certified safe workspace "
                "(strokes within limits, inverse condition number ≥ safe_threshold)"
            )
        return pose

    def sample_task(self, options: dict[str, Any]) -> tuple[np.ndarray, Reference]:
        """Draw a start pose and a target reference with ``self.np_random`` (validated ``options``).

        Args:
            options: The ``reset`` options (keys from ``reset_options``).

        Returns:
            (start pose of shape (1, 3), the target reference of one robot).
        """
        return self.sample_tasks((self.np_random,), options)

    def sample_tasks(
        self, generators: Sequence[np.random.Generator], options: dict[str, Any]
    ) -> tuple[np.ndarray, Reference]:
        """Draw one task per generator, in one compiled call (the vector env's episode starts).

        Task i is the one this env's ``sample_task`` draws when ``np_random`` is ``generators[i]``.

        Args:
            generators: M generators, one per task; each advances as in ``sample_task``.
            options: The ``reset`` options (keys from ``reset_options``), the same for every task.

        Returns:
            (start poses of shape (M, 3), the target references of M robots).
        """
        raise NotImplementedError


class Planar3RPRReachEnv(Planar3RPREnvBase):
    r"""Reach a target pose with a planar 3-RPR parallel robot, and hold it, away from singularities.

    ## Description
    A planar 3-RPR robot (lesson §5): three legs join base anchors B_i (fixed frame {B}) to platform
    points P_i (frame {P}); the strokes q = (L_1, L_2, L_3) [m] are actuated. The platform pose
    x = (x, y, φ) is defined implicitly by Φ_i = ‖p + R(φ) P_i − B_i‖² − L_i² = 0. Each step, the
    strokes move at the commanded rates; the pose follows through ẋ = J_f q̇ with J_f = −J_x⁻¹ J_q
    (Euler or RK4) and is corrected onto Φ = 0 by Newton's method (residual ≤ 1e-10). Near a Type II
    singularity (J_x singular) small stroke rates give huge platform motion: the task is to reach a
    target pose while keeping the homogeneous inverse condition number k away from 0.

    ```
            B_3
            /\          {B}: x to the right, y up, φ counter-clockwise
        L_3/  \
          / P  \       the platform triangle P_1 P_2 P_3 hangs between the three legs
     B_1 /______\ B_2
    ```

    ## Action Space
    `Box(-1, 1, (3,), float32)`; out-of-range finite actions are clipped to [−1, 1].

    | Num | Action | Unit |
    |-----|--------|------|
    | 0-2 | stroke rate q̇_i / max_rate of leg i | 1 (×max_rate m/s) |

    Strokes stop at the limits [L_min, L_max] (hard stops): the achieved rate is the one used.

    ## Observation Space
    `Box(low, high, (18,), float32)`, finite bounds, values clipped into them.

    | Num | Observation | Unit |
    |-----|-------------|------|
    | 0-1 | platform position x, y | m |
    | 2-3 | cos φ, sin φ | 1 |
    | 4-5 | target position x*, y* | m |
    | 6-7 | cos φ*, sin φ* | 1 |
    | 8-9 | position error x* − x, y* − y | m |
    | 10 | orientation error wrap(φ* − φ) | rad |
    | 11-13 | strokes normalised to [−1, 1] over [L_min, L_max] | 1 |
    | 14-16 | stroke error (q(x*) − q) / (L_max − L_min), q(x*) the target's inverse kinematics | 1 |
    | 17 | inverse condition number k of the homogeneous Jacobian | 1 |

    ## Rewards
    r = −(w_p ‖p* − p‖ + w_φ ℓ_c |wrap(φ* − φ)|) − w_s ((k_safe − k)/k_safe)² [k < k_safe]
        − w_a ‖a‖² − P [terminated],
    with w_p = `position_weight`, w_φ = `orientation_weight`, w_s = `singularity_weight`,
    w_a = `action_weight`, P = `termination_penalty`, k_safe = `safe_threshold` and ℓ_c the
    characteristic length. Each term is in `info` (`reward_tracking`, `reward_singularity`,
    `reward_action`, `reward_termination`) and the reward is their sum.

    ## Starting State
    Start and target are drawn from the same connected component of the certified safe workspace
    (strokes inside the limits with a 2 cm margin, k ≥ k_safe; see `envs.workspace`), at least 0.1 m
    apart in (x, y, ℓ_c φ): a singularity-free path between them exists. With `targets="hard"` (or
    `reset(options={"targets": "hard"})`) the straight line from start to target in pose space also
    passes below `hard_threshold`, so a straight-line controller meets the ill-conditioned zone.
    With `targets="mixed"` each episode is hard with probability 1/2 (to train one policy for both).
    `options` may also give `"start"` and/or `"target"` poses explicitly (they must be safe).

    ## Episode End
    Termination (with the penalty P), for the first reason that applies: `newton_failed` (the
    correction did not converge; the robot stays where it was), `assembly_mode_change` (correction
    jumped more than `jump_tolerance` from the prediction), `singularity_crossed` (sign(det J_x)
    flipped), `singular` (k < `hard_threshold`), `out_of_bounds` (pose outside `pose_low`/`pose_high`).
    Truncation after 200 steps (10 s at the default dt). `info["is_success"]`: position error ≤
    `success_position_tolerance` and orientation error ≤ `success_orientation_tolerance`.
    `info["cost"]` is 1.0 while k < k_safe, else 0.0 (the safety-gymnasium convention).

    ## Arguments
    | Parameter | Type | Default | Description |
    |-----------|------|---------|-------------|
    | `render_mode` | str or None | `None` | "rgb_array" (headless) or "human" (a window) |
    | `targets` | str | `"standard"` | "standard", "hard" or "mixed" (each episode hard with probability 1/2) |
    | `base` | array (3, 2) or None | `None` | base anchors B_i [m]; None: the lesson's |
    | `platform` | array (3, 2) or None | `None` | platform points P_i [m]; None: the lesson's |
    | `characteristic_length` | float or None | `None` | ℓ_c [m]; None: farthest platform point |
    | `stroke_limits` | (float, float) | `(0.3, 1.0)` | stroke limits (L_min, L_max) [m] |
    | `pose_low` | (float, float, float) | `(-0.2, -0.3, -1.5707963267948966)` | lower pose bounds [m, m, rad] |
    | `pose_high` | (float, float, float) | `(1.2, 1.2, 1.5707963267948966)` | upper pose bounds [m, m, rad] |
    | `dt` | float | `0.05` | control period [s] |
    | `max_rate` | float | `0.25` | stroke rate of a unit action [m/s] |
    | `integrator` | str | `"euler"` | "euler" or "rk4" prediction of ẋ = J_f q̇ |
    | `safe_threshold` | float | `0.15` | k below which the penalty and the cost start |
    | `hard_threshold` | float | `0.03` | k below which the episode terminates |
    | `position_weight` | float | `1.0` | w_p [1/m] |
    | `orientation_weight` | float | `1.0` | w_φ [1/m], multiplies ℓ_c · orientation error |
    | `singularity_weight` | float | `1.0` | w_s |
    | `action_weight` | float | `0.01` | w_a |
    | `termination_penalty` | float | `50.0` | P, subtracted once at termination |
    | `success_position_tolerance` | float | `0.02` | success position error [m] |
    | `success_orientation_tolerance` | float | `0.1` | success orientation error [rad] |
    | `jump_tolerance` | float | `0.02` | largest prediction–correction gap [m] |
    | `newton_max_iterations` | int | `8` | Newton iterations per step |

    ## Version History
    * v0: Initial version.
    """

    reset_options = ("targets", "start", "target")
    target_modes = _TARGET_MODES

    def __init__(
        self,
        render_mode: str | None = None,
        targets: str = "standard",
        base: Any = None,
        platform: Any = None,
        characteristic_length: float | None = None,
        stroke_limits: tuple[float, float] = EnvParams.stroke_limits,
        pose_low: tuple[float, float, float] = EnvParams.pose_low,
        pose_high: tuple[float, float, float] = EnvParams.pose_high,
        dt: float = EnvParams.dt,
        max_rate: float = EnvParams.max_rate,
        integrator: str = EnvParams.integrator,
        safe_threshold: float = EnvParams.safe_threshold,
        hard_threshold: float = EnvParams.hard_threshold,
        position_weight: float = EnvParams.position_weight,
        orientation_weight: float = EnvParams.orientation_weight,
        singularity_weight: float = EnvParams.singularity_weight,
        action_weight: float = EnvParams.action_weight,
        termination_penalty: float = EnvParams.termination_penalty,
        success_position_tolerance: float = EnvParams.success_position_tolerance,
        success_orientation_tolerance: float = EnvParams.success_orientation_tolerance,
        jump_tolerance: float = EnvParams.jump_tolerance,
        newton_max_iterations: int = EnvParams.newton_max_iterations,
    ) -> None:
        if targets not in _TARGET_MODES:
            raise ValueError(f"targets must be one of {_TARGET_MODES}, got {targets!r}")
        self.targets = targets
        params = build_params(**_build_params_arguments(locals()))
        self._setup(render_mode, params)

    def sample_tasks(
        self, generators: Sequence[np.random.Generator], options: dict[str, Any]
    ) -> tuple[np.ndarray, Reference]:
        """Starts and fixed targets (``sample_reach``), honouring the targets/start/target options."""
        m = len(generators)
        mode = options.get("targets", self.targets)
        if mode not in _TARGET_MODES:
            raise ValueError(f"options['targets'] must be one of {_TARGET_MODES}, got {mode!r}")
        start = self._check_pose("start", options["start"]) if "start" in options else None
        target = self._check_pose("target", options["target"]) if "target" in options else None
        if start is not None and target is not None:
            if self.workspace.component_of(start) != self.workspace.component_of(target):
                raise ValueError(
                    f"start {start.tolist()} and target {target.tolist()} lie in different safe regions "
                    "(different working modes): no singularity-free path joins them"
                )
            starts, targets = np.tile(start, (m, 1)), np.tile(target, (m, 1))
        else:
            # "mixed": each episode draws its kind first, from its own generator
            hard = np.array([g.random() < 0.5 for g in generators]) if mode == "mixed" else np.full(m, mode == "hard")
            starts, targets = np.empty((m, 3)), np.empty((m, 3))
            for kind in (False, True):
                rows = np.flatnonzero(hard == kind)
                if rows.size == 0:
                    continue
                try:
                    starts[rows], targets[rows] = sample_reach(
                        self.params,
                        self.workspace,
                        [generators[i] for i in rows],
                        rows.size,
                        bool(kind),
                        start=start,
                        target=target,
                    )
                except RuntimeError as exc:
                    what = "hard" if kind else "standard"
                    raise ValueError(f"no {what} task exists for the given pose: {exc}") from exc
        reference = Reference(center=targets, radius=np.zeros(m), phase=np.zeros(m), amplitude=np.zeros(m))
        return starts, reference


class Planar3RPRTrackEnv(Planar3RPREnvBase):
    """Follow a moving target pose with a planar 3-RPR parallel robot, away from singularities.

    ## Description
    The robot and its dynamics are those of `Planar3RPRReach-v0` (strokes actuated, pose integrated
    through ẋ = J_f q̇ and corrected onto Φ(q, x) = 0). The target moves along a smooth reference:
    p*(t) = c + r (cos(ωt + θ), sin(ωt + θ)), φ*(t) = c_φ + a sin(ωt), ω = 2π / `track_period`,
    with r ∈ [0.05, 0.15] m and a ∈ [0, 0.4] rad, lying entirely in one safe region of the
    certified workspace.

    ## Action Space
    `Box(-1, 1, (3,), float32)`: stroke rates q̇_i / max_rate [1]; out-of-range finite actions are
    clipped; strokes stop at [L_min, L_max].

    ## Observation Space
    `Box(low, high, (21,), float32)`, finite bounds, values clipped into them.

    | Num | Observation | Unit |
    |-----|-------------|------|
    | 0-17 | as in `Planar3RPRReach-v0` (pose, target, error, strokes, stroke error, k) | m, 1, rad |
    | 18-19 | target velocity ẋ*, ẏ* | m/s |
    | 20 | target angular velocity φ̇* | rad/s |

    ## Rewards
    As in `Planar3RPRReach-v0`, against the moving target:
    r = −(w_p ‖p* − p‖ + w_φ ℓ_c |wrap(φ* − φ)|) − w_s ((k_safe − k)/k_safe)² [k < k_safe]
        − w_a ‖a‖² − P [terminated]; every term is in `info` and the reward is their sum.

    ## Starting State
    The robot starts at rest on the reference, at its pose for t = 0.

    ## Episode End
    Termination as in `Planar3RPRReach-v0`; truncation after 400 steps (two periods at the defaults).
    `info["is_success"]`: the tracking error is within the (looser) success tolerances at that step.

    ## Arguments
    | Parameter | Type | Default | Description |
    |-----------|------|---------|-------------|
    | `render_mode` | str or None | `None` | "rgb_array" (headless) or "human" (a window) |
    | `base` | array (3, 2) or None | `None` | base anchors B_i [m]; None: the lesson's |
    | `platform` | array (3, 2) or None | `None` | platform points P_i [m]; None: the lesson's |
    | `characteristic_length` | float or None | `None` | ℓ_c [m]; None: farthest platform point |
    | `stroke_limits` | (float, float) | `(0.3, 1.0)` | stroke limits (L_min, L_max) [m] |
    | `pose_low` | (float, float, float) | `(-0.2, -0.3, -1.5707963267948966)` | lower pose bounds [m, m, rad] |
    | `pose_high` | (float, float, float) | `(1.2, 1.2, 1.5707963267948966)` | upper pose bounds [m, m, rad] |
    | `dt` | float | `0.05` | control period [s] |
    | `max_rate` | float | `0.25` | stroke rate of a unit action [m/s] |
    | `integrator` | str | `"euler"` | "euler" or "rk4" prediction of ẋ = J_f q̇ |
    | `safe_threshold` | float | `0.15` | k below which the penalty and the cost start |
    | `hard_threshold` | float | `0.03` | k below which the episode terminates |
    | `position_weight` | float | `1.0` | w_p [1/m] |
    | `orientation_weight` | float | `1.0` | w_φ [1/m], multiplies ℓ_c · orientation error |
    | `singularity_weight` | float | `1.0` | w_s |
    | `action_weight` | float | `0.01` | w_a |
    | `termination_penalty` | float | `50.0` | P, subtracted once at termination |
    | `success_position_tolerance` | float | `0.02` | success position error [m] |
    | `success_orientation_tolerance` | float | `0.1` | success orientation error [rad] |
    | `jump_tolerance` | float | `0.02` | largest prediction–correction gap [m] |
    | `newton_max_iterations` | int | `8` | Newton iterations per step |
    | `track_period` | float | `10.0` | period of the reference [s] |

    ## Version History
    * v0: Initial version.
    """

    with_velocity = True

    def __init__(
        self,
        render_mode: str | None = None,
        base: Any = None,
        platform: Any = None,
        characteristic_length: float | None = None,
        stroke_limits: tuple[float, float] = EnvParams.stroke_limits,
        pose_low: tuple[float, float, float] = EnvParams.pose_low,
        pose_high: tuple[float, float, float] = EnvParams.pose_high,
        dt: float = EnvParams.dt,
        max_rate: float = EnvParams.max_rate,
        integrator: str = EnvParams.integrator,
        safe_threshold: float = EnvParams.safe_threshold,
        hard_threshold: float = EnvParams.hard_threshold,
        position_weight: float = EnvParams.position_weight,
        orientation_weight: float = EnvParams.orientation_weight,
        singularity_weight: float = EnvParams.singularity_weight,
        action_weight: float = EnvParams.action_weight,
        termination_penalty: float = EnvParams.termination_penalty,
        success_position_tolerance: float = EnvParams.success_position_tolerance,
        success_orientation_tolerance: float = EnvParams.success_orientation_tolerance,
        jump_tolerance: float = EnvParams.jump_tolerance,
        newton_max_iterations: int = EnvParams.newton_max_iterations,
        track_period: float = EnvParams.track_period,
    ) -> None:
        params = build_params(**_build_params_arguments(locals()))
        self._setup(render_mode, params)

    def sample_tasks(
        self, generators: Sequence[np.random.Generator], options: dict[str, Any]
    ) -> tuple[np.ndarray, Reference]:
        """References inside one safe region each (``sample_track``); the starts are their poses at t = 0."""
        m = len(generators)
        reference = sample_track(self.params, self.workspace, generators, m)
        start, _ = core.reference_pose(self.params, reference, np.zeros(m, dtype=np.int64))
        return start, reference
