"""Pure batched physics of N robots: state, transition, evaluation, reward terms and the step's info.

The ``phys2d`` pattern: constants in ``envs.params.FamilyParams``, the state of N robots in arrays with a
leading dimension N, pure functions (``initial_state``, ``transition``, ``evaluate``, ``step``,
``reward_terms``) over the compiled kernels of ``envs.kernels``. The single environments (N = 1), the native
vector environment, the shield, the HER goal view and the evaluation all call them. The records they take and
return are ``envs.state``'s (also importable from here).
"""

from __future__ import annotations

import operator
from typing import Any

import numpy as np

from envs import hardware
from envs.kernels import generic as fk
from envs.params import FamilyParams
from envs.state import (
    INFO_KEYS,
    REWARD_TERMS,
    STATE_ARRAYS,
    TERMINATION_REASONS,
    FamilyOutcome,
    FamilyReference,
    FamilyState,
    copy_state,
    put_rows,
)

__all__ = [
    "INFO_KEYS",
    "REWARD_TERMS",
    "TERMINATION_REASONS",
    "FamilyOutcome",
    "FamilyReference",
    "FamilyState",
    "NonFiniteActionError",
    "StepBuffers",
    "check_state",
    "copy_state",
    "evaluate",
    "initial_state",
    "observation_bounds",
    "put_rows",
    "reward_terms",
    "step",
    "transition",
    "with_strokes",
    "wrap_angle",
]


class NonFiniteActionError(ValueError):
    """An action with a NaN or an infinity; ``rows`` holds the indices of the robots that got one."""

    def __init__(self, message: str, rows: np.ndarray) -> None:
        super().__init__(message)
        self.rows = rows


def wrap_angle(angle: np.ndarray) -> np.ndarray:
    """Wrap angles to [−π, π).

    Args:
        angle: Angles [rad], any shape.

    Returns:
        Wrapped angles [rad], same shape.
    """
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


def with_strokes(params: FamilyParams, reference: FamilyReference, parallel: bool = False) -> FamilyReference:
    """``reference`` with its ``strokes``, computed from its centres if they are missing.

    ``parallel``: as ``initial_state``.
    """
    if reference.strokes is not None:
        return reference
    strokes = fk.strokes_batch(params.packed_rows, reference.center, params.control == "force", parallel)
    return reference._replace(strokes=strokes)


def observation_bounds(params: FamilyParams, with_velocity: bool) -> tuple[np.ndarray, np.ndarray]:
    """Finite float32 bounds of the observation (layout in ``FamilyReachEnv``'s docstring).

    Args:
        params: Environment constants.
        with_velocity: Whether the target velocity is appended (Track).

    Returns:
        (low, high), read-only float32 arrays.
    """
    return params.observation_bounds[bool(with_velocity)]


