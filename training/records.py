"""The record of one evaluated episode (``training.evaluate`` writes them, ``training.plots`` draws them)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

__all__ = ["EpisodeRecord"]


@dataclass
class EpisodeRecord:
    """One evaluated episode.

    Attributes:
        episode: Index (its reset seed is seed + episode).
        success: ``is_success`` at the last step.
        final_position_error_mm: Position error at the last step [mm].
        final_orientation_error_deg: Orientation error at the last step [deg].
        episode_return: Sum of rewards.
        min_inverse_condition: Smallest inverse condition number along the episode.
        singularity_termination: Whether it ended at a singularity (``training.evaluate.SINGULARITY_REASONS``).
        termination_reason: The env's termination reason ("" if none).
        cost_fraction: Fraction of steps with ``cost`` = 1.
        length: Steps taken.
        poses: Platform poses, one per step including the start, shape (length + 1, 3).
        targets: Target poses, same shape.
        inverse_condition: Inverse condition number per step, shape (length + 1,).
        tracking: For a Track environment, the tracking metrics after ``TRACKING_SETTLING_S`` (see
            ``tracking_metrics``); None otherwise.
        planner: For an agent that plans (``PlannerController``), its ``episode_metrics()`` at the episode's
            end: whether a certified path was found, planned length / straight length, the planned path's
            smallest k and the planning time [s]; None otherwise.
        time_to_target_s: Time from the reset to the end of the first step within the success tolerances [s]
            (steps × dt); None if no step was, or if the env has no ``params.dt``.
        peak_effort: Under force control, the largest |τ_i| / τ_max,i of the episode; else None.
        saturation_fraction: Under force control, the fraction of steps with a drive at its limit; else None.
        target_holding_effort: Under force control, max_i |τ_h,i| / τ_max,i at the episode's (first) target: above
            1 no drive can hold the platform still there; else None.
    """

    episode: int
    success: bool
    final_position_error_mm: float
    final_orientation_error_deg: float
    episode_return: float
    min_inverse_condition: float
    singularity_termination: bool
    termination_reason: str
    cost_fraction: float
    length: int
    poses: np.ndarray = field(repr=False)
    targets: np.ndarray = field(repr=False)
    inverse_condition: np.ndarray = field(repr=False)
    tracking: dict[str, float] | None = field(default=None, repr=False)
    planner: dict[str, float] | None = field(default=None, repr=False)
    time_to_target_s: float | None = None
    peak_effort: float | None = None
    saturation_fraction: float | None = None
    target_holding_effort: float | None = None

    def row(self) -> dict[str, Any]:
        """The scalar fields, for ``episodes.csv`` (the tracking metrics go to ``metrics.json``)."""
        skip = ("poses", "targets", "inverse_condition", "tracking", "planner")
        return {k: v for k, v in asdict(self).items() if k not in skip} | (self.planner or {})
