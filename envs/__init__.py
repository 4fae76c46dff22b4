"""Gymnasium environments for parallel robots; importing this package registers every id in ``ENV_IDS``."""

from gymnasium.envs.registration import register, registry

from envs.env import FamilyReachEnv, FamilyTrackEnv
from envs.params import FamilyParams
from envs.presets import ROBOT_PRESETS
from envs.vector import FamilyReachVectorEnv, FamilyTrackVectorEnv, FamilyVectorEnv
from envs.wrappers import (
    GoalReachWrapper,
    PreviousActionWrapper,
    SingularityShield,
    VectorPreviousActionWrapper,
    VectorSingularityShield,
)

__all__ = [
    "ENV_IDS",
    "FORCE_IDS",
    "PLANAR_3RPR_IDS",
    "ROBOT_PRESETS",
    "FamilyParams",
    "FamilyReachEnv",
    "FamilyReachVectorEnv",
    "FamilyTrackEnv",
    "FamilyTrackVectorEnv",
    "FamilyVectorEnv",
    "GoalReachWrapper",
    "PreviousActionWrapper",
    "SingularityShield",
    "VectorPreviousActionWrapper",
    "VectorSingularityShield",
]

_REACH = ("envs.env:FamilyReachEnv", "envs.vector:FamilyReachVectorEnv")
_TRACK = ("envs.env:FamilyTrackEnv", "envs.vector:FamilyTrackVectorEnv")

#: Every registered id: its env and vector env, episode length and keyword arguments. Every id runs the same
#: env classes; a robot-named id is a preset (``envs.presets.ROBOT_PRESETS``), a task kind is an option.
_SPECS = {
    # The lesson's planar 3-RPR: tasks in the regions of its certified grid; hard targets behind the
    # ill-conditioned zone; "mixed": standard or hard at random per episode (one policy for both kinds).
    "Planar3RPRReach-v0": (*_REACH, 200, {"robot": "planar_3rpr"}),
    # One robot per episode from a family of 3-RPRs (base and platform scaled and sheared by up to ±15 %), known.
    "Planar3RPRReachFamily-v0": (*_REACH, 200, {"robot": "planar_3rpr_family"}),
    "Planar3RPRReachHard-v0": (*_REACH, 200, {"robot": "planar_3rpr", "targets": "hard"}),
    "Planar3RPRReachMixed-v0": (*_REACH, 200, {"robot": "planar_3rpr", "targets": "mixed"}),
    "Planar3RPRTrack-v0": (*_TRACK, 400, {"robot": "planar_3rpr"}),
    "StewartGoughReach-v0": (*_REACH, 200, {"robot": "stewart_gough"}),
    "StewartGoughReachHard-v0": (*_REACH, 200, {"robot": "stewart_gough_hard", "targets": "hard"}),
    "StewartGoughTrack-v0": (*_TRACK, 400, {"robot": "stewart_gough"}),
    # Crank- and slider-driven members (``kinematics.Delta``, ``Planar3RRR``, ``Planar3PRR``): Type I singularities too.
    "DeltaReach-v0": (*_REACH, 200, {"robot": "delta"}),
    "DeltaReachHard-v0": (*_REACH, 200, {"robot": "delta", "targets": "hard"}),
    # The adept cycle (25 mm up, 305 mm across, 25 mm down and back) every 4 s.
    "DeltaTrack-v0": (*_TRACK, 400, {"robot": "delta_track"}),
    "Planar3RRRReach-v0": (*_REACH, 200, {"robot": "planar_3rrr"}),
    "Planar3RRRReachHard-v0": (*_REACH, 200, {"robot": "planar_3rrr", "targets": "hard"}),
    "Planar3PRRReach-v0": (*_REACH, 200, {"robot": "planar_3prr"}),
    # Any robot of the family: ``robot=`` a preset name or a ``kinematics.DistanceConstraintMechanism`` (whose
    # bounds, task box and strokes are derived from its size unless given). The default robot is the hexapod;
    # for hard targets that need a detour, which only the 3-RPR's workspace holds (``docs/results/detour_survey``),
    # the 3-RPR.
    "ParallelRobotReach-v0": (*_REACH, 200, {}),
    "ParallelRobotReachHard-v0": (*_REACH, 200, {"targets": "hard", "robot": "planar_3rpr"}),
    "ParallelRobotTrack-v0": (*_TRACK, 400, {}),
    # Force control (``control="force"``): actions are drive efforts, offsets from the holding forces; the pose
    # follows the rigid-body dynamics (``kinematics.dynamics``, ``envs.kernels.force``).
    "Planar3RPRForceReach-v0": (*_REACH, 200, {"robot": "planar_3rpr", "control": "force"}),
    "StewartGoughForceReach-v0": (*_REACH, 200, {"robot": "stewart_gough", "control": "force"}),
    "DeltaForceReach-v0": (*_REACH, 200, {"robot": "delta", "control": "force"}),
    "DeltaForceTrack-v0": (*_TRACK, 400, {"robot": "delta_track", "control": "force"}),
    "ParallelRobotForceReach-v0": (*_REACH, 200, {"control": "force"}),
}

ENV_IDS: tuple[str, ...] = tuple(_SPECS)
#: The rate-control ids of the lesson's planar 3-RPR (the robot the shipped residual and planner policies use).
PLANAR_3RPR_IDS: tuple[str, ...] = tuple(i for i in ENV_IDS if i.startswith("Planar3RPR") and "Force" not in i)
#: The force-control ids (``control="force"``).
FORCE_IDS: tuple[str, ...] = tuple(i for i in ENV_IDS if "Force" in i)

for _env_id, (_entry_point, _vector_entry_point, _steps, _kwargs) in _SPECS.items():
    if _env_id not in registry:
        register(
            id=_env_id,
            entry_point=_entry_point,
            vector_entry_point=_vector_entry_point,
            max_episode_steps=_steps,
            kwargs=_kwargs,
        )
