"""The ``info`` of the environments' steps: the evaluation's entries, the encoders' and force control's.

``step_info`` gives the per-robot arrays of a batch in the single env's key order (the vector env's layout is
built from them); ``measurement_info`` and ``force_info`` are the entries of ``observation_source="encoders"`` and
of ``control="force"``, which the single env reads too.
"""

from __future__ import annotations

import numpy as np

from envs.kernels import modes
from envs.kernels.force import actions_of_efforts, efforts_of_actions
from envs.params import FamilyParams
from envs.state import _REASON_NAMES, INFO_KEYS, TYPE_I_INFO, FamilyOutcome, FamilyState

__all__ = [
    "actions_of_efforts",
    "efforts_of_actions",
    "force_info",
    "force_info_of_one",
    "measurement_info",
    "step_info",
]


def measurement_info(state: FamilyState) -> dict[str, np.ndarray]:
    """The info entries of what the controllers measure, per robot (empty without encoders).

    ``estimated_pose`` (N, m): the pose estimated from the encoders; ``estimate_inverse_condition_number`` (N,):
    k there (what the observation holds); ``measured_strokes`` (N, n): the encoder readings.
    """
    if state.sensed is None:
        return {}
    sensed = state.sensed
    return {
        "estimated_pose": sensed.x.copy(),
        "estimate_inverse_condition_number": sensed.k.copy(),
        "measured_strokes": sensed.q.copy(),
    }


def force_info(
    params: FamilyParams, state: FamilyState, outcome: FamilyOutcome | None, parallel: bool = False
) -> dict[str, np.ndarray]:
    """The info entries of force control's efforts, per robot (empty under rate control).

    ``actuator_forces`` (N, n): the applied efforts τ; ``holding_forces`` (N, n): τ_h at the period's start (at the
    start pose when ``outcome`` is None: an episode's start, at rest, τ = 0; ``parallel``: solved on the
    multi-core step's kernel, ``envs.kernels.modes``). ``saturated`` (a drive at its limit) is an entry of the
    evaluation (``step_info``).
    """
    if state.twist is None:
        return {}
    if outcome is None:
        hold = modes.holding_batch(params.packed_rows, params.packed_inertia, state.q, state.x, parallel)
        return {"actuator_forces": np.zeros_like(hold), "holding_forces": hold}
    return {"actuator_forces": outcome.effort.copy(), "holding_forces": outcome.hold.copy()}


def force_info_of_one(
    params: FamilyParams, state: FamilyState, outcome: FamilyOutcome | None, info: dict[str, object]
) -> None:
    """Write ``force_info`` of one robot (the single env's) into ``info``, as it holds them: (n,) arrays."""
    if outcome is None:
        for name, value in force_info(params, state, None).items():
            info[name] = value[0]
    else:  # at every step: no dict of its own
        info["actuator_forces"] = outcome.effort[0].copy()
        info["holding_forces"] = outcome.hold[0].copy()


def step_info(
    params: FamilyParams,
    evaluation: np.ndarray,
    reason: np.ndarray,
    state: FamilyState | None = None,
    outcome: FamilyOutcome | None = None,
    parallel: bool = False,
) -> dict[str, np.ndarray]:
    """Per-robot info arrays (leading dimension N) from an evaluation, in the single env's key order.

    ``INFO_KEYS`` in order (``is_success`` as bools, the reasons as names, pose and target as (N, m)), the Type I
    entries last, then ``measurement_info(state)``, and under force control ``force_info(params, state, outcome)``
    and ``saturated`` (the evaluation's row, as bools), if a state is given (``parallel``: as ``force_info``).
    """
    rows = params.evaluation_rows
    info = {name: evaluation[rows[name]].copy() for name in INFO_KEYS if name not in TYPE_I_INFO}
    info["is_success"] = info["is_success"] != 0.0
    info["termination_reason"] = _REASON_NAMES[reason]
    info["pose"] = evaluation[rows["pose"]].T.copy()
    info["target"] = evaluation[rows["target"]].T.copy()
    for name in TYPE_I_INFO:
        info[name] = evaluation[rows[name]].copy()
    if state is not None:
        info.update(measurement_info(state))
        if state.twist is not None:
            info.update(force_info(params, state, outcome, parallel))
            info["saturated"] = evaluation[rows["saturated"]] != 0.0
    return info
