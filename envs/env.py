"""The Gymnasium environments of every robot: ``FamilyReachEnv`` and ``FamilyTrackEnv``, one robot each.

A robot is a ``kinematics.DistanceConstraintMechanism`` given as data or a preset's name
(``envs.presets.ROBOT_PRESETS``); a task kind is an option of the parameters (``envs.params.FamilyParams``).
Both envs step through ``envs.physics``; ``envs.vector`` batches N of them.
"""

from __future__ import annotations

import operator
from collections import deque
from collections.abc import Sequence
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from envs import hardware
from envs.info import force_info_of_one, measurement_info
from envs.kernels import generic as fk
from envs.params import RENDER_MODE, ROBOT, TARGET_MODES, TARGETS, FamilyParams, Parameter, arguments_table
from envs.physics import StepBuffers, evaluate, initial_state, observation_bounds, step
from envs.presets import build_family_params
from envs.rendering import HumanWindow, render_family_frame
from envs.state import (
    INFO_KEYS,
    TERMINATION_REASONS,
    TYPE_I_INFO,
    FamilyOutcome,
    FamilyReference,
    FamilyState,
    copy_state,
    put_rows,
)
from envs.tasks import grid_kernels
from envs.tasks.grid import WorkspaceMap

__all__ = ["TRAIL_LENGTH", "FamilyEnvBase", "FamilyReachEnv", "FamilyTrackEnv", "render_frames"]

#: Poses kept for the drawn trail.
TRAIL_LENGTH = 200
#: Most draws of a task and a robot as built before ``start_episodes`` gives up (see there).
START_ATTEMPTS = 100


def render_frames(params: FamilyParams, state: FamilyState, trails: Sequence[Sequence[np.ndarray]]) -> list[np.ndarray]:
    """The frames (``envs.rendering.render_family_frame``) of the N robots of ``state``, robot i with ``trails[i]``."""
    n = state.q.shape[0]
    action, reason = np.zeros_like(state.q), np.zeros(n, dtype=np.int64)
    evaluation, _ = evaluate(params, state, action, reason, False, parallel=fk.uses_every_core(n))
    target = evaluation[params.evaluation_rows["target"]].T
    return [
        render_family_frame(
            params.robot,
            state.x[i],
            target[i],
            float(state.inverse_condition[i]),
            safe_threshold=params.safe_threshold,
            hard_threshold=params.hard_threshold,
            view_low=params.pose_low,
            view_high=params.pose_high,
            trail=list(trails[i]),
            step=int(state.t[i]),
            q=state.q[i],
        )
        for i in range(n)
    ]


def _in_place(held: FamilyState | None, fresh: FamilyState) -> FamilyState:
    """``fresh`` written into the arrays of ``held``, the state the env's last step left (as the vector env restarts).

    The step's calls into its two buffers (``StepBuffers.call_for``) read those arrays, so they stay valid across
    the reset instead of being built again at its first steps. ``fresh`` itself where there is no such state.
    """
    return fresh if held is None else put_rows(held, slice(None), fresh)


