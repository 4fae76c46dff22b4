"""Shared helpers for the environment tests: expected registry values, info keys, rollouts and safe poses."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from envs.tasks.grid import WorkspaceMap

REPO_ROOT = Path(__file__).resolve().parents[2]


def modules_after(statement: str) -> set[str]:
    """Top-level names of the modules a fresh interpreter holds after running ``statement`` (the layering tests)."""
    code = f"import json, sys\n{statement}\nprint(json.dumps(sorted(sys.modules)))"
    done = subprocess.run([sys.executable, "-c", code], cwd=REPO_ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return {name.split(".")[0] for name in json.loads(done.stdout.splitlines()[-1])}


#: Episode length every registered id promises (README and Episode End sections).
MAX_EPISODE_STEPS = {
    "Planar3RPRReach-v0": 200,
    "Planar3RPRReachFamily-v0": 200,
    "Planar3RPRReachHard-v0": 200,
    "Planar3RPRReachMixed-v0": 200,
    "Planar3RPRTrack-v0": 400,
    "StewartGoughReach-v0": 200,
    "StewartGoughReachHard-v0": 200,
    "StewartGoughTrack-v0": 400,
    "DeltaReach-v0": 200,
    "DeltaReachHard-v0": 200,
    "DeltaTrack-v0": 400,
    "Planar3RRRReach-v0": 200,
    "Planar3RRRReachHard-v0": 200,
    "Planar3PRRReach-v0": 200,
    "ParallelRobotReach-v0": 200,
    "ParallelRobotReachHard-v0": 200,
    "ParallelRobotTrack-v0": 400,
    "Planar3RPRForceReach-v0": 200,
    "StewartGoughForceReach-v0": 200,
    "DeltaForceReach-v0": 200,
    "DeltaForceTrack-v0": 400,
    "ParallelRobotForceReach-v0": 200,
}

#: The reward terms, whose sum is the reward (the Type I term is 0 for legs; the success term 0 by default).
REWARD_TERMS = (
    "reward_tracking",
    "reward_singularity",
    "reward_action",
    "reward_termination",
    "reward_actuator_singularity",
    "reward_success",
)

#: Every key an info dict must carry (reset and step).
INFO_KEYS = (
    *REWARD_TERMS,
    "position_error",
    "orientation_error",
    "inverse_condition_number",
    "constraint_residual",
    "is_success",
    "termination_reason",
    "cost",
    "actuator_condition_number",
    "cost_actuator_singularity",
    "pose",
    "target",
)

#: Termination reasons that mean "the robot met a singularity or left its working mode".
SINGULAR_REASONS = ("singular", "singularity_crossed", "assembly_mode_change", "newton_failed")


def assert_values_equal(a: Any, b: Any, where: str) -> None:
    """Assert two observations, rewards or infos are identical (bit for bit for arrays)."""
    if isinstance(a, dict):
        assert isinstance(b, dict), f"{where}: dict vs {type(b).__name__}"
        assert a.keys() == b.keys(), f"{where}: keys {sorted(a)} vs {sorted(b)}"
        for key in a:
            assert_values_equal(a[key], b[key], f"{where}[{key!r}]")
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray), f"{where}: array vs {type(b).__name__}"
        assert a.dtype == b.dtype and np.array_equal(a, b), f"{where}: {a!r} != {b!r}"
    else:
        assert type(a) is type(b) and a == b, f"{where}: {a!r} != {b!r}"


def assert_steps_equal(a: tuple, b: tuple, where: str) -> None:
    """Assert two ``step`` (or ``reset``) results are identical element by element."""
    assert len(a) == len(b), f"{where}: {len(a)} vs {len(b)} values"
    for i, (u, v) in enumerate(zip(a, b)):
        assert_values_equal(u, v, f"{where}, item {i}")


def numeric_info_values(info: dict[str, Any]) -> dict[str, np.ndarray]:
    """The numeric entries of an info dict (floats, bools and arrays), as float arrays."""
    return {
        key: np.asarray(value, dtype=np.float64)
        for key, value in info.items()
        if isinstance(value, (float, int, bool, np.ndarray)) and not isinstance(value, str)
    }


def all_finite(obs: np.ndarray, reward: float, info: dict[str, Any]) -> bool:
    """Whether an observation, a reward and every numeric info entry are finite."""
    return (
        bool(np.all(np.isfinite(obs)))
        and math.isfinite(reward)
        and all(np.all(np.isfinite(v)) for v in numeric_info_values(info).values())
    )


def straight_line_action(env: gym.Env, target: np.ndarray) -> np.ndarray:
    """Stroke rates that move the pose along the straight line to ``target`` (q̇ = J_i Δx, saturated)."""
    unwrapped = env.unwrapped
    params = unwrapped.params
    q, x = unwrapped.state.q[0], unwrapped.state.x[0]
    q_rate = params.robot.inverse_jacobian(q, x) @ (target - x)
    peak = float(np.max(np.abs(q_rate)))
    if peak == 0.0:
        return np.zeros(q_rate.shape, dtype=np.float32)
    return (q_rate / peak * min(1.0, peak / (params.max_rate * params.dt))).astype(np.float32)


def best_node(workspace: WorkspaceMap, mask: np.ndarray) -> np.ndarray:
    """Pose of the best-conditioned grid node among ``mask`` (flat boolean over the grid), shape (3,)."""
    candidates = np.flatnonzero(mask)
    assert candidates.size, "no grid node satisfies the mask"
    best = candidates[np.argmax(workspace.safety.ravel()[candidates])]
    return workspace.nodes.reshape(-1, 3)[best].copy()


def component_node(
    workspace: WorkspaceMap,
    component: int,
    rank: int = 0,
    box: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Pose of the ``rank``-th best-conditioned node of a sampled component, inside the task box, shape (3,).

    ``box`` is (sample_low, sample_high); None: the pose bounds less two grid cells (the 3-RPR preset's task box).
    """
    spec = workspace.spec
    flat = workspace.component_nodes[int(component)]
    poses = workspace.nodes.reshape(-1, 3)[flat]
    if box is None:
        margin = 2.0 * np.asarray(spec.cell)
        box = (np.asarray(spec.pose_low) + margin, np.asarray(spec.pose_high) - margin)
    inside = np.all((poses >= np.asarray(box[0])) & (poses <= np.asarray(box[1])), axis=1)
    flat, poses = flat[inside], poses[inside]
    order = np.argsort(-workspace.safety.ravel()[flat], kind="stable")
    return poses[order[rank]].copy()


def pose_metric(params: Any) -> np.ndarray:
    """(1, 1, ℓ_c): turns a pose difference (Δx, Δy, Δφ) into metres (Δx, Δy, ℓ_c Δφ), shape (3,)."""
    return np.array([1.0, 1.0, params.robot.characteristic_length])
