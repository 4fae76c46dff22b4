"""Gymnasium environments for parallel robots; importing this package registers every id in ``ENV_IDS``."""

from gymnasium.envs.registration import register, registry

from envs.family import (
    ROBOT_PRESETS,
    FamilyReachEnv,
    FamilyReachVectorEnv,
    FamilyTrackEnv,
    FamilyTrackVectorEnv,
)
from envs.goal import GoalReachWrapper
from envs.planar_3rpr import Planar3RPRReachEnv, Planar3RPRTrackEnv
from envs.planner import PlannerResidualWrapper, PlannerWaypointWrapper
from envs.shield import SingularityShield
from envs.vector import Planar3RPRReachVectorEnv, Planar3RPRTrackVectorEnv, Planar3RPRVectorEnv

__all__ = [
    "ENV_IDS",
    "FAMILY_IDS",
    "PLANAR_3RPR_IDS",
    "FamilyReachEnv",
    "FamilyReachVectorEnv",
    "FamilyTrackEnv",
    "FamilyTrackVectorEnv",
    "GoalReachWrapper",
    "Planar3RPRReachEnv",
    "Planar3RPRReachVectorEnv",
    "Planar3RPRTrackEnv",
    "Planar3RPRTrackVectorEnv",
    "Planar3RPRVectorEnv",
    "PlannerResidualWrapper",
    "PlannerWaypointWrapper",
    "SingularityShield",
]

#: Every registered id, with its entry point, vector entry point, episode length and keyword arguments.
_SPECS = {
    "Planar3RPRReach-v0": ("envs.planar_3rpr:Planar3RPRReachEnv", "envs.vector:Planar3RPRReachVectorEnv", 200, {}),
    "Planar3RPRReachHard-v0": (
        "envs.planar_3rpr:Planar3RPRReachEnv",
        "envs.vector:Planar3RPRReachVectorEnv",
        200,
        {"targets": "hard"},
    ),
    # Standard or hard targets, one of the two at random per episode (one policy for both kinds).
    "Planar3RPRReachMixed-v0": (
        "envs.planar_3rpr:Planar3RPRReachEnv",
        "envs.vector:Planar3RPRReachVectorEnv",
        200,
        {"targets": "mixed"},
    ),
    "Planar3RPRTrack-v0": ("envs.planar_3rpr:Planar3RPRTrackEnv", "envs.vector:Planar3RPRTrackVectorEnv", 400, {}),
    # The Stewart–Gough hexapod on the family core (``envs.family``; ``robot=`` takes any other member).
    "StewartGoughReach-v0": ("envs.family:FamilyReachEnv", "envs.family:FamilyReachVectorEnv", 200, {}),
    "StewartGoughReachHard-v0": (
        "envs.family:FamilyReachEnv",
        "envs.family:FamilyReachVectorEnv",
        200,
        {"targets": "hard", **ROBOT_PRESETS["stewart_gough_hard"]},
    ),
    "StewartGoughTrack-v0": ("envs.family:FamilyTrackEnv", "envs.family:FamilyTrackVectorEnv", 400, {}),
    # Crank- and slider-driven members (``kinematics.Delta``, ``Planar3RRR``, ``Planar3PRR``): Type I singularities too.
    "DeltaReach-v0": ("envs.family:FamilyReachEnv", "envs.family:FamilyReachVectorEnv", 200, ROBOT_PRESETS["delta"]),
    "DeltaReachHard-v0": (
        "envs.family:FamilyReachEnv",
        "envs.family:FamilyReachVectorEnv",
        200,
        {"targets": "hard", **ROBOT_PRESETS["delta"]},
    ),
    # The adept cycle (25 mm up, 305 mm across, 25 mm down and back) every 4 s.
    "DeltaTrack-v0": (
        "envs.family:FamilyTrackEnv",
        "envs.family:FamilyTrackVectorEnv",
        400,
        ROBOT_PRESETS["delta_track"],
    ),
    "Planar3RRRReach-v0": (
        "envs.family:FamilyReachEnv",
        "envs.family:FamilyReachVectorEnv",
        200,
        ROBOT_PRESETS["planar_3rrr"],
    ),
    "Planar3RRRReachHard-v0": (
        "envs.family:FamilyReachEnv",
        "envs.family:FamilyReachVectorEnv",
        200,
        {"targets": "hard", **ROBOT_PRESETS["planar_3rrr"]},
    ),
    "Planar3PRRReach-v0": (
        "envs.family:FamilyReachEnv",
        "envs.family:FamilyReachVectorEnv",
        200,
        ROBOT_PRESETS["planar_3prr"],
    ),
}

ENV_IDS: tuple[str, ...] = tuple(_SPECS)
#: The planar 3-RPR ids (their own compiled kernels, ``envs.core``) and the ids on the family core (``envs.family``).
PLANAR_3RPR_IDS: tuple[str, ...] = tuple(i for i in ENV_IDS if i.startswith("Planar3RPR"))
FAMILY_IDS: tuple[str, ...] = tuple(i for i in ENV_IDS if i not in PLANAR_3RPR_IDS)

for _env_id, (_entry_point, _vector_entry_point, _steps, _kwargs) in _SPECS.items():
    if _env_id not in registry:
        register(
            id=_env_id,
            entry_point=_entry_point,
            vector_entry_point=_vector_entry_point,
            max_episode_steps=_steps,
            kwargs=_kwargs,
        )