class FamilyEnvBase(gym.Env[np.ndarray, np.ndarray]):
    """Shared machinery of the single-robot family environments; see ``FamilyReachEnv`` for the documentation."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["human", "rgb_array"], "render_fps": 20}
    with_velocity = False
    reset_options: tuple[str, ...] = ()
    #: The constructor's named arguments (``envs.params``: documented and checked there); FamilyParams' follow.
    named_arguments: tuple[Parameter, ...] = ()

    def _setup(self, render_mode: str | None, params: FamilyParams) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        self.render_mode = render_mode
        self.params = params
        self.metadata = {**type(self).metadata, "render_fps": 1.0 / params.dt}
        n = params.robot.n_actuators
        self.action_space = spaces.Box(-1.0, 1.0, shape=(n,), dtype=np.float32)
        low, high = observation_bounds(params, self.with_velocity)
        self.observation_space = spaces.Box(low.copy(), high.copy(), dtype=np.float32)
        self._state: FamilyState | None = None
        self._streams: np.ndarray | None = None
        self._buffers = (StepBuffers(params, 1, self.with_velocity), StepBuffers(params, 1, self.with_velocity))
        self._next = 0
        self._action = np.zeros((1, params.robot.n_actuators))
        self._terminated = False
        self._trail: deque[np.ndarray] = deque(maxlen=TRAIL_LENGTH)
        rows = params.evaluation_rows
        self._reward_row, self._saturated_row = rows["reward"], rows["saturated"]
        # info's scalars in its key order (the Type I entries last) and its pose and target (adjacent rows)
        self._info_names = tuple(name for name in INFO_KEYS if name not in TYPE_I_INFO)
        self._info_values = operator.itemgetter(*(rows[name] for name in self._info_names))
        self._type_i_values = operator.itemgetter(*(rows[name] for name in TYPE_I_INFO))
        pose, target = rows["pose"], rows["target"]
        self._pose_target = np.r_[pose, target]  # one gather, two views
        self._n_pose = pose.stop - pose.start
        self._window: HumanWindow | None = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start a new episode (see the class docstring, Starting State)."""
        super().reset(seed=seed)
        options = {} if options is None else options
        if not isinstance(options, dict):
            raise TypeError(f"options must be a dict or None, got {type(options).__name__}")
        unknown = set(options) - set(self.reset_options)
        if unknown:
            raise ValueError(f"unknown reset option(s) {sorted(unknown)}; valid options are {list(self.reset_options)}")
        self._streams = fk.random_streams((self.np_random,)) if self.params.random_hardware else None
        self._state = _in_place(self._state, self.start_episodes((self.np_random,), options, self._streams))
        self._terminated = False
        self._trail.clear()
        if self.render_mode is not None:  # the trail is drawn only
            self._trail.append(self.params.robot.pose_space.position(self._state.x[0]).copy())
        n = self.params.robot.n_actuators
        evaluation, observations = evaluate(
            self.params, self._state, np.zeros((1, n)), np.zeros(1, dtype=np.int64), self.with_velocity, validate=False
        )
        if self.render_mode == "human":
            self.render()
        return observations[0], self._info(evaluation[:, 0], 0, None)[0]

    def step(self, action: Any):
        """Apply normalised stroke rates for one period dt (see the class docstring)."""
        if self._state is None:
            raise gym.error.ResetNeeded("Cannot call step() before reset()")
        if self._terminated:
            raise gym.error.ResetNeeded("The episode has terminated; call reset() before step()")
        a = self._action  # (1, n) float64, read by the step only
        if type(action) is np.ndarray and action.shape == a.shape[1:] and action.dtype.kind == "f":
            a[0] = action
        else:
            n = self.params.robot.n_actuators
            try:
                given = np.asarray(action, dtype=np.float64)
            except (TypeError, ValueError) as exc:
                raise TypeError(f"action must be an array of {n} real numbers, got {action!r}") from exc
            if given.shape != (n,):
                raise ValueError(f"action must have shape ({n},), got shape {given.shape}")
            a[0] = given
        out = self._buffers[self._next]
        state, outcome, evaluation, observations = step(
            self.params, self._state, a, self.with_velocity, out, validate=False, streams=self._streams
        )
        self._next ^= 1
        self._state = state
        reason = outcome.reason.item()
        self._terminated = reason != 0
        info, reward = self._info(evaluation[:, 0], reason, outcome)
        if self.render_mode is not None:
            self._trail.append(self.params.robot.pose_space.position(info["pose"]).copy())
        if self.render_mode == "human":
            self.render()
        return observations[0].copy(), reward, self._terminated, False, info

    def render(self):
        """An RGB frame (``rgb_array``, headless), or a window update (``human``); None without a render mode."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array'")
            return None
        if self._state is None:
            raise gym.error.ResetNeeded("Cannot call render() before reset()")
        frame = render_frames(self.params, self._state, [self._trail])[0]
        if self.render_mode == "rgb_array":
            return frame
        if self._window is None:
            self._window = HumanWindow(self.metadata["render_fps"])
        self._window.show(frame)
        return None

    def close(self) -> None:
        """Close the window of ``human`` rendering, if open."""
        if self._window is not None:
            self._window.close()
            self._window = None
        super().close()

    @property
    def workspace(self) -> WorkspaceMap | None:
        """The certified grid tasks are drawn from (``task_region="grid"``), else None."""
        return self.params.workspace

    @property
    def state(self) -> FamilyState | None:
        """A copy of the current batched state (N = 1), or None before the first reset."""
        return None if self._state is None else copy_state(self._state)

    def _info(self, row: np.ndarray, reason: int, outcome: FamilyOutcome | None) -> tuple[dict[str, Any], float]:
        """(info, reward) of the robot's evaluation column ``row`` (see the class docstring's Info)."""
        v = row.tolist()
        info = dict(zip(self._info_names, self._info_values(v)))
        info["is_success"] = info["is_success"] != 0.0
        info["termination_reason"] = TERMINATION_REASONS[reason]
        pose_target = row[self._pose_target]
        info["pose"], info["target"] = pose_target[: self._n_pose], pose_target[self._n_pose :]
        info.update(zip(TYPE_I_INFO, self._type_i_values(v)))
        state = self._state
        if state.sensed is not None:
            for name, value in measurement_info(state).items():
                info[name] = float(value[0]) if value.ndim == 1 else value[0]
        if state.twist is not None:
            force_info_of_one(self.params, state, outcome, info)
            info["saturated"] = v[self._saturated_row] != 0.0
        return info, v[self._reward_row]

    def start_episodes(
        self,
        generators: Sequence[np.random.Generator],
        options: dict[str, Any],
        streams: np.ndarray | None = None,
        parallel: bool = False,
    ) -> FamilyState:
        """The state at t = 0 of M new episodes, episode i drawn from the i-th generator (its stream ``streams[i]``).

        In this order, from each generator: the robot's own geometry (``geometry_variation``), the task
        (``sample_tasks``), the robot as built (``geometry_tolerance``), the first encoder reading. A robot as
        built that does not assemble near its task's start pose at the nominal strokes (near a singularity a
        millimetre can move the pose by a tenth of a radian, or out of reach) draws its task and itself again,
        from the same generator. The single env and the vector env both start episodes here; a vector env that
        steps on every core passes ``parallel`` (``physics.initial_state``).

        Raises:
            RuntimeError: If a robot as built still does not assemble after ``START_ATTEMPTS`` draws.
        """
        params = self.params
        if streams is None and params.random_hardware:
            streams = fk.random_streams(generators)
        rows, state = np.arange(len(generators)), None
        for _ in range(START_ATTEMPTS):
            own = None if streams is None else streams[rows]
            known = hardware.varied_plants(params, own) if params.geometry_variation else None
            drawn = [generators[i] for i in rows]
            start, reference = self.sample_tasks(drawn, options, own, None if known is None else known[0])
            fresh = initial_state(
                params, start, reference, own if params.random_hardware else None, known, False, parallel
            )
            state = fresh if state is None else put_rows(state, rows, fresh)
            unassembled = ~np.isfinite(fresh.residual)
            if not unassembled.any():
                return state
            rows = rows[unassembled]
        raise RuntimeError(
            f"robots drawn within geometry_tolerance={params.geometry_tolerance} m did not assemble near the start "
            f"pose of {START_ATTEMPTS} tasks in a row; give a smaller tolerance"
        )

    def sample_tasks(
        self,
        generators: Sequence[np.random.Generator],
        options: dict[str, Any],
        streams: np.ndarray | None = None,
        constants: np.ndarray | None = None,
    ) -> tuple[np.ndarray, FamilyReference]:
        """Draw one task per generator in one compiled call (start poses (M, m) and references).

        Args:
            generators: The M generators, task i drawn from the i-th.
            options: Reset options.
            streams: ``envs.kernels.setup.random_streams(generators)``, shape (M, 2), if the caller keeps them
                (the vector env holds one row per sub-environment); None computes them.
            constants: Each robot's own packed constants (M, C_SIZE) to certify its task on (``geometry_variation``),
                or None: the nominal robot's.
        """
        raise NotImplementedError


class FamilyReachEnv(FamilyEnvBase):
    r"""Reach a target pose with any parallel robot of the distance-constraint family, away from singularities.

    ## Description
    Leg i of the robot (``kinematics.DistanceConstraintMechanism``, by default the Stewart–Gough hexapod
    ``kinematics.StewartGough()``) keeps the platform point P_i at the distance q_i from the base anchor B_i:
    Φ_i = ‖p + R P_i − B_i‖² − q_i² = 0. Each step the leg lengths q move at the commanded rates; the pose
    follows through the twist J_f q̇, J_f = −J_x⁻¹ J_q (Euler or RK4 on the rotation group: R ← exp([ω h]×) R),
    and is corrected onto Φ = 0 by Newton's method (residual ≤ 1e-10, in substeps of ≤ 1 cm of predicted
    motion). Near a Type II singularity (J_x singular; for the hexapod, Fichter's: centred and turned by
    ±90° about the vertical) small stroke rates give huge platform motion.

    Cranks and sliders (the Delta ``DeltaReach-v0``, the planar 3-RRR ``Planar3RRRReach-v0``, the 3-PRR
    ``Planar3PRRReach-v0``; ``robot=`` takes a mechanism or a name of ``ROBOTS``) move their link's end
    A_i(q_i) = B_i + a_i (cos q_i u_i + sin q_i v_i) + q_i e_i, Φ_i = ‖p + R P_i − A_i‖² − l_i², and bring Type I
    singularities (J_q singular: a link in line with its crank or square to its rail), measured by the actuator
    condition number k_I.

    ```
        ___P___      {P}: platform frame; pose x = (p [m], rotation vector r [rad]) of {P} in {B}
       /  / \\  \\     six legs B_i → P_i, lengths q_i actuated
      B__B   B__B    {B}: base frame, z up
    ```

    ## Action Space
    `Box(-1, 1, (n,), float32)`: actuator rates q̇_i / max_rate (m/s for legs and sliders, rad/s for cranks);
    actuators stop at `stroke_limits` (the joint limits).

    Under force control (`control="force"`, the `*ForceReach`/`*ForceTrack` ids) the action is each drive's
    effort as an offset from the holding force τ_h (J_iᵀ τ_h = G(x), gravity, at the pose the period starts at;
    clipped to ±τ_max): τ = clip(τ_h + a (τ_max + |τ_h|), −τ_max, τ_max) (`envs.kernels.force.efforts_of_actions`)
    [N for legs and sliders, N·m for cranks], held for dt: a zero action holds a platform at rest still, ±1
    reaches either drive limit. The controller's τ_h is the nominal model's at the pose it knows (with encoders,
    its estimate; the observed twist and rates are then differences of its measurements over the period). The
    platform moves by the rigid-body dynamics M(x) ẍ + c(x, ẋ) + G(x) = J_iᵀ τ (``kinematics.dynamics``: masses
    and inertias `inertia`, `gravity`), integrated by RKMK4 on the pose space with q from the closed-form inverse
    kinematics (Φ at round-off); episodes start at rest. `info` adds `actuator_forces` (τ), `holding_forces`
    (the robot's own τ_h at its true pose) and `saturated` (a drive at its limit), and the action penalty is on
    the applied efforts τ / τ_max.

    ## Observation Space
    `Box(low, high, (D,), float32)` with finite bounds; spatial robots (D = 33, or 39 with Track's velocity):

    | Num | Observation | Unit |
    |-----|-------------|------|
    | 0-2 | platform position p | m |
    | 3-6 | orientation quaternion (w, x, y, z), w ≥ 0 | 1 |
    | 7-9 | target position p* | m |
    | 10-13 | target quaternion, w ≥ 0 | 1 |
    | 14-16 | position error p* − p | m |
    | 17-19 | orientation error: rotation vector of R* Rᵀ (in {B}) | rad |
    | 20-25 | leg lengths normalised to [−1, 1] over the stroke limits | 1 |
    | 26-31 | stroke error (q(x*) − q) / (q_max − q_min) | 1 |
    | 32 | inverse condition number k | 1 |
    | 33-38 | (Track) target velocity ẋ* = (ṗ*, ṙ*) | m/s, rad/s |

    Planar robots: (x, y, cos φ, sin φ), the target likewise, (x* − x, y* − y, wrap(φ* − φ)), strokes,
    stroke errors, k (D = 18). Translational robots (the Delta): p, p*, p* − p, strokes, stroke errors, k (D = 16;
    19 with Track's velocity). With `geometry_variation` (`Planar3RPRReachFamily-v0`) the observation ends with the
    2 d² codes of the episode's robot in [−1, 1] (`envs.hardware.varied_plants`; D = 26 for planar robots), and the
    stroke errors and k are that robot's. With `observation_source="encoders"` the pose, strokes and k are the
    measured and estimated ones (`envs.hardware`; the true pose is `info["pose"]`). Under force control the
    platform twist ẋ (m entries: (ẋ, ẏ, φ̇), ṗ, or (v, ω) in {B}) and the period's mean actuator rates (n) follow
    k, each clipped to ±4 times its range per second (`envs.params.FAST`).

    ## Rewards
    r = −(w_p ‖p* − p‖ + w_o ℓ_c θ_err) − w_s ((k_safe − k)/k_safe)² [k < k_safe] − w_a ‖a‖² − P [terminated],
    − w_s1 ((k_I,safe − k_I)/k_I,safe)² [k_I < k_I,safe] + b [success], with θ_err the angle of R* Rᵀ (the Type I
    term is 0 for legs; b = `success_reward`, 0 by default, is paid at every step that ends with
    `info["is_success"]`). Each term is in `info` (the last as `info["reward_success"]`) and the reward is their
    sum; `info["cost"]` = 1 while k < k_safe or k_I < k_I,safe, and `info["cost_actuator_singularity"]` = 1 while
    k_I < k_I,safe (the Type I part alone).

    ## Starting State
    Tasks are certified, not guessed (a 6-D pose space cannot be gridded): start and target are drawn
    uniformly in the task box (`sample_low`–`sample_high`, rotation-vector coordinates), each *safe* (strokes
    within the limits less 2 cm, k ≥ k_safe), at least `min_distance` apart in (δp, ℓ_c δθ). A *standard*
    target is kept only when the geodesic from the start (p linear, R along one rotation) is safe at points
    at most `segment_spacing` apart with one sign of det J_x at all of them, so a singularity-free path is known
    (the spacing, 1 cm by default, is capped per robot so that the safety cannot fall by more than half the
    margin k_safe − k_hard between two checked points: `envs.presets.certificate_spacing`; 0.5 mm on the
    3-RRR, 1.1 mm on the 3-PRR). A *hard* target is kept
    only when that geodesic dips below `safe_threshold` (staying inside the box and the stroke limits) and a
    waypoint is found whose two geodesics
    start → waypoint → target are safe at the same spacing: a detour is known, the straight line is not safe.
    With `hard_kind="ill_conditioned"` (the hard ids of the hexapod, the Delta and the 3-RRR, whose workspaces
    have no detour tasks: `docs/results/detour_survey`) a hard target lies in the ill-conditioned band
    2 `hard_threshold` ≤ k < `safe_threshold` (toward Fichter's singularity; for the Delta, at the outer, lower edge
    of its workspace), on a geodesic from a safe start that keeps k ≥ 2 `hard_threshold`. For cranks and sliders
    "safe" and the path's k are min(k, k_I k_safe / k_I,safe), both kinds of singularity (the band is on k).
    With `task_region="grid"` (the 3-RPR ids), start and target are instead drawn in one connected safe region
    of the certified grid (``envs.tasks.grid``), at least `min_distance` apart; its hard targets
    (`hard_kind="crossing"`) are those whose straight line from the start dips below `hard_threshold`, while the
    region certifies a detour. `reset(options={"targets": "hard"})` switches for one episode; with the grid,
    `options` may also give a `"start"` and/or a `"target"` pose (safe, in one region).

    ## Episode End
    Termination (penalty P), first applicable: `newton_failed`, `assembly_mode_change` (prediction and
    correction more than `jump_tolerance` apart), `singularity_crossed` (sign(det J_x) flipped),
    `singular` (k < `hard_threshold`), `out_of_bounds` (under force control also a stroke past its hard stop),
    and for cranks and sliders `actuator_singular` (the Type I measure below `actuator_hard_threshold`). Under
    force control `newton_failed` means that the state stopped being finite (a link that cannot reach).
    Truncation after the registered 200 steps.
    `info["is_success"]`: position error ≤ `success_position_tolerance` and orientation error ≤
    `success_orientation_tolerance`.

    {arguments}

    ## Version History
    * v0: Initial version.
    """

    reset_options = ("targets", "start", "target")
    target_modes = TARGET_MODES
    named_arguments = (RENDER_MODE, TARGETS, ROBOT)

    def __init__(
        self, render_mode: str | None = None, targets: str = "standard", robot: Any = None, **kwargs: Any
    ) -> None:
        self.targets = TARGETS.check("targets", targets, {})
        self._setup(render_mode, build_family_params(robot, **kwargs))

    def sample_tasks(
        self,
        generators: Sequence[np.random.Generator],
        options: dict[str, Any],
        streams: np.ndarray | None = None,
        constants: np.ndarray | None = None,
    ) -> tuple[np.ndarray, FamilyReference]:
        """Certified start/target pairs, one per generator (see the class docstring, Starting State).

        "mixed" draws each episode's kind first (hard with probability 1/2, from its own generator).
        """
        mode = options.get("targets", self.targets)
        if mode not in TARGET_MODES:
            raise ValueError(f"options['targets'] must be one of {TARGET_MODES}, got {mode!r}")
        params = self.params
        n, m = len(generators), params.robot.n_pose
        start = self._fixed_pose("start", options["start"]) if "start" in options else None
        target = self._fixed_pose("target", options["target"]) if "target" in options else None
        if start is not None and target is not None:
            workspace = params.workspace
            if workspace is not None and workspace.component_of(start) != workspace.component_of(target):
                raise ValueError(
                    f"start {start.tolist()} and target {target.tolist()} lie in different safe regions "
                    "(different working modes): no singularity-free path joins them"
                )
            self.last_waypoints = np.tile(target, (n, 1))
            return np.tile(start, (n, 1)), FamilyReference(np.tile(target, (n, 1)), np.zeros((n, m)), np.zeros((n, m)))
        if streams is None:
            streams = fk.random_streams(generators)
        if mode != "mixed":
            starts, targets, waypoints = self._draw(streams, n, mode == "hard", start, target, constants)
        else:  # each episode draws its kind first, from its own generator
            hard = np.array([g.random() < 0.5 for g in generators])
            starts, targets, waypoints = np.empty((n, m)), np.empty((n, m)), np.empty((n, m))
            for kind in (False, True):
                rows = np.flatnonzero(hard == kind)
                if rows.size:
                    starts[rows], targets[rows], waypoints[rows] = self._draw(
                        streams[rows], rows.size, kind, start, target, None if constants is None else constants[rows]
                    )
        self.last_waypoints = waypoints
        return starts, FamilyReference(targets, np.zeros((n, m)), np.zeros((n, m)))

    def _draw(
        self,
        streams: np.ndarray,
        n: int,
        hard: bool,
        start: np.ndarray | None,
        target: np.ndarray | None,
        constants: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Certified pairs of one kind, one per stream: (starts, targets, waypoints), each (n, m)."""
        params = self.params
        if constants is not None:  # each robot's task certified on its own geometry
            if start is not None or target is not None:
                raise ValueError("reset options 'start' and 'target' are not available with a geometry_variation")
            m = params.robot.n_pose
            rows = [
                fk.sample_reach_batch(constants[i], streams[i : i + 1], 1, m, hard, params.min_distance)
                for i in range(n)
            ]
            found = None if any(r is None for r in rows) else tuple(np.concatenate(c) for c in zip(*rows))
        elif params.workspace is not None:
            fixed_kind, fixed = (1, start) if start is not None else ((2, target) if target is not None else (0, None))
            found = grid_kernels.sample_reach_batch(
                params.packed, params.workspace.packed, streams, n, hard, params.min_distance, fixed_kind, fixed
            )
            if found is not None:
                found = (*found, found[1])
        elif start is not None or target is not None:
            raise ValueError("reset options 'start' and 'target' alone need task_region='grid'; give both")
        else:
            found = fk.sample_reach_batch(params.packed, streams, n, params.robot.n_pose, hard, params.min_distance)
        if found is None:
            what = "hard" if hard else "standard"
            if start is not None or target is not None:
                raise ValueError(f"no {what} task exists for the given pose")
            hint = (
                f" (hard_kind={params.hard_kind!r}: this robot's task box may hold no such pair; try another "
                "hard_kind or a wider sample_low / sample_high)"
                if hard
                else ""
            )
            raise RuntimeError(f"no certified {what} task found in the task box after {fk.SAMPLER_TRIES} tries{hint}")
        return found

    def _fixed_pose(self, name: str, value: Any) -> np.ndarray:
        """A start or target pose given in ``reset`` options, checked to be finite and safe."""
        m = self.params.robot.n_pose
        try:
            pose = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"options[{name!r}] must be a pose of {m} numbers, got {value!r}") from exc
        if pose.shape != (m,) or not np.isfinite(pose).all():
            raise ValueError(f"options[{name!r}] must be {m} finite numbers, got {value!r}")
        safe = fk.safe_batch(self.params.packed, pose[None])[0]
        if safe and self.params.workspace is not None:
            safe = bool(np.isin(self.params.workspace.component_of(pose), self.params.workspace.component_ids))
        if not safe:
            raise ValueError(
                f"options[{name!r}] = {pose.tolist()} is not in the certified safe set (the task box, strokes "
                f"within the limits less {self.params.stroke_margin}, k ≥ {self.params.safe_threshold})"
            )
        return pose


class FamilyTrackEnv(FamilyEnvBase):
    """Follow a moving target with any robot of the distance-constraint family (a motion-simulator reference).

    ## Description
    As ``FamilyReachEnv``, but the target moves: x*_j(t) = c_j + a_j sin(2π t / track_period + θ_j) for each
    pose coordinate, or, with a `track_path`, along a closed polyline once per `track_period`, at rest at each
    vertex (the Delta's `DeltaTrack-v0`: the adept cycle ``ADEPT_CYCLE``, 25 mm up, 305 mm across, 25 mm down
    and back, in a random horizontal direction, every 4 s). With the hexapod's defaults the reference combines
    surge (x, ≤ 5 cm), heave (z, ≤ 4 cm)
    and pitch (rotation about y, ≤ 0.1 rad): a motion-simulator cue. The centre, amplitudes (½–1 of
    `track_amplitude`) and phases are drawn so that the whole period stays in the safe set (checked at points
    ≤ 1 cm apart). The observation ends with the target velocity. Truncation after the registered 400 steps.

    ## Action Space
    As ``FamilyReachEnv``.

    ## Observation Space
    As ``FamilyReachEnv``, plus the target velocity (m values).

    ## Rewards
    As ``FamilyReachEnv``.

    ## Starting State
    The platform starts on the reference at t = 0.

    ## Episode End
    As ``FamilyReachEnv`` (400 steps).

    {arguments}

    ## Version History
    * v0: Initial version.
    """

    with_velocity = True
    named_arguments = (RENDER_MODE, ROBOT)

    def __init__(self, render_mode: str | None = None, robot: Any = None, **kwargs: Any) -> None:
        self._setup(render_mode, build_family_params(robot, **kwargs))

    def sample_tasks(
        self,
        generators: Sequence[np.random.Generator],
        options: dict[str, Any],
        streams: np.ndarray | None = None,
        constants: np.ndarray | None = None,
    ) -> tuple[np.ndarray, FamilyReference]:
        """References whose whole period is safe, one per generator; the start is the reference at t = 0."""
        params = self.params
        if constants is not None:
            raise ValueError("geometry_variation is available for Reach tasks only")
        n, m = len(generators), params.robot.n_pose
        if streams is None:
            streams = fk.random_streams(generators)
        if params.track_shape == "circle":
            steps = int(np.ceil(params.track_period / params.dt))
            radii, angles = params.track_radius_range, params.track_angle_range
            found = grid_kernels.sample_circle_batch(
                params.packed, params.workspace.packed, streams, n, radii, angles, steps
            )
        else:
            found = fk.sample_track_batch(params.packed, streams, n, m, params.track_amplitude, 64)
        if found is None:
            raise RuntimeError(f"no safe reference found in the task box after {fk.SAMPLER_TRIES} tries")
        center, amplitude, phase = found
        start, _ = fk.reference_batch(params.packed, np.zeros(n, dtype=np.int64), center, amplitude, phase)
        return start, FamilyReference(center, amplitude, phase)


for _cls in (FamilyReachEnv, FamilyTrackEnv):  # the Arguments tables, from the arguments' metadata
    if _cls.__doc__:  # None under python -OO
        _cls.__doc__ = _cls.__doc__.replace("    {arguments}", arguments_table(_cls.named_arguments))