def _rows(a: Any, width: int, name: str) -> np.ndarray:
    arr = np.asarray(a, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != width:
        raise ValueError(f"{name} must have shape (N, {width}), got shape {arr.shape}")
    return np.ascontiguousarray(arr)


def _actions(params: FamilyParams, state: FamilyState, action: Any, validate: bool) -> np.ndarray:
    """``action`` as the kernels take it, (N, n) float64 for the N robots of ``state`` (checked with ``validate``)."""
    n = check_state(params, state) if validate else state.q.shape[0]
    if not (type(action) is np.ndarray and action.shape == state.q.shape and action.dtype == np.float64):
        action = _rows(action, params.robot.n_actuators, "action")
        if action.shape[0] != n:
            raise ValueError(f"action must have shape {state.q.shape}, got {action.shape}")
    return action


def check_state(params: FamilyParams, state: FamilyState) -> int:
    """N, after checking that every array of ``state`` has the shape the kernels index (they do not check).

    Raises:
        ValueError: Naming every array's shape, if one of them does not fit one N and the robot's n and m.
    """
    n_rows = state.q.shape[0]
    n, m = params.robot.n_actuators, params.robot.n_pose
    ref = state.reference
    rows, pose, flat = (n_rows, n), (n_rows, m), (n_rows,)
    strokes = rows if ref.strokes is None else ref.strokes.shape
    got = (
        *(getattr(state, name).shape for name in STATE_ARRAYS[:7]),
        ref.center.shape,
        ref.amplitude.shape,
        ref.phase.shape,
        strokes,
    )
    want = (rows, pose, flat, flat, flat, flat, flat, pose, pose, pose, rows)
    optional = {
        "plant": (state.plant, (n_rows, fk.C_SIZE)),
        "drive": (state.drive, (n_rows, *(params.drive_shape or (0, n)))),
        "geometry": (state.geometry, (n_rows, 2 * params.robot.base.shape[1] ** 2)),
        "twist": (state.twist, pose),
    }
    if (state.twist is None) != (params.control != "force"):
        raise ValueError(
            f"a state under control={params.control!r} must {'' if state.twist is None else 'not '}hold twists"
        )
    if state.sensed is not None:
        optional.update(
            {
                f"sensed.{f}": (v, rows if f == "q" else pose if f == "x" else flat)
                for f, v in state.sensed._asdict().items()
            }
        )
    extra_ok = all(v is None or np.shape(v) == shape for v, shape in optional.values())
    if got != want or not extra_ok:
        shapes = {name: np.shape(getattr(state, name)) for name in STATE_ARRAYS if getattr(state, name) is not None}
        shapes.update({f"reference.{name}": np.shape(v) for name, v in zip(FamilyReference._fields, ref)})
        shapes.update({name: np.shape(v) for name, (v, _) in optional.items() if v is not None})
        raise ValueError(f"state arrays must have shapes (N, {n}), (N, {m}) or (N,) with one N, got {shapes}")
    return n_rows


def _plant(params: FamilyParams, plant: np.ndarray | None) -> np.ndarray:
    """The constants the robots move with, as the kernels take them: a read-only (N or 1, C_SIZE) array."""
    if plant is None:
        return params.packed_rows
    view = plant.view()
    view.setflags(write=False)  # one compiled signature for every caller: the kernels take read-only constants
    return view


def _model(params: FamilyParams, state: FamilyState) -> np.ndarray:
    """The constants the controllers know (the observation's and the reward's), read-only, (N or 1, C_SIZE).

    Each robot's own with a known geometry (``geometry_variation``), else the nominal ones.
    """
    return _plant(params, state.plant) if state.geometry is not None else params.packed_rows


def _with_codes(state: FamilyState, observations: np.ndarray) -> np.ndarray:
    """Write the codes of the robots' known geometries into the last columns of their observations, in place."""
    if state.geometry is not None:
        observations[:, -state.geometry.shape[1] :] = state.geometry
    return observations


def _motion(state: FamilyState) -> tuple[np.ndarray, ...]:
    """The state arrays the transition kernels take: (q, x, t, det_sign, residual)."""
    return state.q, state.x, state.t, state.det_sign, state.residual


def _force(params: FamilyParams, state: FamilyState) -> tuple[np.ndarray, ...]:
    """What the kernels take for force control: (packed inertia, twists), or () under rate control."""
    return () if state.twist is None else (params.packed_inertia, state.twist)


def initial_state(
    params: FamilyParams,
    start: np.ndarray,
    reference: FamilyReference,
    streams: np.ndarray | None = None,
    known: tuple[np.ndarray, np.ndarray] | None = None,
    strict: bool = True,
    parallel: bool = False,
) -> FamilyState:
    """State of N robots at rest at ``start`` (shape (N, m)), strokes from the nominal inverse kinematics.

    With a ``geometry_tolerance``, each robot as built is drawn from its stream (``envs.hardware``) and starts at
    the pose it assembles at for those strokes, near ``start``; with encoders, its first measurement is taken (the
    estimate starts from ``start``, the pose the controller believes). ``streams`` (``random_streams`` of the N
    generators, (N, 2)) is needed only then; the geometry is drawn before the encoder noise. With a
    ``geometry_variation``, ``known`` = (constants (N, C_SIZE), codes (N, 2 d²)) of each robot's own geometry
    (``envs.hardware.varied_plants``, drawn before its task), which its strokes and target strokes are solved with.
    A robot as built that does not assemble near ``start`` raises, or with ``strict=False`` gets residual NaN (the
    envs then draw its task again: ``FamilyEnvBase.start_episodes``). ``parallel``: solve on the multi-core
    step's kernel (``envs.kernels.modes``), as a vector env that steps on every core passes, so that it compiles
    one step only.
    """
    start = _rows(start, params.robot.n_pose, "start")
    n = len(start)
    x, plant, codes = start.copy(), None, None
    force = params.control == "force"
    if known is not None:  # each robot's own geometry
        plant, codes = known
        constants = fk.read_only(plant)  # the state keeps ``plant`` writable (``put_rows`` refills its rows)
    else:
        constants = params.packed_rows
    if reference.strokes is None:  # the targets' strokes, from the same call
        q, k, k1, det_sign, residual, strokes = fk.initial_batch(constants, start, force, parallel, reference.center)
        reference = reference._replace(strokes=strokes)
    else:
        q, k, k1, det_sign, residual = fk.initial_batch(constants, start, force, parallel)
    if streams is None and (params.geometry_tolerance or params.observation_source == "encoders"):
        raise ValueError("initial_state needs the robots' random streams with a geometry tolerance or encoders")
    if params.geometry_tolerance:
        plant = hardware.perturbed_plants(params, streams)
        x, residual, k, k1, det_sign = fk.forward_batch(_plant(params, plant), q, start, 50)
        if strict and not np.isfinite(residual).all():
            raise RuntimeError(
                f"a robot drawn within geometry_tolerance={params.geometry_tolerance} m does not assemble at the "
                f"strokes of its start pose {start[np.flatnonzero(~np.isfinite(residual))[0]].tolist()}"
            )
    drive = None if params.drive_shape is None else np.zeros((n, *params.drive_shape))
    t = np.zeros(n, dtype=np.int64)
    twist = np.zeros((n, params.robot.n_pose)) if params.control == "force" else None
    state = FamilyState(q, x, t, det_sign, k, k1, residual, reference, plant, None, drive, codes, twist)
    if params.observation_source == "encoders":
        state = state._replace(sensed=hardware.sense(params, q, start, streams, _model(params, state)))
    return state


def transition(
    params: FamilyParams, state: FamilyState, action: np.ndarray, *, validate: bool = True
) -> tuple[FamilyState, FamilyOutcome]:
    """Advance N robots by one control period: predict, correct, measure, terminate.

    Under force control, the efforts of the action move (x, ẋ) by the equations of motion instead
    (``envs.kernels.force``). Under rate control, strokes advance by the clipped action (through the drives, if
    limited or delayed) · max_rate · dt, clamped
    to the hard stops (of each robot as built, with a geometry tolerance); the step is split into
    substeps of at most ``max_substep`` of predicted motion; each predicts the pose with the twist
    J_f(q, x) q̇ (Euler or RK4, on the rotation group) and corrects it onto Φ = 0 by Newton's method. A robot
    whose correction fails stays where it was; the others are checked for an assembly-mode jump, a flip of
    sign(det J_x), k < hard_threshold and leaving the pose bounds, in that order.

    It runs the step's own compiled kernel, told not to evaluate (``fk.transition_batch``): an env that has
    compiled its step compiles nothing more to look a period ahead (the shield).

    Args:
        params: Environment constants.
        state: The robots' state.
        action: Normalised stroke rates, shape (N, n), finite.
        validate: Check the state's shapes (``check_state``). The shield passes False after its first call on a
            state.

    Returns:
        (the new state, the outcome); the new state has no measurement (``sensed`` None): ``step`` takes one.
    """
    action = _actions(params, state, action, validate)
    if not np.isfinite(action).all():
        rows = np.flatnonzero(~np.isfinite(action).all(axis=-1))
        raise NonFiniteActionError(f"action must be finite, got {action[rows[0]].tolist()}", rows)
    drive = state.drive
    if drive is not None:
        action, drive = hardware.drive(params, drive, action)
    force = _force(params, state)
    moved = fk.transition_batch(_plant(params, state.plant), _motion(state), action, force)
    twist = effort = hold = None
    if force:
        moved, (twist, effort, hold) = moved
    q, x, k, k1, residual, a, q_rate, reason, jump = moved
    new = FamilyState(
        q, x, state.t + 1, state.det_sign, k, k1, residual, state.reference, state.plant, None, drive, state.geometry,
        twist,
    )  # fmt: skip
    return new, FamilyOutcome(a, q_rate, reason, jump, effort, hold)


def evaluate(
    params: FamilyParams,
    state: FamilyState,
    action: np.ndarray,
    reason: np.ndarray,
    with_velocity: bool,
    rates: np.ndarray | None = None,
    parallel: bool = False,
    validate: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Reward terms, errors, success, cost, targets and observations of a state, in one compiled pass.

    Args:
        params: Environment constants.
        state: The robots' state.
        action: The applied actions, shape (N, n).
        reason: Termination reason codes, shape (N,).
        with_velocity: Whether the observation ends with the target velocity.
        rates: Under force control, the actuator rates the observation holds, shape (N, n) (None: at rest).
        parallel: Compute with the multi-core step's kernel (``fk.evaluate_batch``): a vector env that steps
            on every core passes True, so that it compiles one step only.
        validate: Check the state's shapes (``check_state``). The envs pass False for the states that
            ``initial_state`` just made.

    Returns:
        (evaluation (rows of ``params.evaluation_rows``, N) float64, observations (N, D) float32). The evaluation
        (reward, errors, success, ``info``) is of the true state; the observations are of the measurement
        ``state.sensed`` where there is one (encoders), else of the true state.
    """
    action = _rows(action, params.robot.n_actuators, "action")
    reason = np.asarray(reason, dtype=np.int64)
    n = check_state(params, state) if validate else state.q.shape[0]
    if action.shape[0] != n or reason.shape != (n,):
        raise ValueError(f"action and reason must have {n} rows, got shapes {action.shape} and {reason.shape}")
    low, high = observation_bounds(params, with_velocity)
    ref = with_strokes(params, state.reference, parallel)
    measured = (state.q, state.x, state.t, state.inverse_condition, state.actuator_condition, state.residual)
    outcome = (action, reason)
    if state.twist is not None:
        outcome += (state.twist, np.zeros_like(state.q) if rates is None else _rows(rates, state.q.shape[1], "rates"))
    observation = (low, high, bool(with_velocity))
    model = _model(params, state)
    evaluation, observations = fk.evaluate_batch(model, observation, measured, tuple(ref), outcome, parallel)
    if state.sensed is not None:
        observations = _sensed_observations(params, state, observation, ref, outcome, parallel)
    return evaluation, _with_codes(state, observations)


def _sensed_observations(
    params: FamilyParams,
    state: FamilyState,
    observation: tuple,
    reference: FamilyReference,
    outcome: tuple,
    parallel: bool,
) -> np.ndarray:
    """The observations of N robots from what their controllers measure (``state.sensed``), shape (N, D)."""
    sensed = state.sensed
    measured = (sensed.q, sensed.x, state.t, sensed.k, sensed.k1, state.residual)
    return fk.evaluate_batch(_model(params, state), observation, measured, tuple(reference), outcome, parallel)[1]


def reward_terms(
    params: FamilyParams,
    x: np.ndarray,
    target: np.ndarray,
    inverse_condition: np.ndarray,
    action: np.ndarray,
    reason: np.ndarray,
    actuator_condition: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """Every term of the reward of N poses against fixed targets (what HER's ``compute_reward`` calls).

    Args:
        params: Environment constants.
        x: Poses, shape (N, m).
        target: Target poses, shape (N, m).
        inverse_condition: k, shape (N,).
        action: Applied actions, shape (N, n).
        reason: Termination reason codes, shape (N,) (a terminated step has no success term).
        actuator_condition: k_I, shape (N,) (default 1: no Type I penalty, as for legs).

    Returns:
        The ``REWARD_TERMS``, each shape (N,); ``reward_success`` is ``success_reward`` where reason is 0 and x is
        within the success tolerances of target, else 0.
    """
    m = params.robot.n_pose
    x, target = _rows(x, m, "x"), _rows(target, m, "target")
    n = len(x)
    k = np.asarray(inverse_condition, dtype=np.float64).reshape(n)
    k1 = np.ones(n) if actuator_condition is None else np.asarray(actuator_condition, dtype=np.float64).reshape(n)
    ref = FamilyReference(target, np.zeros((n, m)), np.zeros((n, m)))
    strokes = np.full((n, m), np.mean(params.stroke_limits))
    twist = np.zeros((n, m)) if params.control == "force" else None
    state = FamilyState(strokes, x, np.zeros(n, dtype=np.int64), np.ones(n), k, k1, np.zeros(n), ref, twist=twist)
    evaluation, _ = evaluate(params, state, action, reason, False)
    rows = params.evaluation_rows
    return {name: evaluation[rows[name]].copy() for name in REWARD_TERMS}


class StepBuffers:
    """Output arrays of ``step`` for N robots, reused by every step (an env alternates two of them)."""

    def __init__(self, params: FamilyParams, n: int, with_velocity: bool) -> None:
        obs_dim = observation_bounds(params, with_velocity)[0].shape[0]
        self.arrays = fk.allocate_step(n, params.robot.n_pose, obs_dim)
        q, x, t, k, k1, residual, a, q_rate, reason, jump, evaluation, observations = self.arrays
        self.outcome = FamilyOutcome(a, q_rate, reason, jump)
        self.evaluation, self.observations = evaluation, observations
        self.fields = (q, x, t, k, k1, residual)
        self.shape = (n, params.robot.n_pose, obs_dim)
        self.kernels = fk.path_kernels(params.packed)  # the compiled step of the robot's row path
        #: Force control's outputs (twists, efforts, holding forces), or ().
        self.force = () if params.control != "force" else tuple(np.empty((n, params.robot.n_pose)) for _ in range(3))
        self.one_thread = self.kernels.one_thread(bool(self.force))  # the kernel of a one-thread step
        if self.force:
            self.outcome = self.outcome._replace(effort=self.force[1], hold=self.force[2])
        #: The step's ``StepCall`` into these buffers (one thread or every core), and what it reads (``call_for``).
        self._call: fk.StepCall | None = None
        self._reads: tuple = (object(),)

    def __getstate__(self) -> dict[str, Any]:
        """Pickled (and copied) without the ``StepCall``, which the next step builds again."""
        return self.__dict__ | {"_call": None, "_reads": (object(),)}

    def call_for(
        self, params: FamilyParams, state: FamilyState, reference: FamilyReference, observation: tuple
    ) -> fk.StepCall:
        """The ``StepCall`` that steps ``state`` (with ``reference``) into these buffers.

        ``observation`` is (low, high, with_velocity) of ``observation_bounds``, whose cached ``low`` tells
        ``with_velocity``. The call is built when the arrays it reads change (an env's reset), else the one built
        before is returned: every step of an episode reads the arrays the step before wrote, in the other buffers.
        """
        reads = (observation[0], *_motion(state), state.twist, reference, state.plant, state.geometry)
        if not all(map(operator.is_, reads, self._reads)):
            model, plant, motion, force = self.arguments(params, state)
            threads = fk.uses_every_core(self.shape[0])
            self._call = fk.step_call(
                model, plant, observation, motion, tuple(reference), self.arrays, force, threads=threads
            )
            self._reads = reads
        return self._call

    def arguments(self, params: FamilyParams, state: FamilyState) -> tuple:
        """(model, plant, motion, force) of the compiled step of ``state`` into these buffers (``fk.step_call``)."""
        return _model(params, state), _plant(params, state.plant), _motion(state), _force(params, state) + self.force


def step(
    params: FamilyParams,
    state: FamilyState,
    action: np.ndarray,
    with_velocity: bool,
    out: StepBuffers | None = None,
    *,
    validate: bool = True,
    streams: np.ndarray | None = None,
) -> tuple[FamilyState, FamilyOutcome, np.ndarray, np.ndarray]:
    """``transition`` then ``evaluate``, fused in one compiled pass (on every core for large N).

    Args:
        params: Environment constants.
        state: The robots' state.
        action: Normalised stroke rates (force control: offsets from the holding forces in units of the drive
            limits), shape (N, n), float64.
        with_velocity: Whether the observation ends with the target velocity.
        out: Buffers to write into (none of them may hold ``state``), or None.
        validate: Check the state's and the buffers' shapes (``check_state``). The envs pass False for the
            state they hold, which ``initial_state`` and ``step`` made with the right shapes.
        streams: ``random_streams`` of the N robots' generators, shape (N, 2): the encoder noise is drawn from
            them (needed with ``observation_source="encoders"`` only).

    Returns:
        (new state, outcome, evaluation, observations).

    Raises:
        NonFiniteActionError: If an action is not finite (``state`` is untouched).
    """
    if validate or action.shape != state.q.shape or action.dtype != np.float64:  # the envs' actions skip the call
        action = _actions(params, state, action, validate)
    n = state.q.shape[0]
    if out is None:
        out = StepBuffers(params, n, with_velocity)
    elif validate and out.shape != (n, params.robot.n_pose, observation_bounds(params, with_velocity)[0].shape[0]):
        raise ValueError(f"out holds buffers of shape (N, m, D) = {out.shape}, the step needs N = {n}")
    parallel = fk.uses_every_core(n)
    ref = with_strokes(params, state.reference, parallel)
    low, high = observation_bounds(params, with_velocity)
    observation = (low, high, bool(with_velocity))
    drive = state.drive
    if drive is not None:  # the drives hold actions back: check them before they are queued
        if not np.isfinite(action).all():
            _non_finite(action)
        action, drive = hardware.drive(params, drive, action)
    if state.twist is not None and (state.plant is not None or state.sensed is not None) and state.geometry is None:
        plant = _plant(params, state.plant)
        action = hardware.known_holding_actions(params, state.q, state.x, state.sensed, plant, action, parallel)
    call = out.call_for(params, state, ref, observation)  # the call the buffers keep
    if parallel:
        failed = fk.step_on_every_core(out.kernels, call, action)
    else:
        failed = out.one_thread(call, action)
    if failed:
        _non_finite(action)
    q, x, t, k, k1, residual = out.fields
    twist = out.force[0] if out.force else None
    new = FamilyState(q, x, t, state.det_sign, k, k1, residual, ref, state.plant, None, drive, state.geometry, twist)
    if params.observation_source == "encoders":
        if streams is None:
            raise ValueError("step needs the robots' random streams (streams=) with observation_source='encoders'")
        new = new._replace(sensed=hardware.sense(params, q, state.sensed.x, streams, _model(params, state)))
        outcome = (out.outcome.action, out.outcome.reason)
        if twist is not None:  # the controller's twist and rates: the period's differences of its measurements
            outcome += hardware.sensed_motion(params, state.sensed, new.sensed)
        out.observations[:] = _sensed_observations(params, new, observation, ref, outcome, parallel)
    return new, out.outcome, out.evaluation, _with_codes(new, out.observations)


def _non_finite(action: np.ndarray) -> None:
    """Raise ``NonFiniteActionError`` naming the rows of ``action`` (N, n) that hold a NaN or an infinity."""
    rows = np.flatnonzero(~np.isfinite(action).all(axis=-1))
    where = f" (row(s) {rows[:10].tolist()} of {len(action)})" if len(action) > 1 else ""
    raise NonFiniteActionError(f"action must be finite, got {action[rows[0]].tolist()}{where}", rows)
