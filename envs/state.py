"""The state of N robots and what a step reports: the records every part of the environments passes around.

``FamilyReference`` (the targets' trajectories), ``FamilyState`` (strokes, poses, conditioning, the robots as
built, measurements, drives, twists) and ``FamilyOutcome`` (applied actions, rates, termination reasons, efforts),
with the termination reasons, the reward terms and the ``info`` keys, and the helpers that copy states and write
rows of them. ``envs.physics`` steps them.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from envs.hardware import Measurement

__all__ = [
    "INFO_KEYS",
    "REWARD_TERMS",
    "STATE_ARRAYS",
    "TERMINATION_REASONS",
    "TYPE_I_INFO",
    "FamilyOutcome",
    "FamilyReference",
    "FamilyState",
    "copy_state",
    "put_rows",
    "state_arrays",
]

#: Termination reason codes (index) and names; 0 means the episode goes on.
TERMINATION_REASONS = (
    "",
    "newton_failed",
    "assembly_mode_change",
    "singularity_crossed",
    "singular",
    "out_of_bounds",
    "actuator_singular",
)
NEWTON_FAILED, ASSEMBLY_MODE_CHANGE, SINGULARITY_CROSSED, SINGULAR, OUT_OF_BOUNDS, ACTUATOR_SINGULAR = range(1, 7)
_REASON_NAMES = np.asarray(TERMINATION_REASONS, dtype=object)


#: The reward terms by their info keys, in the order the step sums them.
REWARD_TERMS = (
    "reward_tracking",
    "reward_singularity",
    "reward_action",
    "reward_termination",
    "reward_actuator_singularity",
    "reward_success",
)
#: The scalar entries of a single env's ``info``, in order; "is_success" becomes a bool, then come
#: "termination_reason", "pose" and "target", then the Type I entries (``TYPE_I_INFO``).
INFO_KEYS = (
    "reward_tracking",
    "reward_singularity",
    "reward_action",
    "reward_termination",
    "reward_success",
    "position_error",
    "orientation_error",
    "inverse_condition_number",
    "constraint_residual",
    "is_success",
    "cost",
    "reward_actuator_singularity",
    "actuator_condition_number",
    "cost_actuator_singularity",
)
TYPE_I_INFO = ("reward_actuator_singularity", "actuator_condition_number", "cost_actuator_singularity")


class FamilyReference(NamedTuple):
    """Target trajectories of N robots: x*_j(t) = c_j + a_j sin(ω t + θ_j), ω = 2π / track_period.

    For spatial poses the coordinates are (p, rotation vector); a reference that moves one rotation
    coordinate alone (as Track's pitch) turns about a fixed axis, where ṙ is the angular velocity. A fixed
    target (Reach) has a = 0.

    Attributes:
        center: c, shape (N, m).
        amplitude: a, shape (N, m).
        phase: θ [rad], shape (N, m).
        strokes: The actuator coordinates of c (closed-form inverse kinematics, ``constraints.strokes_batch``),
            shape (N, n), or None: ``initial_state`` fills it. The observation's stroke errors read it while a
            target is fixed, so that a crank's inverse kinematics is solved once per episode, not once per step.
    """

    center: np.ndarray
    amplitude: np.ndarray
    phase: np.ndarray
    strokes: np.ndarray | None = None


class FamilyState(NamedTuple):
    """State of N robots.

    Attributes:
        q: Leg lengths [m], shape (N, n).
        x: Platform poses of {P} in {B}, shape (N, m).
        t: Steps taken in the episode, shape (N,) (int).
        det_sign: sign(det J_x) at the start of the episode (the working mode), shape (N,).
        inverse_condition: Homogeneous inverse condition number k at (q, x) (Type II measure), shape (N,).
        actuator_condition: Actuator condition number at (q, x) (Type I measure; 1 for legs), shape (N,).
        residual: Constraint residual max_i |Φ_i| [m²], shape (N,).
        reference: The targets' trajectories.
        plant: Packed constants of each robot as built (``geometry_tolerance`` > 0: ``envs.hardware``), shape
            (N, C_SIZE), or None: every robot is the nominal one.
        sensed: What the controller measures and estimates (``observation_source="encoders"``), or None.
        drive: The drives' state (``FamilyParams.drive_shape``: the last applied action, then the delayed ones),
            shape (N, 1 + action_delay, n), or None for ideal drives.
        geometry: The codes of each robot's known geometry (``geometry_variation``: ``envs.hardware.varied_plants``,
            whose constants are then ``plant``), shape (N, 2 d²), or None.
        twist: The platform twists ẋ under force control (``kinematics.dynamics``' convention), shape (N, m), or
            None under rate control.
    """

    q: np.ndarray
    x: np.ndarray
    t: np.ndarray
    det_sign: np.ndarray
    inverse_condition: np.ndarray
    actuator_condition: np.ndarray
    residual: np.ndarray
    reference: FamilyReference
    plant: np.ndarray | None = None
    sensed: Measurement | None = None
    drive: np.ndarray | None = None
    geometry: np.ndarray | None = None
    twist: np.ndarray | None = None


#: The fields of ``FamilyState`` that hold one array each, in order (``reference`` and ``sensed`` are records).
STATE_ARRAYS = (
    "q", "x", "t", "det_sign", "inverse_condition", "actuator_condition", "residual", "plant", "drive", "geometry",
    "twist",
)  # fmt: skip


def state_arrays(state: FamilyState) -> list[np.ndarray]:
    """Every array of ``state`` (its own, its reference's and its measurement's; the absent ones left out)."""
    arrays = [getattr(state, name) for name in STATE_ARRAYS]
    arrays += list(state.reference) + (list(state.sensed) if state.sensed is not None else [])
    return [a for a in arrays if a is not None]


class FamilyOutcome(NamedTuple):
    """What a transition reports besides the new state.

    Attributes:
        action: The applied (clipped) action, shape (N, n).
        q_rate: Achieved stroke rates [m/s], shape (N, n).
        reason: Termination reason codes (``TERMINATION_REASONS``), shape (N,).
        jump: Largest prediction–correction gap ‖(δp, ℓ_c δθ)‖ [m], shape (N,) (0 under force control).
        effort: Under force control, the applied efforts τ [N, N·m for cranks], shape (N, n) (``action`` is then
            τ / τ_max and ``q_rate`` the period's mean actuator rates); else None.
        hold: Under force control, the holding forces τ_h at the period's start, shape (N, n); else None.
    """

    action: np.ndarray
    q_rate: np.ndarray
    reason: np.ndarray
    jump: np.ndarray
    effort: np.ndarray | None = None
    hold: np.ndarray | None = None


def put_rows(state: FamilyState, rows: np.ndarray | slice, values: FamilyState) -> FamilyState:
    """Write ``values`` (len(rows) robots) into the rows ``rows`` of ``state``, in place; returns ``state``.

    Both states must hold the same optional parts (``plant``, ``sensed``, ``drive``, ``geometry``).
    """
    for field, value in zip(state_arrays(state), state_arrays(values), strict=True):
        field[rows] = value
    return state


def copy_state(state: FamilyState) -> FamilyState:
    """A deep copy of ``state`` (every array copied)."""

    def copied(record):
        return None if record is None else type(record)(*(None if a is None else a.copy() for a in record))

    own = {name: None if getattr(state, name) is None else getattr(state, name).copy() for name in STATE_ARRAYS}
    return FamilyState(reference=copied(state.reference), sensed=copied(state.sensed), **own)
